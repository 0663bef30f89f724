"""Choosing the integration method from the product alone: leave-one-pair-out cross-validation.

No integration method is best everywhere. The multi-pair Wiener/MAP filter
(the default) assumes stationary jitter: on quasi-harmonic micro-vibrations
it is the most accurate, but it smears a transient (a mirror that starts
rocking inside the record, a damping after a manoeuvre) over the whole
record, because its prior spreads the transient's power over time. The
time-domain regularised least squares (``lsq``) assumes only smoothness and
follows a transient, at the price of more noise on stationary lines.

Which one fits a record is decided from its own differentials: each pair in
turn is left out, the attitude is integrated from the others by the
candidate method, and the left-out pair's differentials are predicted from
it, ``θ̂(t + τ_k + λ_k(t)) − θ̂(t)``; the method whose predictions are
closest (weighted by the samples' inverse variances) is kept. The held-out
differentials carry the same matching noise for every candidate, so the
comparison is fair, and nothing is read from the truth. With one pair there
is nothing to hold out: the default method is kept.
"""
from __future__ import annotations

import numpy as np
from scipy.interpolate import CubicSpline

from .axis_integration import integrate_axis
from .integration import DEFAULT_METHOD

__all__ = ["AUTO_METHOD", "AUTO_CANDIDATES", "predicted_differential", "cross_validation_score", "choose_method",
           "paired_improvement",
           "resolve_method", "resolved_method_name"]

#: ``restoration.method`` value that chooses the method per axis by cross-validation
AUTO_METHOD = "auto"
#: the methods it chooses between (each with its default options)
AUTO_CANDIDATES = ("wiener", "lsq")


def predicted_differential(theta, tau: float, dt: float, lag=None) -> np.ndarray:
    """``θ(n dt + τ + λ[n]) − θ(n dt)`` from a sampled ``theta`` (cubic spline through its finite samples).

    NaN where ``theta`` is NaN or the later time falls outside its finite
    span (no extrapolation).
    """
    th = np.asarray(theta, dtype=np.float64)
    t = np.arange(th.size) * dt
    ok = np.isfinite(th)
    if ok.sum() < 4:
        return np.full(th.shape, np.nan)
    t1 = t + tau + (0.0 if lag is None else np.nan_to_num(np.asarray(lag, dtype=np.float64)))
    later = CubicSpline(t[ok], th[ok], extrapolate=False)(t1)
    return later - th


def _sample_weights(j: int, n: int, sigmas, weights) -> np.ndarray:
    if sigmas is not None:
        s = np.asarray(sigmas[j], dtype=np.float64)
        w = np.where(np.isfinite(s) & (s > 0), 1.0 / np.where(s > 0, s, 1.0) ** 2, 0.0)
        if np.any(w > 0):
            return w
    if weights is not None:
        w = np.asarray(weights[j], dtype=np.float64)
        return np.where(np.isfinite(w) & (w > 0), w, 0.0)
    return np.ones(n)


def _held_out_residuals(method: str, diffs, taus, dt: float, *, lags=None, sigmas=None, weights=None,
                        psd_ceiling=None) -> tuple[np.ndarray, np.ndarray]:
    """Residuals of each pair's differentials predicted from the other pairs, and their weights, pair after
    pair (shape (p·N,); NaN residual where nothing was predicted)."""
    p = len(diffs)
    res, wts = [], []
    for k in range(p):
        keep = [j for j in range(p) if j != k]
        pick = (lambda seq: None if seq is None else [seq[j] for j in keep])  # noqa: E731
        d = np.asarray(diffs[k], dtype=np.float64)
        try:
            fit = integrate_axis([diffs[j] for j in keep], [taus[j] for j in keep], dt, method=method,
                                 lags=pick(lags), sigmas=pick(sigmas), weights=pick(weights),
                                 psd_ceiling=psd_ceiling).theta
            r = d - predicted_differential(fit, float(taus[k]), dt, None if lags is None else lags[k])
        except ValueError:  # the fold cannot be integrated (a pair without any valid sample)
            r = np.full(d.shape, np.nan)
        res.append(r)
        wts.append(_sample_weights(k, d.size, sigmas, weights))
    return np.concatenate(res), np.concatenate(wts)


def cross_validation_score(method: str, diffs, taus, dt: float, *, lags=None, sigmas=None, weights=None,
                           psd_ceiling=None) -> float:
    """Leave-one-pair-out prediction error of ``method`` on these differentials [rad].

    For each pair ``k``: integrate the other pairs (:func:`integrate_axis`,
    default options, no high-pass), predict pair ``k``'s differentials,
    accumulate the weighted squared residuals on its valid samples. Returns
    ``sqrt(Σ w r² / Σ w)`` over all folds (NaN with fewer than two pairs or
    no sample to predict). ``sigmas`` (per-line σ) give the weights
    ``1 / σ²``; else ``weights``; else uniform.
    """
    if len(diffs) < 2:
        return float("nan")
    return _score(*_held_out_residuals(method, diffs, taus, dt, lags=lags, sigmas=sigmas, weights=weights,
                                       psd_ceiling=psd_ceiling))


def _score(r: np.ndarray, w: np.ndarray) -> float:
    """``sqrt(Σ w r² / Σ w)`` over the finite residuals with a positive weight (NaN if none)."""
    ok = np.isfinite(r) & (w > 0)
    return float(np.sqrt(np.sum(w[ok] * r[ok] ** 2) / np.sum(w[ok]))) if ok.any() else float("nan")


#: samples per block of the paired test (the residuals of neighbouring lines are correlated; blocks of
#: 64 lines are long against that correlation and leave tens of blocks on a short record)
_BLOCK = 64
#: another candidate replaces the default only if it predicts the held-out pairs with a weighted squared
#: error smaller by at least this fraction (a few per cent separate the methods on any record, the
#: difference between their models; a transient they handle differently costs tens of per cent) ...
MIN_GAIN = 0.05
#: ... and by this many standard errors of the paired block test (a transient concentrates the gain in
#: a few blocks, so the test is conservative there)
SIGNIFICANCE = 2.0


def paired_improvement(r_ref, r_alt, w) -> tuple[float, float]:
    """How much smaller ``r_alt``'s weighted squared residuals are than ``r_ref``'s: (relative gain, t).

    Over the samples where both are finite: ``gain = 1 − Σw r_alt² / Σw r_ref²``
    and ``t`` the mean of the per-block differences of ``w (r_ref² − r_alt²)``
    over its standard error (blocks of :data:`_BLOCK` samples, so that the
    correlation of neighbouring residuals does not inflate it).
    """
    ok = np.isfinite(r_ref) & np.isfinite(r_alt) & (w > 0)
    if ok.sum() < 2 * _BLOCK:
        return 0.0, 0.0
    a, b, ww = r_ref[ok] ** 2, r_alt[ok] ** 2, w[ok]
    gain = 1.0 - float(np.sum(ww * b) / np.sum(ww * a))
    n = (a.size // _BLOCK) * _BLOCK
    blocks = (ww[:n] * (a[:n] - b[:n])).reshape(-1, _BLOCK).sum(1)
    se = float(np.std(blocks, ddof=1) / np.sqrt(blocks.size))
    return gain, float(np.mean(blocks) / se) if se > 0 else 0.0


def choose_method(diffs, taus, dt: float, *, candidates=AUTO_CANDIDATES, **data) -> tuple[str, dict]:
    """The candidate to run, and every score ``{method: rad}``.

    The first candidate (the default) is kept unless another predicts the
    held-out pairs better by at least :data:`MIN_GAIN` of the weighted
    squared error and by :data:`SIGNIFICANCE` standard errors of a paired
    test on the same samples (:func:`paired_improvement`); among several such,
    the one with the lowest score. ``data``: ``lags``, ``sigmas``,
    ``weights``, ``psd_ceiling`` as for :func:`cross_validation_score`. With
    fewer than two pairs: :data:`restore.integration.DEFAULT_METHOD` and ``{}``.
    """
    if len(diffs) < 2:
        return DEFAULT_METHOD, {}
    held = {m: _held_out_residuals(m, diffs, taus, dt, **data) for m in candidates}
    scores = {m: _score(r, w) for m, (r, w) in held.items()}
    ref = candidates[0]
    better = {}
    for m in candidates[1:]:
        gain, t = paired_improvement(held[ref][0], held[m][0], held[ref][1])
        if gain > MIN_GAIN and t > SIGNIFICANCE:
            better[m] = scores[m]
    return (min(better, key=better.get) if better else ref), scores


def resolve_method(name: str | None, diffs, taus, dt: float, **data) -> tuple[str | None, dict | None]:
    """The integration method to run for ``restoration.method = name``, and how it was chosen.

    A registered method (or None, the default) is returned as is, with None;
    :data:`AUTO_METHOD` is resolved by :func:`choose_method` on these
    differentials and returns ``{"candidates", "scores_rad", "chosen"}``.
    """
    if name != AUTO_METHOD:
        return name, None
    chosen, scores = choose_method(diffs, taus, dt, **data)
    return chosen, {"candidates": list(AUTO_CANDIDATES), "scores_rad": scores, "chosen": chosen}


def resolved_method_name(name: str | None) -> str:
    """The name ``restoration.method = name`` stands for: :data:`AUTO_METHOD`, or the registered method's."""
    from .integration import integration_method

    return AUTO_METHOD if name == AUTO_METHOD else integration_method(name).name
