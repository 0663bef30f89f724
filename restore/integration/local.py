"""CNES local integration (Pleiades ground processing line, §3.2–3.3).

At each time ``t_n`` the attitude is a fixed linear combination of the
differentials of the ``p`` pairs at ``k`` neighbouring samples::

    theta(t_n) = sum_j sum_m w_{j,m} d_j(n + m)

For a stationary sum of harmonics this is exact with ``2 n_lines`` independent
measurements; for quasi-harmonic, noisy signals the weights are learned by
least squares, ``w = R^-1 r`` with ``R = E[d d']`` and ``r = E[d theta]``, over
a *simulated training signal* drawn from a quasi-harmonic model of the
disturbance: line frequencies (given, or estimated from the differentials'
spectrum — never from truth), slow random frequency drifts and amplitude
variations, and white measurement noise at the differentials' noise level.
No Fourier transform of the data is needed.  Gaps and record edges are handled
by dropping the missing taps and re-solving the sub-system (``R`` and ``r``
restricted to the available taps: nothing is re-simulated); the predicted
error variance ``E[theta²] - r_s' R_s^-1 r_s`` of each sub-system tells
whether an estimate exists.

Taps: ``offsets`` (samples, per pair or shared).  The default covers, for every
pair, the samples where ``theta(t_n)`` itself enters the differentials
(``m = 0`` and ``m = -tau_j / dt``) and ``half_window`` samples around them.
"""
from __future__ import annotations

import numpy as np
from scipy.linalg import solve

from ._common import check_positive, per_pair, prepare
from .gaps import estimable_mask, fill_from_differentials, interpolate_gaps
from .spectrum import find_lines
from .wiener import spectrum_for_lines

__all__ = ["LocalIntegrator", "integrate_local", "default_offsets"]


def default_offsets(taus, dt: float, half_window: int) -> list[np.ndarray]:
    """Per-pair tap offsets: ``half_window`` samples around 0 and around ``-tau_j / dt``."""
    out = []
    for tau in np.atleast_1d(taus):
        lag = float(tau) / dt
        a = np.arange(-half_window, half_window + 1)
        b = np.round(-lag).astype(int) + np.arange(-half_window, half_window + 1)
        out.append(np.unique(np.concatenate([a, b])))
    return out


def _simulate(n: int, dt: float, taus, freqs, amps, spreads, amp_noise, noise_std, rng,
              margin: int):
    """Quasi-harmonic training signal and its (noisy) differentials.

    Each line: amplitude ``A (1 + a(t))`` and frequency ``f + s g(t)`` with
    ``a`` and ``g`` slow random processes (sums of random sinusoids below 2 Hz,
    unit standard deviation for ``g``), random phase.
    """
    t = (np.arange(n + 2 * margin) - margin) * dt
    tt = [t + tau for tau in taus]
    theta = np.zeros(t.size)
    shifted = [np.zeros(t.size) for _ in taus]
    for f, a, s in zip(freqs, amps, spreads):
        nu = rng.uniform(0.05, 2.0, 4)
        psi = rng.uniform(0, 2 * np.pi, 4)
        cg = np.sqrt(2 / 4)
        nua = rng.uniform(0.05, 2.0, 3)
        psia = rng.uniform(0, 2 * np.pi, 3)
        ca = amp_noise * np.sqrt(2 / 3)
        ph0 = rng.uniform(0, 2 * np.pi)

        def line(x):
            # phase = 2 pi (f x + s * integral of g)
            xx = x[:, None]
            integ = (cg * (np.cos(psi) - np.cos(2 * np.pi * nu * xx + psi)) / (2 * np.pi * nu)).sum(1)
            amp = a * (1 + (ca * np.sin(2 * np.pi * nua * xx + psia)).sum(1))
            return amp * np.sin(ph0 + 2 * np.pi * (f * x + s * integ))

        theta += line(t)
        for k, x in enumerate(tt):
            shifted[k] += line(x)
    d = np.vstack([shifted[k] - theta for k in range(len(taus))])
    d += rng.standard_normal(d.shape) * np.asarray(noise_std)[:, None]
    return theta, d


class LocalIntegrator:
    """Weights of the CNES local integration, learned on a simulated quasi-harmonic signal.

    Parameters
    ----------
    taus : sequence of float
        Lags (s).
    dt : float
        Sampling step (s).
    frequencies_hz : sequence of float
        Line frequencies (Hz).
    amplitudes : sequence of float
        Line amplitudes (rad).
    noise_std : float or sequence
        Per-pair measurement noise standard deviation (rad).
    offsets : list of int arrays, keyword-only
        Tap offsets per pair (samples); default :func:`default_offsets`.
    half_window : int, keyword-only
        Used by the default offsets.
    frequency_spread : float or sequence, keyword-only
        Standard deviation of the slow frequency variations (Hz), per line or
        shared; default 1 % of each frequency.
    amplitude_noise : float, keyword-only
        Relative standard deviation of the slow amplitude variations.
    n_train : int, keyword-only
        Training samples.
    seed : int, keyword-only
        Seed of the training simulation.
    ridge : float, keyword-only
        Relative Tikhonov term added to ``R`` (numerical safety).
    """

    def __init__(self, taus, dt, frequencies_hz, amplitudes, noise_std, *, offsets=None,
                 half_window: int = 32, frequency_spread=None, amplitude_noise: float = 0.1,
                 n_train: int = 30000, seed: int = 0, ridge: float = 1e-9):
        self.taus = np.atleast_1d(np.asarray(taus, dtype=np.float64))
        self.dt = check_positive("dt", dt)
        p = self.taus.size
        self.freqs = np.atleast_1d(np.asarray(frequencies_hz, dtype=np.float64))
        self.amps = np.broadcast_to(np.asarray(amplitudes, dtype=np.float64), self.freqs.shape)
        if self.freqs.size == 0:
            raise ValueError("frequencies_hz: need at least one line")
        if np.any(~(self.freqs > 0)):
            raise ValueError(f"frequencies_hz: must be > 0, got {self.freqs.tolist()}")
        if int(half_window) < 0:
            raise ValueError(f"half_window: must be >= 0, got {half_window}")
        if int(n_train) < 100:
            raise ValueError(f"n_train: must be >= 100, got {n_train}")
        self.noise_std = per_pair(noise_std, p, "noise_std")
        spread = (0.01 * self.freqs if frequency_spread is None
                  else np.broadcast_to(np.asarray(frequency_spread, float), self.freqs.shape))
        if offsets is None:
            offsets = default_offsets(self.taus, self.dt, int(half_window))
        if len(offsets) != p:
            raise ValueError(f"offsets: need one array per pair ({p}), got {len(offsets)}")
        self.offsets = [np.asarray(o, dtype=int) for o in offsets]
        lo = min(int(o.min()) for o in self.offsets)
        hi = max(int(o.max()) for o in self.offsets)
        margin = max(-lo, hi, 0) + 1
        rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x10CA1]))
        theta, d = _simulate(int(n_train), self.dt, self.taus, self.freqs, self.amps, spread,
                             amplitude_noise, self.noise_std, rng, margin)
        idx = np.arange(margin, margin + int(n_train))
        X = np.hstack([d[j][idx[:, None] + o[None, :]] for j, o in enumerate(self.offsets)])
        y = theta[idx] - theta[idx].mean()
        self.R = X.T @ X / X.shape[0]
        self.r = X.T @ y / X.shape[0]
        self.var = float(y @ y / y.size)
        self.R += ridge * np.trace(self.R) / self.R.shape[0] * np.eye(self.R.shape[0])
        self.weights = np.linalg.solve(self.R, self.r)
        self.error_var = self.var - float(self.r @ self.weights)
        ev = np.linalg.eigvalsh(self.R)
        # dropping taps through the full inverse is fast but needs a well-conditioned R
        self._rinv = np.linalg.inv(self.R) if ev[-1] < 1e10 * max(ev[0], 1e-300) else None
        self._cache: dict = {}

    @property
    def n_taps(self) -> int:
        return self.R.shape[0]

    def solve_subset(self, keep: np.ndarray) -> tuple[np.ndarray, float]:
        """Weights and predicted error variance (rad²) using only the taps ``keep`` (bool)."""
        key = keep.tobytes()
        if key not in self._cache:
            if not keep.any():
                self._cache[key] = (np.zeros(0), self.var)
            else:
                r = self.r[keep]
                miss = ~keep
                if self._rinv is not None and miss.sum() <= 0.25 * keep.sum():
                    # few taps dropped: Schur complement of the full inverse,
                    # (R_kk)^-1 = Ri_kk - Ri_km (Ri_mm)^-1 Ri_mk
                    ri_kk = self._rinv[np.ix_(keep, keep)]
                    ri_km = self._rinv[np.ix_(keep, miss)]
                    ri_mm = self._rinv[np.ix_(miss, miss)]
                    w = ri_kk @ r - ri_km @ solve(ri_mm, ri_km.T @ r, assume_a="pos")
                else:
                    w = solve(self.R[np.ix_(keep, keep)], r, assume_a="pos")
                self._cache[key] = (w, self.var - float(r @ w))
        return self._cache[key]

    def apply(self, diffs, *, max_error: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
        """Estimate theta at every sample.

        Parameters
        ----------
        diffs : array_like, shape (p, N)
            Differentials (rad), NaN at gaps.
        max_error : float, keyword-only
            Samples whose predicted error standard deviation exceeds this
            fraction of the signal's (and twice that of a complete window)
            are set to NaN.

        Returns
        -------
        theta : ndarray, shape (N,)
        error_std : ndarray, shape (N,)
            Predicted error standard deviation (rad) of each sample.
        """
        D = np.atleast_2d(np.asarray(diffs, dtype=np.float64))
        p, n = D.shape
        if p != self.taus.size:
            raise ValueError(f"diffs: need {self.taus.size} rows, got {p}")
        lo = min(int(o.min()) for o in self.offsets)
        hi = max(int(o.max()) for o in self.offsets)
        pad_lo, pad_hi = max(-lo, 0), max(hi, 0)
        Dp = np.pad(D, ((0, 0), (pad_lo, pad_hi)), constant_values=np.nan)
        cols = [Dp[j][np.arange(n)[:, None] + pad_lo + o[None, :]] for j, o in enumerate(self.offsets)]
        X = np.hstack(cols)                        # (N, taps)
        ok = np.isfinite(X)
        full = ok.all(1)
        theta = np.full(n, np.nan)
        err = np.full(n, np.sqrt(self.var))
        theta[full] = X[full] @ self.weights
        err[full] = np.sqrt(max(self.error_var, 0.0))
        rows = np.flatnonzero(~full)
        if rows.size:
            patterns, inv = np.unique(ok[rows], axis=0, return_inverse=True)
            inv = inv.ravel()
            for k, pat in enumerate(patterns):
                sel = rows[inv == k]
                w, e = self.solve_subset(pat)
                err[sel] = np.sqrt(max(e, 0.0))
                if w.size:
                    theta[sel] = X[np.ix_(sel, np.flatnonzero(pat))] @ w
        limit = max(float(max_error) * np.sqrt(self.var), 2.0 * np.sqrt(max(self.error_var, 0.0)))
        theta[err > limit] = np.nan
        return theta, err


def integrate_local(diffs, taus, dt, *, frequencies_hz=None, amplitudes=None, noise_std=None,
                    half_window: int = 32, offsets=None, frequency_spread=None,
                    amplitude_noise: float = 0.1, n_train: int = 30000, seed: int = 0,
                    max_lines: int = 24, max_error: float = 0.05, max_gap_s: float | None = None,
                    spectrum_options: dict | None = None) -> np.ndarray:
    """CNES local integration (see module docstring).

    Parameters
    ----------
    diffs, taus, dt
        As for :func:`restore.integration.integrate`.
    frequencies_hz : sequence of float, keyword-only
        Line frequencies (Hz); estimated from the differentials if None.
    amplitudes : float or sequence, keyword-only
        Line amplitudes (rad); estimated from the spectrum if None (or when
        frequencies are estimated).
    noise_std : float or sequence, keyword-only
        Per-pair noise (rad); estimated if None.
    half_window, offsets, frequency_spread, amplitude_noise, n_train, seed
        See :class:`LocalIntegrator`.  ``frequency_spread`` defaults to the
        larger of each estimated line's width and 0.5 % of its frequency.
    max_lines : int, keyword-only
        At most this many estimated lines.
    max_error : float, keyword-only
        See :meth:`LocalIntegrator.apply`.
    max_gap_s : float, keyword-only
        Longest unobserved interior run filled (s); default the longest lag.
    spectrum_options : dict, keyword-only
        Passed to :func:`~restore.integration.spectrum.estimate_spectrum`.

    Returns
    -------
    ndarray
        theta at ``n dt`` (rad), mean removed, NaN where not estimated.
    """
    D, valid, taus, dt = prepare(diffs, taus, dt)
    spec = spectrum_for_lines(D, taus, dt, noise_std=noise_std,
                              spectrum_options=spectrum_options)
    if frequencies_hz is None:
        lines = find_lines(spec, max_lines=max_lines)
        if len(lines) == 0:
            return np.full(D.shape[1], np.nan)
        freqs = lines.frequency
        amps = np.sqrt(2 * lines.variance) if amplitudes is None else amplitudes
        spread = (np.maximum(lines.width, 0.005 * freqs) if frequency_spread is None
                  else frequency_spread)
    else:
        freqs = np.atleast_1d(np.asarray(frequencies_hz, dtype=np.float64))
        if amplitudes is None:
            # amplitude of each given line from the PSD around it
            amps = np.array([np.sqrt(2 * 2 * spec.psd[np.abs(spec.freq - f) < 1.5].sum()
                                     * (spec.freq[1] - spec.freq[0])) for f in freqs])
            amps = np.maximum(amps, 1e-3 * max(amps.max(), 1e-300))
        else:
            amps = amplitudes
        spread = frequency_spread
    loc = LocalIntegrator(taus, dt, freqs, amps, spec.noise_std, offsets=offsets,
                          half_window=half_window, frequency_spread=spread,
                          amplitude_noise=amplitude_noise, n_train=n_train, seed=seed)
    theta, _ = loc.apply(D, max_error=max_error)
    max_gap = int(round((taus.max() if max_gap_s is None else
                         check_positive("max_gap_s", max_gap_s, allow_zero=True)) / dt))
    want = estimable_mask(valid, taus, dt, max_gap=max_gap)
    if np.any(want & ~np.isfinite(theta)):
        theta = fill_from_differentials(np.where(np.isfinite(theta), theta, np.nan), D, taus, dt)
        theta = interpolate_gaps(theta, max_gap=max_gap)
    theta = np.where(want, theta, np.nan)
    if np.isfinite(theta).any():
        theta -= np.nanmean(theta)
    return theta
