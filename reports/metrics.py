"""The accuracy metric of DESIGN.md.

error(t) = estimated θ(t) − true θ(t) per axis, over the lines where an
estimate exists, with its mean removed (the constant is unobservable from
images alone). Reported as RMS and 99.7th percentile of |error|, in pixels of
the reference band and in µrad, beside the same figures for the uncorrected
knowledge (AOCS) error, and the coverage (fraction of lines estimated).
"""
from __future__ import annotations

import numpy as np

__all__ = ["error_stats", "attitude_errors", "truth_at"]

AXES = ("roll", "pitch", "yaw")


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


def truth_at(truth, axis: str, t) -> np.ndarray:
    """True angle [rad] at times ``t`` (linear interpolation of the finely sampled truth)."""
    return np.interp(np.asarray(t, dtype=np.float64), np.asarray(truth["time"].values),
                     np.asarray(truth[axis].values))


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
        out[a] = s
    return out
