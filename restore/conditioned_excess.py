"""Where the images' estimate exceeds what its knowledge-conditioned prior allows: noise that moves like an attitude.

Where the AOCS knowledge is good, the restoration's prior for what the images
must still restore is the knowledge's own error given the knowledge
(:func:`restore.stages.knowledge_conditioned`): per bin of the record's
periodogram ``S`` (its noise and what its filter leaves), known from the
product, not from the differentials. The MAP's estimate ``ê`` of that residual
attitude is a Wiener filter of the differentials, and a Wiener filter's
output cannot hold more power on average than ``E[X] = S² / (S + N)`` (``N``
the pairs' fused white noise seen as an attitude, ``1 / Σ_j |G_j|² / (σ_j² Δt)``).
An estimate well above it proves that the differentials hold something that
is neither that attitude nor the modelled noise: noise that moves like an
attitude in every pair, which no fit residual shows — the scene's band offset
(:mod:`restore.observability`). The predicted σ does not hold it there, nor,
most likely, above the knowledge's cut-off where the images restore alone.

The estimate's periodogram is read in ``[high-pass, fraction × cut-off]``
(the knowledge's flat part) after the strong lines above that band are fitted
out: a 0.5 px line at 3.3 Hz leaks through the taper's sidelobes into bins
two or three below it at the level of the errors looked for. Bins are
smoothed three at a time (a tapered bin has two degrees of freedom) and a bin
counts where its power exceeds ``factor × E[X]``.

Measured on unseen seeds under a 2 Hz knowledge (low_frequencies 777, pitch,
0.099 px restored against 0.036 predicted): 4.1 × and 5.1 × at 0.6 and 1.2 Hz;
roll, whose σ held: ≤ 2.0 ×.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import uniform_filter1d

from .integration.transfer import fused_snr
from .knowledge_check import _fitted_line, tapered_power

__all__ = ["ConditionedExcess", "lines_above_removed", "wiener_output_power", "conditioned_excess",
           "record_conditioned_excess", "EXCESS_FACTOR", "BAND_FRACTION"]

#: a bin counts where the estimate's smoothed power exceeds this many times the Wiener output's expectation
EXCESS_FACTOR = 2.5
#: the band read ends at this fraction of the knowledge's cut-off (its filter's flat part)
BAND_FRACTION = 0.9
#: a peak above the band is fitted out when its tapered power exceeds this many times the band's mean
LINE_RATIO = 20.0
#: at most this many lines fitted out
MAX_LINES = 8


@dataclass(frozen=True)
class ConditionedExcess:
    """The estimate against its knowledge-conditioned prior in one axis's band (:func:`conditioned_excess`).

    Attributes
    ----------
    band_hz : (float, float)
        The band read [Hz].
    excess_hz : list of float
        The bins where the estimate's power exceeds ``EXCESS_FACTOR`` × its expectation.
    max_ratio : float
        The largest ratio of the smoothed power to its expectation in the band.
    excess_rms_rad : float
        ``√ Σ (X − E[X])`` over those bins: the estimate's power the prior cannot hold [rad].
    """

    band_hz: tuple
    excess_hz: list
    max_ratio: float
    excess_rms_rad: float

    def as_dict(self) -> dict:
        """Plain values, as restoration.nc records them (:meth:`from_dict` reads them back)."""
        return {"band_hz": [float(v) for v in self.band_hz], "excess_hz": [float(v) for v in self.excess_hz],
                "max_ratio": float(self.max_ratio), "excess_rms_rad": float(self.excess_rms_rad)}

    @classmethod
    def from_dict(cls, d: dict) -> "ConditionedExcess":
        """The excess :meth:`as_dict` wrote."""
        return cls(band_hz=tuple(float(v) for v in d["band_hz"]), excess_hz=[float(v) for v in d["excess_hz"]],
                   max_ratio=float(d["max_ratio"]), excess_rms_rad=float(d["excess_rms_rad"]))


def lines_above_removed(x, mask, top_bin: int, *, ratio: float = LINE_RATIO, max_lines: int = MAX_LINES,
                        band_bins=None) -> np.ndarray:
    """``x`` less its strongest sines above bin ``top_bin + 1``, strongest first, while the peak's tapered
    power exceeds ``ratio`` × the mean over ``band_bins`` (default: bins 1 … ``top_bin``); off ``mask``: 0.

    Not :func:`restore.knowledge_check.without_strong_lines`, which keeps the lines within three bins of its
    band as the band's own content: here the lines just above the band are the attitude the knowledge
    misses, and theirs is the leakage that matters (with that function, low_frequencies' 3.3 Hz line two
    bins above a 2 Hz knowledge's band read as 6.1 × and 19.7 × on two unseen seeds' roll, 1.5 × and
    2.7 × with the line fitted out)."""
    v = np.asarray(x, dtype=np.float64)
    m = np.asarray(mask, dtype=bool) & np.isfinite(v)
    n = v.size
    v = np.where(m, v, 0.0)
    if np.count_nonzero(m) < 8 or top_bin < 1:
        return v
    b = np.arange(1, top_bin + 1) if band_bins is None else np.asarray(band_bins)
    t = np.arange(n, dtype=np.float64)
    for _ in range(int(max_lines)):
        p = tapered_power(v, m)
        far = np.zeros(p.size, dtype=bool)
        far[top_bin + 2:-1] = True
        if not far.any():
            break
        j = int(np.argmax(np.where(far, p, 0.0)))
        if p[j] < ratio * float(np.mean(p[b])):
            break
        v = np.where(m, v - _fitted_line(v, m, t, j, n), 0.0)
    return v


def wiener_output_power(prior, noise) -> np.ndarray:
    """The expected power of a Wiener estimate of a signal of power ``prior`` under noise ``noise`` (same
    units, per bin): ``S² / (S + N)`` (0 where both are).

    Examples
    --------
    >>> wiener_output_power([1.0, 1.0, 0.0], [0.0, 1.0, 1.0]).tolist()
    [1.0, 0.5, 0.0]
    """
    s = np.asarray(prior, dtype=np.float64)
    nn = np.asarray(noise, dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(s + nn > 0, s * s / (s + nn), 0.0)


def fused_noise_per_bin(freq, noise_std, taus, dt: float, n: int) -> np.ndarray:
    """The pairs' white noise seen as an attitude, per bin of ``rfftfreq(n, dt)`` in a periodogram that sums to
    the mean square: ``2 Δf / Σ_j |G_j(f)|² / (σ_j² Δt)`` (infinite where every pair is blind)."""
    f = np.asarray(freq, dtype=np.float64)
    sd = np.asarray(noise_std, dtype=np.float64)
    known = sd > 0                                      # a pair without a noise level brings no information
    info = fused_snr(f, np.ones_like(f), sd[known], np.asarray(taus, dtype=np.float64)[known], dt) \
        if known.any() else np.zeros_like(f)
    with np.errstate(divide="ignore"):
        return np.where(info > 0, 2.0 / (n * dt) / info, np.inf)


def conditioned_excess(increment, prior_freq, prior_psd, noise_std, taus, dt: float, *, highpass_hz: float,
                       cutoff_hz: float, fraction: float = BAND_FRACTION,
                       factor: float = EXCESS_FACTOR) -> ConditionedExcess | None:
    """The estimate ``increment`` against the Wiener output its prior allows, in ``[highpass_hz, fraction ×
    cutoff_hz]`` (module docstring); None when that band holds fewer than two bins or the estimate is empty.

    Parameters
    ----------
    increment : ndarray (lines,)
        The MAP's estimate of the attitude the knowledge leaves [rad] (NaN: not estimated).
    prior_freq, prior_psd : ndarray
        Its prior, two-sided PSD [rad²/Hz] on a one-sided grid (the record's conditioned spectrum).
    noise_std, taus : sequence
        Each pair's white noise [rad per line] and delay [s].
    dt : float
        Line period [s].
    highpass_hz, cutoff_hz : float
        The restoration's high-pass and the knowledge's cut-off [Hz].
    """
    x = np.asarray(increment, dtype=np.float64)
    ok = np.isfinite(x)
    n = x.size
    if n < 16 or np.count_nonzero(ok) < 16 or not cutoff_hz > 0:
        return None
    f = np.fft.rfftfreq(n, dt)
    band = (f >= highpass_hz) & (f <= fraction * cutoff_hz) & (f > 0)
    b = np.flatnonzero(band)
    if b.size < 2:
        return None
    v = lines_above_removed(x, ok, int(b[-1]), band_bins=b)
    power = uniform_filter1d(tapered_power(v, ok), 3, mode="nearest") / max(float(np.mean(ok)), 1e-12)
    df = f[1] - f[0]
    prior = np.interp(f, np.asarray(prior_freq, dtype=np.float64), np.asarray(prior_psd, dtype=np.float64)) * 2 * df
    expected = wiener_output_power(prior, fused_noise_per_bin(f, noise_std, taus, dt, n))
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(expected[b] > 0, power[b] / expected[b], np.inf)
    over = ratio > factor
    excess = float(np.sum(np.maximum(power[b][over] - expected[b][over], 0.0)))
    finite = ratio[np.isfinite(ratio)]
    return ConditionedExcess(band_hz=(float(f[b[0]]), float(f[b[-1]])), excess_hz=[float(v) for v in f[b][over]],
                             max_ratio=float(finite.max()) if finite.size else float("inf"),
                             excess_rms_rad=float(np.sqrt(excess)))


def record_conditioned_excess(record, cutoff_hz: float | None) -> ConditionedExcess | None:
    """:func:`conditioned_excess` of an axis's integration record; None unless its prior is conditioned on
    the knowledge (``knowledge_conditioned``) and the knowledge's cut-off is known."""
    if cutoff_hz is None or not getattr(record, "knowledge_conditioned", False) or record.spectrum is None:
        return None
    sp = record.spectrum
    return conditioned_excess(record.increment, sp.freq, sp.psd, sp.noise_std, record.taus,
                              float(record.line_period_s), highpass_hz=float(record.highpass_hz),
                              cutoff_hz=float(cutoff_hz))
