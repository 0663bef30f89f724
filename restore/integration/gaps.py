"""Gaps (clouds, sea, untextured ground): what can be estimated, and filling.

A sample ``theta(n dt)`` is *observed* when at least one valid differential
involves it: ``d_j(n)`` (as ``-theta(n)``) or ``d_j(n - tau_j / dt)`` (as
``+theta(n)``; with a fractional lag, either neighbouring sample).  Outside the
observed samples, an estimate is only given by interpolation between estimated
neighbours on both sides, over interior runs of at most ``max_gap`` samples —
never by extrapolation past the first or last estimated sample.
"""
from __future__ import annotations

import numpy as np

from ._common import check_positive, fractional_sample, prepare

__all__ = ["observed_mask", "estimable_mask", "coverage", "fill_from_differentials",
           "interpolate_gaps", "nan_runs", "finish_estimate"]


def nan_runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """``(start, stop)`` of the runs of True in a 1-D boolean array."""
    m = np.concatenate([[False], np.asarray(mask, dtype=bool), [False]])
    d = np.diff(m.astype(np.int8))
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)))


def observed_mask(valid: np.ndarray, taus, dt: float) -> np.ndarray:
    """Samples of theta involved in at least one valid differential.

    Parameters
    ----------
    valid : ndarray of bool, shape (p, N)
        Valid (finite) differential samples.
    taus : sequence of float
        Lags (s).
    dt : float
        Sampling step (s).

    Returns
    -------
    ndarray of bool, shape (N,)
    """
    valid = np.atleast_2d(np.asarray(valid, dtype=bool))
    n = valid.shape[1]
    out = valid.any(0).copy()
    for j, tau in enumerate(np.atleast_1d(taus)):
        lag = float(tau) / dt
        for shift in {int(np.floor(lag)), int(np.ceil(lag))}:
            if 0 < shift < n:
                out[shift:] |= valid[j, :n - shift]
    return out


def estimable_mask(valid: np.ndarray, taus, dt: float, *, max_gap: int) -> np.ndarray:
    """Observed samples plus interior unobserved runs of at most ``max_gap`` samples."""
    obs = observed_mask(valid, taus, dt)
    out = obs.copy()
    if not obs.any():
        return out
    first, last = np.flatnonzero(obs)[[0, -1]]
    for a, b in nan_runs(~obs):
        if a > first and b <= last and b - a <= max_gap:
            out[a:b] = True
    return out


def coverage(theta) -> float:
    """Fraction of samples with an estimate (finite values)."""
    theta = np.asarray(theta)
    return float(np.isfinite(theta).mean()) if theta.size else 0.0


def fill_from_differentials(theta, diffs, taus, dt, *, max_passes: int = 64) -> np.ndarray:
    """Extend an estimate into its gaps through the differentials at their edges.

    A missing ``theta(n)`` is set to the mean of the available candidates
    ``theta(n + tau_j) - d_j(n)`` and ``theta(n - tau_j) + d_j(n - tau_j)``
    (fractional positions by 4-point Lagrange interpolation of estimated
    values or of valid differentials), repeatedly, so an estimate propagates by
    steps of ``tau`` as far as measurements allow.  Nothing is extrapolated
    beyond what the differentials link to the estimate.

    Parameters
    ----------
    theta : array_like, shape (N,)
        Estimate (rad) with NaN where missing.
    diffs, taus, dt
        As for :func:`restore.integration.integrate`.
    max_passes : int, keyword-only
        Upper bound on the propagation passes.

    Returns
    -------
    ndarray, shape (N,)
    """
    D, valid, taus, dt = prepare(diffs, taus, dt)
    th = np.array(theta, dtype=np.float64)
    if th.shape != (D.shape[1],):
        raise ValueError(f"theta: must have shape ({D.shape[1]},), got {th.shape}")
    n = np.arange(th.size, dtype=np.float64)
    for _ in range(max_passes):
        miss = ~np.isfinite(th)
        if not miss.any():
            break
        idx = np.flatnonzero(miss)
        acc = np.zeros(idx.size)
        cnt = np.zeros(idx.size)
        for j, tau in enumerate(taus):
            lag = tau / dt
            # forward link: theta(n) = theta(n + lag) - d_j(n)
            c1 = fractional_sample(th, n[idx] + lag) - D[j, idx]
            # backward link: theta(n) = theta(n - lag) + d_j(n - lag)
            c2 = fractional_sample(th, n[idx] - lag) + fractional_sample(D[j], n[idx] - lag)
            for c in (c1, c2):
                ok = np.isfinite(c)
                acc[ok] += c[ok]
                cnt[ok] += 1
        new = cnt > 0
        if not new.any():
            break
        th[idx[new]] = acc[new] / cnt[new]
    return th


def _ar_fit(x: np.ndarray, order: int, segments: list[tuple[int, int]]) -> np.ndarray | None:
    rows, rhs = [], []
    for a, b in segments:
        if b - a > order + 1:
            seg = x[a:b]
            win = np.lib.stride_tricks.sliding_window_view(seg, order + 1)
            rows.append(win[:, :-1])
            rhs.append(win[:, -1])
    if not rows:
        return None
    A = np.vstack(rows)
    y = np.concatenate(rhs)
    lam = 1e-6 * np.trace(A.T @ A) / order
    return np.linalg.solve(A.T @ A + lam * np.eye(order), A.T @ y)


def interpolate_gaps(theta, *, max_gap: int, order: int = 32, method: str = "ar") -> np.ndarray:
    """Fill interior NaN runs of at most ``max_gap`` samples from both neighbours.

    ``method="ar"``: an autoregressive model of ``order`` is fitted (least
    squares) on the finite parts of ``theta``; the gap is predicted forward from
    the left edge and backward from the right edge, and the two predictions are
    blended with a raised-cosine weight (suited to quasi-harmonic signals).
    ``method="linear"``: linear interpolation.  Leading and trailing NaNs are
    never filled.

    Returns
    -------
    ndarray
        A copy of ``theta`` with the short interior gaps filled.
    """
    if method not in _GAP_FILLERS:
        raise ValueError(f"method: must be one of {', '.join(repr(m) for m in _GAP_FILLERS)}, got {method!r}")
    if int(max_gap) < 0:
        raise ValueError(f"max_gap: must be >= 0, got {max_gap}")
    th = np.array(theta, dtype=np.float64)
    fin = np.isfinite(th)
    if not fin.any():
        return th
    first, last = np.flatnonzero(fin)[[0, -1]]
    gaps = [(a, b) for a, b in nan_runs(~fin) if a > first and b <= last and b - a <= max_gap]
    if not gaps:
        return th
    return _GAP_FILLERS[method](th, gaps, order, fin)


def _fill_linear(th: np.ndarray, gaps: list, order: int, fin: np.ndarray) -> np.ndarray:
    """Linear interpolation across each gap (in place)."""
    for a, b in gaps:
        th[a:b] = np.interp(np.arange(a, b), [a - 1, b], [th[a - 1], th[b]])
    return th


def _fill_ar(th: np.ndarray, gaps: list, order: int, fin: np.ndarray) -> np.ndarray:
    """AR prediction from both edges, blended with a raised cosine (in place; linear where it cannot)."""
    coef = _ar_fit(th, order, nan_runs(fin))
    for a, b in gaps:
        left = th[max(0, a - order):a]
        right = th[b:b + order]
        if coef is None or left.size < order or right.size < order:
            th[a:b] = np.interp(np.arange(a, b), [a - 1, b], [th[a - 1], th[b]])
            continue
        L = b - a
        fwd = np.concatenate([left, np.zeros(L)])
        for i in range(L):
            fwd[order + i] = fwd[i:order + i] @ coef
        bwd = np.concatenate([right[::-1], np.zeros(L)])
        for i in range(L):  # stationary AR: time-reversed process has the same coefficients
            bwd[order + i] = bwd[i:order + i] @ coef
        wgt = 0.5 * (1 + np.cos(np.pi * (np.arange(L) + 1) / (L + 1)))
        th[a:b] = wgt * fwd[order:] + (1 - wgt) * bwd[order:][::-1]
    return th


#: ``interpolate_gaps(method=...)`` → filler
_GAP_FILLERS = {"ar": _fill_ar, "linear": _fill_linear}


def finish_estimate(theta: np.ndarray, valid: np.ndarray, taus: np.ndarray, dt: float, max_gap_s) -> np.ndarray:
    """``theta`` NaN where the pairs do not observe it (gaps longer than ``max_gap_s``, default the longest
    lag: :func:`restore.integration.gaps.estimable_mask`), mean removed."""
    max_gap = int(round((taus.max() if max_gap_s is None else
                         check_positive("max_gap_s", max_gap_s, allow_zero=True)) / dt))
    theta = np.where(estimable_mask(valid, taus, dt, max_gap=max_gap), theta, np.nan)
    if np.isfinite(theta).any():
        theta -= np.nanmean(theta)
    return theta
