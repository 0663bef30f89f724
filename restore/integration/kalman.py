"""Kalman filter and Rauch–Tung–Striebel smoother, and integration with them.

Textbook linear-Gaussian model (time-invariant), with the usual names::

    x[k+1] = F x[k] + w,   w ~ N(0, Q)
    z[k]   = H x[k] + v,   v ~ N(0, R)         (NaN entries of z[k]: not observed)
    x[0]  ~ N(x0, P0)

:func:`kalman_smooth` and :class:`KalmanSmoother` (same computation; the class
also exposes the forward filter) return smoothed state means and variances.
The smoother keeps the filtered covariances only at checkpoints and recomputes
them segment by segment on the way back, so memory is ``O(checkpoint n²)``.

Integration (:func:`integrate_kalman`) uses a state made of

* one resonator per spectral line — a cascade of ``order`` damped oscillators,
  so the line's prior PSD falls fast away from it and does not leak into the
  blind or low frequencies — with frequency, bandwidth and variance from the
  differentials' spectrum (:func:`~.spectrum.find_lines`);
* a delay line of the last ``L`` samples of ``theta``, so that every
  differential ``theta(t + tau_j) - theta(t)`` is a *linear* observation of the
  state (the fractional part of ``tau_j / dt`` by 4-point Lagrange
  interpolation); ``d_j(n)`` is observed at step ``n + s_j`` with
  ``s_j = ceil(tau_j / dt) + 2``.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.linalg import cho_factor, cho_solve, solve_discrete_lyapunov
from scipy.sparse import csr_matrix

from ._common import lagrange4, prepare
from .gaps import finish_estimate
from .spectrum import find_lines
from .wiener import spectrum_for_lines

__all__ = ["KalmanSmoother", "kalman_smooth", "integrate_kalman", "oscillator_model"]


class KalmanSmoother:
    """Kalman filter + RTS smoother for a time-invariant linear-Gaussian model.

    The smoother is the Rauch–Tung–Striebel smoother in its modified
    Bryson–Frazier form (same estimates, no covariance inversion):
    ``x[k|T] = x[k|k-1] - P[k|k-1] lam_k`` with the adjoint recursion
    ``lam_k = -H' S_k^-1 y_k + (I - K_k H)' F' lam_{k+1}``.

    Parameters
    ----------
    F : ndarray (n, n)
        State transition (a sparse structure is exploited automatically).
    H : ndarray (m, n)
        Observation matrix.
    Q : ndarray (n, n)
        Process noise covariance.
    R : ndarray (m,) or (m, m)
        Observation noise covariance (a vector means diagonal).
    x0 : ndarray (n,)
        Prior mean of the first state.
    P0 : ndarray (n, n)
        Prior covariance of the first state.
    """

    def __init__(self, F, H, Q, R, x0, P0):
        self.F = np.atleast_2d(np.asarray(F, dtype=np.float64))
        n = self.F.shape[0]
        if self.F.shape != (n, n):
            raise ValueError(f"F: must be square, got {self.F.shape}")
        self.H = np.atleast_2d(np.asarray(H, dtype=np.float64))
        if self.H.shape[1] != n:
            raise ValueError(f"H: must have {n} columns, got {self.H.shape}")
        m = self.H.shape[0]
        self.Q = np.asarray(Q, dtype=np.float64).reshape(n, n)
        R = np.asarray(R, dtype=np.float64)
        self.R = np.diag(R) if R.ndim == 1 else R.reshape(m, m)
        if self.R.shape != (m, m):
            raise ValueError(f"R: must be ({m},) or ({m}, {m}), got {R.shape}")
        self.x0 = np.asarray(x0, dtype=np.float64).reshape(n)
        self.P0 = np.asarray(P0, dtype=np.float64).reshape(n, n)
        self.n, self.m = n, m
        sparse = np.count_nonzero(self.F) < 0.2 * n * n
        self._Fs = csr_matrix(self.F) if sparse else None

    def _fp(self, M: np.ndarray) -> np.ndarray:
        return self._Fs @ M if self._Fs is not None else self.F @ M

    def _predict_cov(self, P: np.ndarray) -> np.ndarray:
        """``F P F' + Q`` for symmetric ``P``."""
        A = self._fp(P)                    # F P
        return self._fp(A.T) + self.Q      # F (F P)' = F P F'

    def _update(self, x, P, z):
        """Measurement update; returns (x, P, observed mask, K, S^-1 y, S^-1)."""
        obs = np.isfinite(z)
        if not obs.any():
            return x, P, obs, None, None, None
        H = self.H[obs]
        PHt = P @ H.T
        S = H @ PHt + self.R[np.ix_(obs, obs)]
        Sinv = cho_solve(cho_factor(S), np.eye(S.shape[0]))
        K = PHt @ Sinv
        a = Sinv @ (z[obs] - H @ x)
        x = x + PHt @ a
        P = P - K @ PHt.T
        return x, 0.5 * (P + P.T), obs, K, a, Sinv

    def _check_z(self, z) -> np.ndarray:
        z = np.asarray(z, dtype=np.float64)
        if z.ndim == 1 and self.m == 1:
            z = z[:, None]
        if z.ndim != 2 or z.shape[1] != self.m:
            raise ValueError(f"z: must have shape (T, {self.m}), got {z.shape}")
        return z

    def filter(self, z) -> tuple[np.ndarray, np.ndarray]:
        """Filtered means ``x[k|k]`` (T, n) and variances (diagonal of ``P[k|k]``)."""
        z = self._check_z(z)
        xs = np.empty((z.shape[0], self.n))
        vs = np.empty((z.shape[0], self.n))
        x, P = self.x0, self.P0
        for k in range(z.shape[0]):
            if k:
                x, P = self._fp(x), self._predict_cov(P)
            x, P, *_ = self._update(x, P, z[k])
            xs[k], vs[k] = x, np.diag(P)
        return xs, vs

    def smooth(self, z, *, checkpoint: int = 256, variances: bool = True
               ) -> tuple[np.ndarray, np.ndarray | None]:
        """RTS-smoothed means ``x[k|T]`` (T, n) and variances (or None if not asked).

        Parameters
        ----------
        z : ndarray (T, m)
            Observations, NaN where missing.
        checkpoint : int, keyword-only
            Steps between stored covariances (the others are recomputed).
        variances : bool, keyword-only
            Also compute the smoothed variances (costlier: O(n³) per step).
        """
        z = self._check_z(z)
        T = z.shape[0]
        C = max(1, int(checkpoint))
        xp = np.empty((T, self.n))
        gains: list = [None] * T
        chk: dict[int, np.ndarray] = {}
        x, P = self.x0, self.P0
        for k in range(T):
            if k:
                x, P = self._fp(x), self._predict_cov(P)
            if k % C == 0:
                chk[k] = P
            xp[k] = x
            x, P, obs, K, a, Sinv = self._update(x, P, z[k])
            gains[k] = (obs, K, a, Sinv)
        xs = np.empty((T, self.n))
        vs = np.empty((T, self.n)) if variances else None
        lam_hat = np.zeros(self.n)                    # F' lam_{k+1}
        Lam_hat = np.zeros((self.n, self.n)) if variances else None
        FT = self._Fs.T.tocsr() if self._Fs is not None else self.F.T
        for start in range(((T - 1) // C) * C, -1, -C):
            stop = min(T, start + C)
            Pp = np.empty((stop - start, self.n, self.n))
            P = chk[start]
            for k in range(start, stop):
                if k > start:
                    P = self._predict_cov(P)
                Pp[k - start] = P
                _, P, *_ = self._update(xp[k], P, z[k])
            for k in range(stop - 1, start - 1, -1):
                obs, K, a, Sinv = gains[k]
                if K is None:
                    lam = lam_hat
                    Lam = Lam_hat
                else:
                    H = self.H[obs]
                    lam = lam_hat - H.T @ (a + K.T @ lam_hat)
                    if variances:
                        Ct = np.eye(self.n) - H.T @ K.T        # (I - K H)'
                        Lam = H.T @ Sinv @ H + Ct @ Lam_hat @ Ct.T
                Pk = Pp[k - start]
                xs[k] = xp[k] - Pk @ lam
                if variances:
                    vs[k] = np.diag(Pk) - np.einsum("ij,jk,ki->i", Pk, Lam, Pk)
                    Lam_hat = FT @ (FT @ Lam).T
                lam_hat = FT @ lam
        return xs, vs


def kalman_smooth(z, *, F, H, Q, R, x0, P0, checkpoint: int = 256):
    """Function form of :meth:`KalmanSmoother.smooth`: returns (means (T, n), variances (T, n))."""
    return KalmanSmoother(F, H, Q, R, x0, P0).smooth(z, checkpoint=checkpoint)


def oscillator_model(freqs_hz, widths_hz, variances, dt: float, *, order: int = 2
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Discrete resonators, one per line: transition ``F``, noise ``Q``, output row ``h``.

    A resonator stage rotates a 2-vector by ``2 pi f_i dt`` and damps it by
    ``rho_i = exp(-pi B_i dt)`` per step (``B_i``: full width at half maximum of
    a single stage's Lorentzian, Hz).  ``order`` stages in cascade (each driven
    by the previous one, the first by white noise) give a line whose PSD falls
    as ``1 / df**(2 order)`` away from ``f_i``: ``order >= 2`` keeps the prior
    from leaking into blind and low frequencies.  ``Q`` is scaled so that the
    output ``h x`` of line ``i`` has stationary variance ``variances[i]``.
    """
    f = np.atleast_1d(np.asarray(freqs_hz, dtype=np.float64))
    b = np.broadcast_to(np.asarray(widths_hz, dtype=np.float64), f.shape)
    v = np.broadcast_to(np.asarray(variances, dtype=np.float64), f.shape)
    order = int(order)
    if order < 1:
        raise ValueError(f"order: must be >= 1, got {order}")
    m = 2 * order
    n = m * f.size
    F = np.zeros((n, n))
    Q = np.zeros((n, n))
    h = np.zeros(n)
    for i, (fi, bi, vi) in enumerate(zip(f, b, v)):
        rho = math.exp(-math.pi * bi * dt)
        c, s = math.cos(2 * math.pi * fi * dt), math.sin(2 * math.pi * fi * dt)
        rot = rho * np.array([[c, -s], [s, c]])
        Fi = np.zeros((m, m))
        Fi[:2, :2] = rot
        for st in range(1, order):   # stage st: rot * own state + (1 - rho) * previous stage
            Fi[2 * st:2 * st + 2, 2 * st:2 * st + 2] = rot
            Fi[2 * st:2 * st + 2, 2 * st - 2:2 * st] = (1 - rho) * np.eye(2)
        Qi = np.zeros((m, m))
        Qi[:2, :2] = np.eye(2)
        Pi = solve_discrete_lyapunov(Fi, Qi)
        scale = vi / max(Pi[m - 2, m - 2], 1e-300)
        sl = slice(m * i, m * (i + 1))
        F[sl, sl] = Fi
        Q[sl, sl] = Qi * scale
        h[m * i + m - 2] = 1.0
    return F, Q, h


def integrate_kalman(diffs, taus, dt, *, frequencies_hz=None, noise_std=None,
                     min_width_hz: float = 0.3, width_factor: float = 2.0, max_lines: int = 16,
                     order: int = 2,
                     white_fraction: float = 1e-4, checkpoint: int = 256,
                     max_gap_s: float | None = None, spectrum_options: dict | None = None
                     ) -> np.ndarray:
    """Kalman / RTS integration with oscillators and a delay-line state (module docstring).

    Parameters
    ----------
    diffs, taus, dt
        As for :func:`restore.integration.integrate`.
    frequencies_hz : sequence of float, keyword-only
        Oscillator frequencies (Hz); estimated lines if None.
    noise_std : float or sequence, keyword-only
        Per-pair noise (rad); estimated if None.
    min_width_hz, width_factor : float, keyword-only
        Oscillator bandwidth = max(min_width_hz, width_factor * line width) (Hz).
    max_lines : int, keyword-only
        At most this many oscillators.
    order : int, keyword-only
        Resonator stages per line (see :func:`oscillator_model`).
    white_fraction : float, keyword-only
        Variance of a white component of theta, relative to the lines' total.
    checkpoint : int, keyword-only
        See :meth:`KalmanSmoother.smooth`.
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
    lines = find_lines(spec, max_lines=max_lines)
    if frequencies_hz is not None:
        freqs = np.atleast_1d(np.asarray(frequencies_hz, dtype=np.float64))
        if freqs.size == 0 or np.any(~(freqs > 0)):
            raise ValueError(f"frequencies_hz: must be > 0, got {freqs.tolist()}")
        var = np.full(freqs.size, max(spec.variance, 1e-300) / freqs.size)
        widths = np.full(freqs.size, float(min_width_hz))
    elif len(lines):
        freqs, var = lines.frequency, lines.variance
        widths = np.maximum(float(min_width_hz), float(width_factor) * lines.width)
    else:
        return np.full(n, np.nan)
    Fo, Qo, h = oscillator_model(freqs, widths, var, dt, order=order)
    k = Fo.shape[0] // 2
    lags = taus / dt
    shifts = np.ceil(lags).astype(int) + 2
    L = int(shifts.max()) + 2
    ns = 2 * k + L
    F = np.zeros((ns, ns))
    F[:2 * k, :2 * k] = Fo
    F[2 * k, :2 * k] = h @ Fo           # new theta from the propagated oscillators
    F[2 * k + 1:, 2 * k:ns - 1] = np.eye(L - 1)   # delay line shift
    q_white = float(white_fraction) * float(var.sum())
    Q = np.zeros((ns, ns))
    Q[:2 * k, :2 * k] = Qo
    Q[2 * k, :2 * k] = h @ Qo
    Q[:2 * k, 2 * k] = Qo @ h
    Q[2 * k, 2 * k] = h @ Qo @ h + q_white
    H = np.zeros((p, ns))
    for j in range(p):
        # at step k the state holds theta_k ... theta_{k-L+1} (delay index i <-> theta_{k-i});
        # the observation is d_j(k - s_j) = theta(k - q) - theta(k - s_j), q = s_j - lag in (2, 3]
        q = shifts[j] - lags[j]
        fl = int(math.floor(q))
        if q - fl < 1e-9:
            H[j, 2 * k + fl] += 1.0
        else:
            wts = lagrange4(1.0 - (q - fl))          # position (k - fl - 1) + frac
            for i, node in enumerate((-1, 0, 1, 2)):
                H[j, 2 * k + fl + 1 - node] += wts[i]
        H[j, 2 * k + shifts[j]] -= 1.0
    T = n + int(shifts.max())
    z = np.full((T, p), np.nan)
    for j in range(p):
        z[shifts[j]:shifts[j] + n, j] = D[j]
    P0 = solve_discrete_lyapunov(F, Q)
    P0 = 0.5 * (P0 + P0.T)
    ks = KalmanSmoother(F, H, Q, spec.noise_std**2, np.zeros(ns), P0)
    xs, _ = ks.smooth(z, checkpoint=checkpoint, variances=False)
    theta = xs[:n, 2 * k]
    return finish_estimate(theta, valid, taus, dt, max_gap_s)
