"""Input checks and small helpers shared by the integration methods (private)."""
from __future__ import annotations

import math
import numpy as np

__all__ = ["prepare", "per_pair", "lag_samples", "check_positive", "lagrange4", "lagrange4_weights",
           "fractional_sample"]


def prepare(diffs, taus, dt) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Validate the common inputs of the integration methods.

    Returns
    -------
    D : ndarray, shape (p, N)
        Differentials (float64), NaN at gaps.
    valid : ndarray of bool, shape (p, N)
        Finite samples of ``D``.
    taus : ndarray, shape (p,)
        Lags (s).
    dt : float
        Sampling step (s).
    """
    try:
        dt = float(dt)
    except (TypeError, ValueError):
        raise ValueError(f"dt: must be a number, got {dt!r}") from None
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"dt: must be > 0, got {dt}")
    if isinstance(diffs, np.ndarray) and diffs.ndim == 1:
        diffs = [diffs]
    rows = [np.asarray(d, dtype=np.float64) for d in diffs]
    if not rows:
        raise ValueError("diffs: must hold at least one differential")
    for j, r in enumerate(rows):
        if r.ndim != 1:
            raise ValueError(f"diffs[{j}]: must be 1-D, got shape {r.shape}")
        if r.size != rows[0].size:
            raise ValueError(f"diffs[{j}]: length {r.size} differs from diffs[0] ({rows[0].size})")
    if rows[0].size < 4:
        raise ValueError(f"diffs: need at least 4 samples, got {rows[0].size}")
    D = np.vstack(rows)
    D[np.isinf(D)] = np.nan
    taus = np.atleast_1d(np.asarray(taus, dtype=np.float64))
    if taus.ndim != 1 or taus.size != D.shape[0]:
        raise ValueError(f"taus: must have one lag per differential ({D.shape[0]}), got {taus.size}")
    if not np.all(np.isfinite(taus)) or np.any(taus <= 0):
        raise ValueError(f"taus: must be finite and > 0, got {taus.tolist()}")
    valid = np.isfinite(D)
    if not valid.any():
        raise ValueError("diffs: all samples are NaN")
    return D, valid, taus, dt


def per_pair(value, p: int, name: str) -> np.ndarray | None:
    """Broadcast a scalar-or-sequence option to one value per pair (None stays None)."""
    if value is None:
        return None
    arr = np.atleast_1d(np.asarray(value, dtype=np.float64))
    if arr.size == 1:
        arr = np.full(p, float(arr[0]))
    if arr.shape != (p,):
        raise ValueError(f"{name}: must be a scalar or have one value per pair ({p}), got {arr.size}")
    if not np.all(np.isfinite(arr)) or np.any(arr < 0):
        raise ValueError(f"{name}: must be finite and >= 0, got {arr.tolist()}")
    return arr


def lag_samples(taus: np.ndarray, dt: float) -> np.ndarray:
    """Lags in samples (float)."""
    return np.asarray(taus, dtype=np.float64) / dt


def check_positive(name: str, value, *, allow_zero: bool = False) -> float:
    """A finite float > 0 (or >= 0), else ValueError naming ``name``."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: must be a number, got {value!r}") from None
    if not math.isfinite(v) or (v < 0 if allow_zero else v <= 0):
        raise ValueError(f"{name}: must be {'>=' if allow_zero else '>'} 0, got {value!r}")
    return v


def lagrange4_weights(frac) -> np.ndarray:
    """4-point Lagrange interpolation weights at nodes ``-1, 0, 1, 2`` for positions ``frac`` (any shape,
    usually in [0, 1)); returns shape ``frac.shape + (4,)``."""
    u = np.asarray(frac, dtype=np.float64)
    nodes = (-1.0, 0.0, 1.0, 2.0)
    w = np.ones(u.shape + (4,))
    for i, ni in enumerate(nodes):
        for k, nk in enumerate(nodes):
            if k != i:
                w[..., i] *= (u - nk) / (ni - nk)
    return w


def lagrange4(frac: float) -> np.ndarray:
    """4-point Lagrange interpolation weights at ``-1, 0, 1, 2`` for position ``frac`` in [0, 1)."""
    return lagrange4_weights(float(frac))


def fractional_sample(x: np.ndarray, pos: np.ndarray) -> np.ndarray:
    """Cubic (4-point Lagrange) interpolation of ``x`` at fractional indices ``pos``.

    NaN where the 4 neighbours are not all inside ``x`` and finite.
    """
    x = np.asarray(x, dtype=np.float64)
    pos = np.asarray(pos, dtype=np.float64)
    fl = np.floor(pos).astype(int)
    u = pos - fl
    out = np.zeros(pos.shape)
    ok = (fl - 1 >= 0) & (fl + 2 < x.size)
    idx = np.clip(fl, 1, max(1, x.size - 3))
    w = lagrange4_weights(u)
    for i, ni in enumerate((-1, 0, 1, 2)):
        out += w[..., i] * x[np.clip(idx + ni, 0, x.size - 1)]
    # exact hits (integer positions) need only the sample itself
    exact = (u == 0) & (fl >= 0) & (fl < x.size)
    out = np.where(exact, x[np.clip(fl, 0, x.size - 1)], np.where(ok, out, np.nan))
    return out

