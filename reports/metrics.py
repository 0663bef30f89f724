"""The accuracy metric of docs/design.md.

error(t) = estimated θ(t) − true θ(t) per axis, over the lines where an
estimate exists, with its mean removed (the constant is unobservable from
images alone). Reported as RMS and 99.7th percentile of |error|, in pixels of
the reference band and in µrad, beside the same figures for the uncorrected
knowledge (AOCS) error, and the coverage (fraction of lines estimated).
"""
from __future__ import annotations

import numpy as np

from restore.correction import correct_bands, misregistration, weak_band_misregistration
from simsat.attitude import AttitudeSeries
from simsat.units import AXES

__all__ = ["error_stats", "attitude_errors", "truth_at", "error_split_by_band", "unobservable_split", "yaw_seen", "axis_yaw_seen",
           "restoration_unobservable_split", "clear_line_fraction",
           "clear_line_coverage", "attitude_misregistration", "misregistration_floor"]



def error_stats(error, *, ifov_rad: float) -> dict:
    """RMS / 99.7 % of |error − mean| over finite samples, in px and µrad."""
    e = np.asarray(error, dtype=np.float64)
    m = np.isfinite(e)
    if not m.any():
        return {"rms_px": float("nan"), "p997_px": float("nan"), "rms_urad": float("nan"),
                "p997_urad": float("nan"), "n": 0}
    e = e[m] - e[m].mean()
    rms = float(np.sqrt(np.mean(e ** 2)))
    p = float(np.percentile(np.abs(e), 99.7))
    return {"rms_px": rms / ifov_rad, "p997_px": p / ifov_rad, "rms_urad": rms * 1e6, "p997_urad": p * 1e6,
            "n": int(m.sum())}


def error_split_by_band(error, dt: float, freq, band) -> tuple[float, float]:
    """RMS of an error series inside and outside a frequency band (its periodogram split).

    Over the longest run of finite samples, mean removed; the band is given on
    a one-sided grid ``freq`` [Hz] (``band`` boolean, e.g. the unobservable
    band of :func:`restore.observability.observability`) and read at the
    periodogram's frequencies by nearest-neighbour interpolation. The two
    parts' squares add up to the run's mean square (Parseval).

    Returns
    -------
    (inside_rms, outside_rms) : float
        In the error's unit; NaN when fewer than 16 finite samples.
    """
    from .report_data.series import longest_finite_run

    e = np.asarray(error, dtype=np.float64)
    sl = longest_finite_run(e)
    e = e[sl]
    if e.size < 16:
        return float("nan"), float("nan")
    e = e - e.mean()
    spec = np.abs(np.fft.rfft(e)) ** 2
    f = np.fft.rfftfreq(e.size, dt)
    inside = np.interp(f, np.asarray(freq, dtype=np.float64), np.asarray(band, dtype=float)) >= 0.5
    frac = float(spec[inside].sum() / max(spec.sum(), 1e-300))
    rms = float(np.sqrt(np.mean(e ** 2)))
    return rms * float(np.sqrt(frac)), rms * float(np.sqrt(1.0 - frac))


def unobservable_split(error, dt: float, freq, band, *, predicted_band_rms: float, yaw_seen=None) -> dict:
    """With truth: the parts of a measured error that no pair can see, and the rest (issue 12's "outside").

    In this order (:mod:`restore.observability` says why each is out of reach):

    1. ``yaw_seen`` (off nadir, pitch: coupling × the yaw the knowledge
       missed) is subtracted;
    2. the record's trend (least-squares offset + slope) is subtracted;
    3. of what is left, the power inside the unobservable ``band`` is taken
       out — but never more than ``predicted_band_rms`` (the attitude power
       the product says lies there): error the restoration itself puts in
       the band is the algorithm's, and stays.

    Parameters
    ----------
    error : ndarray (lines,)
        Restored − true [any angle unit], NaN where not restored.
    dt : float
        Line period [s].
    freq, band : ndarray
        The unobservable band on a one-sided grid (:func:`error_split_by_band`).
    predicted_band_rms : float
        The unobservable RMS the product predicts (same unit as ``error``).
    yaw_seen : ndarray (lines,) or None
        The yaw seen as this axis (pitch off nadir across track, roll along track), same unit.

    Returns
    -------
    dict
        ``yaw_rms``, ``trend_rms``, ``band_rms`` (the part taken out),
        ``detrended_rms`` (after 1 and 2) and ``outside_rms`` (after 3).
    """
    from restore.observability import record_trend

    e = np.asarray(error, dtype=np.float64)
    ok = np.isfinite(e)
    if ok.sum() < 16:
        nan = float("nan")
        return {"yaw_rms": nan, "trend_rms": nan, "band_rms": nan, "detrended_rms": nan, "outside_rms": nan}

    def rms(x):
        x = x[ok] - np.mean(x[ok])
        return float(np.sqrt(np.mean(x ** 2)))

    yaw = np.zeros_like(e) if yaw_seen is None else np.asarray(yaw_seen, dtype=np.float64)
    e1 = e - yaw
    trend = record_trend(e1)
    e2 = e1 - trend
    detrended = rms(e2)
    inside, _ = error_split_by_band(e2, dt, freq, band)
    taken = min(inside, float(predicted_band_rms)) if np.isfinite(inside) else 0.0
    return {"yaw_rms": rms(yaw) if yaw_seen is not None else 0.0, "trend_rms": rms(trend), "band_rms": taken,
            "detrended_rms": detrended, "outside_rms": float(np.sqrt(max(detrended ** 2 - taken ** 2, 0.0)))}


def restoration_unobservable_split(res, truth, axis: str) -> dict:
    """:func:`unobservable_split` of a restored axis against truth [rad]; empty when the axis was not integrated.

    ``res``: a :class:`restore.result.RestorationResult`; ``truth``: truth.nc
    (``time``, ``roll``, ``pitch``, ``yaw``). Off nadir the yaw seen as pitch
    (roll, when tilted along track) is ``coupling × (true − knowledge yaw)``.
    """
    from restore.observability import record_observability

    rec = res.integration.get(axis)
    if rec is None:
        return {}
    obs = record_observability(rec)
    err = res.restored[axis] - truth_at(truth, axis, res.time)
    seen = yaw_seen(res.yaw_coupling(axis), truth_at(truth, "yaw", res.time), res.knowledge["yaw"])
    return unobservable_split(err, rec.line_period_s, obs.freq, obs.unobservable_band,
                              predicted_band_rms=obs.unobservable_rms_rad, yaw_seen=seen)


#: a line is "clear" when at least this fraction of its columns sees land that is neither cloud nor water
CLEAR_LINE_MIN_FRACTION = 0.5


def clear_line_fraction(product, texture, *, column_step: int = 16) -> np.ndarray:
    """Per line of the reference band: the fraction of its columns whose ground is clear land (truth).

    The ground point of every ``column_step``-th column (direct location with
    the knowledge attitude: a pixel or two off the truth, nothing at the
    scale of a cloud) is classified by the scene's texture
    (``texture.land_cover``): cloud (opacity above ½) and water are not
    clear. A texture that does not know its land cover (an orthoimage) gives
    NaN.
    """
    from simsat.terrain.texture import LandCover

    ref = product.reference_detector
    n_lines, n_cols = product.image_shapes[ref]
    cols = np.unique(np.r_[np.arange(0, n_cols, max(int(column_step), 1)), n_cols - 1]).astype(np.float64)
    lines = np.arange(n_lines, dtype=np.float64)
    g = product.sensor_model().direct_location(ref, lines[:, None], cols[None, :])
    ok = np.all(np.isfinite(g), axis=-1)
    cls = np.full(ok.shape, LandCover.UNKNOWN, dtype=np.uint8)
    cls[ok] = texture.land_cover(g[..., 0][ok], g[..., 1][ok])
    if np.all(cls[ok] == LandCover.UNKNOWN):
        return np.full(n_lines, np.nan)
    clear = ok & (cls != LandCover.CLOUD) & (cls != LandCover.WATER) & (cls != LandCover.UNKNOWN)
    return clear.mean(axis=1)


def clear_line_coverage(restored, clear_fraction, *, min_clear: float = CLEAR_LINE_MIN_FRACTION) -> float:
    """Fraction of the clear lines (``clear_fraction >= min_clear``) that are restored (finite); NaN if none."""
    clear = np.asarray(clear_fraction, dtype=np.float64) >= min_clear
    if not clear.any():
        return float("nan")
    return float(np.mean(np.isfinite(np.asarray(restored, dtype=np.float64))[clear]))


def truth_at(truth, axis: str, t) -> np.ndarray:
    """True angle [rad] at times ``t`` (linear interpolation of the finely sampled truth)."""
    return np.interp(np.asarray(t, dtype=np.float64), np.asarray(truth["time"].values),
                     np.asarray(truth[axis].values))


#: pitch (roll) errors are also given without the yaw seen as pitch (roll) when |coupling| exceeds this
YAW_COUPLING_REPORTED = 0.02
#: restoration.nc's attribute holding each axis's yaw coupling (:func:`restore.stages.yaw_coupling`)
YAW_COUPLING_ATTRS = {"pitch": "yaw_pitch_coupling", "roll": "yaw_roll_coupling"}


def yaw_seen(coupling: float, true_yaw, knowledge_yaw):
    """The yaw an axis's restoration books as its own, ``coupling × (true − knowledge yaw)``; None when the
    coupling is below :data:`YAW_COUPLING_REPORTED` (at nadir, looking straight down)."""
    if abs(float(coupling)) < YAW_COUPLING_REPORTED:
        return None
    return float(coupling) * (np.asarray(true_yaw, dtype=np.float64) - np.asarray(knowledge_yaw, dtype=np.float64))


def axis_yaw_seen(restoration_attrs, attitude: dict, axis: str) -> tuple:
    """``(coupling, yaw seen as axis per line [rad] or None)`` from restoration.nc's attributes (the axis's
    :data:`YAW_COUPLING_ATTRS`) and a per-line attitude table holding ``true_yaw`` and ``knowledge_yaw``
    (:func:`reports.report_data.attitude_table`); None without truth or below :data:`YAW_COUPLING_REPORTED`."""
    c = float(dict(restoration_attrs).get(YAW_COUPLING_ATTRS.get(axis, ""), 0.0))
    if "true_yaw" not in attitude or "knowledge_yaw" not in attitude:
        return c, None
    return c, yaw_seen(c, attitude["true_yaw"], attitude["knowledge_yaw"])


def attitude_errors(restoration, truth, *, axes=AXES) -> dict:
    """Per-axis error statistics of a restoration dataset against truth.

    Returns
    -------
    dict
        ``{axis: {rms_px, p997_px, rms_urad, p997_urad, knowledge_rms_px,
        knowledge_p997_px, knowledge_rms_urad, knowledge_p997_urad, coverage}}``.
    """
    ifov = float(restoration.attrs["pixel_ifov_rad"])
    t = np.asarray(restoration["time"].values)
    out = {}
    for a in axes:
        if a not in restoration:
            continue
        est = np.asarray(restoration[a].values, dtype=np.float64)
        tru = truth_at(truth, a, t)
        s = error_stats(est - tru, ifov_rad=ifov)
        mask = np.isfinite(est)
        kn = np.asarray(restoration[f"knowledge_{a}"].values) if f"knowledge_{a}" in restoration else None
        if kn is not None:
            k = error_stats(np.where(mask, kn - tru, np.nan), ifov_rad=ifov)
            s.update({f"knowledge_{key}": v for key, v in k.items() if key != "n"})
        s["coverage"] = float(mask.mean())
        # absolute: the mean kept (what star-tracker anchoring is for)
        e_abs = (est - tru)[mask]
        s["absolute_rms_px"] = float(np.sqrt(np.mean(e_abs ** 2)) / ifov) if e_abs.size else float("nan")
        if kn is not None:
            k_abs = (kn - tru)[mask]
            s["knowledge_absolute_rms_px"] = float(np.sqrt(np.mean(k_abs ** 2)) / ifov) if k_abs.size else float("nan")
        c = float(restoration.attrs.get(YAW_COUPLING_ATTRS.get(a, ""), 0.0))
        seen = yaw_seen(c, truth_at(truth, "yaw", t), np.asarray(restoration["knowledge_yaw"].values, dtype=np.float64)
                        ) if "knowledge_yaw" in restoration else None
        if seen is not None:
            # off nadir the images see pitch (roll, tilted along track) + c × (yaw the knowledge misses):
            # the error without that part
            w = error_stats(est - tru - seen, ifov_rad=ifov)
            s["rms_px_without_yaw_coupling"], s["p997_px_without_yaw_coupling"] = w["rms_px"], w["p997_px"]
            s["yaw_coupling"] = c
        out[a] = s
    return out


def attitude_misregistration(restoration, truth, *, extra_pairs: dict | None = None) -> dict:
    """Band-to-band misregistration that the attitude error leaves, per pair (truth-based).

    A pair of bands ``τ`` apart sees the same ground at ``t`` and ``t + τ``;
    imaged with an attitude in error by ``e(t)``, the two bands are
    misregistered by ``e(t + τ) − e(t)``: roll error across track (columns),
    pitch error along track (lines). This is the geometric misregistration of
    images corrected with the restored attitude, free of the matching noise
    that limits the image-based measurement, and without the resampling error
    of the corrected images.

    Parameters
    ----------
    restoration : xarray.Dataset
        ``restoration.nc`` (``time``, ``roll``, ``pitch``, their ``knowledge_*``,
        ``tau_s`` per ``pair`` and the attribute ``pixel_ifov_rad``).
    truth : xarray.Dataset
        ``truth.nc``.
    extra_pairs : dict, optional
        ``{name: tau_s}`` of band pairs the restoration did not use (a weakly
        correlated band measured against its nearest pair band), evaluated the
        same way.

    Returns
    -------
    dict
        ``{pair: {tau_s, restored: {line_px, col_px, total_px}, knowledge: {...}}}``:
        RMS over the lines where both ends are estimated, mean removed.
    """
    ifov = float(restoration.attrs["pixel_ifov_rad"])
    t = np.asarray(restoration["time"].values, dtype=np.float64)
    if "pair" not in restoration.coords or "tau_s" not in restoration:
        return {}
    out = {}
    taus = list(zip(np.asarray(restoration["pair"].values), np.asarray(restoration["tau_s"].values)))
    taus += [(k, v) for k, v in (extra_pairs or {}).items() if np.isfinite(v)]
    for name, tau in taus:
        tau = float(tau)
        row = {"tau_s": tau}
        for which, prefix in (("restored", ""), ("knowledge", "knowledge_")):
            vals = {}
            for axis, key in (("pitch", "line_px"), ("roll", "col_px")):
                var = prefix + axis
                if var not in restoration:
                    vals[key] = float("nan")
                    continue
                x = np.asarray(restoration[var].values, dtype=np.float64)
                ok = np.isfinite(x)
                if ok.sum() < 4:
                    vals[key] = float("nan")
                    continue
                from scipy.interpolate import CubicSpline

                xs = CubicSpline(t[ok], x[ok], extrapolate=False)
                e0 = np.where(ok, x, np.nan) - truth_at(truth, axis, t)
                t1 = t + tau
                # both ends estimated: the line at t + τ must lie between estimated lines
                j = np.clip(np.searchsorted(t, t1), 1, t.size - 1)
                both = ok & (t1 <= t[-1]) & ok[j] & ok[j - 1]
                e1 = np.where(both, xs(np.clip(t1, t[0], t[-1])), np.nan) - truth_at(truth, axis, t1)
                d = (e1 - e0)[both]
                vals[key] = float(np.sqrt(np.mean((d - d.mean()) ** 2)) / ifov) if d.size else float("nan")
            vals["total_px"] = float(np.hypot(vals["line_px"], vals["col_px"]))
            row[which] = vals
        out[str(name)] = row
    return out


def misregistration_floor(product, truth, pairs, settings, *, weak_bands: bool = True) -> dict:
    """Image-measured misregistration of bands corrected with the *true* attitude (a control).

    The bands are resampled exactly as :func:`restore.correction.correct_bands`
    does, but with the true attitude of ``truth.nc`` instead of the restored
    one, and measured by :func:`restore.correction.misregistration` with the
    same points, matcher and weights as the restoration's own "after"
    figure. A perfect restoration would measure this: what it shows is the
    floor of the image-based measurement (cross-band matching noise and
    resampling), not misregistration left by the attitude. Benchmarks and
    reports only: it reads the truth.

    Parameters
    ----------
    product : simsat.product.Product
    truth : xarray.Dataset
        ``truth.nc`` (``time``, ``roll``, ``pitch``, ``yaw`` [rad]).
    pairs : list of restore.pipeline.PairData
        The restoration's matched pairs (their points are re-used).
    settings : restore.pipeline.RestorationSettings
    weak_bands : bool, keyword-only
        Also the bands no pair uses, against their nearest pair band
        (:func:`restore.correction.weak_band_misregistration`).

    Returns
    -------
    dict
        ``{pair: {after_px, after_line_px, after_col_px, after_noise_px,
        after_signal_px, ...}}`` as :func:`restore.correction.misregistration`.
    """
    series = AttitudeSeries(time=np.asarray(truth["time"].values, dtype=np.float64),
                            **{a: np.asarray(truth[a].values, dtype=np.float64) for a in AXES})
    import tempfile
    from pathlib import Path

    used = {b for p in pairs for b in (p.ahead, p.behind)}
    if weak_bands:
        used = set(product.band_names)
    with tempfile.TemporaryDirectory(prefix="simsat-control-") as tmp:
        # in a scratch file, block by block: memory bounded by one band, whatever the product's size
        corrected = correct_bands(product, restored=series, column_step=settings.correction_column_step, bands=used,
                                  path=Path(tmp) / "corrected_true.nc")
        try:
            out = misregistration(product, corrected, pairs, settings)
            if weak_bands:
                out.update(weak_band_misregistration(product, corrected, pairs, settings))
            return out
        finally:
            corrected.close()
