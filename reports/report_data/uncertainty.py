"""Run report data: the predicted 1-σ per line against the actual error (see :mod:`reports.report_data`)."""
from __future__ import annotations

import json

import numpy as np

from reports.metrics import axis_yaw_seen

from .headline import attitude_table, restored_axes
from .loading import RunData

__all__ = ["uncertainty", "sigma_calibration"]


def sigma_calibration(sigma, error, *, bins: int = 8) -> dict:
    """Actual RMS error against predicted σ, lines grouped in ``bins`` quantile bins of σ.

    Returns
    -------
    dict
        ``predicted`` (RMS σ of the bin's lines), ``actual`` (RMS error of the
        same lines), ``lines`` (count per bin); empty arrays when no line has both.
    """
    s = np.asarray(sigma, dtype=np.float64)
    e = np.asarray(error, dtype=np.float64)
    ok = np.isfinite(s) & np.isfinite(e)
    if not ok.any():
        return {"predicted": np.zeros(0), "actual": np.zeros(0), "lines": np.zeros(0, int)}
    s, e = s[ok], e[ok]
    edges = np.unique(np.quantile(s, np.linspace(0, 1, bins + 1)))
    idx = np.clip(np.searchsorted(edges, s, side="right") - 1, 0, max(edges.size - 2, 0))
    pred, act, cnt = [], [], []
    for k in range(max(edges.size - 1, 1)):
        m = idx == k
        if m.any():
            pred.append(np.sqrt(np.mean(s[m] ** 2)))
            act.append(np.sqrt(np.mean(e[m] ** 2)))
            cnt.append(int(m.sum()))
    return {"predicted": np.array(pred), "actual": np.array(act), "lines": np.array(cnt, dtype=int)}


def uncertainty(run: RunData) -> dict:
    """Per restored axis: predicted σ per line, flags, and (with truth) the actual error beside it [rad].

    Returns
    -------
    dict
        ``{axis: {time_s, sigma, flagged, flag_limit, flag_judged_on ("model": the model's σ before the local
        error raised it, or "reported"), predicted_rms, noise_scale, band_shares, knowledge_check (the restored
        angle against the smoothed knowledge: :meth:`restore.knowledge_check.KnowledgeCheck.as_dict`, or {}),
        fused_lines (lines whose low band took the AOCS knowledge's: :mod:`restore.knowledge_fusion`),
        [error (off nadir less the yaw seen as this axis, which σ does not hold: ``yaw_seen_removed`` the
        coupling), actual_rms, ratio, within_2sigma, calibration]}}``; empty when
        the restoration carries no predicted σ (``posterior_samples = 0``).
    """
    rest = run.restoration
    if rest is None:
        return {}
    att = attitude_table(run)
    out = {}
    for a in restored_axes(run):
        if f"sigma_{a}" not in rest:
            continue
        sg = np.asarray(rest[f"sigma_{a}"].values, dtype=np.float64)
        fl = np.asarray(rest[f"flagged_{a}"].values, dtype=bool) if f"flagged_{a}" in rest else np.zeros(sg.size, bool)
        valid = np.isfinite(np.asarray(rest[a].values, dtype=np.float64)) & np.isfinite(sg)
        d = {"time_s": att["time_s"], "sigma": sg, "flagged": fl,
             "flag_limit": float(rest[f"sigma_{a}"].attrs.get("flag_limit_rad", np.nan)),
             "flag_judged_on": str(rest[f"sigma_{a}"].attrs.get("flag_judged_on", "reported")),
             "noise_scale": float(rest[f"sigma_{a}"].attrs.get("noise_scale", 1.0)),
             "band_shares": json.loads(rest[f"sigma_{a}"].attrs.get("band_noise_shares", "{}")),
             "knowledge_check": json.loads(rest[f"sigma_{a}"].attrs.get("knowledge_check", "{}") or "{}"),
             "predicted_rms": float(np.sqrt(np.mean(sg[valid] ** 2))) if valid.any() else float("nan"),
             "fused_lines": int(np.count_nonzero(np.asarray(rest[f"knowledge_fusion_weight_{a}"].values) > 0))
             if f"knowledge_fusion_weight_{a}" in rest else 0}
        if f"error_{a}" in att:
            e = np.where(valid, att[f"error_{a}"], np.nan)
            coupling, seen = axis_yaw_seen(rest.attrs, att, a)
            if seen is not None:     # off nadir: the yaw this axis books as its own, which no pair can tell apart
                e = e - seen
                e = e - np.nanmean(e) if np.isfinite(e).any() else e
                d["yaw_seen_removed"] = coupling
            d["error"] = e
            d["actual_rms"] = float(np.sqrt(np.nanmean(e ** 2))) if valid.any() else float("nan")
            d["ratio"] = d["actual_rms"] / d["predicted_rms"] if d["predicted_rms"] > 0 else float("nan")
            d["within_2sigma"] = float(np.mean(np.abs(e[valid]) <= 2 * sg[valid])) if valid.any() else float("nan")
            d["calibration"] = sigma_calibration(sg, e)
        out[a] = d
    return out
