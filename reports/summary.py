"""The few lines a user reads in the terminal after ``simsat run`` / ``simsat restore``.

Restored error per axis (RMS and 99.7 % of |error|, mean removed, against
truth when the run has it), the AOCS knowledge error beside it, coverage, and
the verdict against the scenario's requirement -- the same figures as the
report's headline (:func:`reports.report_data.headline`), from the same code.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from . import report_data as D

__all__ = ["run_summary"]


def _fmt(x: float) -> str:
    return "n/a" if x is None or x != x else f"{x:.3f}"


def _attitude_errors(run) -> dict:
    from .metrics import attitude_errors

    return attitude_errors(run.restoration, run.truth)


def blind_tone_line(restoration, axes) -> str | None:
    """The line saying which axes had a tone on or near the pairs' common blind frequencies (through the lags,
    or seen by one pair inside the notch)
    (``blind_tone_hz`` of ``prior_noise_std_<axis>`` in restoration.nc), or None."""
    found = []
    for a in axes:
        v = restoration.variables.get(f"prior_noise_std_{a}") if restoration is not None else None
        if v is not None and "blind_tone_hz" in v.attrs:
            hz = ", ".join(f"{float(f):.2f}" for f in np.atleast_1d(v.attrs["blind_tone_hz"]))
            found.append(f"{a} {hz} Hz")
    if not found:
        return None
    return ("  a line on or near a frequency every pair is blind to, found as a tone, restored: "
            + "; ".join(found))


def _integration_info(restoration) -> dict | None:
    """restoration.nc's ``integration`` record (axis → pairs, method, options), or None (none, or unreadable)."""
    import json

    if restoration is None:
        return None
    try:
        return json.loads(str(restoration.attrs.get("integration", "{}")))
    except ValueError:
        return None


def transient_line(restoration, axes) -> str | None:
    """The line windows where a transient the stationary prior could not follow was restored without it
    (``transient_lines`` in the options of restoration.nc's ``integration`` record), or None."""
    info = _integration_info(restoration)
    if info is None:
        return None
    found = []
    for a in axes:
        wins = (info.get(a) or {}).get("options", {}).get("transient_lines")
        if wins:
            found.append(f"{a} lines " + ", ".join(f"{int(lo)}–{int(hi) - 1}" for lo, hi in wins))
    if not found:
        return None
    return ("  a transient the stationary prior could not follow, restored without it (least squares): "
            + "; ".join(found))


def knowledge_band_noise_line(restoration, axes) -> str | None:
    """The axes whose pairs' matching noise was read from their differentials in the AOCS knowledge's band, and
    weighed by (``knowledge_band_hz`` of restoration.nc's ``integration`` record, the largest factor of
    ``prior_noise_colour_<axis>`` there; :mod:`restore.knowledge_band_noise`), or None."""
    import numpy as np

    info = _integration_info(restoration)
    if info is None:
        return None
    found = []
    for a in axes:
        band = (info.get(a) or {}).get("knowledge_band_hz")
        col = restoration.variables.get(f"prior_noise_colour_{a}")
        if not band or col is None:
            continue
        f = np.asarray(restoration[f"colour_freq_{a}"].values, dtype=np.float64)
        inside = (f >= float(band[0])) & (f <= float(band[1]))
        values = np.asarray(col.values, dtype=np.float64)[:, inside]
        if values.size and np.isfinite(values).any():
            found.append(f"{a} up to {np.nanmax(values):.1f} × the white noise at {float(band[0]):.2f}–"
                         f"{float(band[1]):.2f} Hz")
    if not found:
        return None
    return ("  the pairs' differentials in the AOCS knowledge's band showed matching noise no residual can "
            "(the scene's band offset moves them like an attitude); integrated again weighed by it, the noise there "
            "taken as " + "; ".join(found) + " (a lower bound); σ draws the excess as an offset that moves the pairs "
            "like an attitude")


def notch_level_line(restoration, axes) -> str | None:
    """The notches whose prior the integration took from their own level (``notch_levels`` in the options of
    restoration.nc's ``integration`` record: :func:`restore.axis_integration._notch_prior`), with the RMS that
    level holds over each notch [px], or None."""
    info = _integration_info(restoration)
    if info is None:
        return None
    ifov = float(restoration.attrs.get("pixel_ifov_rad", np.nan))
    found = []
    for a in axes:
        raised = (info.get(a) or {}).get("options", {}).get("notch_levels")
        if raised:
            # a two-sided PSD over the notch's band and its mirror image
            found.append(f"{a} " + ", ".join(f"{lo:.1f}–{hi:.1f} Hz ({np.sqrt(2 * lv * (hi - lo)) / ifov:.3f} px)"
                                             for lo, hi, lv in raised))
    if not found:
        return None
    return ("  a blind notch's prior taken from its own level (the pairs' flanks see a continuum through it; "
            "its middle stays unobservable): " + "; ".join(found))


#: below this fraction of restored lines the terminal says which lines were not restored, and why
COVERAGE_SHOWN = 0.95
#: at most this many line ranges are named (the longest)
RANGES_SHOWN = 4


def line_ranges(missing) -> list[tuple[int, int]]:
    """Runs of True in a boolean per line, as (first, last) line numbers, longest first."""
    m = np.concatenate([[False], np.asarray(missing, dtype=bool), [False]])
    d = np.diff(m.astype(np.int8))
    starts, stops = np.flatnonzero(d == 1), np.flatnonzero(d == -1) - 1
    order = np.argsort(-(stops - starts), kind="stable")
    return [(int(starts[k]), int(stops[k])) for k in order]


def coverage_line(restoration, axes) -> str:
    """When fewer than 95 % of the lines are restored: how many, and the longest unrestored line ranges by why
    they were not restored — a run most of whose lines were flagged for a predicted σ above the limit (few or
    poor matches: short clear islands, gap edges, a transient over poor ground, the record's ends), or one with
    no differentials (no usable texture, or the record's ends); else ""."""
    if restoration is None:
        return ""
    axes = [a for a in axes if a != "yaw" and a in restoration]
    if not axes:
        return ""
    missing = np.zeros(restoration.sizes["time"], dtype=bool)
    flagged = np.zeros_like(missing)
    for a in axes:
        missing |= ~np.isfinite(np.asarray(restoration[a].values, dtype=np.float64))
        if f"flagged_{a}" in restoration:
            flagged |= np.asarray(restoration[f"flagged_{a}"].values) != 0
    if 1.0 - missing.mean() >= COVERAGE_SHOWN:
        return ""
    ranges = line_ranges(missing)
    shown = ranges[:RANGES_SHOWN]
    groups = {True: [], False: []}
    for a, b in sorted(shown):
        groups[bool(np.mean(flagged[a:b + 1]) >= 0.5)].append(f"{a}–{b}" if b > a else f"{a}")
    more = f" (and {len(ranges) - RANGES_SHOWN} shorter runs)" if len(ranges) > RANGES_SHOWN else ""
    n_flag = int(np.count_nonzero(flagged & missing))
    parts = []
    if groups[True]:
        parts.append(f"flagged for a predicted σ above restoration.max_sigma_px (few or poor matches: short clear "
                     f"islands, gap edges, a transient over poor ground, the record's ends): lines "
                     f"{', '.join(groups[True])}")
    if groups[False]:
        parts.append(f"no differentials (no usable texture: cloud, water, flat or dark ground; or at the record's "
                     f"ends, where a pair's second band has not seen the ground): lines {', '.join(groups[False])}")
    flags = f" ({n_flag} of them flagged for their predicted σ)" if n_flag else ""
    return f"  not restored: {missing.mean() * 100:.1f} % of the lines{flags} — " + "; ".join(parts) + more


#: the terminal names the error outside the unobservable parts when they take at least this much off an axis [px]
UNOBSERVABLE_SHOWN_PX = 0.005


def unobservable_line(run, axes) -> str:
    """With truth: the restored error without what no pair sees, when that is material on some axis; else "".

    The record's trend (constant differentials), the yaw seen as pitch (roll)
    off nadir across (along) track and the blind band up to its predicted power
    (:func:`reports.metrics.restoration_unobservable_split`).
    """
    from restore.restoration_io import result_from_dataset

    from .metrics import error_stats, restoration_unobservable_split, truth_at

    res = result_from_dataset(run.restoration)
    px = res.pixel_ifov_rad
    parts, material = [], False
    for a in axes:
        if a == "yaw":
            continue
        sp = restoration_unobservable_split(res, run.truth, a)
        if not sp or not np.isfinite(sp["outside_rms"]):
            continue
        total = error_stats(res.restored[a] - truth_at(run.truth, a, res.time), ifov_rad=px)["rms_px"]
        out = sp["outside_rms"] / px
        material |= total - out >= UNOBSERVABLE_SHOWN_PX
        named = [f"{k} {sp[key] / px:.3f}" for key, k in (("trend_rms", "trend"), ("yaw_rms", f"yaw seen as {a}"),
                                                          ("band_rms", "blind band")) if sp[key] / px >= 0.001]
        parts.append(f"{a} {out:.3f} px" + (f" ({', '.join(named)} taken out)" if named else ""))
    if not material:
        return ""
    return "  without what no pair sees (record trend, yaw seen as roll or pitch, blind band): " + "; ".join(parts)


def scene_offset_line(product_attrs, taus, axes, ephemeris=None) -> str | None:
    """The line saying where the images alone restore the attitude and the scene's band offset passes as one.

    ``product_attrs``: product.nc's attributes (the knowledge's cut-off, the sun's azimuth, the acquisition);
    ``taus``: the delays of the pairs the restoration used [s]; ``ephemeris``: the platform positions (lines,
    3) [m], whose direction gives the track's azimuth (+x when absent). None when the knowledge reaches the top
    of the band (:func:`restore.observability.scene_offset_band`), the product does not record the sun or the
    knowledge, or it is not a push-broom acquisition.
    """
    from restore.observability import scene_offset_band, sun_offset_shares, track_azimuth_deg

    at = dict(product_attrs or {})
    if at.get("acquisition", "pushbroom") != "pushbroom" or "sun_azimuth_deg" not in at:
        return None
    band = scene_offset_band(taus, at.get("knowledge_cutoff_hz"))
    if band is None:
        return None
    track = track_azimuth_deg(ephemeris)
    shares = sun_offset_shares(float(at["sun_azimuth_deg"]), track)
    named = [f"{shares[a] * 100:.0f} % on {a}" for a in ("pitch", "roll") if a in axes]
    if not named:
        return None
    rel = (float(at["sun_azimuth_deg"]) - track + 180.0) % 360.0 - 180.0
    return (f"  images alone at {band[0]:.1f}–{band[1]:.1f} Hz (above the AOCS knowledge's cut-off): there the "
            f"scene's band-to-band offset towards the sun ({rel:.0f}° from the track: {', '.join(named)}) moves the "
            f"bands as an attitude would, and σ does not hold it")


def sigma_if_images_short(sigma_rad: float, check: dict, *, took_share: bool = True) -> float:
    """σ as it would be if the images' prediction were the short one: the share of the knowledge check's excess
    it took (``booked_rms_rad``; none when ``took_share`` is False) replaced by all of it (``excess_rms_rad``),
    in quadrature [rad].

    Examples
    --------
    >>> round(sigma_if_images_short(3.0, {"booked_rms_rad": 1.0, "excess_rms_rad": 2.0}) ** 2, 9)
    12.0
    >>> round(sigma_if_images_short(3.0, {"booked_rms_rad": 1.0, "excess_rms_rad": 2.0}, took_share=False) ** 2, 9)
    13.0
    """
    booked = float(check.get("booked_rms_rad", 0.0) or 0.0) if took_share else 0.0
    excess = float(check.get("excess_rms_rad", 0.0) or 0.0)
    return float(np.sqrt(max(sigma_rad ** 2 - booked ** 2, 0.0) + excess ** 2))


def _sigma_json(variable, key: str) -> dict | None:
    """The JSON attribute ``key`` of a ``sigma_<axis>`` variable as a dict ({} when absent or no variable);
    None when it does not parse."""
    import json

    if variable is None:
        return {}
    try:
        return json.loads(str(variable.attrs.get(key, "{}")) or "{}")
    except ValueError:
        return None


def knowledge_check_line(restoration, axes, *, took_share: bool = True) -> str | None:
    """The line saying where the restored angle and its smoothed AOCS knowledge disagree beyond both predicted
    errors (the ``knowledge_check`` of ``sigma_<axis>`` in restoration.nc, where its excess passed the limit),
    or None.

    The data cannot tell which prediction is short: σ takes the images' share of the excess
    (``restoration.sigma_knowledge_check``); the line also gives σ as it would be if the images' prediction were
    the short one, ``√(σ² − booked² + excess²)``, so that a reader without truth sees how optimistic σ may be.
    ``took_share``: whether σ holds that share (the setting ``sigma_knowledge_check``, on by default).
    """
    if restoration is None or "pixel_ifov_rad" not in restoration.attrs:
        return None
    ifov = float(restoration.attrs["pixel_ifov_rad"])
    took = bool(took_share)
    found = []
    for a in axes:
        v = restoration.variables.get(f"sigma_{a}")
        chk = _sigma_json(v, "knowledge_check")
        if chk is None:
            continue
        excess = float(chk.get("excess_rms_rad", 0.0) or 0.0)
        sigma = float(v.attrs.get("predicted_detrended_rms_rad", np.nan)) if v is not None else np.nan
        if not (excess > 0 and np.isfinite(sigma)):
            continue
        booked = float(chk.get("booked_rms_rad", 0.0) or 0.0) if took else 0.0
        lo, hi = chk["band_hz"]
        worst = sigma_if_images_short(sigma, chk, took_share=took)
        found.append(f"{a} at {lo:.1f}–{hi:.1f} Hz {float(chk['ratio']):.2f} × (limit {float(chk['threshold']):.2f}): "
                     f"σ {sigma / ifov:.4f} px takes {booked / ifov:.4f} px of the {excess / ifov:.4f} px excess, "
                     f"{worst / ifov:.4f} px if the images' prediction is the short one")
    if not found:
        return None
    return ("  the AOCS knowledge disagrees with the restored angle beyond both predicted errors (σ may be "
            "optimistic): " + "; ".join(found))


def conditioned_excess_line(restoration, axes) -> str | None:
    """The line saying where the images' estimate exceeds what its knowledge-conditioned prior allows (the
    ``conditioned_excess`` of ``sigma_<axis>`` in restoration.nc, :mod:`restore.conditioned_excess`), or None.

    Such an excess is noise that moves like an attitude in every pair (the scene's band offset), or knowledge
    error the prior lacks: either way the restored angle there holds more error than σ predicts.
    """
    if restoration is None or "pixel_ifov_rad" not in restoration.attrs:
        return None
    ifov = float(restoration.attrs["pixel_ifov_rad"])
    found, shrunk, shared = [], False, []
    for a in axes:
        ex = _sigma_json(restoration.variables.get(f"sigma_{a}"), "conditioned_excess")
        if ex and ex.get("shared_above_rad"):
            shared.append(f"{a} {float(ex['shared_above_rad']) / ifov:.4f} px")
        if not ex or not ex.get("excess_hz"):
            continue
        hz = [float(f) for f in ex["excess_hz"]]
        text = (f"{a} at {min(hz):.1f}–{max(hz):.1f} Hz (up to {float(ex['max_ratio']):.1f} × what the "
                f"prior allows, {float(ex['excess_rms_rad']) / ifov:.4f} px beyond it")
        if ex.get("shrink_error_rad") is not None and ex["excess_hz"]:
            shrunk = True
            text += (f"; shrunk to a Wiener estimate there, σ holds its {float(ex['shrink_error_rad']) / ifov:.4f} px"
                     f" and {float(ex.get('above_error_rad') or 0.0) / ifov:.4f} px of the same offset above the "
                     "knowledge's band")
        found.append(text + ")")
    if not found:
        return None
    return ("  the images' estimate exceeds what the AOCS knowledge lets its prior hold: " + "; ".join(found)
            + ": noise that moves like an attitude in every pair (the scene's band offset), or knowledge error "
              "its model lacks" + ("" if shrunk else "; σ may be optimistic there and above the knowledge's cut-off")
            + ("" if not shared else "; the same offset, split by the sun's direction, σ holds above the band on "
               + ", ".join(shared)))


def scene_offset_line_of_run(run, axes) -> str | None:
    """:func:`scene_offset_line` of a loaded run (None without a restoration)."""
    if run.restoration is None:
        return None
    # the pairs' delays as restoration.nc records them (no need to rebuild the whole result for them)
    taus = run.restoration["tau_s"].values if "tau_s" in run.restoration else []
    ds = getattr(run.product, "ds", None)
    eph = ds["ephemeris"].values if ds is not None and "ephemeris" in ds else None
    return scene_offset_line(ds.attrs if ds is not None else {}, taus, axes, eph)


#: the knowledge filter's line is said when its error below the high-pass is at least this on some axis [px]
KNOWLEDGE_FILTER_SHOWN_PX = 0.01


def knowledge_filter_line(product_attrs, restoration, axes) -> str | None:
    """The line saying how much of the AOCS filter's own error stays in the restored angle below the high-pass
    (:func:`restore.observability.knowledge_filter_error_below`, which σ holds:
    :func:`restore.stages.raise_by_knowledge_filter`), where it is at least :data:`KNOWLEDGE_FILTER_SHOWN_PX` on
    some axis, with a causal filter's lag; else None.

    ``product_attrs``: product.nc's attributes (the knowledge's filter); ``restoration``: restoration.nc (the
    knowledge at the lines, each axis's high-pass)."""
    import json

    from restore.knowledge_prior import knowledge_response
    from restore.observability import knowledge_filter_error_below

    at = dict(product_attrs or {})
    if restoration is None or "knowledge_cutoff_hz" not in at or "knowledge_filter_order" not in at \
            or "integration" not in restoration.attrs or "pixel_ifov_rad" not in restoration.attrs:
        return None
    integ = json.loads(restoration.attrs["integration"])
    cutoff, order = float(at["knowledge_cutoff_hz"]), int(at["knowledge_filter_order"])
    kind = str(at.get("knowledge_filter", "butterworth_zero_phase"))
    dephased = any(f"knowledge_dephasing_{a}" in restoration for a in axes)
    if dephased:  # the restoration took the causal phase out first (restore.knowledge_dephasing)
        from restore.knowledge_dephasing import DEPHASABLE_KINDS
        kind = DEPHASABLE_KINDS.get(kind, kind)
    px = float(restoration.attrs["pixel_ifov_rad"])
    found = []
    for a in axes:
        if a == "yaw" or a not in integ or f"knowledge_{a}" not in restoration:
            continue
        used = np.asarray(restoration[f"knowledge_{a}"].values, dtype=np.float64)
        if f"knowledge_dephasing_{a}" in restoration:
            used = used + np.asarray(restoration[f"knowledge_dephasing_{a}"].values, dtype=np.float64)
        e = knowledge_filter_error_below(used,
                                         float(integ[a]["line_period_s"]), highpass_hz=float(integ[a]["highpass_hz"]),
                                         cutoff_hz=cutoff, order=order, kind=kind)
        found.append((a, e / px, float(integ[a]["highpass_hz"])))
    if not found or max(v for _, v, _ in found) < KNOWLEDGE_FILTER_SHOWN_PX:
        return None
    f0 = 1e-3 * cutoff
    lag = -float(np.angle(complex(np.atleast_1d(knowledge_response(np.array([f0]), cutoff, order, kind))[0]))) \
        / (2 * np.pi * f0)
    what = f"its causal filter lags the attitude by {lag:.2f} s" if lag > 1e-4 else \
        "its filter's own error (its causal phase taken out)" if dephased else "its filter's own error"
    return (f"  below the high-pass ({found[0][2]:.2f} Hz) the restored angle is the AOCS knowledge, and {what}: "
            + ", ".join(f"{a} {v:.3f} px" for a, v, _ in found)
            + " there, not restored (σ holds it)")


def knowledge_dephasing_line(product_attrs, restoration) -> str | None:
    """The line saying that a causal AOCS knowledge had its filter's phase taken out before it was used
    (:mod:`restore.knowledge_dephasing`): the filter and its lag; None when nothing was dephased."""
    at = dict(product_attrs or {})
    if restoration is None or not any(f"knowledge_dephasing_{a}" in restoration for a in ("roll", "pitch", "yaw")) \
            or "knowledge_cutoff_hz" not in at or "knowledge_filter_order" not in at:
        return None
    from restore.knowledge_dephasing import DEPHASABLE_KINDS, group_delay_at_zero

    kind = str(at.get("knowledge_filter", "butterworth_zero_phase"))
    if kind not in DEPHASABLE_KINDS:
        return None
    cutoff, order = float(at["knowledge_cutoff_hz"]), int(at["knowledge_filter_order"])
    lag = group_delay_at_zero(cutoff, order, kind)
    return (f"  the AOCS knowledge's causal filter (order {order}, {cutoff:g} Hz) lags the attitude by {lag:.3f} s: "
            "its phase was taken out before the knowledge was used (restoration.knowledge_dephasing)")


def knowledge_timing_line(restoration) -> str | None:
    """The line saying the AOCS knowledge's latency the images measured and took out
    (:mod:`restore.knowledge_timing`), where it was taken out (shrunk by its σ); else None."""
    import json

    if restoration is None:
        return None
    est = json.loads(restoration.attrs.get("knowledge_latency", "{}") or "{}")
    # a restoration written before the shrinkage (thirty-ninth session) says "significant" and took it whole
    if not est or not est.get("taken", est.get("significant")):
        return None
    lo, hi = est["band_hz"]
    how = (f"advanced by {est['applied_s'] * 1e3:.1f} ms (the estimate shrunk by its σ)" if "applied_s" in est
           else "advanced by that")
    return (f"  the AOCS knowledge was {est['delay_s'] * 1e3:.1f} ± {est['sigma_s'] * 1e3:.1f} ms late against the "
            f"images ({', '.join(est['axes'])} at {lo:.2f}–{hi:.2f} Hz): {how} before it was used")


def knowledge_filter_line_of_run(run, axes) -> str | None:
    """:func:`knowledge_filter_line` of a loaded run (None without a restoration or a product)."""
    ds = getattr(run.product, "ds", None) if getattr(run, "product", None) is not None else None
    if run.restoration is None or ds is None:
        return None
    return knowledge_filter_line(ds.attrs, run.restoration, axes)


#: the notch line is said when the low bridge costs at least this much on some axis [px]
NOTCH_CONTINUUM_SHOWN_PX = 0.01


def notch_continuum_line(records: dict, axes, ifov_rad: float) -> str | None:
    """Where a notch round the pairs' common blind frequencies was bridged below the continuum on its sides
    (:func:`restore.observability.notch_continuum`), costing at least :data:`NOTCH_CONTINUUM_SHOWN_PX`: the
    notch, the prior inside against the sides' level, and the error that adds; else None.

    ``records``: ``{axis: integration record}`` (their prior, pairs, sampling and high-pass)."""
    from restore.observability import record_notch_continuum

    found = []
    for a in axes:
        rec = records.get(a)
        if rec is None or a == "yaw":
            continue
        for n in record_notch_continuum(rec):
            px = n.missing_rms_rad / ifov_rad
            if px >= NOTCH_CONTINUUM_SHOWN_PX:
                found.append(f"{a} {n.band_hz[0]:.1f}–{n.band_hz[1]:.1f} Hz (prior {n.bridged:.1e} against "
                             f"{n.sides:.1e} rad²/Hz beside it): {px:.3f} px")
    if not found:
        return None
    return ("  a blind frequency's notch bridged below the continuum on its sides, so the pairs' flanks there are "
            "not restored and σ does not hold it: " + "; ".join(found))


def notch_continuum_line_of_run(run, axes) -> str | None:
    """:func:`notch_continuum_line` of a loaded run (None without a restoration)."""
    if run.restoration is None:
        return None
    from restore.restoration_io import result_from_dataset

    res = result_from_dataset(run.restoration)
    return notch_continuum_line(res.integration, axes, res.pixel_ifov_rad)


def run_summary(run_dir: str | Path, *, report_path: str | Path | None = None) -> str:
    """A short text summary of a restored run.

    Parameters
    ----------
    run_dir : path
        Run directory (product.nc, restoration.nc, truth.nc when simulated).
    report_path : path, optional
        Where the HTML report is, said on the last line.

    Returns
    -------
    str
        Several lines: one per axis with restored and knowledge errors [px and
        µrad for yaw], coverage, then ``PASS``/``FAIL`` and the reason, or why
        the requirement cannot be checked.
    """
    from .frames_report import frames_summary, is_frames_run

    if is_frames_run(run_dir):
        return frames_summary(run_dir, report_path=report_path)
    run = D.load_run(run_dir)
    hd = D.headline(run)
    axes_r = D.restored_axes(run)
    lines = []
    if run.restoration is None:
        lines.append("no restoration in this run (run `simsat restore RUN_DIR`)")
    elif run.truth is None:
        lines.append("no truth in this run: the restored error cannot be measured")
        for a in axes_r:
            d = hd["axes"][a]
            lines.append(f"  {a:5s}  coverage {d.get('coverage', float('nan')) * 100:5.1f} %, "
                         f"correction {d.get('correction_rms_px', float('nan')):.3f} px RMS")
    else:
        lines.append(f"{'':12s}{'restored error':>18s}  {'AOCS knowledge':>18s}  {'coverage':>9s}")
        lines.append(f"{'':12s}{'RMS':>9s}{'99.7 %':>9s}  {'RMS':>9s}{'99.7 %':>9s}")
        for a in axes_r:
            d = hd["axes"][a]
            unit, key = ("µrad", "urad") if a == "yaw" else ("px", "px")  # yaw barely moves the image
            lines.append(f"  {a:5s}{'[' + unit + ']':>5s}"
                         f"{_fmt(d.get('rms_' + key)):>9s}{_fmt(d.get('p997_' + key)):>9s}  "
                         f"{_fmt(d.get('knowledge_rms_' + key)):>9s}{_fmt(d.get('knowledge_p997_' + key)):>9s}  "
                         f"{d.get('coverage', float('nan')) * 100:8.1f}%")
        lines.append("  (error = estimate − truth, mean removed: the constant is unobservable from images)")
        outside = unobservable_line(run, axes_r)
        if outside:
            lines.append(outside)
        if int(run.restoration.attrs.get("anchored_on_star_tracker", 0)):
            errs = _attitude_errors(run)
            lines.append("  absolute (mean kept), anchored on the star tracker: " + ", ".join(
                f"{a} {errs[a]['absolute_rms_px']:.3f} px (knowledge {errs[a].get('knowledge_absolute_rms_px', float('nan')):.3f})"
                for a in axes_r if a in errs and a != "yaw"))
    cov = coverage_line(run.restoration, axes_r)
    if cov:
        lines.append(cov)
    transient = transient_line(run.restoration, axes_r)
    if transient:
        lines.append(transient)
    tone = blind_tone_line(run.restoration, axes_r)
    if tone:
        lines.append(tone)
    offset = scene_offset_line_of_run(run, axes_r)
    if offset:
        lines.append(offset)
    product_attrs = getattr(getattr(run, "product", None), "ds", None)
    product_attrs = product_attrs.attrs if product_attrs is not None else {}
    for lag in (knowledge_dephasing_line(product_attrs, run.restoration), knowledge_timing_line(run.restoration),
                knowledge_filter_line_of_run(run, axes_r)):
        if lag:
            lines.append(lag)
    for notch in (notch_level_line(run.restoration, axes_r), notch_continuum_line_of_run(run, axes_r),
                  knowledge_band_noise_line(run.restoration, axes_r)):
        if notch:
            lines.append(notch)
    disagreement = knowledge_check_line(run.restoration, axes_r,
                                        took_share=bool(run.settings.get("sigma_knowledge_check", True)))
    if disagreement:
        lines.append(disagreement)
    excess = conditioned_excess_line(run.restoration, axes_r)
    if excess:
        lines.append(excess)
    verdict = hd.get("verdict") or ""
    if hd.get("passed") is True:
        lines.append(f"requirement: {verdict}")
    elif hd.get("passed") is False:
        lines.append(f"requirement: {verdict}")
    elif verdict:
        lines.append(f"requirement not checked: {verdict}")
    if report_path is not None:
        lines.append(f"report: {report_path}")
    return "\n".join(lines)
