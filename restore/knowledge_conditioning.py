"""The images' integration conditioned on the AOCS knowledge: restore the attitude, not only the knowledge's error.

The images restore ``e = θ − k``, the error of the AOCS knowledge ``k``, and
the restored angle is ``k + ê``. Estimating ``e`` from the images alone, with
the prior of ``e``, throws away what ``k`` itself says about ``e``: the two are
not independent, since ``k = G θ + ε`` and ``e = (1 − G) θ − ε`` share the
knowledge's noise ``ε``. Wherever the attitude is quiet (no jitter between a
few Hz and the first micro-vibration line, say) but the knowledge is noisy,
``e`` is almost exactly ``−k`` — and the images, asked to restore a noise
``e`` of the knowledge's size, pass their own matching noise through a filter
opened for it.

Per frequency, with ``S_θ`` the attitude's PSD, ``N`` the knowledge's noise
PSD and ``G`` the knowledge's response to the attitude (its AOCS filter and
its spline interpolation), ``(e, k)`` is jointly Gaussian and

    E[e | k] = h k,   h = ((1 − G) G* S_θ − N) / (|G|² S_θ + N)
    Var[e | k] = V = S_θ N / (|G|² S_θ + N)

(the cross terms cancel: ``S_e Var k − |Cov(e, k)|² = S_θ N |1 − G + G|²``).
So the integration runs again on ``e' = e − h k``: the differentials of the
known mean ``μ = h k`` are taken off the measured ones, the prior is ``V``
(never above the prior of ``e``), and ``μ`` is added back. Where ``S_θ = 0``,
``h = −1`` and ``V = 0``: the knowledge's noise is removed and nothing of the
images' noise enters; where the knowledge says nothing (``G = 0``), ``h = −1``
and ``V = S_θ``: the images restore the attitude itself; where ``S_θ ≫ N``,
``h → (1 − G) / G`` and ``V → N / |G|²``: the knowledge deconvolved by its
filter, the images correcting it.

``S_θ`` is the restored angle's power less the power of its predicted error
(the posterior draws, :attr:`restore.posterior.PosteriorSigma.error_power`).
The restored angle is tapered by a Tukey window (flat over its middle, so that
a transient near a record end, a chirp's onset, keeps its weight; a Hann taper
halved a 3 px chirp's power starting 0.2 s into a 1.6 s record, and the prior
it gave shrank the chirp). The knowledge's response counts only where it is at
least :data:`MIN_GAIN` (its band): beyond, a small ``G`` makes ``(1 − G) / G``
a large amplification of every way the knowledge departs from its model (the
filter's start-up, the spline's aliases), and the knowledge is taken as noise
only. Above the knowledge's Nyquist frequency its noise is not modelled and
the prior is left as it was (``h = 0``); so below :data:`LOWEST_BINS` bins of the
record, where the quadratic trend taken out of the restored angle took ``S_θ``
with it (the knowledge's own slow drift would be taken for its noise: a 2000-line
record of geo_noisy_knowledge got a 0.076 px slope that way).
"""
from __future__ import annotations

import numpy as np
from scipy.ndimage import uniform_filter1d
from scipy.signal.windows import tukey

from .knowledge_prior import knowledge_noise_floor, knowledge_response, spline_response

__all__ = ["MIN_GAIN", "TAPER_ALPHA", "SMOOTH_HZ", "LOWEST_BINS", "conditional_prior", "knowledge_signal_response",
           "attitude_psd", "apply_response", "KnowledgeConditioning", "knowledge_conditioning"]

#: the knowledge's response to the attitude counts where at least this (its band); 0 beyond
MIN_GAIN = 0.5
#: Tukey taper's tapered fraction for the restored angle's power
TAPER_ALPHA = 0.25
#: running-mean width of the powers [Hz]
SMOOTH_HZ = 2.0
#: nothing is conditioned below this many frequency bins of the record (the quadratic trend's reach)
LOWEST_BINS = 3


def conditional_prior(psd_theta, response, noise_psd) -> tuple[np.ndarray, np.ndarray]:
    """Prior PSD of ``e = θ − k`` given the knowledge ``k = G θ + ε``, and the filter of its mean.

    Parameters
    ----------
    psd_theta : array_like
        Attitude PSD ``S_θ`` (any one-sidedness, the same as ``noise_psd``).
    response : array_like (complex or real)
        The knowledge's response ``G`` to the attitude.
    noise_psd : array_like
        The knowledge's noise PSD ``N``.

    Returns
    -------
    variance : ndarray
        ``S_θ N / (|G|² S_θ + N)`` (``S_θ`` where both ``G`` and ``N`` vanish).
    mean_filter : ndarray (complex)
        ``h`` with ``E[e | k] = h k``: ``((1 − G) G* S_θ − N) / (|G|² S_θ + N)`` (``−1`` where the denominator
        vanishes and ``N`` does not, 0 where both vanish).
    """
    s = np.maximum(np.asarray(psd_theta, dtype=np.float64), 0.0)
    g = np.asarray(response, dtype=complex)
    nk = np.maximum(np.asarray(noise_psd, dtype=np.float64), 0.0)
    den = np.abs(g) ** 2 * s + nk
    pos = den > 0
    safe = np.where(pos, den, 1.0)
    variance = np.where(pos, s * nk / safe, s)
    mean_filter = np.where(pos, ((1.0 - g) * np.conj(g) * s - nk) / safe, 0.0)
    return variance, mean_filter


def knowledge_signal_response(freq, *, cutoff_hz: float, order: int, kind: str, rate_hz: float,
                              min_gain: float = MIN_GAIN) -> np.ndarray:
    """The knowledge's response to the attitude: its AOCS filter times the spline interpolation of its samples,
    set to 0 where its modulus is below ``min_gain`` (see the module's notes)."""
    f = np.abs(np.asarray(freq, dtype=np.float64))
    g = knowledge_response(f, cutoff_hz, order, kind) * spline_response(f, rate_hz)
    return np.where(np.abs(g) >= min_gain, g, 0.0)


def _smoothed_on(freq, f_bins, power_bins, smooth_hz: float) -> np.ndarray:
    df = f_bins[1] - f_bins[0]
    width = max(1, int(round(smooth_hz / df)))
    return np.interp(np.abs(freq), f_bins, uniform_filter1d(power_bins, width, mode="nearest"))


def attitude_psd(restored, error_power, freq, dt: float, *, taper_alpha: float = TAPER_ALPHA,
                 smooth_hz: float = SMOOTH_HZ) -> np.ndarray:
    """Two-sided attitude PSD [rad²/Hz] at ``freq``: the restored angle's power less its predicted error's.

    ``restored`` (lines,) [rad], gaps (NaN) filled linearly; quadratic trend removed, Tukey taper.
    ``error_power`` (lines // 2 + 1,) per bin of ``rfftfreq(lines, dt)`` [rad²], summing to about the error's
    mean square (:attr:`restore.posterior.PosteriorSigma.error_power`). Both are smoothed over ``smooth_hz``.
    """
    x = np.asarray(restored, dtype=np.float64)
    n = x.size
    ok = np.isfinite(x)
    if ok.sum() < 16:
        raise ValueError("restored: fewer than 16 finite lines")
    idx = np.arange(n)
    x = np.interp(idx, idx[ok], x[ok])
    x = x - np.polyval(np.polyfit(idx, x, 2), idx)
    w = tukey(n, taper_alpha)
    f_bins = np.fft.rfftfreq(n, dt)
    df = f_bins[1] - f_bins[0]
    p_r = np.abs(np.fft.rfft(x * w)) ** 2 * dt / np.sum(w ** 2)
    p_e = np.asarray(error_power, dtype=np.float64) / (2.0 * df)
    if p_e.shape != p_r.shape:
        raise ValueError(f"error_power: {p_e.shape[0]} bins for a record of {n} lines ({p_r.shape[0]} bins)")
    return np.maximum(_smoothed_on(freq, f_bins, p_r, smooth_hz) - _smoothed_on(freq, f_bins, p_e, smooth_hz), 0.0)


def apply_response(x, response, freq, dt: float) -> np.ndarray:
    """``x`` (lines,) filtered by ``response`` given at ``freq`` [Hz] (FFT), its quadratic trend kept out.

    Beyond the record the rest is taken as zero, its expectation for the knowledge's white noise: mirrored
    ends would hand the filter a copy of the noise near each end as if it were what lies beyond, and a
    sharp band filter rings with it over ``1 / f`` of its lowest frequency (a 0.8 s record of
    geo_noisy_knowledge, whose knowledge is noisy, took 0.1 px errors at both ends that way).
    """
    x = np.asarray(x, dtype=np.float64)
    n = x.size
    idx = np.arange(n)
    c = x - np.polyval(np.polyfit(idx, x, 2), idx) if n > 3 else x - x.mean()
    padded = np.concatenate([np.zeros(n), c, np.zeros(n)])
    f = np.fft.rfftfreq(padded.size, dt)
    r = np.asarray(response, dtype=complex)
    h = np.interp(f, freq, r.real) + 1j * np.interp(f, freq, r.imag)
    return np.fft.irfft(np.fft.rfft(padded) * h, padded.size)[n:2 * n]


class KnowledgeConditioning:
    """What :func:`knowledge_conditioning` found for one axis (arrays on the prior's frequency grid)."""

    def __init__(self, freq, psd_theta, variance, mean_filter, noise_psd, response):
        self.freq = np.asarray(freq, dtype=np.float64)
        self.psd_theta = psd_theta
        self.variance = variance
        self.mean_filter = mean_filter
        self.noise_psd = noise_psd
        self.response = response

    def mean(self, knowledge, dt: float) -> np.ndarray:
        """``E[e | k]`` at the lines of ``knowledge`` (the knowledge series, (lines,) [rad])."""
        return apply_response(knowledge, self.mean_filter, self.freq, dt)


def knowledge_conditioning(freq, prior_psd, restored, error_power, dt: float, *, cutoff_hz: float, order: int,
                           kind: str, rate_hz: float, noise_rad: float) -> KnowledgeConditioning:
    """The prior of ``e`` given the knowledge (see the module's notes), on the prior's grid ``freq``.

    ``prior_psd``: the prior of ``e`` the integration used, kept above the knowledge's Nyquist frequency (where
    its noise is not modelled; the mean's filter is 0 there).
    """
    freq = np.asarray(freq, dtype=np.float64)
    prior_psd = np.asarray(prior_psd, dtype=np.float64)
    s_theta = attitude_psd(restored, error_power, freq, dt)
    g = knowledge_signal_response(freq, cutoff_hz=cutoff_hz, order=order, kind=kind, rate_hz=rate_hz)
    nk = knowledge_noise_floor(freq, rate_hz=rate_hz, noise_rad=noise_rad)
    variance, h = conditional_prior(s_theta, g, nk)
    # below ~3 bins of the record the quadratic trend taken out of the restored angle took S_θ with it: there the
    # knowledge's slow content would be taken for noise (h = −1), so nothing is conditioned
    n = np.asarray(restored).size
    band = (nk > 0) & (np.abs(freq) >= LOWEST_BINS / (n * dt))
    variance = np.where(band, variance, prior_psd)
    h = np.where(band, h, 0.0)
    # a variance under 1e-12 of the largest is numerically zero for the MAP
    variance = np.where(variance > 1e-12 * max(float(np.max(variance)), 1e-300), variance, 0.0)
    return KnowledgeConditioning(freq, s_theta, variance, h, nk, g)
