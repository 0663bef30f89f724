"""Weighting the lines where the two bands' windows are distorted relative to each other.

Band B sees the ground of line ``l`` of A at line ``l + τ/Te + λ(l)``: the
per-line lag ``λ`` is the along-track differential in lines (time
synchronisation, :func:`restore.stages.line_lag`). Where ``λ`` changes fast
from line to line, B's rows no longer sample the ground at A's spacing: the
window of a few lines matched in B is stretched or squeezed along track by
``|dλ/dl|`` lines per line (at 4 × phr_cmg's amplitude up to 3 lines per line
on 1 % of the lines: the band folds). A translation fitted to a stretched
window is a poorer measurement; at 4 × the amplitude, the differentials of the
10 % most stretched lines are off by 0.42 px RMS against 0.09-0.12 px on the
rest (measured against the exact differentials).

The integration weighs every line by its matched points only. Here each
pair's differentials get a weight factor from the data themselves: the
residual of the fit (the measured differentials minus those the integrated
attitude predicts, :func:`restore.posterior.fit_residuals`) is binned by
stretch, its mean square per bin is made non-decreasing in the stretch
(isotonic regression: a more distorted window cannot match better), and a
line's factor is the least distorted bin's mean square over its own. Nothing
is tuned per scene: where the residual does not grow with the stretch the
factors stay near 1.
"""
from __future__ import annotations

import numpy as np

__all__ = ["window_stretch", "isotonic_increasing", "stretch_weight_factors", "STRETCH_BINS",
           "MIN_LINES_PER_BIN"]

#: stretch bins per pair (quantiles of its usable lines)
STRETCH_BINS = 20
#: fewest usable lines per bin: fewer bins below 20 × this many lines, no weighting below 2 bins
MIN_LINES_PER_BIN = 50


def window_stretch(lag_lines: np.ndarray) -> np.ndarray:
    """Along-track stretch of band B's window relative to A's [lines per line]: ``|dλ/dl|``.

    ``lag_lines`` (line,) or (pair, line): the per-line lag in lines; NaN
    (no lag known) counts as 0. Central differences inside, one-sided at the
    ends (:func:`numpy.gradient`).
    """
    lg = np.nan_to_num(np.asarray(lag_lines, dtype=np.float64))
    if lg.shape[-1] < 2:
        return np.zeros_like(lg)
    return np.abs(np.gradient(lg, axis=-1))


def isotonic_increasing(y, w=None) -> np.ndarray:
    """Least-squares non-decreasing fit of ``y`` (weights ``w``): pool adjacent violators.

    >>> isotonic_increasing([1.0, 3.0, 2.0, 4.0]).tolist()
    [1.0, 2.5, 2.5, 4.0]
    """
    y = np.asarray(y, dtype=np.float64)
    w = np.ones_like(y) if w is None else np.asarray(w, dtype=np.float64)
    if y.ndim != 1 or w.shape != y.shape:
        raise ValueError(f"isotonic_increasing: y and w must be 1-D of one length, got {y.shape} and {w.shape}")
    means: list = []
    weights: list = []
    counts: list = []
    for v, wt in zip(y, w):
        means.append(float(v))
        weights.append(float(wt))
        counts.append(1)
        while len(means) > 1 and means[-2] > means[-1]:
            m2, w2, c2 = means.pop(), weights.pop(), counts.pop()
            m1, w1, c1 = means.pop(), weights.pop(), counts.pop()
            wt = w1 + w2
            means.append((m1 * w1 + m2 * w2) / wt if wt > 0 else 0.5 * (m1 + m2))
            weights.append(wt)
            counts.append(c1 + c2)
    return np.repeat(np.array(means), counts)


def stretch_weight_factors(residuals: np.ndarray, stretch: np.ndarray, usable: np.ndarray | None = None, *,
                           bins: int = STRETCH_BINS, min_lines: int = MIN_LINES_PER_BIN) -> np.ndarray:
    """Per pair and line, the weight factor (0, 1] that the fit residual's growth with the stretch calls for.

    Parameters
    ----------
    residuals : ndarray (pair, line)
        Fit residuals of one axis's differentials [any unit], NaN where none.
    stretch : ndarray (pair, line)
        :func:`window_stretch` of each pair's lags.
    usable : ndarray of bool (pair, line), optional
        Lines whose residual counts (e.g. weight > 0); default: finite residuals.
    bins, min_lines : int
        Quantile bins of the stretch per pair, each of at least ``min_lines``
        usable lines (fewer bins on a short record; a pair with fewer than
        ``2 × min_lines`` usable lines keeps factor 1).

    Returns
    -------
    ndarray (pair, line)
        ``v(least stretched bin) / v(s)`` with ``v`` the residual's mean square
        per bin made non-decreasing in the stretch and interpolated linearly
        between the bins' median stretches (held beyond); 1 on a pair that
        cannot be binned.
    """
    r = np.asarray(residuals, dtype=np.float64)
    s = np.asarray(stretch, dtype=np.float64)
    if r.shape != s.shape or r.ndim != 2:
        raise ValueError(f"residuals and stretch must be (pair, line) of one shape, got {r.shape} and {s.shape}")
    ok_all = np.isfinite(r) & np.isfinite(s)
    if usable is not None:
        ok_all &= np.asarray(usable, dtype=bool)
    out = np.ones_like(r)
    for j in range(r.shape[0]):
        ok = ok_all[j]
        nb = min(int(bins), int(ok.sum()) // max(int(min_lines), 1))
        if nb < 2:
            continue
        order = np.argsort(s[j][ok], kind="stable")
        groups = np.array_split(order, nb)
        rr, ss = r[j][ok], s[j][ok]
        centre = np.array([np.median(ss[g]) for g in groups])
        ms = np.array([np.mean(rr[g] ** 2) for g in groups])
        v = isotonic_increasing(ms, np.array([g.size for g in groups], dtype=np.float64))
        if not v[0] > 0:
            continue
        out[j] = v[0] / np.interp(s[j], centre, v)
    return out
