"""Run report data: scenario and headline (see :mod:`reports.report_data`)."""
from __future__ import annotations

import numpy as np

from reports.metrics import error_stats, truth_at
from simsat.units import AXES

from .loading import RunData

__all__ = ['scenario_summary', 'restored_axes', 'attitude_table', 'headline']


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
    return judge(res, out_axes, req, axes_r)


def judge(res: dict, per_axis: dict, req: dict, axes) -> dict:
    """Set ``res``'s ``worst`` (over ``axes`` of ``per_axis``), ``passed`` and ``verdict`` against ``req``."""
    worst = {"rms_px": max(per_axis[a]["rms_px"] for a in axes), "p997_px": max(per_axis[a]["p997_px"] for a in axes)}
    res["worst"] = worst
    if not req:
        res["verdict"] = "no requirement in the scenario"
        return res
    res["passed"], res["verdict"] = requirement_verdict(worst, req, axes)
    return res


def requirement_verdict(worst: dict, req: dict, axes) -> tuple[bool, str]:
    """(passed, "PASS: …" / "FAIL: …") of the worst-axis figures against ``max_rms_px`` / ``max_p997_px``."""
    checks = []
    ok = True
    for key, wkey, label in (("max_rms_px", "rms_px", "RMS"), ("max_p997_px", "p997_px", "99.7 %")):
        if key in req:
            good = bool(worst[wkey] <= req[key])
            ok &= good
            checks.append(f"worst-axis {label} {worst[wkey]:.4f} px {'≤' if good else '>'} {req[key]:g} px")
    return ok, ("PASS" if ok else "FAIL") + ": " + "; ".join(checks) + f" (restored axes: {', '.join(axes)})"
