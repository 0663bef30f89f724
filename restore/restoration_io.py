"""``restoration.nc``: its writer, its reader, and the checks of what is read back.

:func:`restoration_dataset` writes a :class:`~restore.result.RestorationResult`;
:func:`read_restoration` reads it back into the same type, so a consumer (the
report, a study) works from what the pipeline did, never re-deriving it.

A restoration that cannot belong to its product (another length, other line
times), that lost variables (truncated, edited), or that holds nothing
(every restored sample NaN) is refused with one line naming the file and the
variable, never drawn.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import xarray as xr

from simsat.product import ProductError

from .axis_integration import PriorSpectrum
from .knowledge_check import KnowledgeCheck
from .stages import sigma_limit
from .result import IntegrationRecord, PairData, RestorationResult
from .settings import RestorationSettings, settings_dict
from .synthesis import AXES

__all__ = ["open_restoration", "check_restoration", "restoration_dataset", "read_restoration",
           "result_from_dataset", "REQUIRED_VARIABLES", "REQUIRED_ATTRS"]
REQUIRED_VARIABLES = tuple(f"{p}{a}" for a in AXES for p in ("", "knowledge_", "correction_", "diff_")) + (
    "time", "pair", "tau_s")
REQUIRED_ATTRS = ("pixel_ifov_rad", "settings", "method")


def open_restoration(path: str | Path):
    """Load ``restoration.nc`` (no check of its content: see :func:`check_restoration`).

    Raises
    ------
    ProductError
        The file is not readable NetCDF (truncated, corrupt).
    """
    p = Path(path)
    try:
        return xr.load_dataset(p, engine="netcdf4")
    except Exception as e:
        raise ProductError(f"{p}: cannot read as NetCDF ({type(e).__name__}: {e}); "
                           f"run `simsat restore` again") from None


def check_restoration(ds, path: str | Path, *, product_time: np.ndarray) -> list[str]:
    """Refuse a restoration that does not belong to its product or holds nothing.

    Parameters
    ----------
    ds : xarray.Dataset
        The restoration as read.
    path : path
        Its file, for the messages.
    product_time : ndarray
        Line times of the product [s].

    Returns
    -------
    list of str
        The restored axes (from the recorded settings).

    Raises
    ------
    ProductError
        Naming the file and the variable or attribute at fault.
    """
    p = Path(path)
    for name in REQUIRED_VARIABLES:
        if name not in ds.variables:
            raise ProductError(f"{p}: no variable {name!r} (a truncated or foreign file); run `simsat restore` again")
    for name in REQUIRED_ATTRS:
        if name not in ds.attrs:
            raise ProductError(f"{p}: no global attribute {name!r}; run `simsat restore` again")
    try:
        settings = json.loads(str(ds.attrs["settings"]))
    except json.JSONDecodeError:
        raise ProductError(f"{p}: attribute 'settings' is not JSON; run `simsat restore` again") from None
    if not isinstance(settings, dict):
        raise ProductError(f"{p}: attribute 'settings' must be a JSON object")
    ifov = ds.attrs["pixel_ifov_rad"]
    try:
        ok = float(ifov) > 0 and np.isfinite(float(ifov))
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise ProductError(f"{p}: attribute 'pixel_ifov_rad' must be a finite angle > 0 [rad], got {ifov!r}")
    t = np.asarray(ds["time"].values, dtype=np.float64)
    pt = np.asarray(product_time, dtype=np.float64)
    if t.shape != pt.shape:
        raise ProductError(f"{p}: variable 'time' has {t.size} lines but the product has {pt.size}: "
                           f"this restoration belongs to another product; run `simsat restore` again")
    if not np.allclose(t, pt, rtol=0, atol=1e-9):
        raise ProductError(f"{p}: variable 'time' differs from the product's line times "
                           f"(by up to {np.nanmax(np.abs(t - pt)):.3g} s): another product; run `simsat restore` again")
    axes = [a for a in settings.get("axes", ["roll", "pitch"]) if a in AXES]
    if not axes:
        raise ProductError(f"{p}: attribute 'settings' names no restored axis")
    for a in axes:
        v = np.asarray(ds[a].values, dtype=np.float64)
        if v.shape != t.shape:
            raise ProductError(f"{p}: variable {a!r} has shape {v.shape}, expected ({t.size},) like 'time'")
        if not np.isfinite(v).any():
            raise ProductError(f"{p}: variable {a!r} is NaN on every line: nothing was restored on this axis "
                               f"(no usable match); see the restore command's messages")
        kn = np.asarray(ds[f"knowledge_{a}"].values, dtype=np.float64)
        if kn.shape != t.shape or not np.isfinite(kn).all():
            raise ProductError(f"{p}: variable 'knowledge_{a}' must be finite on every line")
    n_pairs = int(np.atleast_1d(ds["pair"].values).size)
    for a in AXES:
        shape = tuple(ds[f"diff_{a}"].shape)
        if shape != (n_pairs, t.size):
            raise ProductError(f"{p}: variable 'diff_{a}' has shape {shape}, expected ({n_pairs} pairs, {t.size} lines)")
    return axes


# --------------------------------------------------------------------------- writer
_MATCH_FIELDS = ("line_a", "col_a", "meas_line_b", "meas_col_b", "pred_line_b", "pred_col_b", "quality", "std_line",
                 "std_col", "corr_line_col")


def _match_variables(pairs: list) -> dict:
    """The matches of every pair, concatenated along ``match`` (``match_pair`` says whose)."""
    data = {}
    cols = {k: [] for k in _MATCH_FIELDS}
    mp, valid, inl = [], [], []
    for i, p in enumerate(pairs):
        mp.append(np.full(p.valid.size, i, dtype=np.int16))
        for k in cols:
            v = getattr(p, k)
            cols[k].append(np.full(p.valid.size, np.nan) if v is None else np.asarray(v, dtype=np.float64))
        valid.append(p.valid)
        inl.append(p.inlier if p.inlier is not None else np.zeros(p.valid.size, bool))
    data["match_pair"] = ("match", np.concatenate(mp) if mp else np.zeros(0, np.int16))
    for k, v in cols.items():
        attrs = ({"units": "1", "long_name": "normalised correlation of the match"} if k == "quality"
                 else {"units": "1", "long_name": "correlation of the match's line and column errors"}
                 if k == "corr_line_col" else {"units": "px"})
        data[f"match_{k}"] = ("match", np.concatenate(v) if v else np.zeros(0), attrs)
    data["match_valid"] = ("match", np.concatenate(valid).astype(np.int8))
    data["match_inlier"] = ("match", np.concatenate(inl).astype(np.int8))
    data["match_residual_line"] = ("match", data["match_meas_line_b"][1] - data["match_pred_line_b"][1],
                                   {"units": "px"})
    data["match_residual_col"] = ("match", data["match_meas_col_b"][1] - data["match_pred_col_b"][1], {"units": "px"})
    return data


def _integration_variables(res: RestorationResult) -> tuple[dict, dict]:
    """Per restored axis, the inputs and output of its last integration (over all pairs; NaN: pair not used)."""
    data, coords = {}, {}
    names = [p.name for p in res.pairs]
    n = res.time.size
    for a, rec in res.integration.items():
        idx = [names.index(nm) for nm in rec.pairs]

        def full(x, fill=np.nan):
            out = np.full((len(names), n), fill)
            out[idx] = x
            return out
        data[f"integrated_diff_{a}"] = (("pair", "time"), full(rec.diffs), {
            "units": "rad", "long_name": f"{a} differentials as integrated (gaps dropped / filled, window compensated)"})
        data[f"integrated_sigma_{a}"] = (("pair", "time"), full(rec.sigmas), {"units": "rad"})
        data[f"line_lag_{a}"] = (("pair", "time"), full(rec.lags_s), {
            "units": "s", "long_name": "extra delay of the pair at each line (time synchronisation)"})
        data[f"line_weight_{a}"] = (("pair", "time"), full(rec.weights), {"long_name": "relative weight of the line"})
        tau = np.full(len(names), np.nan)
        tau[idx] = rec.taus
        data[f"integrated_tau_{a}"] = ("pair", tau, {"units": "s", "long_name": "actual delay τ′ integrated with"})
        data[f"increment_{a}"] = ("time", rec.increment, {"units": "rad", "long_name": "last integration's output"})
        data[f"previous_estimate_{a}"] = ("time", rec.previous, {"units": "rad"})
        if rec.spectrum is not None:
            coords[f"prior_freq_{a}"] = (f"prior_freq_{a}", rec.spectrum.freq, {"units": "Hz"})
            data[f"prior_psd_{a}"] = (f"prior_freq_{a}", rec.spectrum.psd, {
                "units": "rad2 s", "long_name": "PSD prior the method estimated from the data (two-sided)"
                + (", given the AOCS knowledge" if rec.knowledge_conditioned else "")})
            nstd = np.full(len(names), np.nan)
            nstd[idx] = rec.spectrum.noise_std
            attrs = {"units": "rad"}
            if rec.spectrum.tones is not None:  # the blind-frequency tone found through the lags
                attrs.update(blind_tone_hz=np.asarray(rec.spectrum.tones[0], dtype=np.float64),
                             blind_tone_prior_sd_rad=float(rec.spectrum.tones[1]))
                if len(rec.spectrum.tones) > 2:
                    attrs["blind_tone_order"] = int(rec.spectrum.tones[2])
                if len(rec.spectrum.tones) > 3 and rec.spectrum.tones[3] is not None:  # each tone's sweep rate
                    attrs["blind_tone_chirp_hz_per_s"] = np.asarray(rec.spectrum.tones[3], dtype=np.float64)
            data[f"prior_noise_std_{a}"] = ("pair", nstd, attrs)
            if rec.spectrum.noise_colour is not None:  # the noise colour the MAP weighed the residual with
                fc, col = rec.spectrum.noise_colour
                full_col = np.full((len(names), len(fc)), np.nan)
                full_col[idx] = col
                coords[f"colour_freq_{a}"] = (f"colour_freq_{a}", np.asarray(fc, dtype=np.float64), {"units": "Hz"})
                data[f"prior_noise_colour_{a}"] = (("pair", f"colour_freq_{a}"), full_col, {
                    "long_name": "each pair's noise power relative to white, as the MAP weighed its residual"})
    return data, coords


def restoration_dataset(res: RestorationResult) -> xr.Dataset:
    """The ``restoration.nc`` dataset of a result (read back by :func:`read_restoration`)."""
    data = {}
    for a in AXES:
        data[a] = ("time", res.restored[a], {"units": "rad", "long_name": f"restored line-of-sight {a}",
                                             "coverage": res.coverage[a]})
        data[f"knowledge_{a}"] = ("time", res.knowledge[a], {"units": "rad"})
        data[f"correction_{a}"] = ("time", res.correction[a], {"units": "rad"})
        if a in res.knowledge_smoothing:
            data[f"knowledge_smoothing_{a}"] = (
                "time", res.knowledge_smoothing[a],
                {"units": "rad", "long_name": f"part of correction_{a} that smooths the AOCS knowledge's noise below "
                                              "the high-pass (restore.knowledge_smoothing)"})
        if a in res.knowledge_dephasing:
            data[f"knowledge_dephasing_{a}"] = (
                "time", res.knowledge_dephasing[a],
                {"units": "rad", "long_name": f"part of correction_{a} that takes the causal AOCS filter's phase and the "
                                              "latency the images measured out of the knowledge "
                                              "(restore.knowledge_dephasing, restore.knowledge_timing)"})
    names = [p.name for p in res.pairs]
    for k, a in enumerate(AXES):
        data[f"diff_{a}"] = (("pair", "time"), np.stack([p.synthesis.diff[:, k] for p in res.pairs]),
                             {"units": "rad", "long_name": f"per-line {a} differential θ(t+τ)−θ(t) (remaining error)"})
        data[f"diff_sigma_{a}"] = (("pair", "time"), np.stack([p.synthesis.sigma[:, k] for p in res.pairs]),
                                   {"units": "rad", "long_name": "formal 1-sigma of the differential"})
    w = np.stack([p.synthesis.n_points for p in res.pairs]).astype(np.int32)
    data["diff_points"] = (("pair", "time"), w, {"long_name": "inlier matches per line (synthesis weight)"})
    data["tau_s"] = ("pair", np.array([p.tau_s for p in res.pairs]), {"units": "s", "long_name": "actual delay τ′"})
    data["nominal_tau_s"] = ("pair", np.array([p.nominal_tau_s if p.nominal_tau_s is not None else np.nan
                                               for p in res.pairs]), {"units": "s"})
    data["residual_rms_px"] = ("pair", np.array([p.residual_rms_px for p in res.pairs]), {"units": "px"})
    data.update(_match_variables(res.pairs))
    integ, coords = _integration_variables(res)
    data.update(integ)
    attrs = {"title": "simsat restoration", "method": res.method, "pixel_ifov_rad": res.pixel_ifov_rad,
             "pairs": ",".join(names), "settings": json.dumps(settings_dict(res.settings), sort_keys=True),
             "timings": json.dumps(res.timings, sort_keys=True),
             "misregistration": json.dumps(res.misregistration, sort_keys=True),
             "anchored_on_star_tracker": int(res.anchored),
             "yaw_pitch_coupling": float(res.yaw_pitch_coupling),
             "yaw_roll_coupling": float(res.yaw_roll_coupling),
             "knowledge_latency": json.dumps(res.knowledge_latency, sort_keys=True),
             "integration": json.dumps({a: {"pairs": rec.pairs, "method": rec.method, "options": rec.options,
                                            "highpass_hz": rec.highpass_hz, "line_period_s": rec.line_period_s,
                                            "unobservable_rms_rad": rec.unobservable_rms_rad,
                                            "floor_rms_rad": rec.floor_rms_rad, "selection": rec.selection,
                                            "knowledge_conditioned": bool(rec.knowledge_conditioned),
                                            "knowledge_band_hz": (None if rec.knowledge_band_hz is None else
                                                                  [float(v) for v in rec.knowledge_band_hz])}
                                        for a, rec in res.integration.items()}, sort_keys=True)}
    for a in AXES:
        attrs[f"coverage_{a}"] = res.coverage[a]
    for a, sg in res.sigma.items():
        data[f"sigma_{a}"] = ("time", sg, {"units": "rad", "long_name": f"predicted 1-sigma of the restored {a}",
                                           "noise_scale": float(res.noise_scale.get(a, 1.0)),
                                           "band_noise_shares": json.dumps(res.band_shares.get(a, {}),
                                                                           sort_keys=True),
                                           "predicted_detrended_rms_rad": float(res.detrended_rms.get(a, np.nan)),
                                           "flag_limit_rad": float(res.flag_limits[a][0]) if a in res.flag_limits
                                           else sigma_limit(sg, res.settings.max_sigma_px, res.pixel_ifov_rad),
                                           "flag_judged_on": res.flag_limits[a][1] if a in res.flag_limits
                                           else "reported",
                                           "knowledge_check": json.dumps(res.knowledge_checks[a].as_dict()
                                                                         if a in res.knowledge_checks else {},
                                                                         sort_keys=True),
                                           "conditioned_excess": json.dumps(
                                               res.conditioned_excess[a].as_dict()
                                               if a in getattr(res, "conditioned_excess", {}) else {},
                                               sort_keys=True)})
        data[f"flagged_{a}"] = ("time", np.asarray(res.flagged.get(a, np.zeros(sg.size, bool)), dtype=np.int8), {
            "long_name": f"1: {a} not restored, predicted sigma above restoration.max_sigma_px"})
    for a, fu in getattr(res, "knowledge_fusion", {}).items():
        data[f"knowledge_fusion_weight_{a}"] = ("time", np.asarray(fu.weight, dtype=np.float64), {
            "long_name": f"weight of the AOCS knowledge's band in the restored {a} (0: the images' estimate kept; "
                         "restore.knowledge_fusion)", "band_top_hz": float(fu.band_top_hz),
            "lines_kept_hz": np.asarray(getattr(fu, "lines_kept_hz", ()), dtype=np.float64)})
        data[f"knowledge_fusion_variance_{a}"] = ("time", np.asarray(fu.knowledge_band_rad2, dtype=np.float64), {
            "units": "rad2", "long_name": "the knowledge's expected error variance in the band, per line"})
    coords.update({"time": ("time", res.time, {"units": "s"}), "pair": ("pair", np.array(names))})
    return xr.Dataset(data, coords=coords, attrs=attrs)


# --------------------------------------------------------------------------- reader
def _sigma_records_from(ds, key: str, cls) -> dict:
    """``{axis: cls.from_dict(...)}`` of the JSON attribute ``key`` recorded on the ``sigma_<axis>`` variables
    (none in older files)."""
    out = {}
    for a in AXES:
        if f"sigma_{a}" in ds.variables:
            d = json.loads(ds[f"sigma_{a}"].attrs.get(key, "{}") or "{}")
            if d:
                out[a] = cls.from_dict(d)
    return out


def _knowledge_checks_from(ds) -> dict:
    """``{axis: KnowledgeCheck}`` recorded on the ``sigma_<axis>`` variables (none in older files)."""
    return _sigma_records_from(ds, "knowledge_check", KnowledgeCheck)


def _conditioned_excess_from(ds) -> dict:
    """``{axis: ConditionedExcess}`` recorded on the ``sigma_<axis>`` variables (none in older files)."""
    from .conditioned_excess import ConditionedExcess

    return _sigma_records_from(ds, "conditioned_excess", ConditionedExcess)


def _knowledge_fusion_from(ds) -> dict:
    """``{axis: KnowledgeFusion}`` recorded as ``knowledge_fusion_weight_<axis>`` (none in older files)."""
    from .knowledge_fusion import KnowledgeFusion

    out = {}
    for a in AXES:
        if f"knowledge_fusion_weight_{a}" in ds.variables:
            w = _values(ds, f"knowledge_fusion_weight_{a}")
            v = _values(ds, f"knowledge_fusion_variance_{a}")
            attrs = ds[f"knowledge_fusion_weight_{a}"].attrs
            out[a] = KnowledgeFusion(weight=w, band_top_hz=float(attrs.get("band_top_hz", np.nan)),
                                     knowledge_band_rad2=v, added_rad2=w * v,
                                     lines_kept_hz=tuple(float(f) for f in np.atleast_1d(attrs.get("lines_kept_hz", ()))))
    return out


def _values(ds, name, dtype=np.float64):
    return np.asarray(ds[name].values, dtype=dtype) if name in ds.variables else None


def _pairs_from(ds) -> list[PairData]:
    names = [str(x) for x in np.atleast_1d(ds["pair"].values)]
    mp = _values(ds, "match_pair", np.int64)
    out = []
    for j, name in enumerate(names):
        ahead, behind = name.split("/")
        sel = mp == j if mp is not None else np.zeros(0, bool)
        f = {k: (v[sel] if (v := _values(ds, f"match_{k}")) is not None else None) for k in _MATCH_FIELDS}
        valid = (_values(ds, "match_valid", np.int8)[sel] != 0) if mp is not None else np.zeros(0, bool)
        inl = (_values(ds, "match_inlier", np.int8)[sel] != 0) if "match_inlier" in ds.variables else None
        nom = _values(ds, "nominal_tau_s")
        rms = _values(ds, "residual_rms_px")
        out.append(PairData(name=name, ahead=ahead, behind=behind, tau_s=float(ds["tau_s"].values[j]),
                            line_a=f["line_a"], col_a=f["col_a"], meas_line_b=f["meas_line_b"],
                            meas_col_b=f["meas_col_b"], quality=f["quality"], valid=valid,
                            pred_line_b=f["pred_line_b"], pred_col_b=f["pred_col_b"], inlier=inl,
                            std_line=f["std_line"], std_col=f["std_col"], corr_line_col=f["corr_line_col"],
                            nominal_tau_s=None if nom is None or not np.isfinite(nom[j]) else float(nom[j]),
                            residual_rms_px=float("nan") if rms is None else float(rms[j])))
    return out


def _records_from(ds, info: dict) -> dict:
    names = [str(x) for x in np.atleast_1d(ds["pair"].values)]
    out = {}
    for a, meta in info.items():
        if f"integrated_diff_{a}" not in ds.variables:
            continue
        idx = [names.index(nm) for nm in meta["pairs"]]
        spec = None
        if f"prior_psd_{a}" in ds.variables:
            spec = PriorSpectrum(np.asarray(ds[f"prior_freq_{a}"].values, dtype=np.float64),
                                 _values(ds, f"prior_psd_{a}"), _values(ds, f"prior_noise_std_{a}")[idx])
            at = ds[f"prior_noise_std_{a}"].attrs
            if "blind_tone_hz" in at:
                spec.tones = ([float(x) for x in np.atleast_1d(at["blind_tone_hz"])],
                              float(at["blind_tone_prior_sd_rad"]))
                if "blind_tone_order" in at:
                    spec.tones += (int(at["blind_tone_order"]),)
                    if "blind_tone_chirp_hz_per_s" in at:
                        spec.tones += ([float(x) for x in np.atleast_1d(at["blind_tone_chirp_hz_per_s"])],)
            if f"prior_noise_colour_{a}" in ds.variables:
                spec.noise_colour = (np.asarray(ds[f"colour_freq_{a}"].values, dtype=np.float64),
                                     _values(ds, f"prior_noise_colour_{a}")[idx])
        out[a] = IntegrationRecord(
            axis=a, pairs=list(meta["pairs"]), diffs=_values(ds, f"integrated_diff_{a}")[idx],
            sigmas=_values(ds, f"integrated_sigma_{a}")[idx], taus=_values(ds, f"integrated_tau_{a}")[idx],
            lags_s=_values(ds, f"line_lag_{a}")[idx], weights=_values(ds, f"line_weight_{a}")[idx],
            line_period_s=float(meta["line_period_s"]), method=str(meta["method"]), options=dict(meta["options"]),
            highpass_hz=float(meta["highpass_hz"]), spectrum=spec, increment=_values(ds, f"increment_{a}"),
            previous=_values(ds, f"previous_estimate_{a}"),
            unobservable_rms_rad=float(meta.get("unobservable_rms_rad", float("nan"))),
            floor_rms_rad=float(meta.get("floor_rms_rad", float("nan"))), selection=meta.get("selection"),
            knowledge_conditioned=bool(meta.get("knowledge_conditioned", False)),
            knowledge_band_hz=(None if meta.get("knowledge_band_hz") is None
                               else tuple(float(v) for v in meta["knowledge_band_hz"])))
    return out


def _settings_from(d: dict) -> RestorationSettings:
    s = RestorationSettings()
    for k, v in d.items():
        if hasattr(s, k):
            setattr(s, k, tuple(v) if k in ("window", "search", "pilot_search", "axes", "rematch_search") else v)
    return s


def result_from_dataset(ds, path: str | Path | None = None) -> RestorationResult:
    """A :class:`RestorationResult` from a ``restoration.nc`` dataset (see :func:`read_restoration`)."""
    def js(key, default):
        try:
            return json.loads(str(ds.attrs.get(key, default)))
        except json.JSONDecodeError:
            raise ProductError(f"{path}: attribute {key!r} is not JSON; run `simsat restore` again") from None
    return RestorationResult(
        run_dir=Path(path).parent if path else None, time=_values(ds, "time"),
        restored={a: _values(ds, a) for a in AXES}, knowledge={a: _values(ds, f"knowledge_{a}") for a in AXES},
        correction={a: _values(ds, f"correction_{a}") for a in AXES},
        coverage={a: float(ds.attrs.get(f"coverage_{a}", np.nan)) for a in AXES}, pairs=_pairs_from(ds),
        timings=js("timings", "{}"), misregistration=js("misregistration", "{}"),
        settings=_settings_from(js("settings", "{}")), pixel_ifov_rad=float(ds.attrs["pixel_ifov_rad"]),
        method=str(ds.attrs["method"]), integration=_records_from(ds, js("integration", "{}")),
        anchored=bool(int(ds.attrs.get("anchored_on_star_tracker", 0))), path=Path(path) if path else None,
        sigma={a: _values(ds, f"sigma_{a}") for a in AXES if f"sigma_{a}" in ds.variables},
        flagged={a: _values(ds, f"flagged_{a}", np.int8) != 0 for a in AXES if f"flagged_{a}" in ds.variables},
        noise_scale={a: float(ds[f"sigma_{a}"].attrs.get("noise_scale", 1.0)) for a in AXES
                     if f"sigma_{a}" in ds.variables},
        detrended_rms={a: float(ds[f"sigma_{a}"].attrs.get("predicted_detrended_rms_rad", np.nan)) for a in AXES
                       if f"sigma_{a}" in ds.variables},
        band_shares={a: json.loads(ds[f"sigma_{a}"].attrs.get("band_noise_shares", "{}")) for a in AXES
                     if f"sigma_{a}" in ds.variables},
        yaw_pitch_coupling=float(ds.attrs.get("yaw_pitch_coupling", 0.0)),
        yaw_roll_coupling=float(ds.attrs.get("yaw_roll_coupling", 0.0)),
        knowledge_latency=json.loads(ds.attrs.get("knowledge_latency", "{}")),
        knowledge_smoothing={a: _values(ds, f"knowledge_smoothing_{a}") for a in AXES
                             if f"knowledge_smoothing_{a}" in ds.variables},
        knowledge_dephasing={a: _values(ds, f"knowledge_dephasing_{a}") for a in AXES
                             if f"knowledge_dephasing_{a}" in ds.variables},
        knowledge_checks=_knowledge_checks_from(ds), knowledge_fusion=_knowledge_fusion_from(ds),
        conditioned_excess=_conditioned_excess_from(ds))


def read_restoration(path: str | Path, *, product_time: np.ndarray | None = None):
    """Read ``restoration.nc`` into a :class:`RestorationResult` (checked against ``product_time`` if given).

    Per pair: matches, inliers, actual delay τ′, synthesis residual (the
    per-line synthesis itself is in the file's ``diff_*`` variables, not in
    ``PairData.synthesis``); per restored axis: the :class:`IntegrationRecord`
    of its last integration. A matrix detector's restoration (global
    attribute ``acquisition = "frames"``) is read into a
    :class:`restore.frames.FrameRestoration` instead.

    Raises
    ------
    ProductError
        Unreadable file, or (with ``product_time``) one that does not belong to its product.
    """
    ds = open_restoration(path)
    if str(ds.attrs.get("acquisition", "pushbroom")) == "frames":
        from .frames import frames_restoration_from_dataset

        res = frames_restoration_from_dataset(ds, path)
        if product_time is not None and res.time.shape != np.shape(product_time):
            raise ProductError(f"{path}: {res.time.size} frame times, the product has {np.size(product_time)}; "
                               f"run `simsat restore` again")
        return res
    if product_time is not None:
        check_restoration(ds, path, product_time=product_time)
    return result_from_dataset(ds, path)
