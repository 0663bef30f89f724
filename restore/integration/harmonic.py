"""Harmonic-model integration: lines with slowly varying complex amplitudes.

Model::

    theta(t) = sum_i sum_k B_k(t) [a_ik cos(2 pi f_i t) + b_ik sin(2 pi f_i t)]

with ``f_i`` line frequencies estimated from the differentials' spectrum (or
given), ``B_k`` cubic B-splines with knots every ``knot_spacing_s`` (the slowly
varying amplitudes and phases absorb frequency drift and amplitude noise).
The coefficients are fitted by weighted least squares directly on the
differentials, whose model ``theta(t + tau_j) - theta(t)`` is evaluated exactly
at the fractional lags; gaps just remove rows.  The normal equations are
accumulated window by window (B-splines have local support), so the cost is
linear in the record length.  Optionally the residual differentials (what the
line model does not explain) are integrated by another method and added.
"""
from __future__ import annotations

import numpy as np
from scipy.interpolate import BSpline

from ._common import check_positive, prepare
from .gaps import finish_estimate
from .methods import integration_method
from .spectrum import find_lines
from .wiener import spectrum_for_lines

__all__ = ["integrate_harmonic", "HarmonicModel"]


def _merge(freqs: np.ndarray, weights: np.ndarray, merge_hz: float) -> np.ndarray:
    order = np.argsort(freqs)
    f, w = freqs[order], weights[order]
    out, grp_f, grp_w = [], [f[0]], [w[0]]
    for fi, wi in zip(f[1:], w[1:]):
        if fi - grp_f[-1] < merge_hz:
            grp_f.append(fi)
            grp_w.append(wi)
        else:
            out.append(np.average(grp_f, weights=grp_w))
            grp_f, grp_w = [fi], [wi]
    out.append(np.average(grp_f, weights=grp_w))
    return np.asarray(out)


class HarmonicModel:
    """Lines with B-spline amplitudes on ``[t0, t1]``; linear in its coefficients.

    Parameters
    ----------
    frequencies_hz : array_like
        Carrier frequencies (Hz).
    t0, t1 : float
        Time span covered (s).
    knot_spacing_s : float
        B-spline knot spacing (s).
    """

    def __init__(self, frequencies_hz, t0: float, t1: float, knot_spacing_s: float):
        self.freqs = np.atleast_1d(np.asarray(frequencies_hz, dtype=np.float64))
        self.h = check_positive("knot_spacing_s", knot_spacing_s)
        n_int = max(1, int(np.ceil((t1 - t0) / self.h)))
        self.t0 = float(t0)
        self.knots = t0 + self.h * np.arange(-3, n_int + 4)
        self.n_basis = self.knots.size - 4
        self.n_lines = self.freqs.size
        self.n_coef = self.n_basis * 2 * self.n_lines

    def columns(self, t: np.ndarray, k_lo: int, k_hi: int) -> np.ndarray:
        """Design columns for basis functions ``k_lo..k_hi-1`` at times ``t`` (dense)."""
        t = np.asarray(t, dtype=np.float64)
        x = np.clip(t, self.knots[3], self.knots[-4] - 1e-12 * self.h)
        B = BSpline.design_matrix(x, self.knots, 3).toarray()[:, k_lo:k_hi]   # (n, nb)
        ph = 2 * np.pi * (t[:, None] - self.t0) * self.freqs[None, :]
        car = np.stack([np.cos(ph), np.sin(ph)], axis=-1).reshape(t.size, -1)  # (n, 2L)
        return (B[:, :, None] * car[:, None, :]).reshape(t.size, -1)

    def basis_range(self, t_lo: float, t_hi: float) -> tuple[int, int]:
        """Basis functions whose support meets ``[t_lo, t_hi]``."""
        k_lo = int(np.clip(np.floor((t_lo - self.knots[0]) / self.h) - 3, 0, self.n_basis))
        k_hi = int(np.clip(np.floor((t_hi - self.knots[0]) / self.h) + 1, 0, self.n_basis))
        return k_lo, max(k_hi, k_lo + 1)

    def slice(self, k_lo: int, k_hi: int) -> slice:
        return slice(k_lo * 2 * self.n_lines, k_hi * 2 * self.n_lines)

    def evaluate(self, coef: np.ndarray, t: np.ndarray, *, block: int = 2048) -> np.ndarray:
        """theta (rad) at times ``t`` (s) for coefficients ``coef``."""
        t = np.asarray(t, dtype=np.float64)
        out = np.empty(t.size)
        for a in range(0, t.size, block):
            tb = t[a:a + block]
            k_lo, k_hi = self.basis_range(tb.min(), tb.max())
            out[a:a + block] = self.columns(tb, k_lo, k_hi) @ coef[self.slice(k_lo, k_hi)]
        return out


def integrate_harmonic(diffs, taus, dt, *, frequencies_hz=None, knot_spacing_s: float = 0.2,
                       noise_std=None, max_lines: int = 24, merge_hz: float = 1.0,
                       ridge: float = 1e-8, residual: str | None = None,
                       max_gap_s: float | None = None, spectrum_options: dict | None = None
                       ) -> np.ndarray:
    """Harmonic-model integration (see module docstring).

    Parameters
    ----------
    diffs, taus, dt
        As for :func:`restore.integration.integrate`.
    frequencies_hz : sequence of float, keyword-only
        Line frequencies (Hz); estimated from the differentials if None.
    knot_spacing_s : float, keyword-only
        Knot spacing of the amplitude splines (s).
    noise_std : float or sequence, keyword-only
        Per-pair noise (rad), used as weights; estimated if None.
    max_lines : int, keyword-only
        At most this many estimated lines.
    merge_hz : float, keyword-only
        Estimated lines closer than this (Hz) share one carrier.
    ridge : float, keyword-only
        Relative Tikhonov regularisation of the normal equations.
    residual : str, keyword-only
        Name of a method (e.g. ``"wiener"``) that integrates the residual
        differentials; its result is added.  None: lines only.
    max_gap_s : float, keyword-only
        Longest unobserved interior run returned (s); default the longest lag.
    spectrum_options : dict, keyword-only
        Passed to :func:`~restore.integration.spectrum.estimate_spectrum`.

    Returns
    -------
    ndarray
        theta at ``n dt`` (rad), mean removed, NaN where not estimated.
    """
    D, valid, taus, dt = prepare(diffs, taus, dt)
    p, n = D.shape
    spec = spectrum_for_lines(D, taus, dt, noise_std=noise_std,
                              spectrum_options=spectrum_options)
    if frequencies_hz is None:
        lines = find_lines(spec, max_lines=max_lines)
        if len(lines) == 0:
            return np.full(n, np.nan)
        freqs = _merge(lines.frequency, lines.variance, merge_hz)
    else:
        freqs = np.atleast_1d(np.asarray(frequencies_hz, dtype=np.float64))
        if freqs.size == 0 or np.any(~(freqs > 0)):
            raise ValueError(f"frequencies_hz: must be > 0, got {freqs.tolist()}")
    t = np.arange(n) * dt
    model = HarmonicModel(freqs, 0.0, t[-1] + taus.max(), knot_spacing_s)
    wts = 1.0 / spec.noise_std**2
    AtA = np.zeros((model.n_coef, model.n_coef))
    Atb = np.zeros(model.n_coef)
    step = max(1, int(round(model.h / dt)))
    for a in range(0, n, step):
        sl = slice(a, min(n, a + step))
        k_lo, k_hi = model.basis_range(t[sl][0], t[sl][-1] + taus.max())
        cs = model.slice(k_lo, k_hi)
        for j, tau in enumerate(taus):
            ok = valid[j, sl]
            if not ok.any():
                continue
            tt = t[sl][ok]
            A = model.columns(tt + tau, k_lo, k_hi) - model.columns(tt, k_lo, k_hi)
            AtA[cs, cs] += wts[j] * (A.T @ A)
            Atb[cs] += wts[j] * (A.T @ D[j, sl][ok])
    lam = float(ridge) * np.trace(AtA) / model.n_coef + 1e-300
    coef = np.linalg.solve(AtA + lam * np.eye(model.n_coef), Atb)
    theta = model.evaluate(coef, t)
    if residual is not None:
        pred = np.vstack([model.evaluate(coef, t + tau) - theta for tau in taus])
        extra = integration_method(residual).function(np.where(valid, D - pred, np.nan), taus, dt,
                                                      noise_std=spec.noise_std, max_gap_s=max_gap_s)
        theta = theta + np.nan_to_num(extra - np.nanmean(extra))
    return finish_estimate(theta, valid, taus, dt, max_gap_s)
