"""Data preparation for the run report (``simsat report RUN_DIR``).

Every function here reads a run (product, restoration, truth) and returns plain
dicts of NumPy arrays and numbers — no drawing (that is
:mod:`reports.report_plots`) and no file writing (that is
:mod:`reports.run_report`). Tests check these numbers against independent
computations.

Conventions
-----------
* Angles are rad inside; the tables the report writes are in µrad and in pixels
  of the reference band (``pixel_ifov_rad``).
* ``δ(t) = true(t) − knowledge(t)`` is the part of the attitude the images have to
  restore; the restoration's *correction* is ``restored − knowledge``.
* Errors follow docs/design.md: estimate − truth over the lines where an estimate
  exists, mean removed, RMS and 99.7th percentile of |error|
  (:func:`reports.metrics.error_stats`).
* A pair's differential at line ``l`` is ``δ(t_l + τ) − δ(t_l)`` (restoration's
  ``diff_<axis>``); the integrator has the signature of
  :func:`restore.integration.integrate`:
  ``integrate(diffs, taus, te, method=..., **options) -> θ̂`` (NaN where not
  estimated).
"""
from __future__ import annotations

import json
import time as _time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from simsat.units import AXES

from reports.metrics import error_stats, misregistration_floor, truth_at
from restore.integration.methods import integration_method
from restore.integration.transfer import chain_gain, fused_chain_gain
from restore.restoration_io import check_restoration, open_restoration, result_from_dataset
from simsat.product import ProductError, read_product, read_truth

__all__ = [
    "AXES", "RunData", "load_run", "get_integrator", "scenario_summary", "restored_axes",
    "attitude_table", "headline", "minmax_decimate", "zoom_window", "longest_finite_run", "welch_settings",
    "spectra", "integration_probe", "measured_transfer", "analytic_chain_gain", "analytic_joint_gain",
    "regularisation_k", "true_differentials", "line_lags", "integration_record", "error_budget", "frozen_chain_gain", "probe_window_gain",
    "axis_integration", "measured_differentials", "match_density", "misregistration_rows",
    "scene_geometry", "pair_file_tag",
]



# =============================================================================
# Loading
# =============================================================================

@dataclass
class RunData:
    """Everything the report reads from a run directory.

    Attributes
    ----------
    run_dir : Path
    product : simsat.product.Product
        Geometry, knowledge and DEM (images are *not* loaded: see
        :attr:`simsat.product.Product.image_shapes`).
    image_shapes : dict
        ``{band: (lines, columns)}``.
    restoration : xarray.Dataset or None
        ``restoration.nc`` (None when the run was not restored).
    result : restore.result.RestorationResult or None
        The same file read back by :func:`restore.restoration_io.result_from_dataset`:
        what the pipeline did (pairs, τ′, per-axis integration records), never re-derived here.
    truth : xarray.Dataset or None
        ``truth.nc`` (None for a real product).
    run_info : dict
        ``run.json`` ({} when absent).
    notes : list of str
        What could not be read, to be said in the page.
    """

    run_dir: Path
    product: object
    image_shapes: dict
    restoration: object = None
    truth: object = None
    run_info: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)
    has_corrected: bool = False
    result: object = None
    _cache: dict = field(default_factory=dict, repr=False)

    @property
    def ifov(self) -> float:
        """Pixel IFOV of the reference band [rad]."""
        if self.restoration is not None and "pixel_ifov_rad" in self.restoration.attrs:
            return float(self.restoration.attrs["pixel_ifov_rad"])
        return float(self.product.pixel_ifov_rad)

    @property
    def line_period_s(self) -> float:
        return float(self.product.instrument.line_period_s)

    @property
    def time(self) -> np.ndarray:
        """Line times [s] (restoration's when present, else the product's)."""
        if self.restoration is not None:
            return np.asarray(self.restoration["time"].values, dtype=np.float64)
        return self.product.time

    @property
    def settings(self) -> dict:
        """Restoration settings (JSON attr ``settings``), {} when unknown."""
        if "settings" not in self._cache:
            s = {}
            if self.restoration is not None:
                try:
                    s = json.loads(str(self.restoration.attrs.get("settings", "{}")))
                except json.JSONDecodeError:
                    s = {}
            self._cache["settings"] = s
        return self._cache["settings"]

    @property
    def pairs(self) -> list:
        """Pair names of the restoration (``"A/B"``), [] without restoration."""
        if self.restoration is None:
            return []
        return [str(p) for p in np.atleast_1d(self.restoration["pair"].values)]

    @property
    def taus(self) -> list:
        """Delays τ [s] used by the restoration, per pair."""
        if self.restoration is None:
            return []
        return [float(t) for t in np.atleast_1d(self.restoration["tau_s"].values)]


def load_run(run_dir) -> RunData:
    """Read a run directory: product (without images), restoration, truth, run.json.

    Raises
    ------
    simsat.product.ProductError
        When ``product.nc`` is missing or malformed (the only required file).
    """
    run_dir = Path(run_dir)
    notes: list = []
    product = read_product(run_dir)  # images stay in the file (opened lazily)
    shapes = product.image_shapes
    rest = result = None
    if (run_dir / "restoration.nc").exists():
        rest = open_restoration(run_dir / "restoration.nc")
        check_restoration(rest, run_dir / "restoration.nc", product_time=product.time)
        result = result_from_dataset(rest, run_dir / "restoration.nc")
    else:
        notes.append("No restoration.nc in the run: run `simsat restore RUN_DIR` for the restored attitude; "
                     "only the product (and truth) are shown.")
    truth = None
    if (run_dir / "truth.nc").exists():
        truth = read_truth(run_dir, product_time=product.time)
    else:
        notes.append("No truth.nc (a real product): errors, spectra of truth and error, the measured transfer "
                     "and the error budget rows that need truth are left out.")
    info = {}
    if (run_dir / "run.json").exists():
        try:
            info = json.loads((run_dir / "run.json").read_text())
        except (json.JSONDecodeError, OSError, UnicodeDecodeError) as e:
            raise ProductError(f"{run_dir / 'run.json'}: not a readable JSON file ({e})") from None
        if not isinstance(info, dict):
            raise ProductError(f"{run_dir / 'run.json'}: must hold a JSON object (simsat's run record), "
                               f"got {type(info).__name__}")
    return RunData(run_dir=run_dir, product=product, image_shapes=shapes, restoration=rest, truth=truth,
                   run_info=info, notes=notes, has_corrected=(run_dir / "corrected.nc").exists(), result=result)


def get_integrator(integrator: Callable | None = None) -> tuple:
    """The integration function to re-run, or ``(None, why)``.

    Returns ``(callable, "")`` — ``integrator`` if given, else
    ``restore.integration.integrate`` when importable.
    """
    if integrator is not None:
        return integrator, ""
    try:
        from restore.integration import integrate  # noqa: WPS433 (optional, lazy)
    except Exception as e:  # ImportError or a half-written package
        return None, f"restore.integration.integrate is not importable ({type(e).__name__}: {e})"
    return integrate, ""


def pair_file_tag(pair: str) -> str:
    """File-name-safe tag of a pair name (``"B1/B0"`` → ``"B1-B0"``)."""
    return "".join(c if c.isalnum() or c in "-_" else "-" for c in pair.replace("/", "-"))


# =============================================================================
# Scenario and headline
# =============================================================================

def _requirement(info: dict) -> dict:
    try:
        req = info["scenario"]["raw"]["scenario"]["requirement"]
    except (KeyError, TypeError):
        return {}
    out = {}
    for k in ("max_rms_px", "max_p997_px"):
        if isinstance(req, dict) and req.get(k) is not None:
            out[k] = float(req[k])
    return out


def scenario_summary(run: RunData) -> dict:
    """Scenario facts for the top of the page.

    Returns
    -------
    dict
        name, description, lines, columns, line_period_s, duration_s, ifov_rad,
        bands (list of {name, band, along_mm}), pairs (list of {name, tau_s,
        tau_lines, nominal_tau_s}), method, iterations, requirement,
        reference_band, seed.
    """
    p = run.product
    info = run.run_info or {}
    raw = (info.get("scenario") or {}).get("raw") or {}
    sc = raw.get("scenario") or {}
    name = info.get("name") or sc.get("name") or str(p.ds.attrs.get("scenario", run.run_dir.name))
    te = run.line_period_s
    n_lines = int(p.time.size)
    bands = [{"name": d.name, "band": d.band, "along_mm": d.along_m * 1e3, "pixels": d.pixels}
             for d in p.instrument.detectors]
    nominal = {}
    if "delay_s" in p.ds:
        for k, v in zip(np.atleast_1d(p.ds["pair"].values), np.atleast_1d(p.ds["delay_s"].values)):
            nominal[str(k)] = float(v)
    pairs = []
    if run.restoration is not None:
        for name_p, tau in zip(run.pairs, run.taus):
            pairs.append({"name": name_p, "tau_s": tau, "tau_lines": tau / te, "nominal_tau_s": nominal.get(name_p)})
    else:
        for name_p, tau in nominal.items():
            pairs.append({"name": name_p, "tau_s": tau, "tau_lines": tau / te, "nominal_tau_s": tau})
    rest = run.restoration
    return {
        "name": name, "description": sc.get("description", ""), "seed": info.get("seed"),
        "lines": n_lines, "columns": max(d.pixels for d in p.instrument.detectors),
        "line_period_s": te, "duration_s": n_lines * te, "ifov_rad": run.ifov,
        "reference_band": p.reference_detector, "bands": bands, "pairs": pairs,
        "method": None if rest is None else str(rest.attrs.get("method", "?")),
        "iterations": run.settings.get("iterations"), "integration_options": run.settings.get("integration_options", {}),
        "restored_axes": restored_axes(run), "requirement": _requirement(info),
        "anchored": None if rest is None else bool(int(rest.attrs.get("anchored_on_star_tracker", 0))),
    }


def restored_axes(run: RunData) -> list:
    """Axes the restoration estimated (settings ``axes``, else axes with finite differentials)."""
    rest = run.restoration
    if rest is None:
        return []
    ax = run.settings.get("axes")
    if ax:
        return [a for a in AXES if a in ax and a in rest]
    out = []
    for a in AXES:
        if f"diff_{a}" in rest and np.isfinite(np.asarray(rest[f"diff_{a}"].values)).any():
            out.append(a)
    return out


def attitude_table(run: RunData) -> dict:
    """Per-line attitude series [rad] at line times.

    Returns
    -------
    dict
        ``line``, ``time_s`` and for each axis ``knowledge_<a>``, and when
        available ``restored_<a>``, ``correction_<a>``, ``true_<a>``,
        ``error_<a>`` (restored − true, mean over estimated lines removed, NaN
        where not estimated), ``knowledge_error_<a>`` (knowledge − true on the
        same lines, mean removed; on every line when there is no restoration),
        ``delta_<a>`` (true − knowledge, the part to restore).
    """
    if "attitude" in run._cache:
        return run._cache["attitude"]
    t = run.time
    out = {"line": np.arange(t.size), "time_s": t}
    rest = run.restoration
    if rest is not None:
        kn = {a: np.asarray(rest[f"knowledge_{a}"].values, dtype=np.float64) for a in AXES}
    else:
        kr, kp, ky = run.product.knowledge.at(t, outside="nan")
        kn = dict(zip(AXES, (kr, kp, ky)))
    for a in AXES:
        out[f"knowledge_{a}"] = kn[a]
        if rest is not None:
            est = np.asarray(rest[a].values, dtype=np.float64)
            out[f"restored_{a}"] = est
            if f"correction_{a}" in rest:
                out[f"correction_{a}"] = np.asarray(rest[f"correction_{a}"].values, dtype=np.float64)
            else:
                out[f"correction_{a}"] = est - kn[a]
        if run.truth is not None:
            tru = truth_at(run.truth, a, t)
            out[f"true_{a}"] = tru
            out[f"delta_{a}"] = tru - kn[a]
            mask = np.isfinite(out[f"restored_{a}"]) if rest is not None else np.isfinite(kn[a])
            if rest is not None:
                e = np.where(mask, out[f"restored_{a}"] - tru, np.nan)
                out[f"error_{a}"] = e - np.nanmean(e) if mask.any() else e
            ke = np.where(mask, kn[a] - tru, np.nan)
            out[f"knowledge_error_{a}"] = ke - np.nanmean(ke) if mask.any() else ke
    run._cache["attitude"] = out
    return out


def headline(run: RunData) -> dict:
    """Headline accuracy per axis and pass/fail against the scenario requirement.

    Returns
    -------
    dict
        ``axes``: {axis: {rms_px, p997_px, rms_urad, p997_urad, knowledge_rms_px,
        knowledge_p997_px, knowledge_rms_urad, knowledge_p997_urad, coverage,
        improvement_rms, improvement_p997, restored (bool), correction_rms_px}}
        (error keys only with truth); ``requirement`` (dict, maybe empty);
        ``worst`` {rms_px, p997_px} over restored axes; ``passed`` (True,
        False, or None when it cannot be decided); ``verdict`` (text).
    """
    att = attitude_table(run)
    ifov = run.ifov
    rest = run.restoration
    axes_r = restored_axes(run)
    out_axes = {}
    for a in AXES:
        d: dict = {"restored": a in axes_r}
        if rest is not None:
            est = att[f"restored_{a}"]
            mask = np.isfinite(est)
            d["coverage"] = float(mask.mean())
            c = np.where(mask, att[f"correction_{a}"], np.nan)
            cs = error_stats(c, ifov_rad=ifov)
            d["correction_rms_px"] = cs["rms_px"]
            d["correction_rms_urad"] = cs["rms_urad"]
        if run.truth is not None:
            mask = np.isfinite(att[f"restored_{a}"]) if rest is not None else np.isfinite(att[f"knowledge_{a}"])
            k = error_stats(np.where(mask, att[f"knowledge_{a}"] - att[f"true_{a}"], np.nan), ifov_rad=ifov)
            d.update({f"knowledge_{key}": v for key, v in k.items() if key != "n"})
            if rest is not None:
                s = error_stats(att[f"restored_{a}"] - att[f"true_{a}"], ifov_rad=ifov)
                d.update({key: v for key, v in s.items() if key != "n"})
                d["n"] = s["n"]
                with np.errstate(divide="ignore", invalid="ignore"):
                    d["improvement_rms"] = float(d["knowledge_rms_px"] / d["rms_px"]) if d["rms_px"] > 0 else float("inf")
                    d["improvement_p997"] = (float(d["knowledge_p997_px"] / d["p997_px"]) if d["p997_px"] > 0
                                             else float("inf"))
        out_axes[a] = d
    req = _requirement(run.run_info)
    res = {"axes": out_axes, "requirement": req, "worst": {}, "passed": None, "verdict": ""}
    if rest is None:
        res["verdict"] = "no restoration: nothing to check"
        return res
    if run.truth is None:
        res["verdict"] = ("requirement cannot be checked without truth" if req else
                          "no requirement in the scenario; no truth")
        return res
    if not axes_r:
        res["verdict"] = "no axis restored"
        return res
    worst = {"rms_px": max(out_axes[a]["rms_px"] for a in axes_r),
             "p997_px": max(out_axes[a]["p997_px"] for a in axes_r)}
    res["worst"] = worst
    if not req:
        res["verdict"] = "no requirement in the scenario"
        return res
    checks = []
    ok = True
    for key, wkey, label in (("max_rms_px", "rms_px", "RMS"), ("max_p997_px", "p997_px", "99.7 %")):
        if key in req:
            good = bool(worst[wkey] <= req[key])
            ok &= good
            checks.append(f"worst-axis {label} {worst[wkey]:.4f} px {'≤' if good else '>'} {req[key]:g} px")
    res["passed"] = ok
    res["verdict"] = ("PASS" if ok else "FAIL") + ": " + "; ".join(checks) + f" (restored axes: {', '.join(axes_r)})"
    return res


# =============================================================================
# Time-series helpers
# =============================================================================

def minmax_decimate(x, y, max_points: int = 4000) -> tuple:
    """Decimate a series for plotting, keeping the envelope (min and max per bucket).

    Returns ``(x, y)`` unchanged when already short; otherwise, per bucket of
    consecutive samples, the samples at its min and max (in time order). NaN
    gaps stay gaps (a bucket of NaN gives NaN).
    """
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    n = x.size
    if n <= max_points:
        return x, y
    nb = max(1, max_points // 2)
    size = int(np.ceil(n / nb))
    pad = nb * size - n
    yp = np.concatenate([y, np.full(pad, np.nan)]).reshape(nb, size)
    xp = np.concatenate([x, np.full(pad, np.nan)]).reshape(nb, size)
    allnan = np.all(~np.isfinite(yp), axis=1)
    yf = np.where(np.isfinite(yp), yp, np.inf)
    i_min = np.argmin(yf, axis=1)
    yf = np.where(np.isfinite(yp), yp, -np.inf)
    i_max = np.argmax(yf, axis=1)
    lo = np.minimum(i_min, i_max)
    hi = np.maximum(i_min, i_max)
    r = np.arange(nb)
    xs = np.stack([xp[r, lo], xp[r, hi]], axis=1).ravel()
    ys = np.stack([yp[r, lo], yp[r, hi]], axis=1).ravel()
    ys[np.repeat(allnan, 2)] = np.nan
    # bucket x of all-NaN buckets (argmin over inf gives index 0): use bucket start
    xs[np.repeat(allnan, 2)] = np.repeat(xp[allnan, 0], 2)
    keep = np.isfinite(xs)
    return xs[keep], ys[keep]


def longest_finite_run(*arrays) -> slice:
    """Slice of the longest run of samples finite in every array (empty slice if none)."""
    m = np.ones(np.asarray(arrays[0]).shape, dtype=bool)
    for a in arrays:
        m &= np.isfinite(np.asarray(a, dtype=np.float64))
    if not m.any():
        return slice(0, 0)
    d = np.diff(np.concatenate([[0], m.astype(np.int8), [0]]))
    starts = np.flatnonzero(d == 1)
    ends = np.flatnonzero(d == -1)
    k = int(np.argmax(ends - starts))
    return slice(int(starts[k]), int(ends[k]))


def zoom_window(t, valid=None, *, duration_s: float = 0.05) -> tuple:
    """A ``duration_s`` window centred in the (longest valid run of the) record: ``(t0, t1)`` [s]."""
    t = np.asarray(t, dtype=np.float64)
    if valid is None:
        sl = slice(0, t.size)
    else:
        sl = longest_finite_run(np.where(np.asarray(valid, bool), 0.0, np.nan))
        if sl.stop <= sl.start:
            sl = slice(0, t.size)
    ts = t[sl]
    mid = 0.5 * (ts[0] + ts[-1])
    half = 0.5 * min(duration_s, ts[-1] - ts[0] if ts.size > 1 else duration_s)
    return float(mid - half), float(mid + half)


# =============================================================================
# Spectra and transfer functions
# =============================================================================

def welch_settings(n: int) -> dict:
    """Welch parameters used everywhere in the report for a record of ``n`` samples.

    Hann window, segments of ``nperseg`` = largest power of two ≤ n/4
    (64 … 8192; the whole record when n < 64), 50 % overlap, constant detrend,
    one-sided density.
    """
    if n < 64:
        nps = max(int(n), 1)
    else:
        nps = int(2 ** np.floor(np.log2(max(n / 4.0, 64))))
        nps = int(min(max(nps, 64), 8192))
    return {"window": "hann", "nperseg": nps, "noverlap": nps // 2, "detrend": "constant",
            "scaling": "density", "return_onesided": True}


def spectra(run: RunData) -> dict:
    """Welch PSDs [rad²/Hz] per axis over the longest fully estimated stretch.

    Returns
    -------
    dict
        ``freq_hz`` (common frequency grid); per axis ``psd_delta_<a>``
        (true − knowledge), ``psd_correction_<a>``, ``psd_error_<a>`` (restored −
        true) — only those that exist —, ``span_<a>`` (first line, stop line),
        ``fs_hz``, ``nperseg``.
    """
    from scipy.signal import welch

    att = attitude_table(run)
    fs = 1.0 / run.line_period_s
    out: dict = {"fs_hz": fs}
    have_truth = run.truth is not None
    have_rest = run.restoration is not None
    series_all = {}
    for a in AXES:
        s = {}
        if have_truth:
            s["delta"] = att[f"delta_{a}"]
        if have_rest:
            s["correction"] = att[f"correction_{a}"]
            if have_truth:
                s["error"] = att[f"restored_{a}"] - att[f"true_{a}"]
        if have_rest:
            s = {k: np.where(np.isfinite(att[f"restored_{a}"]), v, np.nan) for k, v in s.items()}
        series_all[a] = s
    # one common span (shortest over axes) so that all PSDs share a frequency grid
    spans = {a: longest_finite_run(*series_all[a].values()) if series_all[a] else slice(0, 0) for a in AXES}
    n = min((sl.stop - sl.start) for sl in spans.values()) if spans else 0
    if n < 16:
        out["freq_hz"] = np.zeros(0)
        out["nperseg"] = 0
        return out
    ws = welch_settings(n)
    out["nperseg"] = ws["nperseg"]
    for a in AXES:
        sl = spans[a]
        out[f"span_{a}"] = (sl.start, sl.stop)
        for k, v in series_all[a].items():
            f, p = welch(np.asarray(v[sl], dtype=np.float64), fs=fs, **ws)
            out["freq_hz"] = f
            out[f"psd_{k}_{a}"] = p
    return out


def _band_limited_probe(n: int, te: float, taus: Sequence[float], rng) -> tuple:
    """Band-limited random θ (periodic over n samples) and its exact differentials θ(t+τ) − θ(t)."""
    nf = n // 2 + 1
    x = rng.standard_normal(nf) + 1j * rng.standard_normal(nf)
    x[0] = 0.0
    if n % 2 == 0:
        x[-1] = 0.0  # Nyquist bin: a fractional delay of it is ambiguous
    f = np.fft.rfftfreq(n, te)
    theta = np.fft.irfft(x, n)
    diffs = [np.fft.irfft(x * (np.exp(2j * np.pi * f * tau) - 1.0), n) for tau in taus]
    return theta, diffs


def _transfer_estimate(x, y, fs, ws) -> tuple:
    """Cross-spectral transfer estimate Y/X: (freq, Pxy, Pxx, Pyy) over the longest common finite run."""
    from scipy.signal import csd, welch

    sl = longest_finite_run(x, y)
    xs, ys = np.asarray(x[sl], float), np.asarray(y[sl], float)
    if xs.size < ws["nperseg"]:
        ws = welch_settings(xs.size)
    f, pxy = csd(xs, ys, fs=fs, **ws)
    _, pxx = welch(xs, fs=fs, **ws)
    _, pyy = welch(ys, fs=fs, **ws)
    return f, pxy, pxx, pyy


def _options_for_pairs(options: dict, idx: Sequence[int], n_pairs: int) -> dict:
    """Options restricted to the pairs ``idx`` (per-pair sequences such as ``noise_std`` are sliced)."""
    out = dict(options)
    for key in ("noise_std",):
        v = out.get(key)
        if v is not None and np.ndim(v) == 1 and len(v) == n_pairs:
            out[key] = np.asarray(v, dtype=np.float64)[list(idx)]
    w = out.get("weights")
    if w is not None and len(w) == n_pairs:  # one array per pair
        out["weights"] = [w[i] for i in idx]
    return out


def frozen_chain_gain(freq_hz, taus: Sequence[float], spectrum: dict, te: float) -> np.ndarray:
    """Analytic chain gain of the multi-pair Wiener filter with a frozen prior.

    ``F = Σ_j |G_j|² S/N_j / (1 + Σ_j |G_j|² S/N_j)``, ``G_j = e^{jωτ_j} − 1``,
    ``S`` the (two-sided) PSD prior of θ and ``N_j = σ_j² Δt`` the PSD of the
    white noise of pair j (std ``σ_j`` per sample):
    :func:`restore.integration.transfer.fused_chain_gain`.
    """
    f = np.asarray(freq_hz, dtype=np.float64)
    s = np.interp(np.abs(f), spectrum["freq"], spectrum["psd"], left=0.0, right=0.0)
    sig = np.broadcast_to(np.asarray(spectrum["noise_std"], dtype=np.float64), (len(taus),))
    return fused_chain_gain(f, list(taus), signal_psd=s, noise_psd=np.maximum(sig * sig * te, 1e-300))


def probe_window_gain(freq_hz, taus: Sequence[float], spectrum: dict, te: float, n: int, *,
                      oversample: int = 16) -> np.ndarray:
    """:func:`frozen_chain_gain` as :func:`integration_probe` sees it: averaged over its spectral window.

    The probe estimates the gain by Welch cross-spectra (Hann segments of
    ``welch_settings(2 n)["nperseg"]`` samples), i.e. the filter's gain
    averaged over the Hann window's spectral kernel |W(ν)|² (a main lobe of
    ± 2 bins). A prior estimated from quasi-harmonic jitter has lines
    narrower than that, where the point formula jumps between 0 and 1 and the
    probe cannot: comparing like with like needs the same averaging.
    """
    from scipy.signal import get_window

    f = np.asarray(freq_hz, dtype=np.float64)
    nps = welch_settings(2 * n)["nperseg"]
    fs = 1.0 / te
    w = get_window("hann", nps)
    kern = np.abs(np.fft.fft(w, nps * oversample)) ** 2
    kern /= kern.sum()
    off = np.fft.fftfreq(nps * oversample, te)
    keep = kern > kern.max() * 1e-6
    kern, off = kern[keep] / kern[keep].sum(), off[keep]
    fine = np.arange(0.0, fs / 2 + fs / (nps * oversample), fs / (nps * oversample))
    g = frozen_chain_gain(fine, taus, spectrum, te)
    return np.array([np.sum(kern * np.interp(np.abs(fi - off), fine, g)) for fi in f])


def integration_probe(taus: Sequence[float], te: float, n: int, *, integrate: Callable, method: str | None,
                      options: dict | None = None, pair_names: Sequence[str] | None = None,
                      n_realisations: int = 1, seed: int = 0, amplitude_rad: float = 1e-6) -> dict:
    """Transfer θ → θ̂ of the integration actually used, measured by re-running it.

    A band-limited random attitude θ (flat spectrum up to Nyquist) and its exact
    differentials for every pair are integrated with ``integrate`` (all pairs:
    *fused*; each pair alone: *per pair*); the transfer is the Welch
    cross-spectrum θ̂·θ* over the θ PSD (Welch segments of the largest power of
    two ≤ n/2: the probe has no noise, resolution matters more than averaging),
    averaged over ``n_realisations``. ``options`` are those of the run, frozen
    where the method adapts to its data (:func:`freeze_integration`); per-pair
    options (``noise_std`` as a sequence) are sliced for the single pairs. The
    probe has a physical size (RMS ``amplitude_rad``): iterative solvers stop on
    tolerances that are not scale-free, and a 1-rad probe is not integrated like
    µrad jitter.

    Returns
    -------
    dict
        ``freq_hz``, ``gain_fused``, ``phase_fused_deg``, ``gain_<pair>`` (NaN
        if integrating that pair alone failed), ``errors`` {label: message},
        ``seconds``.
    """
    t0 = _time.perf_counter()
    opts = dict(options or {})
    names = list(pair_names) if pair_names is not None else [f"pair{j}" for j in range(len(taus))]
    rng = np.random.default_rng(seed)
    fs = 1.0 / te
    # the probe is noise-free: longer segments (n/2) for frequency resolution, 3 of them with the overlap
    ws = welch_settings(2 * n)
    acc: dict = {}
    errors: dict = {}
    freq = None
    cases = [("fused", list(range(len(taus))))]
    if len(taus) > 1:
        cases += [(names[j], [j]) for j in range(len(taus))]
    else:
        cases += [(names[0], [0])]
    for _ in range(n_realisations):
        theta, diffs = _band_limited_probe(n, te, taus, rng)
        scale = float(amplitude_rad) / max(float(np.std(theta)), 1e-300)
        theta = theta * scale
        diffs = [d * scale for d in diffs]
        for label, idx in cases:
            if label in errors:
                continue
            if label != "fused" and len(taus) == 1 and "fused" in acc:
                acc[label] = acc["fused"]
                continue
            try:
                est = integrate([diffs[j] for j in idx], [float(taus[j]) for j in idx], te, method=method,
                                **_options_for_pairs(opts, idx, len(taus)))
                est = np.asarray(est, dtype=np.float64)
                if est.shape != theta.shape:
                    raise ValueError(f"integrate returned shape {est.shape}, expected {theta.shape}")
                f, pxy, pxx, _ = _transfer_estimate(theta, est, fs, ws)
            except Exception as e:  # one case failing must not sink the report
                errors[label] = f"{type(e).__name__}: {e}"
                continue
            freq = f if freq is None else freq
            if f.shape != freq.shape:
                errors[label] = "estimated span too short"
                continue
            s = acc.setdefault(label, [0.0, 0.0])
            s[0] = s[0] + pxy
            s[1] = s[1] + pxx
    out: dict = {"freq_hz": freq if freq is not None else np.zeros(0), "errors": errors}
    for label, _ in cases:
        key = "fused" if label == "fused" else label
        if label in acc and label not in errors:
            h = acc[label][0] / acc[label][1]
            out[f"gain_{key}"] = np.abs(h)
            out[f"phase_{key}_deg"] = np.degrees(np.angle(h))
        else:
            n_f = 0 if freq is None else freq.size
            out[f"gain_{key}"] = np.full(n_f, np.nan)
            out[f"phase_{key}_deg"] = np.full(n_f, np.nan)
    out["seconds"] = _time.perf_counter() - t0
    return out


def measured_transfer(run: RunData) -> dict:
    """Measured transfer of the whole chain, per axis: correction vs (true − knowledge).

    ``H(f) = P_{δ,c}(f) / P_{δ,δ}(f)`` (Welch cross-spectrum of the part to
    restore δ = true − knowledge and the restored correction c, over the δ
    PSD), with the coherence ``γ² = |P_{δc}|² / (P_δδ P_cc)``. ``significant``
    marks the bins where the ratio means something: δ has power there (PSD
    ≥ 1e-4 of its maximum above DC) and more than ten times the part of the
    correction that is not correlated with it, ``P_cc (1 − γ²)`` (so a blind
    frequency, where the correlated part vanishes, still shows if δ has power).

    Returns
    -------
    dict
        ``freq_hz``; per axis ``gain_<a>``, ``phase_<a>_deg``, ``coherence_<a>``,
        ``psd_delta_<a>``, ``significant_<a>`` (bool). Empty without truth or
        restoration.
    """
    if run.truth is None or run.restoration is None:
        return {}
    att = attitude_table(run)
    fs = 1.0 / run.line_period_s
    out: dict = {}
    spans = {}
    for a in restored_axes(run):
        m = np.isfinite(att[f"restored_{a}"])
        spans[a] = longest_finite_run(np.where(m, att[f"delta_{a}"], np.nan), att[f"correction_{a}"])
    if not spans:
        return {}
    n = min(sl.stop - sl.start for sl in spans.values())
    if n < 16:
        return {}
    ws = welch_settings(n)
    for a, sl in spans.items():
        x = att[f"delta_{a}"][sl]
        y = att[f"correction_{a}"][sl]
        f, pxy, pxx, pyy = _transfer_estimate(x, y, fs, ws)
        with np.errstate(divide="ignore", invalid="ignore"):
            h = pxy / pxx
            coh = np.abs(pxy) ** 2 / (pxx * pyy)
        out["freq_hz"] = f
        out[f"gain_{a}"] = np.abs(h)
        out[f"phase_{a}_deg"] = np.degrees(np.angle(h))
        out[f"coherence_{a}"] = coh
        out[f"psd_delta_{a}"] = pxx
        peak = np.max(pxx[1:]) if pxx.size > 1 else np.inf
        with np.errstate(invalid="ignore"):
            uncorrelated = pyy * np.clip(1.0 - coh, 0.0, 1.0)
            sig = (pxx >= 1e-4 * peak) & (pxx >= 10.0 * uncorrelated) & np.isfinite(h)
        sig[0] = False
        out[f"significant_{a}"] = sig
    return out


def analytic_chain_gain(freq_hz, tau_s: float, k: float) -> np.ndarray:
    """Single-pair Wiener chain gain ``F_k = 2(1−cos ωτ) / (2(1−cos ωτ) + k)`` (:func:`restore.integration.transfer.chain_gain`)."""
    return np.asarray(chain_gain(np.asarray(freq_hz, float), float(tau_s), float(k)), dtype=np.float64)


def analytic_joint_gain(freq_hz, taus: Sequence[float], k: float) -> np.ndarray:
    """Joint multi-pair Wiener chain gain ``Σ|G_j|² / (Σ|G_j|² + k)``, ``G_j = e^{jωτ_j} − 1``."""
    return fused_chain_gain(np.asarray(freq_hz, float), list(taus), k=k)


def regularisation_k(method: str | None, options: dict) -> float | None:
    """The fixed regularisation k of a method that is the stationary filter Σ|G|²/(Σ|G|² + k), if it has one."""
    try:
        key = integration_method(method or None).gain_option
    except ValueError:
        return None
    v = (options or {}).get(key) if key else None
    if key and v is None:
        v = integration_method(method or None).options().get(key)
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) and v > 0 else None


# =============================================================================
# Error budget
# =============================================================================

def _truth_interpolant(truth, axis: str):
    """Cubic interpolant of the finely sampled truth (exact at its samples)."""
    from scipy.interpolate import CubicSpline

    t = np.asarray(truth["time"].values, dtype=np.float64)
    return CubicSpline(t, np.asarray(truth[axis].values, dtype=np.float64), extrapolate=False)


def integration_record(run: RunData, axis: str):
    """The pipeline's record of the last integration of ``axis`` (:class:`restore.result.IntegrationRecord`).

    None without restoration, for an axis that was not restored, or when the
    record does not cover every pair of the restoration.
    """
    if run.result is None:
        return None
    rec = run.result.integration.get(axis)
    if rec is None or list(rec.pairs) != run.pairs:
        return None
    return rec


def line_lags(run: RunData, axis: str | None = None) -> np.ndarray | None:
    """Extra delay of each pair at each line of band A [lines] (time synchronisation), as the pipeline used it.

    Band B sees the ground of line ``l`` of A at ``t + τ + λ(l)·Te`` (pitch
    jitter changes the actual delay): the measured differentials are
    ``δ(t + τ + λ Te) − δ(t)``. Read from the integration record of ``axis``
    (default: the first restored axis); (pair, line) or None.
    """
    axes = restored_axes(run)
    rec = integration_record(run, axis or (axes[0] if axes else "roll"))
    if rec is None:
        return None
    return rec.lags_s / rec.line_period_s


def true_differentials(run: RunData, axis: str, *, previous_estimate=None, lags=None) -> tuple:
    """True differentials ``δ(t+τ_j) − δ(t)`` per pair (pair, line) [rad], NaN where the measured one is NaN.

    ``δ = true − knowledge − previous`` is the remaining error the last
    iteration measured. ``previous`` is the estimate of the earlier iterations
    as the pipeline used it: zero where it was not estimated, and, where it
    was, ``previous_estimate`` (known up to a constant, since the restoration
    removes the mean of its final correction) plus a constant ``c``. Between
    lines it is a cubic spline over the line grid (as the pipeline's attitude
    series). ``c`` cancels except on lines whose τ-partner straddles an
    unestimated stretch; it is fitted there by least squares against the
    measured differentials (0 without a previous estimate or without such lines).
    Truth: cubic interpolation of its fine sampling; knowledge: the product's
    series. ``lags`` (pair, line) [lines], e.g. :func:`line_lags`: the far end
    is taken at ``t + τ_j + lag·Te`` (the delay actually seen by the images)
    instead of the nominal ``t + τ_j``.

    Returns
    -------
    dtrue : ndarray (pair, line)
    previous : ndarray (line,) or None
        The previous estimate at line times, as used (zeros where not estimated).
    """
    from scipy.interpolate import CubicSpline

    t = run.time
    ftrue = _truth_interpolant(run.truth, axis)
    kn_series = run.product.knowledge
    k_idx = AXES.index(axis)

    def delta(tt):
        return ftrue(tt) - kn_series.at(tt, outside="nan")[k_idx]

    meas = np.asarray(measured_differentials(run, axis), dtype=np.float64)
    base = np.full(meas.shape, np.nan)
    slope = np.zeros(meas.shape)
    d0 = delta(t)
    sp_r = sp_m = None
    if previous_estimate is not None:
        pe = np.asarray(previous_estimate, dtype=np.float64)
        m = np.isfinite(pe)
        sp_r = CubicSpline(t, np.where(m, pe, 0.0))
        sp_m = CubicSpline(t, m.astype(np.float64))
    for j, tau in enumerate(run.taus):
        t1 = t + tau + (0.0 if lags is None else np.asarray(lags[j], dtype=np.float64) * run.line_period_s)
        b = delta(t1) - d0
        if sp_r is not None:
            b = b - (sp_r(t1) - sp_r(t))
            slope[j] = -(sp_m(t1) - sp_m(t))
        base[j] = np.where(np.isfinite(meas[j]), b, np.nan)
    c = 0.0
    if sp_r is not None:
        ok = np.isfinite(meas) & np.isfinite(base) & (np.abs(slope) > 1e-9)
        den = float(np.sum(slope[ok] ** 2))
        if den > 0:
            c = float(np.sum(slope[ok] * (meas[ok] - base[ok])) / den)
    dtrue = base + c * slope
    prev = None
    if previous_estimate is not None:
        pe = np.asarray(previous_estimate, dtype=np.float64)
        prev = np.where(np.isfinite(pe), pe + c, 0.0)
    return dtrue, prev


def measured_differentials(run: RunData, axis: str) -> list:
    """The run's differentials of ``axis`` per pair as the pipeline integrated them (raw synthesis if unrecorded)."""
    rec = integration_record(run, axis)
    if rec is not None:
        return [d for d in rec.diffs]
    return [m for m in np.asarray(run.restoration[f"diff_{axis}"].values, dtype=np.float64)]


def axis_integration(run: RunData, axis: str) -> dict:
    """The integration the pipeline applied to ``axis``, from its record in ``restoration.nc``.

    Returns
    -------
    dict
        ``options`` (the method's options with a data-estimated prior frozen:
        re-running with them applies the same, fixed filter), ``theta`` (the
        last integration's output), ``frozen`` (bool), ``spectrum`` ({freq,
        psd, noise_std} or None), ``record`` (or None), ``error`` (str).
    """
    rec = integration_record(run, axis)
    if rec is None:
        return {"options": dict(run.settings.get("integration_options") or {}), "theta": None, "frozen": False,
                "spectrum": None, "record": None,
                "error": "restoration.nc has no integration record for this axis (written by an older simsat: "
                         "run `simsat restore` again)"}
    sp = rec.spectrum
    return {"options": rec.frozen_options(), "theta": rec.increment, "frozen": sp is not None,
            "spectrum": None if sp is None else {"freq": sp.freq, "psd": sp.psd, "noise_std": sp.noise_std},
            "record": rec, "error": ""}


def _stats_row(component: str, axis: str, e, ifov: float, note: str = "") -> dict:
    s = error_stats(e, ifov_rad=ifov)
    return {"axis": axis, "component": component, "rms_px": s["rms_px"], "p997_px": s["p997_px"],
            "rms_urad": s["rms_urad"], "p997_urad": s["p997_urad"], "n": s["n"], "note": note}


def _quad_row(component: str, axis: str, total: dict, part: dict, note: str) -> dict:
    row = {"axis": axis, "component": component, "n": total["n"], "note": note}
    for k in ("rms_px", "p997_px", "rms_urad", "p997_urad"):
        a, b = total[k], part[k]
        row[k] = float(np.sqrt(max(a * a - b * b, 0.0))) if np.isfinite(a) and np.isfinite(b) else float("nan")
    return row


BUDGET_COMPONENTS = ("uncorrected knowledge", "matching noise", "model / synthesis", "measurement (noise + model)",
                     "integration", "total (restored − true)")


def _centred(e):
    e = np.asarray(e, dtype=np.float64)
    m = np.isfinite(e)
    return e - e[m].mean() if m.any() else e


def error_budget(run: RunData, *, integrate: Callable | None = None, seed: int = 0,
                 max_seconds: float = 120.0) -> dict:
    """Error budget per axis (px and µrad, RMS and 99.7 %).

    Components (each an attitude error over the estimated lines, mean removed):

    * **uncorrected knowledge** — knowledge − true;
    * **integration** — the *true* differentials (θ(t+τ) − θ(t) of the true
      remaining error, same gaps) integrated with the run's method, minus the
      true remaining error: what the integration loses with perfect
      differentials (blind frequencies, regularisation, ends, gaps);
    * **measurement (noise + model)** — total − integration: what the errors of
      the measured differentials cost after integration;
    * **matching noise** — white noise with the per-line formal σ of the
      differentials (``diff_sigma_<axis>``, from the scatter of the inlier
      residuals), same gaps, added to the true differentials: integrate(true +
      noise) − integrate(true) (one seeded draw);
    * **model / synthesis** — the part of the measurement error that matching
      noise does not explain: √(measurement² − noise²), per figure;
    * **total** — restored − true (the headline).

    Every re-run goes through the pipeline's own integration step with the
    inputs ``restoration.nc`` recorded (:meth:`restore.result.IntegrationRecord.rerun`:
    time synchronisation with the recorded per-line lags, weights, the
    method's options, the prior a data-adaptive method estimated, frozen, and
    the high-pass), so every component goes through the filter that was
    actually applied. With several iterations the last one is analysed,
    starting from the recorded previous estimate (see :func:`true_differentials`).

    Returns
    -------
    dict
        ``rows`` (list of dicts: axis, component, rms_px, p997_px, rms_urad,
        p997_urad, n, note); ``differential_rows`` (per pair and axis at the
        differential level: matching σ, measured − true, model, in µrad and
        px); ``notes`` (list of str); ``series`` {axis: {component: array}};
        ``seconds``.
    """
    t0 = _time.perf_counter()
    rows: list = []
    drows: list = []
    notes: list = []
    series: dict = {}
    rest = run.restoration
    if rest is None:
        return {"rows": rows, "differential_rows": drows, "notes": ["no restoration"], "series": series,
                "seconds": 0.0}
    ifov = run.ifov
    att = attitude_table(run)
    iterations = int(run.settings.get("iterations") or 1)
    have_truth = run.truth is not None
    axes = restored_axes(run)
    # cost guard: the run's own integration time per call
    calls = len(axes) * 3
    try:
        tim = json.loads(str(rest.attrs.get("timings", "{}")))
        per_call = float(tim.get("integration_s", 0.0)) / max(1, iterations * max(1, len(axes)))
    except (json.JSONDecodeError, TypeError, ValueError):
        per_call = 0.0
    if integrate is not None and per_call * calls > max_seconds:
        notes.append(f"integration not re-run for the budget: ~{per_call * calls:.0f} s expected "
                     f"(> {max_seconds:.0f} s allowed)")
        integrate = None
    rng = np.random.default_rng(seed)
    for a in axes:
        mask = np.isfinite(att[f"restored_{a}"])
        meas = np.asarray(measured_differentials(run, a), dtype=np.float64)
        sig = np.asarray(rest[f"diff_sigma_{a}"].values, dtype=np.float64) if f"diff_sigma_{a}" in rest else None
        ser: dict = {}
        if have_truth:
            rows.append(_stats_row("uncorrected knowledge", a, np.where(mask, att[f"knowledge_{a}"] - att[f"true_{a}"],
                                                                        np.nan), ifov))
        fz = axis_integration(run, a)
        rec = fz["record"]
        if fz["error"]:
            notes.append(f"{a}: {fz['error']}; budget at the differential level only")
        prev = rec.previous if rec is not None and np.any(rec.previous) else None
        if integrate is None or rec is None:
            rec = None
        else:
            # the recorded inputs must reproduce what the pipeline's integration returned
            c = _centred(np.where(mask, rec.increment, np.nan))
            r = _centred(np.where(mask, rec.rerun(), np.nan))
            d = (c - r)[np.isfinite(c - r)]
            cc = c[np.isfinite(c)]
            if d.size and cc.size and np.sqrt(np.mean(d ** 2)) > 0.02 * np.sqrt(np.mean(cc ** 2)):
                notes.append(f"{a}: re-running the integration differs from the restoration's by "
                             f"{np.sqrt(np.mean(d ** 2)) / np.sqrt(np.mean(cc ** 2)) * 100:.0f} % RMS; the split "
                             "between measurement and integration is approximate")
        noise = None
        if sig is not None:
            s_ = np.where(np.isfinite(meas), sig, np.nan)
            fill = np.nanmedian(s_) if np.isfinite(s_).any() else 0.0
            s_ = np.where(np.isfinite(meas) & ~np.isfinite(s_), fill, s_)
            noise = s_ * rng.standard_normal(s_.shape)
        dtrue = prev_used = dlag = None
        if have_truth:
            dtrue, prev_used = true_differentials(run, a, previous_estimate=prev)
            lags = line_lags(run)
            if lags is not None:
                dlag = true_differentials(run, a, previous_estimate=prev, lags=lags)[0]
        # differential-level rows
        for j, pname in enumerate(run.pairs):
            row = {"pair": pname, "axis": a, "tau_s": run.taus[j], "lines": int(np.isfinite(meas[j]).sum())}
            if sig is not None:
                sj = sig[j][np.isfinite(meas[j]) & np.isfinite(sig[j])]
                row["matching_sigma_urad"] = float(np.sqrt(np.mean(sj ** 2)) * 1e6) if sj.size else float("nan")
            if dtrue is not None:
                # measured against the truth at the delay the images actually saw (time
                # synchronisation): what is left is the error of the measurement itself
                ref = dlag if dlag is not None else dtrue
                r = meas[j] - ref[j]
                r = r[np.isfinite(r)]
                if dlag is not None:
                    ts = (dlag[j] - dtrue[j])[np.isfinite(meas[j])]
                    ts = ts[np.isfinite(ts)]
                    row["time_sync_rms_urad"] = float(np.sqrt(np.mean((ts - ts.mean()) ** 2)) * 1e6) if ts.size \
                        else float("nan")
                row["meas_minus_true_rms_urad"] = float(np.sqrt(np.mean((r - r.mean()) ** 2)) * 1e6) if r.size \
                    else float("nan")
                row["meas_minus_true_mean_urad"] = float(r.mean() * 1e6) if r.size else float("nan")
                ms = row.get("matching_sigma_urad", 0.0)
                mm = row["meas_minus_true_rms_urad"]
                row["model_rms_urad"] = float(np.sqrt(max(mm * mm - ms * ms, 0.0))) if np.isfinite(mm) else float("nan")
            for k in list(row):
                if k.endswith("_urad"):
                    row[k.replace("_urad", "_px")] = row[k] * 1e-6 / ifov
            drows.append(row)
        if rec is None or not have_truth:
            if have_truth:
                rows.append(_stats_row("total (restored − true)", a, att[f"restored_{a}"] - att[f"true_{a}"], ifov))
            elif rec is not None and noise is not None:
                # no truth: integrate(measured + σ·noise) − integrate(measured)
                th_meas = rec.rerun()
                th_noisy = rec.rerun(meas + noise)
                en = np.where(mask, th_noisy - th_meas, np.nan)
                rows.append(_stats_row("matching noise", a, en, ifov,
                                       "integrate(measured + σ·noise) − integrate(measured), 1 draw"))
                ser["matching noise"] = en
            series[a] = ser
            continue
        # perfect differentials as the images saw them (at t + τ + λ), through the same integration
        dperfect = dlag if dlag is not None else dtrue
        th_true = rec.rerun(dperfect)
        remaining = att[f"delta_{a}"] - (prev_used if prev_used is not None else 0.0)
        eint = _centred(np.where(mask, th_true - remaining, np.nan))
        total = _centred(att[f"restored_{a}"] - att[f"true_{a}"])
        emeas = total - eint
        r_noise = None
        if noise is not None:
            th_noisy = rec.rerun(dperfect + noise)
            en = np.where(mask, th_noisy - th_true, np.nan)
            r_noise = _stats_row("matching noise", a, en, ifov, "integrate(true + σ·noise) − integrate(true), 1 draw")
            rows.append(r_noise)
            ser["matching noise"] = en
        r_meas = _stats_row("measurement (noise + model)", a, emeas, ifov, "total − integration")
        if r_noise is not None:
            rows.append(_quad_row("model / synthesis", a, r_meas, r_noise, "√(measurement² − noise²)"))
        rows.append(r_meas)
        rows.append(_stats_row("integration", a, eint, ifov, "integrate(true differentials) − truth"))
        rows.append(_stats_row("total (restored − true)", a, total, ifov, "= measurement + integration"))
        ser.update({"measurement": emeas, "integration": eint, "total": total})
        series[a] = ser
    if integrate is None:
        notes.append("attitude-domain propagation (matching noise, model, integration) needs re-running the integration; "
                     "only the differential-level figures are given")
    if not have_truth:
        notes.append("no truth: only the matching noise can be budgeted")
    return {"rows": rows, "differential_rows": drows, "notes": notes, "series": series,
            "seconds": _time.perf_counter() - t0}


# =============================================================================
# Matches and misregistration
# =============================================================================

def match_density(run: RunData, *, line_bins: int = 200, col_bins: int = 16, max_rejected_points: int = 3000,
                  seed: int = 0) -> dict:
    """Where the matches fell, per pair (in band-A image coordinates).

    Returns
    -------
    dict
        ``{pair: {line_edges, col_edges, inliers (2-D counts, line × column),
        rejected (2-D counts: valid but rejected by the synthesis, or invalid
        match), n_total, n_valid, n_inlier, rejected_lines, rejected_cols
        (valid matches rejected by the synthesis) and failed_lines,
        failed_cols (matches that failed, e.g. low correlation) — random
        subsets of at most ``max_rejected_points`` each, for drawing —,
        gap_intervals (list of (first_line, stop_line) where the pair gave no
        differential), points_per_line (inliers per line), n_lines, n_columns,
        ahead, behind}}``.
    """
    rest = run.restoration
    if rest is None or "match_pair" not in rest:
        return {}
    mp = np.asarray(rest["match_pair"].values)
    la = np.asarray(rest["match_line_a"].values, dtype=np.float64)
    ca = np.asarray(rest["match_col_a"].values, dtype=np.float64)
    valid = np.asarray(rest["match_valid"].values).astype(bool)
    inl = np.asarray(rest["match_inlier"].values).astype(bool)
    n_lines = run.time.size
    rng = np.random.default_rng(seed)
    out = {}
    for j, name in enumerate(run.pairs):
        ahead, behind = name.split("/") if "/" in name else (name, "")
        n_cols = run.image_shapes.get(ahead, (n_lines, max(d.pixels for d in run.product.instrument.detectors)))[1]
        le = np.linspace(0, n_lines, min(line_bins, n_lines) + 1)
        ce = np.linspace(0, n_cols, min(col_bins, n_cols) + 1)
        sel = mp == j
        ok = sel & np.isfinite(la) & np.isfinite(ca)
        hi, _, _ = np.histogram2d(la[ok & inl], ca[ok & inl], bins=(le, ce))
        rej = ok & ~inl
        hr, _, _ = np.histogram2d(la[rej], ca[rej], bins=(le, ce))
        idx = np.flatnonzero(rej & valid)
        if idx.size > max_rejected_points:
            idx = np.sort(rng.choice(idx, max_rejected_points, replace=False))
        idf = np.flatnonzero(rej & ~valid)
        if idf.size > max_rejected_points:
            idf = np.sort(rng.choice(idf, max_rejected_points, replace=False))
        if "diff_points" in rest:
            ppl = np.asarray(rest["diff_points"].values)[j].astype(np.int64)
        else:
            ppl = np.bincount(np.rint(la[ok & inl]).astype(np.int64).clip(0, n_lines - 1), minlength=n_lines)
        gap_mask = np.ones(n_lines, dtype=bool)
        for a in restored_axes(run) or AXES:
            if f"diff_{a}" in rest:
                gap_mask &= ~np.isfinite(np.asarray(rest[f"diff_{a}"].values)[j])
        d = np.diff(np.concatenate([[0], gap_mask.astype(np.int8), [0]]))
        gaps = list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist()))
        out[name] = {"line_edges": le, "col_edges": ce, "inliers": hi, "rejected": hr,
                     "n_total": int(sel.sum()), "n_valid": int((sel & valid).sum()), "n_inlier": int((sel & inl).sum()),
                     "n_rejected_valid": int((sel & valid & ~inl).sum()), "n_invalid": int((sel & ~valid).sum()),
                     "rejected_lines": la[idx], "rejected_cols": ca[idx],
                     "failed_lines": la[idf], "failed_cols": ca[idf], "gap_intervals": gaps,
                     "points_per_line": ppl, "n_lines": n_lines, "n_columns": int(n_cols),
                     "ahead": ahead, "behind": behind}
    return out


def misregistration_rows(run: RunData) -> list:
    """Band-to-band misregistration before/after correction (restoration attr ``misregistration``).

    Returns a list of ``{pair, before_px, after_px, before_line_px, before_col_px,
    after_line_px, after_col_px, after_noise_px, after_signal_px,
    after_line_signal_px, after_col_signal_px, lines, improvement}`` (missing
    keys NaN). ``after_px`` is as measured (matching noise of a per-line mean
    included, ``after_noise_px``); ``after_signal_px`` is the split-half
    estimate without that noise (see :func:`restore.correction.per_line_shift_rms`).
    """
    rest = run.restoration
    if rest is None:
        return []
    try:
        mis = json.loads(str(rest.attrs.get("misregistration", "{}")) or "{}")
    except json.JSONDecodeError:
        return []
    rows = []
    keys = ("before_px", "after_px", "before_line_px", "before_col_px", "after_line_px", "after_col_px",
            "after_noise_px", "after_signal_px", "after_line_signal_px", "after_col_signal_px")
    for pair, v in mis.items():
        if not isinstance(v, dict):
            continue
        r = {"pair": pair}
        for k in keys:
            x = v.get(k)
            r[k] = float(x) if isinstance(x, (int, float)) and x is not None else float("nan")
        r["lines"] = int(v.get("lines", 0) or 0)
        r["improvement"] = r["before_px"] / r["after_px"] if r["after_px"] and r["after_px"] > 0 else float("nan")
        rows.append(r)
    # with truth: the misregistration the restored attitude's error leaves (geometric, noise-free)
    geo = {}
    if run.truth is not None:
        from .metrics import attitude_misregistration
        try:
            geo = attitude_misregistration(rest, run.truth)
        except (KeyError, ValueError):
            geo = {}
    for r in rows:
        g = geo.get(r["pair"], {}).get("restored", {})
        for k in ("line_px", "col_px", "total_px"):
            r[f"attitude_{k}"] = float(g.get(k, float("nan")))
    floor = misregistration_with_true_attitude(run) if rows else {}
    for r in rows:
        f = floor.get(r["pair"], {})
        for k in ("px", "line_px", "col_px"):
            r[f"true_attitude_{k}"] = float(f.get(f"after_{k}", float("nan")))
    return rows


def misregistration_with_true_attitude(run: RunData) -> dict:
    """The "after" measurement repeated on bands corrected with the *true* attitude (needs truth).

    Same points (the restoration's valid matches, from ``restoration.nc``),
    same matcher settings: what a perfect restoration would measure, i.e. the
    floor of the image-based measurement. ``{}`` without truth, without
    corrected images, or when it cannot be computed (said in ``run.notes``).
    See :func:`reports.metrics.misregistration_floor`.
    """
    rest = run.restoration
    if run.truth is None or rest is None or not run.has_corrected or "match_pair" not in rest:
        return {}
    if "true_attitude_floor" in run._cache:
        return run._cache["true_attitude_floor"]
    out = {}
    try:
        product = read_product(run.run_dir)
        pairs, settings = run.result.pairs, run.result.settings
        out = misregistration_floor(product, run.truth, pairs, settings)
    except (ProductError, KeyError, ValueError, OSError) as ex:
        run.notes.append(f"misregistration with the true attitude not computed: {ex}")
    run._cache["true_attitude_floor"] = out
    return out


# =============================================================================
# 3-D scene
# =============================================================================

def scene_geometry(run: RunData, *, edge_samples: int = 160, max_dem_side: int = 160, margin_frac: float = 0.15) -> dict:
    """DEM (cropped around the footprints, decimated) and the bands' ground footprints.

    Footprints are the outlines of each band's image on the ground by the
    product's sensor model (knowledge attitude, known DEM):
    ``direct_location(band, lines, cols)`` along the four image edges.

    Returns
    -------
    dict
        ``x``, ``y`` (1-D, m), ``z`` (2-D, m, rows = y); ``footprints``
        {band: (N, 3) closed outline, m}; ``centre_line`` {band: (M, 3) ground
        track of the middle column}; ``z_exaggeration`` (suggested vertical
        exaggeration for drawing).
    """
    p = run.product
    sm = p.sensor_model()
    n_lines = p.time.size
    fps = {}
    centre = {}
    for d in p.instrument.detectors:
        nl = run.image_shapes.get(d.name, (n_lines, d.pixels))[0]
        nc = d.pixels
        ls = np.linspace(0, nl - 1, edge_samples)
        cs = np.linspace(0, nc - 1, max(8, edge_samples // 3))
        lines = np.concatenate([np.zeros(cs.size), ls, np.full(cs.size, nl - 1), ls[::-1], [0]])
        cols = np.concatenate([cs, np.full(ls.size, nc - 1), cs[::-1], np.zeros(ls.size), [0]])
        g = sm.direct_location(d.name, lines, cols)
        fps[d.name] = g
        centre[d.name] = sm.direct_location(d.name, ls, np.full(ls.size, 0.5 * (nc - 1)))
    dem = p.dem
    allp = np.concatenate([g[np.all(np.isfinite(g), axis=1)] for g in fps.values()] or [np.zeros((0, 3))])
    x, y, z = dem.x, dem.y, dem.z
    if allp.size:
        x0, x1 = allp[:, 0].min(), allp[:, 0].max()
        y0, y1 = allp[:, 1].min(), allp[:, 1].max()
        mx = margin_frac * max(x1 - x0, y1 - y0, 10 * dem.dx_m)
        ix = np.flatnonzero((x >= x0 - mx) & (x <= x1 + mx))
        iy = np.flatnonzero((y >= y0 - mx) & (y <= y1 + mx))
        if ix.size >= 2 and iy.size >= 2:
            x, y, z = x[ix], y[iy], z[np.ix_(iy, ix)]
    sx = max(1, int(np.ceil(x.size / max_dem_side)))
    sy = max(1, int(np.ceil(y.size / max_dem_side)))
    x, y, z = x[::sx], y[::sy], np.asarray(z)[::sy, ::sx]
    horiz = max(float(x[-1] - x[0]), float(y[-1] - y[0]), 1.0)
    relief = float(np.ptp(z)) if z.size else 0.0
    ex = 1.0 if relief <= 0 else float(np.clip(0.15 * horiz / relief, 1.0, 20.0))
    return {"x": x, "y": y, "z": z, "footprints": fps, "centre_line": centre, "z_exaggeration": ex,
            "dem_source": "product DEM (known by the ground segment)"}
