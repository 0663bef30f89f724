"""Global parametric synthesis (CNES §2, SPOT5): a few tens of parameters over the whole record.

On SPOT5 the rocking of the line-of-sight corrector mirror after each
manoeuvre was modelled as "an extinguishing sinus with a linear frequency
drift" plus a low-frequency attitude polynomial of degree 3, and fitted by
least squares on all the measured shifts of the record at once. This module
is that baseline, on the attitude differentials:

    theta(t) = sum_c e_c(t) [a_c cos psi_c(t) + b_c sin psi_c(t)]
               + sum_{k=1..degree} p_k u**k,
    e_c(t)   = exp(-x / T_c)  for x = t - s_c >= 0, else 0,
    psi_c(t) = 2 pi (f_c x + k_c x**2 / 2),

so ``d_j(t) = theta(t + tau_j) - theta(t)`` is linear in ``(a_c, b_c, p_k)``
and non-linear in each component's start ``s_c``, frequency ``f_c``, chirp rate
``k_c`` and damping time ``T_c``. The linear part is solved exactly for each
trial of the non-linear one (variable projection) and the non-linear part by
trust-region least squares (:func:`scipy.optimize.least_squares`) on all the
valid samples of all pairs, each pair weighted by its noise.

The starting point comes from a non-parametric estimate of ``theta`` (the
default integration): the strongest spectral line of its detrended residual
gives ``f``, the analytic signal's envelope gives the start (half of the peak
on the rise) and ``T`` (log-linear decay), its unwrapped phase gives ``f`` and
``k`` (quadratic fit); each further component is sought in what the previous
ones leave.

What it is for: a **baseline**. It is exact when the jitter is what the model
says (a damped chirp over a slow drift), and it books everything else —
harmonics of the wheels, broadband noise — as residual error; CNES measured
0.1 px RMS left over a 3 px SPOT5 rocking with it. Compare with the default
(:func:`restore.integration.wiener.integrate_wiener`), which assumes no shape.
"""
from __future__ import annotations

import numpy as np

from ._common import check_positive, prepare
from .gaps import finish_estimate
from .polynomial import _check_degree, pair_noise, polynomial_design

__all__ = ["integrate_parametric", "ParametricModel", "damped_chirp_basis", "initial_components"]


def damped_chirp_basis(t, start_s: float, frequency_hz: float, chirp_hz_per_s: float,
                       damping_time_s: float) -> np.ndarray:
    """The two basis functions ``e(t) cos psi(t)`` and ``e(t) sin psi(t)`` at ``t`` (s), shape (len(t), 2)."""
    t = np.asarray(t, dtype=np.float64)
    x = t - start_s
    xp = np.maximum(x, 0.0)
    env = np.where(x >= 0, np.exp(-xp / damping_time_s), 0.0)
    psi = 2.0 * np.pi * (frequency_hz * xp + 0.5 * chirp_hz_per_s * xp * xp)
    return np.stack([env * np.cos(psi), env * np.sin(psi)], axis=-1)


class ParametricModel:
    """``theta(t)`` = damped chirps + a polynomial without constant, and its differentials.

    Parameters
    ----------
    components : sequence of (start_s, frequency_hz, chirp_hz_per_s, damping_time_s)
        The non-linear parameters of each damped chirp.
    degree : int
        Degree of the low-frequency polynomial (1 to 5).
    t_c, h : float
        Centre and half-span of the record (s), for the polynomial's conditioning.
    """

    def __init__(self, components, degree: int, t_c: float, h: float):
        self.components = [tuple(float(v) for v in c) for c in components]
        self.degree = _check_degree(degree)
        self.t_c, self.h = float(t_c), float(h)

    @property
    def n_linear(self) -> int:
        """Number of linear coefficients: ``2`` per component, then ``degree``."""
        return 2 * len(self.components) + self.degree

    def attitude_design(self, t) -> np.ndarray:
        """Columns of ``theta(t)`` (one per linear coefficient), shape (len(t), n_linear)."""
        t = np.asarray(t, dtype=np.float64)
        cols = [damped_chirp_basis(t, *c) for c in self.components]
        u = (t - self.t_c) / self.h
        cols.append(u[:, None] ** np.arange(1, self.degree + 1))
        return np.concatenate(cols, axis=1)

    def differential_design(self, t, tau: float) -> np.ndarray:
        """Columns of ``theta(t + tau) - theta(t)``, shape (len(t), n_linear)."""
        t = np.asarray(t, dtype=np.float64)
        cols = [damped_chirp_basis(t + tau, *c) - damped_chirp_basis(t, *c) for c in self.components]
        cols.append(polynomial_design(t, tau, self.degree, t_c=self.t_c, h=self.h))
        return np.concatenate(cols, axis=1)


def _analytic(x: np.ndarray) -> np.ndarray:
    from scipy.signal import hilbert

    return hilbert(x)


def initial_components(theta, dt: float, n_components: int, *, degree: int, f_min_hz: float = 1.0):
    """Starting (start, f, k, T) of each damped chirp from a sampled attitude ``theta`` (rad).

    The polynomial of ``degree`` is removed first; each component is read from
    the strongest spectral line above ``f_min_hz`` of what remains (band-passed
    to an octave around it): start where the envelope first reaches half its
    peak, damping from a log-linear fit of the envelope after the peak, frequency
    and chirp from a quadratic fit of the unwrapped phase; the fitted component
    is subtracted before the next one is sought. Returns a list of tuples.
    """
    from scipy.signal import butter, sosfiltfilt

    th = np.asarray(theta, dtype=np.float64)
    n = th.size
    t = np.arange(n) * dt
    ok = np.isfinite(th)
    if ok.sum() < 16:
        raise ValueError("theta: fewer than 16 finite samples to start the parametric fit from")
    r = np.interp(t, t[ok], th[ok])
    u = (t - t.mean()) / max(np.ptp(t) / 2, dt)
    V = u[:, None] ** np.arange(0, degree + 1)
    r = r - V @ np.linalg.lstsq(V, r, rcond=None)[0]
    nyq = 0.5 / dt
    out = []
    for _ in range(n_components):
        w = np.hanning(n)
        spec = np.abs(np.fft.rfft(r * w)) ** 2
        f = np.fft.rfftfreq(n, dt)
        band = (f >= f_min_hz) & (f < 0.9 * nyq)
        if not band.any():
            break
        f_peak = float(f[band][np.argmax(spec[band])])
        lo, hi = max(0.5 * f_peak, 0.2 * f_min_hz), min(2.0 * f_peak, 0.95 * nyq)
        sos = butter(4, [lo, hi], btype="bandpass", fs=1.0 / dt, output="sos")
        z = _analytic(sosfiltfilt(sos, r))
        env = np.abs(z)
        i_peak = int(np.argmax(env))
        rise = np.nonzero(env[:i_peak + 1] >= 0.5 * env[i_peak])[0]
        i0 = int(rise[0]) if rise.size else 0
        start = float(t[i0])
        after = np.arange(i_peak, n)
        keep = after[env[after] > 0.05 * env[i_peak]]
        # the analytic signal rings at the record's end: fit the decay and the phase away from it
        keep = keep[keep < n - max(8, int(0.5 / (f_peak * dt)))]
        if keep.size >= 8:
            slope = np.polyfit(t[keep], np.log(env[keep]), 1)[0]
            damping = float(-1.0 / slope) if slope < -1e-9 else 10.0 * np.ptp(t)
        else:
            damping = 10.0 * np.ptp(t)
        damping = float(np.clip(damping, 2.0 / f_peak, 1e3 * max(np.ptp(t), dt)))
        seg = np.arange(i0, keep[-1] + 1) if keep.size >= 8 else np.arange(i0, n)
        x = t[seg] - start
        phase = np.unwrap(np.angle(z[seg]))
        c2, c1, _ = np.polyfit(x, phase, 2) if seg.size >= 8 else (0.0, 2 * np.pi * f_peak, 0.0)
        freq = float(c1 / (2 * np.pi)) if c1 > 0 else f_peak
        chirp = float(c2 / np.pi)
        comp = (start, freq, chirp, damping)
        out.append(comp)
        B = damped_chirp_basis(t, *comp)
        r = r - B @ np.linalg.lstsq(B, r, rcond=None)[0]
    return out


def _pack(components) -> np.ndarray:
    return np.array([[s, f, k, np.log(T)] for s, f, k, T in components], dtype=np.float64).ravel()


def _unpack(q) -> list[tuple[float, float, float, float]]:
    q = np.asarray(q, dtype=np.float64).reshape(-1, 4)
    return [(s, f, k, float(np.exp(lt))) for s, f, k, lt in q]


def integrate_parametric(diffs, taus, dt, *, components: int = 1, degree: int = 3, noise_std=None,
                         max_gap_s: float | None = None, max_nfev: int = 200,
                         return_details: bool = False):
    """Global parametric synthesis: damped chirps + a polynomial fitted on all the differentials.

    Parameters
    ----------
    diffs, taus, dt
        As for :func:`restore.integration.integrate`.
    components : int, keyword-only
        Number of damped chirps (0 to 4; 0: the polynomial alone).
    degree : int, keyword-only
        Degree of the low-frequency polynomial, 1 to 5 (CNES: 3).
    noise_std : float or sequence, keyword-only
        Per-pair noise standard deviation (rad), for the weights; estimated if None.
    max_gap_s : float, keyword-only
        Longest unobserved interior run returned (s); default the longest lag.
    max_nfev : int, keyword-only
        Most evaluations of the non-linear least squares.
    return_details : bool, keyword-only
        Also return a dict with the fitted ``components`` (start, f, chirp,
        damping per chirp), the linear ``coefficients`` and the weighted
        ``cost`` at the solution.

    Returns
    -------
    ndarray
        theta at ``n dt`` (rad), mean removed, NaN where not estimated.
    """
    D, valid, taus, dt = prepare(diffs, taus, dt)
    deg = _check_degree(degree)
    nc = int(components)
    if nc != components or not 0 <= nc <= 4:
        raise ValueError(f"components: must be an integer in [0, 4], got {components!r}")
    check_positive("max_nfev", max_nfev)
    p, n = D.shape
    sig = pair_noise(D, taus, dt, noise_std)
    t = np.arange(n) * dt
    span = t[-1] + taus.max()
    t_c, h = 0.5 * span, max(0.5 * span, dt)
    rows_t = [t[valid[j]] for j in range(p)]
    rhs = np.concatenate([D[j, valid[j]] / sig[j] for j in range(p)])

    def design(model):
        return np.vstack([model.differential_design(rows_t[j], taus[j]) / sig[j] for j in range(p)])

    def solve(q):
        model = ParametricModel(_unpack(q), deg, t_c, h)
        M = design(model)
        coef, *_ = np.linalg.lstsq(M, rhs, rcond=None)
        return model, coef, rhs - M @ coef

    if nc:
        from .wiener import integrate_wiener

        first = integrate_wiener(D, taus, dt)
        q0 = _pack(initial_components(first, dt, nc, degree=deg))
        nc = q0.size // 4
    if nc:
        from scipy.optimize import least_squares

        nyq = 0.5 / dt
        k_max = 2.0 * nyq / span  # a chirp that crosses the whole band within the record
        lb = np.tile([-span, 1e-3, -k_max, np.log(2 * dt)], nc)
        ub = np.tile([2 * span, nyq, k_max, np.log(1e4 * span)], nc)
        margin = 1e-6 * (ub - lb)
        q0 = np.clip(q0, lb + margin, ub - margin)
        scale = np.tile([max(dt, 1e-3 * span), 0.1, 1.0, 0.1], nc)
        fit = least_squares(lambda q: solve(q)[2], q0, bounds=(lb, ub), x_scale=scale, max_nfev=int(max_nfev),
                            method="trf")
        q = fit.x
    else:
        q = np.zeros(0)
    model, coef, res = solve(q)
    theta = model.attitude_design(t) @ coef
    theta = finish_estimate(theta, valid, taus, dt, max_gap_s)
    if return_details:
        return theta, {"components": model.components, "coefficients": coef, "cost": 0.5 * float(res @ res)}
    return theta
