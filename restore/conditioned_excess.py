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
smoothed three at a time (a tapered bin has two degrees of freedom, three
adjacent ones about 3.65) and a bin counts where its power exceeds
:func:`excess_factor` × ``E[X]``, the threshold that a model-true estimate
crosses somewhere in the band in 5 % of records. Where the attitude is strong
the prior is allowed :data:`KNOWLEDGE_MODEL_ERROR` of it more: the knowledge's
latency, dephasing and filter are known only so well, and the error they
leave at a strong line is real attitude the images restore rightly.

Where the test fails, the estimate is no longer the minimum-variance one: its
input holds ``O = T − S − N`` besides the attitude and the noise (``T`` the
input's power, ``X / g²``, ``g = S / (S + N)``). :func:`shrunk_excess` then
takes each bin above its expectation by the gain that counts ``O`` as noise,
``E[X] / X`` (the lines above the band kept whole), and books the error that
estimate still has there beyond the draws' on σ. Above the knowledge's band
the images restore alone and nothing tells the offset from the attitude: σ may
still be short there (the summary says so).

Measured on unseen seeds under a 2 Hz knowledge (low_frequencies 777, pitch,
0.099 px restored against 0.036 predicted): 4.1 × and 5.1 × at 0.6 and 1.2 Hz;
roll, whose σ held: ≤ 2.0 ×.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.ndimage import uniform_filter1d
from scipy.stats import chi2

from .integration.transfer import fused_snr
from .knowledge_check import _fitted_line, tapered_power

__all__ = ["ConditionedExcess", "ExcessShrink", "lines_above_removed", "strong_lines_above", "wiener_output_power", "estimate_power",
           "conditioned_excess", "record_conditioned_excess", "excess_gain", "shrunk_excess", "excess_factor", "offset_error_above", "offset_shared_by_sun", "as_read", "input_offset",
           "EXCESS_FALSE_ALARM", "BIN_DOF",
           "BAND_FRACTION", "KNOWLEDGE_MODEL_ERROR", "OFFSET_SLOPE"]

#: the chance, per record and axis, that a Wiener output drawn as the model says shows an excess somewhere in its
#: band (a family-wise false alarm: a false excess shrinks the attitude's own content by its fluctuation)
EXCESS_FALSE_ALARM = 0.05
#: the degrees of freedom of a 3-bin running mean of a Hann-tapered periodogram bin (adjacent bins are correlated):
#: 2 mean² / variance over 400 white records of 4000 lines, 3.65
BIN_DOF = 3.65


#: once the band's test fires, each bin whose power exceeds this many times its expectation is shrunk
SHRINK_FROM = 1.0


def excess_factor(bins: int, false_alarm: float = EXCESS_FALSE_ALARM) -> float:
    """How many times its expectation a smoothed bin must exceed so that ``bins`` bins of a model-true estimate
    cross it with chance ``false_alarm`` in all (Bonferroni over the bins, each a χ² of :data:`BIN_DOF` dof).

    Examples
    --------
    >>> round(excess_factor(4), 2), round(excess_factor(16), 2)
    (3.32, 4.17)
    """
    return float(chi2.isf(false_alarm / max(int(bins), 1), BIN_DOF) / BIN_DOF)
#: the band read ends at this fraction of the knowledge's cut-off (its filter's flat part)
BAND_FRACTION = 0.9
#: a peak above the band is fitted out when its tapered power exceeds this many times the band's mean
LINE_RATIO = 20.0
#: at most this many lines fitted out
MAX_LINES = 8
#: the knowledge's response to the attitude is known to about this fraction (its latency, its dephasing, its
#: filter's model): where the attitude is strong the knowledge's error may hold this fraction of it beyond its
#: noise. An unseen scene under a causal 4 Hz knowledge 15 ms late (taken out as 12.7 ms) kept 7 % of its 2.2 Hz
#: line, 0.035 px, against a conditioned prior of 0.015: not the scene's offset, not to be shrunk
KNOWLEDGE_MODEL_ERROR = 0.1


@dataclass(frozen=True)
class ConditionedExcess:
    """The estimate against its knowledge-conditioned prior in one axis's band (:func:`conditioned_excess`).

    Attributes
    ----------
    band_hz : (float, float)
        The band read [Hz].
    excess_hz : list of float
        The bins where the estimate's power exceeds :func:`excess_factor` × its expectation.
    max_ratio : float
        The largest ratio of the smoothed power to its expectation in the band.
    excess_rms_rad : float
        ``√ Σ (X − E[X])`` over those bins: the estimate's power the prior cannot hold [rad].
    """

    band_hz: tuple
    excess_hz: list
    max_ratio: float
    excess_rms_rad: float
    #: where the estimate was shrunk (:func:`shrunk_excess`), the Wiener error the excess still leaves there
    #: beyond the draws' [rad], booked on σ; None: not shrunk (a diagnostic only)
    shrink_error_rad: float | None = None
    #: where shrunk, the error the same offset brings above the band, where the images restore alone [rad]
    #: (:func:`offset_error_above`), booked on σ too; None: not shrunk
    above_error_rad: float | None = None
    #: the error above the band the scene's offset shrunk on another axis brings to this one, by the sun's split
    #: (:func:`offset_shared_by_sun`) [rad]; None: none shared
    shared_above_rad: float | None = None

    @property
    def booked_rad(self) -> float | None:
        """What σ books of it [rad]: the shrink's error in the band and, in quadrature, the larger of the two
        estimates of the offset's error above it (this axis's own, the one shared by the sun's split: the same
        offset, measured twice); None where neither was booked."""
        if self.shrink_error_rad is None and not self.shared_above_rad:
            return None
        above = max(self.above_error_rad or 0.0, self.shared_above_rad or 0.0)
        return float(np.hypot(self.shrink_error_rad or 0.0, above))

    def as_dict(self) -> dict:
        """Plain values, as restoration.nc records them (:meth:`from_dict` reads them back)."""
        return {"band_hz": [float(v) for v in self.band_hz], "excess_hz": [float(v) for v in self.excess_hz],
                "max_ratio": float(self.max_ratio), "excess_rms_rad": float(self.excess_rms_rad),
                "shrink_error_rad": None if self.shrink_error_rad is None else float(self.shrink_error_rad),
                "above_error_rad": None if self.above_error_rad is None else float(self.above_error_rad),
                "shared_above_rad": None if self.shared_above_rad is None else float(self.shared_above_rad)}

    @classmethod
    def from_dict(cls, d: dict) -> "ConditionedExcess":
        """The excess :meth:`as_dict` wrote."""
        return cls(band_hz=tuple(float(v) for v in d["band_hz"]), excess_hz=[float(v) for v in d["excess_hz"]],
                   max_ratio=float(d["max_ratio"]), excess_rms_rad=float(d["excess_rms_rad"]),
                   shrink_error_rad=None if d.get("shrink_error_rad") is None else float(d["shrink_error_rad"]),
                   above_error_rad=None if d.get("above_error_rad") is None else float(d["above_error_rad"]),
                   shared_above_rad=None if d.get("shared_above_rad") is None else float(d["shared_above_rad"]))


def _strongest_line_above(v, m, top_bin: int, band_bins, ratio: float, max_bin: int | None = None) -> int | None:
    """Bin of the strongest peak of ``v``'s tapered periodogram above ``top_bin + 1`` (up to ``max_bin``) when it
    exceeds ``ratio`` × the mean over ``band_bins``; None otherwise."""
    p = tapered_power(v, m)
    far = np.zeros(p.size, dtype=bool)
    far[top_bin + 2:-1 if max_bin is None else min(int(max_bin) + 1, p.size - 1)] = True
    if not far.any():
        return None
    j = int(np.argmax(np.where(far, p, 0.0)))
    return j if p[j] >= ratio * float(np.mean(p[band_bins])) else None


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
        j = _strongest_line_above(v, m, top_bin, b, ratio)
        if j is None:
            break
        v = np.where(m, v - _fitted_line(v, m, t, j, n), 0.0)
    return v


#: the joint fit of :func:`strong_lines_above` takes the record's quadratic with its lines (a slow drift would
#: otherwise lean on the lowest one), and refines each frequency against the others this many times
JOINT_POLY_DEGREE = 2
JOINT_REFINE_ROUNDS = 3


def _joint_sines(v, m, t, u, freqs) -> tuple[float, np.ndarray]:
    """Least squares of ``v`` on the lines ``m`` over a quadratic in ``u`` and a sine per frequency of ``freqs``
    [cycles per line]: (residual sum of squares, the sines' sum over all lines)."""
    cols = [u ** d for d in range(JOINT_POLY_DEGREE + 1)]
    for f in freqs:
        cols += [np.cos(2.0 * np.pi * f * t), np.sin(2.0 * np.pi * f * t)]
    a = np.stack(cols, axis=1)
    coef, *_ = np.linalg.lstsq(a[m], v[m], rcond=None)
    r = v[m] - a[m] @ coef
    k = JOINT_POLY_DEGREE + 1
    return float(r @ r), a[:, k:] @ coef[k:]


def strong_lines_above(x, mask, top_bin: int, *, ratio: float = LINE_RATIO, max_lines: int = MAX_LINES,
                       band_bins=None, max_bin: int | None = None) -> tuple[np.ndarray, list]:
    """The strong sines of ``x`` above bin ``top_bin + 1`` and up to ``max_bin`` (found as
    :func:`lines_above_removed` finds them), fitted jointly: ``(their sum over all lines, their frequencies
    [cycles per line])``; zeros and ``[]`` when there are none.

    One sine at a time, each fitted on what the previous ones left, is biased by the others' leakage when a
    record holds a few cycles of lines a few bins apart (3.3, 5.1 and 7.7 Hz over 1.6 s), and its residual
    is largest at the record's ends. Here every line found is fitted again with the others and a quadratic
    (amplitudes and phases by least squares, each frequency refined within half a bin against the rest,
    :data:`JOINT_REFINE_ROUNDS` times). On the true knowledge error of an unseen low_frequencies scene (seed
    777, roll: its 3.3, 5.1 and 7.7 Hz lines and five CMG ones) the residual's content at 0.4–1.4 Hz on the
    record's first line: 0.16 px one line at a time, 0.046 jointly (the knowledge's white noise there: 0.029).
    """
    from scipy.optimize import minimize_scalar

    v = np.asarray(x, dtype=np.float64)
    m = np.asarray(mask, dtype=bool) & np.isfinite(v)
    n = v.size
    v = np.where(m, v, 0.0)
    if np.count_nonzero(m) < 8 or top_bin < 1:
        return np.zeros(n), []
    b = np.arange(1, top_bin + 1) if band_bins is None else np.asarray(band_bins)
    t = np.arange(n, dtype=np.float64)
    u = np.linspace(-1.0, 1.0, n)
    freqs: list = []
    r = v
    for _ in range(int(max_lines)):
        j = _strongest_line_above(r, m, top_bin, b, ratio, max_bin)
        if j is None:
            break
        f_new = float(minimize_scalar(lambda f: _joint_sines(v, m, t, u, freqs + [f])[0],
                                      bounds=((j - 1.0) / n, (j + 1.0) / n), method="bounded",
                                      options={"xatol": 1e-4 / n}).x)
        if any(abs(f_new - f) < 1.0 / n for f in freqs):   # a sidelobe of what is left of a line already fitted
            break
        freqs.append(f_new)
        r = np.where(m, v - _joint_sines(v, m, t, u, freqs)[1], 0.0)
    if not freqs:
        return np.zeros(n), []
    found = list(freqs)
    for _ in range(JOINT_REFINE_ROUNDS if len(freqs) > 1 else 0):
        for i, f0 in enumerate(found):            # within half a bin of where each was found: lines stay apart
            def cost(f, i=i):
                return _joint_sines(v, m, t, u, freqs[:i] + [f] + freqs[i + 1:])[0]
            freqs[i] = float(minimize_scalar(cost, bounds=(f0 - 0.5 / n, f0 + 0.5 / n), method="bounded",
                                             options={"xatol": 1e-4 / n}).x)
    return _joint_sines(v, m, t, u, freqs)[1], freqs


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


def _band_powers(increment, prior_freq, prior_psd, noise_std, taus, dt: float, highpass_hz: float,
                 cutoff_hz: float, fraction: float, model_psd=None):
    """What both :func:`conditioned_excess` and :func:`shrunk_excess` read, or None (too short a record or band):
    ``(f, band, v, power, prior, model, noise, expected)`` — the estimate ``v`` with the strong lines above the
    band fitted out, its smoothed tapered power, the MAP's prior, the prior with the knowledge's model
    error (:data:`KNOWLEDGE_MODEL_ERROR`), the fused noise, and the estimate's expected power as the periodogram
    reads it (:func:`estimate_power`, :func:`as_read`), per bin of ``rfftfreq(n, dt)``."""
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
    pf = np.asarray(prior_freq, dtype=np.float64)
    df = f[1] - f[0]
    prior = np.interp(f, pf, np.asarray(prior_psd, dtype=np.float64)) * 2 * df
    model = prior if model_psd is None else \
        prior + KNOWLEDGE_MODEL_ERROR ** 2 * np.interp(f, pf, np.asarray(model_psd, dtype=np.float64)) * 2 * df
    noise = fused_noise_per_bin(f, noise_std, taus, dt, n)
    # read within the band (beyond it lie the strong lines fitted out of ``v``); a bin whose expectation is
    # nothing next to the band's (the conditioned prior where the attitude is below its predicted error) holds
    # only what leaks from out of the band, and is not read (0)
    expected = np.zeros_like(f)
    expected[b] = as_read(estimate_power(prior, model, noise)[b])
    expected[expected < NOTHING_EXPECTED * float(np.median(expected[b]))] = 0.0
    return f, band, v, power, prior, model, noise, expected


#: the band change may hold at most this many times the power it is meant to take (the shrunk bins' (1 − w)² X)
CHANGE_GUARD = 4.0
#: a bin whose expected power is below this fraction of the band's median is not read (nothing is expected there)
NOTHING_EXPECTED = 1e-3
#: the expected Hann-tapered periodogram of a process is its power per bin convolved with this (the taper's
#: spectral window, normalised)
HANN_LEAKAGE = np.array([1.0, 4.0, 1.0]) / 6.0


def as_read(expected) -> np.ndarray:
    """The power per bin ``expected`` as the smoothed tapered periodogram reads it: through the Hann taper's
    leakage and the 3-bin running mean. A prior that drops to zero (the conditioned prior where the attitude is
    below its predicted error) is then not compared with what its neighbours leak into it.

    Examples
    --------
    >>> as_read([0.0, 0.0, 6.0, 0.0, 0.0, 0.0]).round(3).tolist()
    [0.333, 1.667, 2.0, 1.667, 0.333, 0.0]
    """
    e = np.nan_to_num(np.asarray(expected, dtype=np.float64), nan=0.0, posinf=0.0)
    leaked = np.convolve(np.pad(e, 1, mode="edge"), HANN_LEAKAGE, mode="valid")
    return uniform_filter1d(leaked, 3, mode="nearest")


def estimate_power(prior, truth_prior, noise) -> np.ndarray:
    """The expected power of the MAP's estimate with prior ``S`` of an attitude whose power is ``S'`` under
    noise ``N``: ``(S / (S + N))² (S' + N)`` (:func:`wiener_output_power` where ``S' = S``)."""
    sp = np.asarray(prior, dtype=np.float64)
    nn = np.asarray(noise, dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        g = np.where(sp + nn > 0, sp / (sp + nn), 0.0)
        return np.nan_to_num(g * g * (np.asarray(truth_prior, dtype=np.float64) + nn), nan=0.0, posinf=0.0)


def conditioned_excess(increment, prior_freq, prior_psd, noise_std, taus, dt: float, *, highpass_hz: float,
                       cutoff_hz: float, fraction: float = BAND_FRACTION, factor: float | None = None,
                       model_psd=None) -> ConditionedExcess | None:
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
    model_psd : ndarray, optional
        The attitude's PSD the conditioning read, on ``prior_freq``: the knowledge's model error
        (:data:`KNOWLEDGE_MODEL_ERROR` of it) may hold that much more than the prior.
    """
    got = _band_powers(increment, prior_freq, prior_psd, noise_std, taus, dt, highpass_hz, cutoff_hz, fraction,
                       model_psd)
    return None if got is None else _excess_of(got, factor)


def _excess_of(got, factor: float | None) -> ConditionedExcess | None:
    """The test of :func:`conditioned_excess` on what :func:`_band_powers` read (``got``); None when fewer than
    two bins of the band expect anything."""
    f, band, _, power, _, _, _, expected = got
    b = np.flatnonzero(band & (expected > 0))          # a bin no prior reaches says nothing
    if b.size < 2:
        return None
    ratio = power[b] / expected[b]
    over = ratio > (excess_factor(b.size) if factor is None else factor)
    excess = float(np.sum(np.maximum(power[b][over] - expected[b][over], 0.0)))
    return ConditionedExcess(band_hz=(float(f[b[0]]), float(f[b[-1]])), excess_hz=[float(v) for v in f[b][over]],
                             max_ratio=float(ratio.max()), excess_rms_rad=float(np.sqrt(excess)))


def record_conditioned_excess(record, cutoff_hz: float | None) -> ConditionedExcess | None:
    """:func:`conditioned_excess` of an axis's integration record; None unless its prior is conditioned on
    the knowledge (``knowledge_conditioned``) and the knowledge's cut-off is known."""
    if cutoff_hz is None or not getattr(record, "knowledge_conditioned", False) or record.spectrum is None:
        return None
    sp = record.spectrum
    return conditioned_excess(record.increment, sp.freq, sp.psd, sp.noise_std, record.taus,
                              float(record.line_period_s), highpass_hz=float(record.highpass_hz),
                              cutoff_hz=float(cutoff_hz), model_psd=getattr(record, "conditioned_attitude_psd", None))


def excess_gain(power, expected, *, factor: float = 1.0) -> np.ndarray:
    """Per bin, the gain that makes the MAP's estimate of power ``power`` a minimum-variance one where it holds
    more than ``factor`` × its expectation ``expected`` (:func:`estimate_power`): ``expected / power`` there, 1
    elsewhere (and where nothing is expected).

    The estimate is ``g = S / (S + N)`` × its input; an input of power ``T = X / g²`` above ``S' + N`` holds
    ``O = T − S' − N`` that is neither the attitude nor the modelled noise, and the minimum-variance gain with
    ``O`` counted as noise, ``S' / T``, is the estimate's own times ``S' / (g T) = E[X] / X`` (``S'`` the
    attitude's power, ``E[X] = g² (S' + N)`` at the MAP's ``S = S'``; with ``S' > S`` the excess test already
    allows for it).

    Examples
    --------
    >>> excess_gain([0.5, 2.0, 0.1, 1.0], [1.0, 0.5, 1.0, 0.0]).tolist()
    [1.0, 0.25, 1.0, 1.0]
    """
    x = np.asarray(power, dtype=np.float64)
    e = np.asarray(expected, dtype=np.float64)
    over = (x > factor * e) & (e > 0) & (x > 0)
    return np.where(over, np.clip(e / np.where(over, x, 1.0), 0.0, 1.0), 1.0)


def _added_error(power, expected, prior, truth_prior, noise, gain) -> np.ndarray:
    """Per bin, what the offset ``O`` adds to the draws' error ``S' N / (S' + N)`` once the estimate is shrunk by
    ``w = gain``: ``(1 − w g)² S' + w² g² (O + N)`` less that, ``g = S / (S + N)`` the MAP's gain and
    ``O = (X / E[X] − 1)(S' + N)`` the input's power beyond its expectation (:func:`excess_gain`); 0 where not
    shrunk."""
    sp = np.asarray(prior, dtype=np.float64)
    st = np.asarray(truth_prior, dtype=np.float64)
    nn = np.asarray(noise, dtype=np.float64)
    w = np.asarray(gain, dtype=np.float64)
    shrunk = (w < 1.0) & (sp > 0)
    offset = input_offset(power, expected, truth_prior, noise)
    with np.errstate(divide="ignore", invalid="ignore"):
        g = sp / (sp + nn)
        after = (1.0 - w * g) ** 2 * st + (w * g) ** 2 * (offset + nn)
        before = st * nn / (st + nn)
    return np.where(shrunk, np.maximum(np.nan_to_num(after - before, nan=0.0, posinf=0.0), 0.0), 0.0)


def input_offset(power, expected, truth_prior, noise) -> np.ndarray:
    """Per bin, the differentials' power beyond the attitude's and the noise's, seen as an attitude:
    ``(X / E[X] − 1)(S' + N)``, at least 0 (0 where nothing is expected)."""
    x = np.asarray(power, dtype=np.float64)
    e = np.asarray(expected, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        o = (x / np.where(e > 0, e, 1.0) - 1.0) * (np.asarray(truth_prior, dtype=np.float64) + noise)
    return np.where(e > 0, np.maximum(np.nan_to_num(o, nan=0.0, posinf=0.0), 0.0), 0.0)


@dataclass(frozen=True)
class ExcessShrink:
    """What :func:`shrunk_excess` did to one axis's estimate.

    Attributes
    ----------
    increment : ndarray (lines,)
        The estimate, its band shrunk where it held an excess [rad] (NaN where not estimated).
    excess : ConditionedExcess
        The excess found (before the shrink), its ``shrink_error_rad`` set.
    gain : ndarray
        The gain per bin of ``rfftfreq(lines, Δt)`` (1 outside the shrunk bins).
    """

    increment: np.ndarray
    excess: ConditionedExcess
    gain: np.ndarray

    @property
    def shrunk(self) -> bool:
        """Whether any bin was shrunk."""
        return bool(np.any(self.gain < 1.0))


def _band_change(v, mask, gain, freq, dt: float) -> np.ndarray:
    """What ``gain`` (< 1 on a few bins of ``freq = rfftfreq(n, dt)``) changes in ``v`` (n,): the sines at those
    bins fitted jointly by least squares on ``mask`` with a quadratic trend, each taken down by ``1 − gain``.

    Not an FFT of the record: its slow trend (a fraction of a pixel) spreads over the first bins of any
    extension of the record, and its content up to hundreds of hertz leaks from a mirror's kink; a shrink of
    the 0.6 Hz bin moved a whole restored axis by 0.08 px that way. A strong line near the shrunk bins leaks
    into this fit at the rectangular window's full sidelobes, which the tapered periodogram that found the
    excess does not see: :func:`shrunk_excess` keeps the estimate where the change exceeds what it was meant
    to take (:data:`CHANGE_GUARD`; geo_noisy_knowledge's pitch would have moved by 0.32 px). Fitting every bin
    up to past the shrunk ones instead moved what the shrunk bins hold (low_frequencies 777's pitch 0.099 →
    0.117 px)."""
    n = v.size
    m = np.asarray(mask, dtype=bool)
    at = np.flatnonzero(np.asarray(gain) < 1.0)
    t = np.arange(n) * dt
    u = np.linspace(-1.0, 1.0, n)
    trend = np.stack([np.ones(n), u, u * u], axis=1)
    sines = np.stack([fn(2 * np.pi * freq[j] * t) for j in at for fn in (np.cos, np.sin)], axis=1)
    # the sines less their quadratic trend (what the tapered periodogram read, and what no pair sees): a sine of
    # one cycle per record is close to a quadratic, and fitted beside it its coefficient would swing both
    q, _ = np.linalg.qr(trend[m])
    perp = sines - trend @ np.linalg.lstsq(trend[m], sines[m], rcond=None)[0]
    vm = v[m] - q @ (q.T @ v[m])
    coef, *_ = np.linalg.lstsq(perp[m], vm, rcond=None)
    down = np.repeat(1.0 - np.asarray(gain)[at], 2)
    return -(perp * (coef * down)).sum(axis=1)


def shrunk_excess(increment, prior_freq, prior_psd, noise_std, taus, dt: float, *, highpass_hz: float,
                  cutoff_hz: float, fraction: float = BAND_FRACTION, factor: float | None = None,
                  model_psd=None, top_hz: float | None = None) -> ExcessShrink | None:
    """The estimate with its band's excess over the Wiener output shrunk (:func:`excess_gain`), the strong
    lines above the band fitted out first and kept whole; None where :func:`conditioned_excess` is None.
    The excess returned holds the offset's Wiener error in the shrunk bins (``shrink_error_rad``) and, with
    ``top_hz`` (the top of :func:`restore.observability.scene_offset_band`), the error the same offset brings
    above the band up to there (``above_error_rad``, :func:`offset_error_above`): what σ must hold beyond the
    draws. Parameters as :func:`conditioned_excess`."""
    got = _band_powers(increment, prior_freq, prior_psd, noise_std, taus, dt, highpass_hz, cutoff_hz, fraction,
                       model_psd)
    ex = None if got is None else _excess_of(got, factor)
    if ex is None:
        return None
    f, band, v, power, prior, model, noise, expected = got
    # the test is the band's (family-wise); once it fires, every bin above its expectation is shrunk by the
    # plug-in Wiener gain: the offset is broad, and a bin of it below the threshold keeps it otherwise
    gain = np.where(band, excess_gain(power, expected, factor=SHRINK_FROM), 1.0) if ex.excess_hz \
        else np.ones_like(f)
    x = np.asarray(increment, dtype=np.float64)
    if np.all(gain == 1.0):
        return ExcessShrink(x, replace(ex, shrink_error_rad=0.0, above_error_rad=0.0), gain)
    ok = np.isfinite(x)
    change = _band_change(v, ok, gain, f, dt)
    # what the shrink may take at most: the shrunk bins' own power, (1 − w)² X; a change far beyond it is a fit
    # gone wrong (leakage the taper did not see), and the estimate is kept as it is
    allowed = float(np.sum((1.0 - gain) ** 2 * power))
    if np.mean(change[ok] ** 2) > CHANGE_GUARD * allowed:     # not shrunk, nothing booked: the excess reported
        return ExcessShrink(x, ex, np.ones_like(f))
    new = np.where(ok, x + change, np.nan)
    added = float(np.sqrt(np.sum(_added_error(power, expected, prior, model, noise, gain))))
    fired = np.isin(f, ex.excess_hz)
    offset = np.where(fired, input_offset(power, expected, model, noise), 0.0)
    above = offset_error_above(offset, f, fired, prior, noise, float(f[band].max()), top_hz) \
        if top_hz is not None else 0.0
    return ExcessShrink(new, replace(ex, shrink_error_rad=added, above_error_rad=float(np.sqrt(above))), gain)


#: the scene's band offset in the differentials falls as ``1 / f`` in power above the bins it was measured in
#: (:func:`offset_error_above`): taken flat, the error booked above a 2 Hz knowledge was 0.6-1.9 × the whole
#: error found there (unseen low_frequencies scenes, whose draws' part is in it too), with this slope 0.4-1.2 ×
OFFSET_SLOPE = 1.0


def offset_error_above(offset, freq, fired, prior, noise, band_top_hz: float, top_hz: float,
                       slope: float = OFFSET_SLOPE) -> float:
    """The error [rad², a mean square] an attitude-like offset measured in the bins ``fired`` brings above the
    band (``band_top_hz``) up to ``top_hz``, where the images restore alone and nothing tells it from the
    attitude. A band offset proportional to the bands' places, following the scene's content, gives pair ``j``
    ``τ_j`` times a slow signal: an attitude's differential ``2π f τ_j θ`` below ``1 / (2π τ)``. That signal's
    power falls as ``1 / f^slope`` (the scene's content: :data:`OFFSET_SLOPE`), so in the attitude
    ``O(f) = c / f^(2 + slope)``, ``c`` the mean of ``O f^(2 + slope)`` over ``fired``; per bin, the Wiener
    error with ``O`` counted as noise less the draws' own, ``S (O + N) / (S + O + N) − S N / (S + N)``.
    Measured on unseen low-bandwidth scenes (restored at the commit that set the slope; booked against the
    error found at 1.3–6.8 Hz, which holds the draws' part too): seed 777 pitch 0.073 → 0.047 px against
    0.042, roll (by the sun's split) 0.042 → 0.027 against 0.022; seed 1234 pitch 0.031 → 0.020 against 0.036,
    roll 0.019 → 0.013 against 0.030; σ's actual / predicted, roll / pitch, 0.63 / 0.65 → 0.82 / 0.88 and
    0.77 / 0.82 → 0.80 / 0.89.

    Examples
    --------
    >>> f = np.arange(8.0)
    >>> o = np.where((f >= 1) & (f <= 2), 4.0 / np.maximum(f, 1) ** 2, 0.0)          # flat: c = 4
    >>> round(offset_error_above(o, f, o > 0, np.full(8, 1e9), np.zeros(8), 2.0, 4.0, slope=0.0), 4)  # 4/9 + 4/16
    0.6944
    >>> o = np.where((f >= 1) & (f <= 2), 4.0 / np.maximum(f, 1) ** 3, 0.0)          # 1 / f: c = 4
    >>> round(offset_error_above(o, f, o > 0, np.full(8, 1e9), np.zeros(8), 2.0, 4.0), 4)             # 4/27 + 4/64
    0.2106
    """
    f = np.asarray(freq, dtype=np.float64)
    b = np.asarray(fired, dtype=bool) & (f > 0)
    if not b.any():
        return 0.0
    k = 2.0 + float(slope)
    c = float(np.mean(np.asarray(offset, dtype=np.float64)[b] * f[b] ** k))
    above = (f > band_top_hz) & (f <= top_hz)
    sp = np.asarray(prior, dtype=np.float64)[above]
    nn = np.asarray(noise, dtype=np.float64)[above]
    oo = c / f[above] ** k
    with np.errstate(divide="ignore", invalid="ignore"):
        after = np.where(sp + oo + nn > 0, sp * (oo + nn) / (sp + oo + nn), 0.0)
        before = np.where(sp + nn > 0, sp * nn / (sp + nn), 0.0)
    return float(np.sum(np.maximum(np.nan_to_num(after - before, nan=0.0, posinf=0.0), 0.0)))


def offset_shared_by_sun(above: dict, shares: dict) -> dict:
    """Per axis, the error [rad] the scene's band offset measured on another axis brings above the knowledge's
    band to this one: ``e_a √(s_b / s_a)`` from each axis ``a`` whose offset was shrunk and booked (``above``:
    its :func:`offset_error_above`, in amplitude) onto each other axis ``b`` of ``shares``
    (:func:`restore.observability.sun_offset_shares`, power shares of an offset towards the sun), the largest;
    only from an axis with at least ``b``'s share, so that no estimate is scaled up. 0 where nothing is shared.

    The offset is one displacement of the bands towards the sun, split between the axes as ``cos²`` and
    ``sin²`` of its angle to the track; the axis along the sun shows it first and most (low_frequencies 31,
    150° from the track: pitch's band 8.2 × what its prior allows and shrunk, roll's 1.8 ×, under the test,
    while roll's error was 1.71 × its σ above the band).

    Examples
    --------
    >>> got = offset_shared_by_sun({"pitch": 3.0}, {"roll": 0.25, "pitch": 0.75})
    >>> round(got["roll"], 4), got["pitch"]
    (1.7321, 0.0)
    >>> offset_shared_by_sun({"roll": 1.0}, {"roll": 0.25, "pitch": 0.75})
    {'roll': 0.0, 'pitch': 0.0}
    """
    out = {}
    for b, sb in shares.items():
        best = 0.0
        for a, e in above.items():
            sa = float(shares.get(a, 0.0))
            if a != b and e is not None and e > 0 and sa > 0 and sa >= sb:
                best = max(best, float(e) * float(np.sqrt(sb / sa)))
        out[b] = best
    return out
