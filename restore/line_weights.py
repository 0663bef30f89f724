"""Line weights learnt from the fit residual: where a known cause makes the matches worse, weigh the lines less.

The integration weighs every line of a pair by its matched points only
(noise variance ∝ 1 / points). Two causes make whole lines worse than that,
and both are known per line before any truth:

* **Stretched windows.** Band B sees the ground of line ``l`` of A at line
  ``l + τ/Te + λ(l)``: the per-line lag ``λ`` is the along-track differential
  in lines (time synchronisation, :func:`restore.stages.line_lag`). Where
  ``λ`` changes fast from line to line, B's rows no longer sample the ground
  at A's spacing: the window of a few lines matched in B is stretched or
  squeezed along track by ``|dλ/dl|`` lines per line (at 4 × phr_cmg's
  amplitude up to 3 lines per line on 1 % of the lines: the band folds). A
  translation fitted to a stretched window is a poorer measurement: there the
  10 % most stretched lines' differentials are off by 0.42 px RMS against
  0.09-0.12 px on the rest (measured against the exact differentials).
* **Gap edges.** Next to a cloud, water or a stretch without texture, the
  few clear lines match worse (windows touching the gap, thin texture): with
  half the scene under cloud, the differentials within 50 lines of a gap are
  off by 2-3 × the RMS of those farther away, and the fit residual shows it
  (:func:`gap_distance`).

For each cause and pair, the fit residual (the measured differentials minus
those the integrated attitude predicts, :func:`restore.posterior.fit_residuals`),
normalised by the current weights, is binned by the cause's covariate, its
mean square per bin is made monotone in it (isotonic regression: a more
stretched window, a line closer to a gap, cannot match better), and a line's
factor is the best bin's mean square over its own. Nothing is tuned per scene:
where the residual does not grow with the covariate the factors stay near 1
(the growth is counted beyond three standard errors of a bin's estimate).
"""
from __future__ import annotations

import numpy as np
from scipy.ndimage import distance_transform_edt

__all__ = ["window_stretch", "gap_distance", "isotonic_increasing", "residual_weight_factors", "COVARIATE_BINS",
           "MIN_LINES_PER_BIN"]

#: covariate bins per pair (quantiles of its usable lines)
COVARIATE_BINS = 20
#: fewest usable lines per bin: fewer bins below 20 × this many lines
MIN_LINES_PER_BIN = 50
#: no weighting with fewer bins (500 usable lines): on tiny's 384 lines the relation, learnt from 7 bins of 55,
#: weighed half the pitch lines by 0.05-0.9 and a line dropped elsewhere moved the restored pitch by 0.15 px
MIN_BINS = 10


def window_stretch(lag_lines: np.ndarray) -> np.ndarray:
    """Along-track stretch of band B's window relative to A's [lines per line]: ``|dλ/dl|``.

    ``lag_lines`` (line,) or (pair, line): the per-line lag in lines, NaN
    where none is known (a gap). The mean of the differences to the previous
    and the next line (a central difference), of the one that exists beside a
    gap or at an end; 0 on a line with no known neighbour.
    """
    lg = np.asarray(lag_lines, dtype=np.float64)
    if lg.shape[-1] < 2:
        return np.zeros_like(lg)
    step = np.abs(np.diff(lg, axis=-1))
    pad = np.full(lg.shape[:-1] + (1,), np.nan)
    both = np.stack([np.concatenate([pad, step], axis=-1), np.concatenate([step, pad], axis=-1)])
    n = np.isfinite(both).sum(axis=0)
    return np.where(n > 0, np.nansum(both, axis=0) / np.maximum(n, 1), 0.0)


def gap_distance(usable: np.ndarray) -> np.ndarray:
    """Lines from each line to the nearest unusable one, per row of ``usable`` ((line,) or (pair, line)).

    0 on an unusable line; the record's ends are not gaps, nor the unusable
    lines that run to them (a pair's last τ/Te lines, whose partner lies
    beyond the record): a row without an inner gap gets its length.
    """
    u = np.atleast_2d(np.asarray(usable, dtype=bool))
    out = np.empty(u.shape)
    for j, row in enumerate(u):
        inner = row.copy()
        idx = np.flatnonzero(row)
        if idx.size:
            inner[:idx[0]] = True
            inner[idx[-1] + 1:] = True
        out[j] = distance_transform_edt(inner) if not inner.all() else row.size
        out[j][~row] = 0.0
    return out.reshape(np.shape(usable))


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


def residual_weight_factors(residuals: np.ndarray, covariate: np.ndarray, usable: np.ndarray | None = None,
                            weights: np.ndarray | None = None, *, increasing: bool = True,
                            bins: int = COVARIATE_BINS, min_lines: int = MIN_LINES_PER_BIN) -> np.ndarray:
    """Per pair and line, the weight factor (0, 1] that the fit residual's growth with ``covariate`` calls for.

    Parameters
    ----------
    residuals : ndarray (pair, line)
        Fit residuals of one axis's differentials [any unit], NaN where none.
    covariate : ndarray (pair, line)
        What the matching error may grow with, e.g. :func:`window_stretch` of
        each pair's lags, or :func:`gap_distance` (with ``increasing=False``).
    usable : ndarray of bool (pair, line), optional
        Lines whose residual counts (e.g. weight > 0); default: finite residuals.
    weights : ndarray (pair, line), optional
        The weights the residuals were fitted with (noise variance ∝ 1 /
        weight): the residuals are normalised by them first, so a cause the
        weights already model is not counted twice.
    increasing : bool
        The residual's mean square can only grow with the covariate (True) or
        only shrink (False: distance to a gap).
    bins, min_lines : int
        Quantile bins of the covariate per pair, each of at least ``min_lines``
        usable lines (fewer bins on a short record; a pair with fewer than
        :data:`MIN_BINS` × ``min_lines`` usable lines keeps factor 1).

    Returns
    -------
    ndarray (pair, line)
        ``v(best bin) / v(covariate)`` with ``v`` the normalised residual's
        mean square per bin, made monotone in the covariate and interpolated
        linearly between the bins' median covariates (held beyond); 1 on a
        pair that cannot be binned.
    """
    r = np.asarray(residuals, dtype=np.float64)
    c = np.asarray(covariate, dtype=np.float64)
    if r.shape != c.shape or r.ndim != 2:
        raise ValueError(f"residuals and covariate must be (pair, line) of one shape, got {r.shape} and {c.shape}")
    ok_all = np.isfinite(r) & np.isfinite(c)
    if usable is not None:
        ok_all &= np.asarray(usable, dtype=bool)
    if weights is not None:
        w = np.asarray(weights, dtype=np.float64)
        ok_all &= np.isfinite(w) & (w > 0)
        r = r * np.sqrt(np.where(ok_all, w, 0.0))
    sign = 1.0 if increasing else -1.0
    out = np.ones_like(r)
    for j in range(r.shape[0]):
        ok = ok_all[j]
        nb = min(int(bins), int(ok.sum()) // max(int(min_lines), 1))
        if nb < min(MIN_BINS, int(bins)):
            continue
        x = sign * c[j]
        groups = np.array_split(np.argsort(x[ok], kind="stable"), nb)
        rr, xx = r[j][ok], x[ok]
        centre = np.array([np.median(xx[g]) for g in groups])
        # the mean square, not a robust scale: a linear estimate's error grows with the variance, tails included
        # (with a median per bin large_amplitude's pitch 0.045 → 0.050 px: the stretched lines' errors are
        # heavy-tailed); a cluster of gross lines the despiker keeps raises its bin
        v = isotonic_increasing(np.array([np.mean(rr[g] ** 2) for g in groups]),
                                np.array([g.size for g in groups], dtype=np.float64))
        if not v[0] > 0:
            continue
        # a bin's mean square scatters by ≈ √(2 / m) over m Gaussian lines: growth within 3 of those is noise,
        # taken off (continuously: a threshold would flip the weights of a short record on a small change)
        ratio = 1.0 + np.maximum(v / v[0] - 1.0 - 3.0 * np.sqrt(2.0 / min(g.size for g in groups)), 0.0)
        out[j] = np.where(np.isfinite(x), 1.0 / np.interp(np.nan_to_num(x), centre, ratio), 1.0)
    return out
