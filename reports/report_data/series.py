"""Run report data: time-series helpers (see :mod:`reports.report_data`)."""
from __future__ import annotations

import numpy as np

__all__ = ['minmax_decimate', 'longest_finite_run', 'zoom_window']


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
