"""Polynomial (low-frequency) integration by weighted least squares (patent step c).

Model ``theta(t) = theta_0 + sum_{k=1..n} theta_k u**k`` with ``u = (t - t_c) / h``
(``t_c`` the centre and ``h`` the half-span of the record, for conditioning), so
``d_j(t) = sum_k theta_k [(u + tau_j / h)**k - u**k]``: the constant
``theta_0`` is unobservable.  The coefficients are the weighted least-squares
solution ``(M' W M)^-1 M' W d`` with ``W = diag(1 / sigma_j**2)``.  Per the
patent, the gain ``sigma_est / sigma_meas`` of this estimator falls roughly as
``1 / tau`` (:func:`polynomial_gain`).
"""
from __future__ import annotations

import numpy as np

from ._common import check_positive, per_pair, prepare
from .gaps import finish_estimate
from .spectrum import estimate_differential_noise

__all__ = ["integrate_polynomial", "polynomial_gain", "polynomial_design", "pair_noise"]


def _check_degree(degree) -> int:
    d = int(degree)
    if d != degree or not 1 <= d <= 5:
        raise ValueError(f"degree: must be an integer in [1, 5], got {degree!r}")
    return d


def pair_noise(D: np.ndarray, taus: np.ndarray, dt: float, noise_std) -> np.ndarray:
    """Per-pair noise σ of the differentials for least-squares weights: ``noise_std`` (scalar or one per
    pair), else estimated (1 on records shorter than 64 samples); floored away from zero."""
    p, n = D.shape
    sig = per_pair(noise_std, p, "noise_std")
    if sig is None:
        sig = estimate_differential_noise(D, taus, dt) if n >= 64 else np.ones(p)
    return np.maximum(sig, 1e-12 * max(np.nanstd(D), 1e-300))


def polynomial_design(t, tau: float, degree: int, *, t_c: float = 0.0, h: float = 1.0) -> np.ndarray:
    """Rows ``[(u + tau/h)**k - u**k]_{k=1..degree}`` for times ``t`` (s), ``u = (t - t_c) / h``."""
    u = (np.asarray(t, dtype=np.float64) - t_c) / h
    k = np.arange(1, _check_degree(degree) + 1)
    return (u[:, None] + tau / h) ** k - u[:, None] ** k


def integrate_polynomial(diffs, taus, dt, *, degree: int = 3, noise_std=None,
                         max_gap_s: float | None = None) -> np.ndarray:
    """Weighted least-squares polynomial integration (constant unobservable).

    Parameters
    ----------
    diffs, taus, dt
        As for :func:`restore.integration.integrate`.
    degree : int, keyword-only
        Polynomial degree, 1 to 5.
    noise_std : float or sequence, keyword-only
        Per-pair noise standard deviation (rad), for the weights; estimated if None.
    max_gap_s : float, keyword-only
        Longest unobserved interior run returned (s); default the longest lag.

    Returns
    -------
    ndarray
        theta at ``n dt`` (rad), mean removed, NaN where not estimated.
    """
    D, valid, taus, dt = prepare(diffs, taus, dt)
    deg = _check_degree(degree)
    p, n = D.shape
    sig = pair_noise(D, taus, dt, noise_std)
    t = np.arange(n) * dt
    t_c, h = 0.5 * (t[-1] + taus.max()), max(0.5 * (t[-1] + taus.max()), dt)
    rows, rhs = [], []
    for j, tau in enumerate(taus):
        ok = valid[j]
        rows.append(polynomial_design(t[ok], tau, deg, t_c=t_c, h=h) / sig[j])
        rhs.append(D[j, ok] / sig[j])
    coef, *_ = np.linalg.lstsq(np.vstack(rows), np.concatenate(rhs), rcond=None)
    u = (t - t_c) / h
    theta = (u[:, None] ** np.arange(1, deg + 1)) @ coef
    return finish_estimate(theta, valid, taus, dt, max_gap_s)


def polynomial_gain(tau_s: float, *, duration_s: float, step_s: float, degree: int = 4
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Patent fig. 14: gain ``sigma_est(t) / sigma_meas`` of the polynomial estimator.

    Independent measurements of equal noise every ``step_s`` over ``[0, duration_s]``
    of a single pair of lag ``tau_s``; the error of ``theta(t) - theta(0)`` has
    standard deviation ``sigma_meas [T(t) (M' M)^-1 T(t)']**0.5`` with
    ``T(t) = (t, t², ..., t**degree)`` and ``M`` the rows
    ``(tau, (t_i + tau)² - t_i², ...)``.

    Parameters
    ----------
    tau_s : float
        Lag (s).
    duration_s, step_s : float, keyword-only
        Span and spacing of the measurements (s).
    degree : int, keyword-only
        Number of estimated coefficients (1 to 5; the patent's example uses
        five coefficients including the unobservable constant, i.e. 4 here).

    Returns
    -------
    t : ndarray
        Measurement times (s).
    gain : ndarray
        ``sigma_est(t) / sigma_meas`` (dimensionless); 0 at ``t = 0``.
    """
    tau = check_positive("tau_s", tau_s)
    dur = check_positive("duration_s", duration_s)
    step = check_positive("step_s", step_s)
    deg = _check_degree(degree)
    t = np.arange(0.0, dur + 0.5 * step, step)
    M = polynomial_design(t, tau, deg, h=dur)        # scaled basis: u = t / duration
    u = t / dur
    T = u[:, None] ** np.arange(1, deg + 1)
    cov = np.linalg.inv(M.T @ M)
    return t, np.sqrt(np.einsum("ij,jk,ik->i", T, cov, T))
