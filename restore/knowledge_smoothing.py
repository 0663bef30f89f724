"""The AOCS knowledge's own noise, taken out where the images leave the knowledge: a Wiener shrinkage.

Below the restoration's high-pass the restored angle *is* the AOCS knowledge
(``restored = k + HP(ê)``): the images' estimate is discarded there, since the
differentials say little at those frequencies and a band's slow bias would
pass for attitude. The knowledge's white noise (``σ_k`` per sample at ``f_k``,
as product.nc records it) therefore stays in the restored angle below the
high-pass. On phr_cmg that was 0.014 px of roll and 0.013 px of pitch, the
largest single part of a 0.024 / 0.027 px error.

Nothing but the knowledge itself is needed to take much of it out. Its
samples are the attitude (through the AOCS filter) plus white noise of known
level. In an orthonormal DCT-II of the samples (an even extension: the
record's ends are no jump) the noise stays white, ``σ_k²`` per coefficient,
while an attitude with little power in part of the band leaves those
coefficients at the noise level. Each coefficient is multiplied by the
empirical Wiener gain

    W_j = max(0, 1 − σ_k² / P̄_j)

where ``P̄_j`` is the mean power of the coefficient and its neighbours
(``pool`` of them: one coefficient alone is too noisy an estimate of its own
power, and gains that follow each coefficient's noise lose on records with a
real low-frequency attitude). A low-order polynomial (``degree``) is fitted
first and kept whole: a record's trend leaks over many DCT coefficients well
above the noise and would hold every gain near 1. The error left in each
coefficient is the Wiener error ``S σ² / (S + σ²) = W σ²`` (``S = P̄ − σ²``,
the attitude's own power), and the polynomial passes its share of the noise
whole; :meth:`KnowledgeSmoothing.error_draw` draws exactly that.

Only the part of the smoothed knowledge below the high-pass is used
(:func:`lowband_correction`): above it the images correct the knowledge's
error whatever it is. Measured by Monte Carlo (a trend, weak and strong
random walks, sines of 0.05–1 px at 0.5–1.6 Hz; 10–200 Hz telemetry; 0.8–4 s
records): the low-band error falls by up to 45 % where the attitude has little
low-frequency power and rises by at most 5 % (a 0.8 s record with a 1 px,
0.5 Hz sine) where it has much; on the rendered stress scenes (restore
unchanged, the correction added): phr_cmg 0.0238 / 0.0273 → 0.0177 / 0.0224 px,
no scenario worse by more than 0.0013 px.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.fft import dct, idct

from simsat.attitude import AttitudeSeries

from .synthesis import highpass_nan

__all__ = ["KnowledgeSmoothing", "knowledge_smoothing", "wiener_shrinkage_gain", "lowband_correction",
           "lowband", "lowband_rows", "samples_at_lines", "DEFAULT_DEGREE", "DEFAULT_POOL", "MIN_SAMPLES"]

#: degree of the polynomial kept whole (the record's offset, slope and curvature)
DEFAULT_DEGREE = 2
#: DCT coefficients whose power is averaged into each gain
DEFAULT_POOL = 5
#: fewer knowledge samples than this over the record: nothing is smoothed (the pool and the polynomial would
#: leave too few coefficients to tell the attitude from the noise)
MIN_SAMPLES = 16


def wiener_shrinkage_gain(coefficients, noise_rad: float, *, pool: int = DEFAULT_POOL) -> np.ndarray:
    """Empirical Wiener gain of each coefficient of an orthonormal transform of signal + white noise.

    ``W_j = max(0, 1 − σ² / P̄_j)`` with ``P̄_j`` the mean of ``c²`` over the
    ``pool`` coefficients centred on ``j`` (fewer at the ends: the mean is over
    those that exist). ``noise_rad`` 0 gives gain 1 everywhere.

    Parameters
    ----------
    coefficients : array_like (n,)
        Transform coefficients (noise ``noise_rad`` per coefficient).
    noise_rad : float
        Noise standard deviation per coefficient.
    pool : int, keyword-only
        Odd number of neighbouring coefficients averaged (1: each its own).

    Returns
    -------
    ndarray (n,)
        Gains in [0, 1].
    """
    c = np.asarray(coefficients, dtype=np.float64)
    if pool < 1 or pool % 2 == 0:
        raise ValueError(f"pool: must be an odd number >= 1, got {pool}")
    if not noise_rad >= 0:
        raise ValueError(f"noise_rad: must be >= 0, got {noise_rad}")
    if noise_rad == 0 or c.size == 0:
        return np.ones(c.shape)
    kernel = np.ones(pool)
    power = np.convolve(c * c, kernel, mode="same") / np.convolve(np.ones(c.size), kernel, mode="same")
    with np.errstate(divide="ignore"):
        return np.clip(1.0 - noise_rad ** 2 / power, 0.0, 1.0)


@dataclass(frozen=True)
class KnowledgeSmoothing:
    """The shrinkage of one axis's knowledge samples (:func:`knowledge_smoothing`).

    Attributes
    ----------
    time : ndarray (m,)
        Knowledge sample times [s].
    noise_rad : float
        White noise per sample [rad].
    degree : int
        Degree of the polynomial kept whole.
    gain : ndarray (m,)
        Wiener gain of each DCT-II coefficient of the samples minus the polynomial.
    """

    time: np.ndarray
    noise_rad: float
    degree: int
    gain: np.ndarray

    def _basis(self) -> np.ndarray:
        t = self.time - self.time.mean()
        span = max(float(np.ptp(t)), 1e-12)
        return np.vander(2.0 * t / span, self.degree + 1)

    def _split(self, values: np.ndarray) -> tuple:
        """(polynomial fit, DCT of what it leaves) of samples ``values``."""
        a = self._basis()
        coef, *_ = np.linalg.lstsq(a, values, rcond=None)
        base = a @ coef
        return base, dct(values - base, norm="ortho")

    def apply(self, values) -> np.ndarray:
        """The smoothed samples: the polynomial plus the shrunk DCT of the rest."""
        base, c = self._split(np.asarray(values, dtype=np.float64))
        return base + idct(c * self.gain, norm="ortho")

    def error_draw(self, rng: np.random.Generator) -> np.ndarray:
        """One draw of the smoothed samples' error [rad]: the polynomial's share of the noise whole, and
        ``√W σ`` per DCT coefficient of the rest (the Wiener error, ``W σ²``, of each)."""
        noise = rng.standard_normal(self.time.size) * self.noise_rad
        base, c = self._split(noise)
        return base + idct(c * np.sqrt(self.gain), norm="ortho")

    def error_draws(self, rng: np.random.Generator, count: int) -> np.ndarray:
        """``count`` draws (draw, sample) of :meth:`error_draw`'s error at once [rad]."""
        noise = rng.standard_normal((int(count), self.time.size)) * self.noise_rad
        a = self._basis()
        coef, *_ = np.linalg.lstsq(a, noise.T, rcond=None)
        base = (a @ coef).T
        return base + idct(dct(noise - base, norm="ortho", axis=1) * np.sqrt(self.gain), norm="ortho", axis=1)


def knowledge_smoothing(time, values, noise_rad: float, *, degree: int = DEFAULT_DEGREE,
                        pool: int = DEFAULT_POOL) -> KnowledgeSmoothing | None:
    """The Wiener shrinkage of an axis's knowledge samples (module docstring); None with too few samples.

    Parameters
    ----------
    time, values : array_like (m,)
        Knowledge sample times [s] (increasing) and angles [rad].
    noise_rad : float
        White noise per sample [rad], as the product records it.
    degree, pool : int, keyword-only
        Polynomial kept whole; coefficients pooled per gain.
    """
    t = np.asarray(time, dtype=np.float64)
    v = np.asarray(values, dtype=np.float64)
    if t.shape != v.shape or t.ndim != 1:
        raise ValueError(f"time and values: must be 1-D of the same length, got {t.shape} and {v.shape}")
    if degree < 0:
        raise ValueError(f"degree: must be >= 0, got {degree}")
    if t.size < max(MIN_SAMPLES, degree + 1 + pool) or not np.all(np.isfinite(v)):
        return None
    probe = KnowledgeSmoothing(t, float(noise_rad), int(degree), np.ones(t.size))
    _, c = probe._split(v)
    return KnowledgeSmoothing(t, float(noise_rad), int(degree), wiener_shrinkage_gain(c, noise_rad, pool=pool))


def samples_at_lines(samples, sample_time, line_time) -> np.ndarray:
    """Sampled values read at the lines by cubic interpolation, as the product's knowledge is read, clamped to the
    samples' span (a line a fraction of a sample beyond the telemetry's ends reads the end sample's value) [rad]."""
    s = np.asarray(samples, dtype=np.float64)
    ts = np.asarray(sample_time, dtype=np.float64)
    return AttitudeSeries(ts, s, s, s).at(np.clip(np.asarray(line_time, dtype=np.float64), ts[0], ts[-1]))[0]


def lowband(samples, sample_time, line_time, *, line_period_s: float, highpass_hz: float) -> np.ndarray:
    """What lies below the high-pass of sampled values read at the lines (:func:`samples_at_lines`), minus its
    high-passed part (:func:`restore.synthesis.highpass_nan`) [rad]."""
    x = samples_at_lines(samples, sample_time, line_time)
    if not highpass_hz > 0:
        return np.zeros(x.shape)
    return x - highpass_nan(x, dt=line_period_s, cutoff_hz=highpass_hz)


def lowband_rows(samples, sample_time, line_time, *, line_period_s: float, highpass_hz: float) -> np.ndarray:
    """:func:`lowband` of each row of ``samples`` (row, sample) at once, (row, line) [rad]: the rows read at the
    lines by a cubic spline (clamped to the samples' span) and low-passed by the Gaussian :func:`highpass_nan`
    subtracts (every line finite, the record's ends as missing data beyond)."""
    from scipy.interpolate import CubicSpline
    from scipy.signal import fftconvolve

    from .synthesis import lowpass_sigma_lines

    s = np.atleast_2d(np.asarray(samples, dtype=np.float64))
    ts = np.asarray(sample_time, dtype=np.float64)
    t = np.asarray(line_time, dtype=np.float64)
    if not highpass_hz > 0:
        return np.zeros((s.shape[0], t.size))
    x = CubicSpline(ts, s, axis=1)(np.clip(t, ts[0], ts[-1]))
    # the kernel scipy.ndimage.gaussian_filter1d uses (truncated at 4 σ), by FFT: hundreds of taps on many rows
    sig = lowpass_sigma_lines(dt=line_period_s, cutoff_hz=highpass_hz)
    u = np.arange(-int(4.0 * sig + 0.5), int(4.0 * sig + 0.5) + 1, dtype=np.float64)
    g = np.exp(-0.5 * (u / sig) ** 2)
    g /= g.sum()
    den = fftconvolve(np.ones(t.size), g, mode="same")
    return fftconvolve(x, g[None, :], mode="same", axes=1) / np.maximum(den, 1e-12)


def lowband_correction(smoothing: KnowledgeSmoothing, values, line_time, *, line_period_s: float,
                       highpass_hz: float) -> np.ndarray:
    """What to add to ``knowledge + HP(ê)`` at the lines so that its low band is the smoothed knowledge's:
    ``−LP(k − k_s)`` [rad] (zero without a high-pass: the integration then restores every frequency)."""
    v = np.asarray(values, dtype=np.float64)
    return -lowband(v - smoothing.apply(v), smoothing.time, line_time, line_period_s=line_period_s,
                    highpass_hz=highpass_hz)
