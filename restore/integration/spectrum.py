"""Spectral analysis of attitude differentials: noise level, signal PSD, lines.

Everything here is estimated from the differentials themselves (never from
truth).  Model: ``d_j(n) = theta(n dt + tau_j) - theta(n dt) + b_j(n)`` with
``b_j`` white of variance ``sigma_j**2``, so the two-sided PSDs (rad²/Hz) obey
``P_j(f) = |G_j(f)|**2 S(f) + sigma_j**2 dt`` with ``G_j = exp(2 pi i f tau_j) - 1``.

* Noise: ``P_j`` near pair ``j``'s blind frequencies ``n / tau_j`` (n >= 1), where
  ``|G_j|**2 < 0.05``, is (almost) pure noise; its median gives ``sigma_j``.
* Signal PSD: the pairs' smoothed periodograms are combined by weighted least
  squares, ``S = sum_j b_j (P_j / nu_j - 1)``; a frequency is kept only where
  this exceeds a significance threshold (gamma approximation of the smoothed
  periodogram's distribution, Bonferroni over the band), so that noise-only
  frequencies get ``S = 0`` and the Wiener gain there is 0.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.fft import next_fast_len, rfft
from scipy.linalg import toeplitz
from scipy.ndimage import maximum_filter1d, median_filter, uniform_filter1d
from scipy.signal import find_peaks
from scipy.stats import chi2, gamma

from ._common import per_pair, prepare

__all__ = ["SpectralEstimate", "estimate_differential_noise", "estimate_spectrum", "find_lines", "Lines",
           "notch_mask", "NotchLevel", "notch_levels", "null_space_colour"]

_BLIND_G2 = 0.05


def _taper(n: int) -> np.ndarray:
    return np.hanning(n + 2)[1:-1]


def _segments(valid_row: np.ndarray, min_len: int) -> list[tuple[int, int]]:
    m = np.concatenate([[False], valid_row, [False]]).astype(np.int8)
    d = np.diff(m)
    segs = list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)))
    long = [(a, b) for a, b in segs if b - a >= min_len]
    return long or ([max(segs, key=lambda s: s[1] - s[0])] if segs else [])


def _rel_var(w: np.ndarray, n_fft: int, L: int) -> float:
    """Relative variance of an L-bin running mean of a periodogram with taper ``w``."""
    W = np.abs(np.fft.fft(w**2, n=n_fft)) / np.sum(w**2)
    lags = np.arange(-L + 1, L)
    rho2 = W[np.abs(lags)] ** 2
    return float(np.sum((L - np.abs(lags)) * rho2) / L**2)


def _periodograms(D: np.ndarray, valid: np.ndarray, dt: float, n_fft: int, *,
                  min_segment: int, smooth_bins: tuple[int, ...]):
    """Two-sided PSD estimates (rad²/Hz) of each row, averaged over its gap-free segments.

    Each segment gets its own Hann taper (no leakage through the gap pattern)
    and mean removal; segments are averaged with weights proportional to their
    taper energy.  Also returns, per row and per running-mean width, the gamma
    shape ``k`` (= dof / 2) of the smoothed estimate.
    """
    p = D.shape[0]
    P = np.zeros((p, n_fft // 2 + 1))
    shapes = np.zeros((p, len(smooth_bins)))
    cache: dict = {}
    for j in range(p):
        segs = _segments(valid[j], min_segment)
        energies, rel = [], []
        for a, b in segs:
            x = D[j, a:b]
            w = _taper(b - a)
            F = rfft((x - np.sum(x * w) / np.sum(w)) * w, n=n_fft)
            e = float(np.sum(w**2))
            P[j] += np.abs(F) ** 2 * dt
            energies.append(e)
            key = b - a
            if key not in cache:
                cache[key] = [_rel_var(w, n_fft, L) for L in smooth_bins]
            rel.append(cache[key])
        e = np.asarray(energies)
        P[j] /= max(e.sum(), 1e-300)
        wts = e / max(e.sum(), 1e-300)
        shapes[j] = 1.0 / np.maximum((wts[:, None] ** 2 * np.asarray(rel)).sum(0), 1e-12)
    return P, shapes


def _min_segment(taus: np.ndarray, dt: float) -> int:
    return max(32, int(np.ceil(2 * taus.max() / dt)))


def _noise_levels(P: np.ndarray, f: np.ndarray, taus: np.ndarray) -> np.ndarray:
    """``sigma_j**2 dt`` per pair from the periodogram near blind frequencies."""
    out = np.empty(P.shape[0])
    f_nyq = f[-1]
    for j, tau in enumerate(taus):
        g2 = 2 * (1 - np.cos(2 * np.pi * f * tau))
        sel = (g2 < _BLIND_G2) & (f > 0.5 / tau)
        if sel.sum() >= 16:
            out[j] = np.median(P[j, sel]) / np.log(2)
        else:  # no blind frequency below Nyquist: least-contaminated upper sub-band
            bands = np.array_split(np.flatnonzero(f > 0.1 * f_nyq), 8)
            out[j] = min(np.median(P[j, b]) for b in bands if b.size) / np.log(2)
    return out


def null_space_colour(resid, taus, dt: float, noise_std, *, band_hz: float = 20.0) -> tuple[np.ndarray, np.ndarray] | None:
    """The noise's power over its white level, per frequency, from the part of a fit residual no attitude can make:
    ``(freq, colour)`` on ``rfftfreq(lines, dt)``, or None with fewer than two pairs or too few common lines.

    At each frequency an attitude moves the pairs' differentials along one
    direction, ``(G_j(f) / √ν_j)_j`` in whitened units; the residual's spectrum
    projected on the ``p − 1`` directions orthogonal to it holds noise alone,
    whatever the attitude and whatever the fit missed of it, and its power
    over ``p − 1`` (Hann taper over the lines every pair has, averaged over
    ``band_hz``) is the noise's colour there. On a fit's residual the lines
    are taken out first; on raw differentials the taper's leakage of strong
    lines and per-line lags would put signal outside that direction. A noise
    part that moves like an attitude (a band shared by pairs) lies along it
    and is not seen: the colour is a lower bound below the lowest tens of Hz.
    """
    R = np.asarray(resid, dtype=np.float64)
    if R.ndim != 2 or R.shape[0] < 2:
        return None
    p, n = R.shape
    ok = np.all(np.isfinite(R), axis=0)
    if ok.sum() < 64:
        return None
    sd = per_pair(noise_std, p, "noise_std")
    taus = np.asarray(taus, dtype=np.float64)
    w = _taper(n) * ok
    ref = float(np.sum(w**2))
    X = np.empty((p, n // 2 + 1), dtype=np.complex128)
    for j in range(p):
        x = np.where(ok, R[j], 0.0)
        X[j] = rfft((x - np.sum(x * w) / np.sum(w)) * w) / sd[j]
    f = np.fft.rfftfreq(n, dt)
    g = (np.exp(2j * np.pi * f[None, :] * taus[:, None]) - 1.0) / sd[:, None]
    norm = np.linalg.norm(g, axis=0)
    gn = g / np.where(norm > 0, norm, 1.0)
    proj = X - gn * np.sum(np.conj(gn) * X, axis=0)
    null = np.sum(np.abs(proj) ** 2, axis=0) / ((p - 1) * ref)
    L = max(1, int(round(band_hz / (f[1] - f[0])))) | 1
    # a running median, over the chi-square's own median: a narrow feature (a strong line's sideband through
    # the per-line lags, its leakage) does not move it, a colour tens of Hz wide does
    colour = median_filter(null, size=L, mode="nearest") / (chi2.median(2 * (p - 1)) / (2 * (p - 1)))
    colour[norm <= 1e-3 * norm.max()] = 1.0
    return f, colour


@dataclass
class SpectralEstimate:
    """Spectral description of the signal behind a set of differentials.

    Attributes
    ----------
    freq : ndarray
        Frequencies (Hz) of the rfft grid of length ``n_fft`` and step ``dt``.
    psd : ndarray
        Estimated two-sided PSD of ``theta`` (rad²/Hz), 0 where no signal was
        detected (and at 0 Hz: the constant is unobservable).
    noise_std : ndarray
        Per-pair white-noise standard deviation of the differentials (rad).
    detected : ndarray of bool
        Frequencies where signal was detected.
    n_fft : int
        FFT length.
    dt : float
        Sampling step (s).
    above_ceiling : ndarray of bool or None
        Frequencies where the estimate reached the ceiling a caller clipped it
        to (the AOCS knowledge's, :func:`restore.integration.wiener.integrate_wiener`);
        None when it was not clipped.
    """

    freq: np.ndarray
    psd: np.ndarray
    noise_std: np.ndarray
    detected: np.ndarray
    n_fft: int
    dt: float
    above_ceiling: np.ndarray | None = None

    @property
    def variance(self) -> float:
        """Variance of theta implied by the PSD (rad²)."""
        return float(2 * np.sum(self.psd) / (self.n_fft * self.dt))


def estimate_differential_noise(diffs, taus, dt, *, n_fft: int | None = None) -> np.ndarray:
    """White-noise standard deviation of each differential (rad), from the data.

    Uses the tapered periodogram near each pair's blind frequencies ``n / tau``
    (``n >= 1``), where the signal is suppressed by ``|G|**2 < 0.05``.

    Parameters
    ----------
    diffs : sequence of 1-D arrays
        Differentials (rad), NaN at gaps.
    taus : sequence of float
        Lags (s).
    dt : float
        Sampling step (s).
    n_fft : int, optional
        FFT length (default: next fast length >= 1.5 N).
    """
    D, valid, taus, dt = prepare(diffs, taus, dt)
    n_fft = n_fft or next_fast_len(int(1.5 * D.shape[1]))
    P, _ = _periodograms(D, valid, dt, n_fft, min_segment=_min_segment(taus, dt), smooth_bins=(1,))
    f = np.fft.rfftfreq(n_fft, dt)
    return np.sqrt(_noise_levels(P, f, taus) / dt)


def estimate_spectrum(diffs, taus, dt, *, n_fft: int | None = None, noise_std=None,
                      resolution_hz: float = 0.5, detection_hz: float = 2.0,
                      false_alarm: float = 0.01, dilate_hz: float = 1.0,
                      noise_floor: float = 1e-4, min_gain: float = 0.1,
                      noise_colour=None) -> SpectralEstimate:
    """Estimate the signal PSD and the noise levels from the differentials.

    Parameters
    ----------
    diffs, taus, dt
        As for :func:`restore.integration.integrate`.
    n_fft : int, optional
        FFT length (>= N; default next fast length >= 1.5 N).
    noise_std : float or sequence, optional
        Known per-pair noise standard deviation (rad); estimated if None.
    resolution_hz : float
        Width of the running mean giving the PSD values (Hz).
    detection_hz : float
        Second, wider running mean used only for detection (Hz).
    false_alarm : float
        Probability of at least one false detection over the band.
    dilate_hz : float
        Detected frequencies are widened by this (Hz) to keep line skirts.
    noise_floor : float
        Lower bound of the noise standard deviation relative to the
        differentials' standard deviation (keeps noise-free data well posed).
    min_gain : float
        Where ``sum_j |G_j|²`` (noise-weighted) is below this fraction of its
        maximum over the neighbouring ``2 detection_hz + dilate_hz``, i.e. in
        the notches at the blind frequencies ``n / tau`` (``n >= 1``; not the
        low-frequency end), the PSD is set to the smaller of its values at the
        notch's two edges instead of being divided by ~0 (a strong line's
        leakage would otherwise make it explode there, and a line's skirt on
        one side would make the filter amplify the noise in the notch).
    noise_colour : (freq, colour), optional
        The noise's power over its white level, common to the pairs
        (:func:`null_space_colour`): the estimate and its detection take each
        pair's noise as ν_j times the colour where that is above 1 (a noise
        above its white level, read as signal, would raise the prior there).

    Returns
    -------
    SpectralEstimate
    """
    D, valid, taus, dt = prepare(diffs, taus, dt)
    p, n = D.shape
    n_fft = int(n_fft or next_fast_len(int(1.5 * n)))
    if n_fft < n:
        raise ValueError(f"n_fft: must be >= the number of samples ({n}), got {n_fft}")
    for name, v in (("resolution_hz", resolution_hz), ("detection_hz", detection_hz),
                    ("dilate_hz", dilate_hz)):
        if not v >= 0:
            raise ValueError(f"{name}: must be >= 0, got {v}")
    if not 0 < false_alarm < 1:
        raise ValueError(f"false_alarm: must be in (0, 1), got {false_alarm}")
    f = np.fft.rfftfreq(n_fft, dt)
    df = f[1] - f[0]
    widths = tuple(max(1, int(round(hz / df))) | 1 for hz in (resolution_hz, detection_hz))
    P, shapes = _periodograms(D, valid, dt, n_fft, min_segment=_min_segment(taus, dt),
                              smooth_bins=widths)
    known = per_pair(noise_std, p, "noise_std")
    nu = known**2 * dt if known is not None else _noise_levels(P, f, taus)
    var_d = np.array([np.var(D[j, valid[j]]) if valid[j].any() else 0.0 for j in range(p)])
    nu = np.maximum(nu, (noise_floor**2) * var_d * dt + 1e-300)
    g2 = 2 * (1 - np.cos(2 * np.pi * f[None, :] * taus[:, None]))
    nu_f = nu[:, None] * np.ones((1, f.size))
    if noise_colour is not None:
        nu_f = nu_f * np.maximum(np.interp(f, np.asarray(noise_colour[0], dtype=np.float64),
                                           np.asarray(noise_colour[1], dtype=np.float64)), 1.0)[None, :]
    a = g2 / nu_f
    den = (a**2).sum(0) + 1e-300
    b = a / den                       # S_hat = sum_j b_j (P_j / nu_j - 1)
    mu = b.sum(0)
    detected = np.zeros(f.size, dtype=bool)
    s_fine = None
    for i, (hz, L) in enumerate(zip((resolution_hz, detection_hz), widths)):
        Ps = uniform_filter1d(P, L, axis=-1, mode="nearest") if L > 1 else P
        q = (b * Ps / nu_f).sum(0)
        var = (b**2 / shapes[:, i:i + 1]).sum(0)
        n_tests = max(1.0, f[-1] / max(hz, df))
        with np.errstate(invalid="ignore", divide="ignore"):
            thr = gamma.ppf(1 - false_alarm / (2 * n_tests), a=mu**2 / var, scale=var / mu)
        detected |= np.nan_to_num(q > thr)
        if s_fine is None:
            s_fine = np.clip(q - mu, 0.0, None)
    Ld = max(1, int(round(dilate_hz / df))) | 1
    if Ld > 1:
        detected = maximum_filter1d(detected.astype(np.uint8), Ld).astype(bool)
    S = np.where(detected, s_fine, 0.0)
    # Near blind frequencies (and 0 Hz) the ratio (P - nu) / |G|² is meaningless (leakage
    # and noise divided by ~0): bridge those bins linearly from well-observed neighbours.
    poor = notch_mask(f, taus, nu, min_gain=min_gain, window_hz=2 * detection_hz + dilate_hz)
    if poor.any() and (~poor).any():
        # each notch gets the smaller of its two edge values: a line's skirt on one side
        # must not raise the prior where the data cannot tell signal from noise (that
        # would amplify the noise, |G| ~ 0), and nothing there can be restored anyway
        edges = np.diff(np.r_[0, poor.astype(np.int8), 0])
        for a, b in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)):
            left = S[a - 1] if a > 0 else 0.0
            right = S[b] if b < S.size else 0.0
            S[a:b] = min(left, right)
    S[0] = 0.0
    if n_fft % 2 == 0:
        S[-1] = 0.0
    return SpectralEstimate(freq=f, psd=S, noise_std=np.sqrt(nu / dt), detected=detected,
                            n_fft=n_fft, dt=dt)


def notch_mask(f, taus, nu, *, min_gain: float = 0.1, window_hz: float = 5.0) -> np.ndarray:
    """The frequencies :func:`estimate_spectrum` does not estimate: the notches around the blind frequencies.

    Where the pairs' fused gain ``Σ_j |G_j|² ν_min / ν_j`` is below ``min_gain``
    of its best over the neighbouring ``max(window_hz, 1 / (2 τ_min))`` (half
    the shortest pair's notch spacing: the notches' whole depth, not just
    their bottom), above ``1 / (2 τ_max)``. ``nu``: each pair's noise power.
    """
    f = np.asarray(f, dtype=np.float64)
    taus = np.asarray(taus, dtype=np.float64)
    nu = np.asarray(nu, dtype=np.float64)
    df = f[1] - f[0]
    g2 = 2 * (1 - np.cos(2 * np.pi * f[None, :] * taus[:, None]))
    info = (g2 * (nu.min() / nu)[:, None]).sum(0)
    Lw = max(1, int(round(max(window_hz, 0.5 / taus.min()) / df))) | 1
    return (info < min_gain * maximum_filter1d(info, Lw)) & (f >= 0.5 / taus.max())


@dataclass
class NotchLevel:
    """A flat PSD level estimated over one notch of :func:`notch_mask` (:func:`notch_levels`)."""

    #: the notch's bins on the frequency grid, ``[start, stop)``
    bins: tuple[int, int]
    #: its frequencies [Hz], first and last bin
    band_hz: tuple[float, float]
    #: least-squares level of the two-sided PSD over the notch [rad²/Hz] (may be < 0: noise)
    level: float
    #: the level that noise alone exceeds with the test's false-alarm probability [rad²/Hz]
    threshold: float

    @property
    def detected(self) -> bool:
        return bool(self.level > self.threshold)


def notch_levels(diffs, taus, dt, *, n_fft: int, noise_std, false_alarm: float = 0.01, min_gain: float = 0.1,
                 window_hz: float = 5.0, low_hz: float = 0.0, residual_of=None) -> list[NotchLevel]:
    """The flat PSD level of each notch :func:`estimate_spectrum` bridges, from the notch's own periodograms.

    Bin by bin the notch is unusable (``|G_j|² ≈ 0``: noise and leakage over
    ~0); over its whole width it is not: the pairs' flanks still see the
    attitude, weakly. Modelling the PSD as one constant ``S`` across the notch,
    ``P_j(f) / ν_j − 1 = a_j(f) S`` with ``a_j = |G_j|² / ν_j`` (ν_j the pair's
    white level, or with ``residual_of`` its level on the notch's sides) is fitted by
    least squares over the notch's bins and the pairs,
    ``S = Σ a_j (P_j/ν_j − 1) / Σ a_j²`` — dominated by the flanks, where the
    pairs see most. Noise alone gives ``Σ a_j P_j / ν_j`` the mean ``Σ a_j``
    and a variance from the taper's correlation of neighbouring bins; a gamma
    law with those moments gives the level noise exceeds with probability
    ``false_alarm`` over all the notches (Bonferroni).

    Call it on differentials from which everything outside the notches has
    been taken out (the residual of a fit, the fit's own in-notch part added
    back): a strong line beside a notch leaks into its flanks, which weigh
    most here.

    Parameters
    ----------
    diffs, taus, dt
        As for :func:`estimate_spectrum` (NaN = gap).
    n_fft : int
        The frequency grid's FFT length (the notches' bins are on it).
    noise_std : float or sequence
        Each pair's white-noise standard deviation [rad per sample].
    false_alarm : float
        Probability that noise alone makes at least one notch detected.
    min_gain, window_hz
        The notches' definition (:func:`notch_mask`).
    low_hz : float
        Notches starting below this are not estimated (the AOCS knowledge's band).
    residual_of : (freq, psd), optional
        The prior [Hz, rad²/Hz two-sided] of the fit whose residual ``diffs``
        is. Given, each pair's noise level at a notch is read from the
        residual on the notch's two sides (twice its width each, other
        notches left out), where a fit with that prior leaves ``ν_j (1 − h_j)``
        of the pair's noise ν_j, ``h_j = a_j S / (1 + S Σ_i a_i)`` its
        leverage: the white level ν_j is a median over the blind frequencies
        of the whole band, and matching noise is coloured (at 12 px peak
        jitter 3-4 × ν_j at 240-340 Hz); a floor above ν_j read as a level
        would raise a notch's prior on noise, which the filter then amplifies
        through the notch. The level is only ever raised, never lowered below ν_j.

    Returns
    -------
    list of NotchLevel
    """
    D, valid, taus, dt = prepare(diffs, taus, dt)
    p, n = D.shape
    n_fft = int(n_fft)
    if n_fft < n:
        raise ValueError(f"n_fft: must be >= the number of samples ({n}), got {n_fft}")
    if not 0 < false_alarm < 1:
        raise ValueError(f"false_alarm: must be in (0, 1), got {false_alarm}")
    sd = per_pair(noise_std, p, "noise_std")
    if sd is None or not np.all(sd > 0):
        raise ValueError(f"noise_std: must be > 0 for every pair, got {noise_std!r}")
    nu = sd**2 * dt
    f = np.fft.rfftfreq(n_fft, dt)
    poor = notch_mask(f, taus, nu, min_gain=min_gain, window_hz=window_hz)
    edges = np.diff(np.r_[0, poor.astype(np.int8), 0])
    spans = [(a, b) for a, b in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)) if f[a] >= low_hz]
    if not spans:
        return []
    P, shapes = _periodograms(np.where(valid, D, 0.0), valid, dt, n_fft, min_segment=_min_segment(taus, dt),
                              smooth_bins=(1,))
    # correlation of neighbouring periodogram bins: the taper of the longest segment
    seg = max((b - a for j in range(p) for a, b in _segments(valid[j], _min_segment(taus, dt))), default=n)
    w2 = _taper(seg) ** 2
    width = max(b - a for a, b in spans)
    rho2 = (np.abs(np.fft.fft(w2, n=n_fft))[:width] / np.sum(w2)) ** 2
    local = _flank_levels(P, f, taus, nu, poor, spans, residual_of) if residual_of is not None else None
    out = []
    for i, (a, b) in enumerate(spans):
        g2 = 2 * (1 - np.cos(2 * np.pi * f[None, a:b] * taus[:, None]))
        nu_n = nu if local is None else nu * local[i]      # each pair's noise at this notch
        A = g2 / nu_n[:, None]
        norm = float((A**2).sum())
        if not norm > 0:
            continue
        t_stat = float((A * P[:, a:b] / nu_n[:, None]).sum())
        mu = float(A.sum())
        corr = toeplitz(rho2[:b - a])
        var = float(sum(A[j] @ corr @ A[j] / shapes[j, 0] for j in range(p)))
        thr = gamma.ppf(1 - false_alarm / len(spans), a=mu**2 / var, scale=var / mu) if var > 0 else mu
        out.append(NotchLevel(bins=(int(a), int(b)), band_hz=(float(f[a]), float(f[b - 1])),
                              level=(t_stat - mu) / norm, threshold=float(thr - mu) / norm))
    return out


def _flank_levels(P: np.ndarray, f: np.ndarray, taus: np.ndarray, nu: np.ndarray, poor: np.ndarray, spans: list,
                  prior) -> list[np.ndarray]:
    """Per notch, each pair's noise level on the notch's two sides in units of its white level ν_j (at least 1):
    the mean of ``P_j / (ν_j (1 − h_j))`` over twice the notch's width on each side, other notches left out
    (:func:`notch_levels`, ``residual_of``)."""
    S = np.interp(f, np.asarray(prior[0], dtype=np.float64), np.asarray(prior[1], dtype=np.float64))
    a_all = 2 * (1 - np.cos(2 * np.pi * f[None, :] * taus[:, None])) / nu[:, None]
    h = a_all * S[None, :] / (1.0 + S[None, :] * a_all.sum(axis=0)[None, :])
    out = []
    for a, b in spans:
        w = b - a
        idx = np.r_[max(a - 2 * w, 1):a, b:min(b + 2 * w, f.size)]
        idx = idx[~poor[idx]]
        if idx.size < w:
            out.append(np.ones(nu.size))
            continue
        ratio = P[:, idx] / (nu[:, None] * np.maximum(1.0 - h[:, idx], 0.05))
        out.append(np.maximum(ratio.mean(axis=1), 1.0))
    return out


@dataclass
class Lines:
    """Spectral lines: frequency (Hz), variance (rad²) and width (Hz) of each."""

    frequency: np.ndarray
    variance: np.ndarray
    width: np.ndarray

    def __len__(self) -> int:
        return self.frequency.size


def find_lines(spec: SpectralEstimate, *, max_lines: int = 32, min_separation_hz: float = 0.75,
               min_fraction: float = 1e-4) -> Lines:
    """Spectral lines of an estimated PSD.

    Peaks of ``spec.psd`` at least ``min_separation_hz`` apart; each detected
    bin is given to the nearest peak of its contiguous detected band; a line's
    variance is its share of ``2 ∫ S df``, its frequency the power-weighted
    centroid, its width the power-weighted standard deviation (Hz, at least one
    bin).  Lines below ``min_fraction`` of the strongest are dropped, and at
    most ``max_lines`` are kept (strongest first, returned sorted by frequency).
    """
    S, f = spec.psd, spec.freq
    df = f[1] - f[0]
    if not np.any(S > 0):
        z = np.zeros(0)
        return Lines(z, z, z)
    peaks, _ = find_peaks(np.concatenate([[0.0], S, [0.0]]),
                          distance=max(1, int(round(min_separation_hz / df))))
    peaks = peaks - 1
    peaks = peaks[S[peaks] > 0]
    # contiguous bands of S > 0
    pos = S > 0
    band = np.cumsum(np.diff(np.concatenate([[0], pos.astype(int)])) == 1) * pos
    bins = np.flatnonzero(pos)
    pk_band = band[peaks]
    owner = np.empty(bins.size, dtype=int)
    for b_id in np.unique(band[bins]):
        sel = band[bins] == b_id
        cand = np.flatnonzero(pk_band == b_id)
        if cand.size == 0:
            cand = np.array([np.argmin(np.abs(peaks - bins[sel].mean()))])
        d = np.abs(bins[sel][:, None] - peaks[cand][None, :])
        owner[sel] = cand[np.argmin(d, axis=1)]
    var = np.bincount(owner, weights=2 * S[bins] * df, minlength=peaks.size)
    m1 = np.bincount(owner, weights=2 * S[bins] * df * f[bins], minlength=peaks.size)
    m2 = np.bincount(owner, weights=2 * S[bins] * df * f[bins] ** 2, minlength=peaks.size)
    keep = var > 0
    freq = np.where(keep, m1 / np.where(keep, var, 1), 0)
    width = np.sqrt(np.maximum(np.where(keep, m2 / np.where(keep, var, 1), 0) - freq**2, df**2))
    keep &= var >= min_fraction * var.max()
    idx = np.flatnonzero(keep)
    idx = idx[np.argsort(var[idx])[::-1][:max_lines]]
    idx = idx[np.argsort(freq[idx])]
    return Lines(freq[idx], var[idx], width[idx])
