"""Local fusion with the AOCS knowledge at low frequencies, where the images' estimate has gone astray.

Between the restoration's high-pass ``f_hp`` and the knowledge's flat part
(``0.7 ×`` its cut-off), two estimates of the attitude exist: the images'
(the integrated differentials) and the AOCS knowledge, whose error there is
its own white noise, known from product.nc. The images' error at those
frequencies is the matching errors every pair shares in the proportion of its
delay: band-to-band offsets that follow the scene's content (shading towards
the sun, a field border, a cloud's rim), which three bands in three pairs
cannot separate from an attitude and the fit residual does not show. In the
interior of a record the prior holds them; near a record end or a gap edge,
where only one side constrains the estimate, they integrate into a drift (an
unseen scene with 25 % cloud and the sun across the track: 0.27 px of roll
over the last 100 lines, from differential errors of −0.08 to −0.15 px over
the 400 lines before; the predicted σ there 0.027 px).

The restoration's estimate ``ê`` (the correction above the high-pass, the
knowledge ``k`` beneath) holds in that band ``L(ê) = L(θ − k) + L(e_I)``:
the knowledge's error through the band and the images' error. The
knowledge's error ``θ − k`` is exactly what the restoration estimates above
its high-pass: its variance in the band ``v_k`` is the larger of its white
noise's (from its noise and rate, known: :func:`knowledge_band_variance`) and
the error PSD the caller gives (which holds, besides that noise, what the
AOCS filter leaves out of the attitude: lines at 3-8 Hz above a 2 Hz
knowledge, a causal filter's lag in its own band; the pipeline gives the
ceiling the knowledge's own periodogram and filter put on it where the filter
passes half the attitude, the restoration's prior beyond:
:func:`restore.stages.knowledge_error_prior`). Near the record's ends and gaps the band's filter sees one side
only and passes more of a strong attitude: ``v_k`` is taken per line, as the
mean over :data:`FUSION_DRAWS` stationary draws of that error, high-passed,
masked and filtered as the estimate is (:func:`expected_band_power`). The
estimate's local mean square ``P`` over :data:`FUSION_WINDOW_S` therefore
estimates ``v_k`` plus the images' local error power; where ``P`` exceeds
``v_k`` by :data:`FUSION_THRESHOLD` (with
about one degree of freedom per window the target's own content gets there in
~0.2 % of the windows), the images' band error is ``P − v_k`` and the
minimum-variance combination of the two estimates takes the knowledge's band
with the weight ``w = 1 − v_k / P``:

    ê′ = ê − w L(ê),      error variance in the band  w v_k

(the images' ``(1 − w)² (P − v_k)`` plus the knowledge's ``w² v_k``). Where
nothing is in excess nothing changes (``w = 0``): a restoration that holds
its band keeps it, bit for bit. The weight comes in gradually between half
the threshold and the threshold (:func:`fusion_weight`), so that a line at
the threshold does not put a step into the restored angle.

**The lines above the band are kept whole.** Above a knowledge of a few hertz
the estimate holds the attitude the knowledge's filter misses — lines of a
pixel at 3-8 Hz under a 2 Hz knowledge — and a Gaussian band filter passes a
share of them (15 % of a 3.3 Hz line under a 1.4 Hz top, more near an end,
where it sees one side only). Taken for the knowledge's error that share made
``v_k`` 0.12-0.5 px and blinded the test; taken out with the band, it would
remove part of the lines. So the strong lines above the band are fitted first,
jointly (:func:`restore.conditioned_excess.strong_lines_above`), the test and
the fusion read the band of the estimate without them, and above the band the
knowledge's error PSD is the smaller of the prior and what the estimate holds
there without its lines (:func:`continuum_prior`): the continuum, which is
what leaks into the band; lines are fitted up to :data:`LINES_UP_TO` × the
band's top. Measured (unseen low_frequencies scenes under a 2 Hz knowledge,
outside the unobservable part, fe4ecb3 → 1209b24): seed 777 roll / pitch
0.036 / 0.092 → 0.033 / 0.053 px, seed 1234 0.039 / 0.072 → 0.039 / 0.059,
seed 2027 0.064 / 0.065 → 0.036 / 0.028.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import uniform_filter1d

from .conditioned_excess import strong_lines_above
from .knowledge_check import tapered_power
from .knowledge_prior import knowledge_noise_floor
from .synthesis import highpass_gain, highpass_nan

__all__ = ["FUSION_THRESHOLD", "FUSION_WINDOW_S", "FUSION_HIGH_FRACTION", "LINES_UP_TO", "KnowledgeFusion", "band_part",
           "band_gain", "knowledge_error_psd", "continuum_prior", "knowledge_band_variance", "expected_band_power", "local_mean_square", "fusion_weight", "fuse_with_knowledge"]

#: a window's band power must exceed the knowledge's own by this factor before the knowledge takes over
FUSION_THRESHOLD = 10.0
#: the running window of the local band power [s] (250 lines at 0.4 ms: an end's drift spans 100-300 lines)
FUSION_WINDOW_S = 0.1
#: draws of the knowledge's error that give its expected band power per line
FUSION_DRAWS = 32
#: the band's top: this fraction of the knowledge's cut-off (the filter's flat part, as the knowledge check)
FUSION_HIGH_FRACTION = 0.7
#: strong lines are fitted out, and the prior read as the continuum, up to this many times the band's top only:
#: beyond, the band's Gaussian filter passes nothing of a line inside the record (2^-18), and near an end what it
#: passes is the prior's share, which a line's fit would trade for its misfit (CMG lines of 4-12 px at 45-120 Hz
#: with 5 % amplitude noise: taken out, the misfit at the record's start was fused, large_amplitude's roll
#: 0.018 → 0.024 px, 99.7 % 0.058 → 0.158)
LINES_UP_TO = 6.0


@dataclass
class KnowledgeFusion:
    """What the fusion did on one axis."""

    #: weight of the knowledge's band per line (0: the images' estimate kept)
    weight: np.ndarray
    #: the band's top [Hz] and the knowledge's error variance in the band per line [rad²]
    band_top_hz: float
    knowledge_band_rad2: np.ndarray
    #: error variance added per line where the knowledge took part (``w v_k``) [rad²]
    added_rad2: np.ndarray
    #: the strong lines above the band kept whole, their frequencies [Hz]
    lines_kept_hz: tuple = ()

    @property
    def lines_fused(self) -> int:
        return int(np.count_nonzero(self.weight > 0))


def band_part(estimate, *, dt: float, top_hz: float) -> np.ndarray:
    """The content of ``estimate`` below ``top_hz`` (Gaussian low-pass, NaN-aware; NaN kept)."""
    x = np.asarray(estimate, dtype=np.float64)
    return x - highpass_nan(x, dt=dt, cutoff_hz=top_hz)


def band_gain(freq, *, highpass_hz: float, top_hz: float) -> np.ndarray:
    """Gain of the band: the restoration's high-pass at ``highpass_hz`` times the band's low-pass at ``top_hz``."""
    f = np.asarray(freq, dtype=np.float64)
    return highpass_gain(f, highpass_hz) * (1.0 - highpass_gain(f, top_hz))


def knowledge_error_psd(freq, *, noise_rad: float, rate_hz: float, prior=None) -> np.ndarray:
    """Two-sided PSD [rad²/Hz] of the knowledge's error at ``freq``: its white noise floor
    (:func:`restore.knowledge_prior.knowledge_noise_floor`), or the restoration's prior ``(freq, two-sided PSD)``
    where that holds more."""
    f = np.asarray(freq, dtype=np.float64)
    psd = knowledge_noise_floor(f, rate_hz=rate_hz, noise_rad=noise_rad)
    if prior is not None:
        pf, pp = (np.asarray(x, dtype=np.float64) for x in prior)
        psd = np.maximum(psd, np.interp(f, pf, pp, right=0.0))
    return psd


def knowledge_band_variance(*, noise_rad: float, rate_hz: float, dt: float, highpass_hz: float, top_hz: float,
                            prior=None) -> float:
    """Variance [rad²] of the knowledge's error (:func:`knowledge_error_psd`) through the band (:func:`band_gain`),
    away from the record's ends: the level :func:`expected_band_power` finds in the interior."""
    f = np.linspace(0.0, 0.5 / dt, 65537)
    g2 = band_gain(f, highpass_hz=highpass_hz, top_hz=top_hz) ** 2
    psd = knowledge_error_psd(f, noise_rad=noise_rad, rate_hz=rate_hz, prior=prior)
    return float(np.trapezoid(2.0 * psd * g2, f))


def expected_band_power(mask, *, dt: float, highpass_hz: float, top_hz: float, window_lines: int, noise_rad: float,
                        rate_hz: float, prior=None, draws: int = FUSION_DRAWS, seed: int = 0) -> np.ndarray:
    """Per line, the mean over ``draws`` of :func:`local_mean_square` of :func:`band_part` of a stationary draw of
    the knowledge's error (two-sided PSD: the larger of its white noise floor and ``prior``), high-passed at
    ``highpass_hz`` and missing where ``mask`` is False, as the estimate is [rad²]."""
    from scipy.fft import irfft, next_fast_len

    ok = np.asarray(mask, dtype=bool)
    n = ok.size
    m = next_fast_len(2 * n)
    f = np.fft.rfftfreq(m, dt)
    psd = knowledge_error_psd(f, noise_rad=noise_rad, rate_hz=rate_hz, prior=prior)
    one_sided = 2.0 * psd * highpass_gain(f, highpass_hz) ** 2
    amp = m * np.sqrt(one_sided * (f[1] - f[0]) / 4.0)
    amp[0] = 0.0
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x4B46]))
    acc = np.zeros(n)
    for _ in range(int(draws)):
        z = amp * (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size))
        x = np.where(ok, irfft(z, m)[:n], np.nan)
        acc += np.nan_to_num(local_mean_square(band_part(x, dt=dt, top_hz=top_hz), window_lines))
    return acc / int(draws)


def local_mean_square(x, window_lines: int) -> np.ndarray:
    """Running mean of ``x²`` over ``window_lines`` (NaN lines skipped; NaN where the window holds none)."""
    x = np.asarray(x, dtype=np.float64)
    ok = np.isfinite(x)
    num = uniform_filter1d(np.where(ok, x * x, 0.0), int(window_lines), mode="nearest")
    den = uniform_filter1d(ok.astype(np.float64), int(window_lines), mode="nearest")
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, num / den, np.nan)


def fusion_weight(power, knowledge_var, *, threshold: float = FUSION_THRESHOLD) -> np.ndarray:
    """The minimum-variance share ``1 − v_k / P`` where ``P > threshold · v_k``, brought in linearly from
    ``P = threshold / 2 · v_k`` (0) to the threshold, so that the weight has no step (``v_k`` a scalar or per
    line; 0 where ``P`` is not finite or ``v_k`` not positive).

    Examples
    --------
    >>> [round(w, 3) for w in fusion_weight([1.0, 5.0, 7.5, 10.0, 20.0], 1.0).tolist()]
    [0.0, 0.0, 0.433, 0.9, 0.95]
    """
    p = np.asarray(power, dtype=np.float64)
    v = np.broadcast_to(np.asarray(knowledge_var, dtype=np.float64), p.shape)
    ok = np.isfinite(p) & (v > 0) & (p > 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        r = np.where(ok, p / np.where(v > 0, v, 1.0), 0.0)
        ramp = np.clip((r - 0.5 * threshold) / (0.5 * threshold), 0.0, 1.0)
        return np.where(ok & (ramp > 0), ramp * (1.0 - 1.0 / np.where(r > 0, r, 1.0)), 0.0)


def continuum_prior(prior, residual, mask, *, dt: float, top_hz: float, up_to_hz: float = np.inf):
    """``prior`` (freq, two-sided PSD) with, above ``top_hz`` and up to ``up_to_hz``, the smaller of it and the
    two-sided PSD of ``residual`` on the lines ``mask`` (tapered as :func:`restore.knowledge_check.tapered_power`,
    three bins averaged): the estimate without its strong lines is all the knowledge's error can hold there
    besides them."""
    if prior is None:
        return None
    pf, pp = (np.asarray(v, dtype=np.float64) for v in prior)
    m = np.asarray(mask, dtype=bool) & np.isfinite(residual)
    n = m.size
    if np.count_nonzero(m) < 8:
        return pf, pp
    power = uniform_filter1d(tapered_power(np.where(m, residual, 0.0), m), 3, mode="nearest")
    # tapered_power: |X|² / n² per bin (one-sided power, mean over the taper): as a two-sided PSD, × n Δt / 2
    psd = power * n * dt / 2.0
    fx = np.fft.rfftfreq(n, dt)
    return pf, np.where((pf > top_hz) & (pf <= up_to_hz), np.minimum(pp, np.interp(pf, fx, psd)), pp)


def fuse_with_knowledge(estimate, *, dt: float, highpass_hz: float, cutoff_hz: float, noise_rad: float,
                        rate_hz: float, prior=None, threshold: float = FUSION_THRESHOLD,
                        window_s: float = FUSION_WINDOW_S, seed: int = 0) -> tuple[np.ndarray, KnowledgeFusion | None]:
    """The images' estimate with the knowledge's band taken where the estimate's band power proves it astray.

    Parameters
    ----------
    estimate : ndarray (lines,)
        The restoration's correction above its high-pass [rad] (NaN: not restored).
    dt : float
        Line period [s].
    highpass_hz : float
        The restoration's high-pass on this axis (the knowledge answers below it).
    cutoff_hz, noise_rad, rate_hz : float
        The AOCS knowledge as product.nc records it: filter cut-off, white noise per sample, sample rate.
    prior : (freq, psd), optional
        The restoration's prior on this axis [Hz, two-sided rad²/Hz] (:func:`knowledge_band_variance`).
    threshold, window_s
        :data:`FUSION_THRESHOLD`, :data:`FUSION_WINDOW_S`.
    seed : int
        Seed of the draws of :func:`expected_band_power`.

    Returns
    -------
    (ndarray, KnowledgeFusion or None)
        The estimate (unchanged where ``w = 0``), and what was done; None (estimate unchanged) when there is
        no band (``0.7 × cutoff_hz`` not above ``1.25 ×`` the high-pass) or the knowledge has no noise model.
    """
    x = np.asarray(estimate, dtype=np.float64)
    top = FUSION_HIGH_FRACTION * float(cutoff_hz)
    if not (highpass_hz > 0 and top > 1.25 * highpass_hz and noise_rad > 0 and rate_hz > 0) \
            or not np.isfinite(x).any():
        return x, None
    ok = np.isfinite(x)
    window = max(int(round(window_s / dt)), 3)
    lines, freqs = strong_lines_above(x, ok, int(np.floor(top * x.size * dt)),
                                      max_bin=int(np.floor(LINES_UP_TO * top * x.size * dt)))
    rest = np.where(ok, x - lines, np.nan)
    v_k = expected_band_power(ok, dt=dt, highpass_hz=highpass_hz, top_hz=top, window_lines=window,
                              noise_rad=noise_rad, rate_hz=rate_hz,
                              prior=continuum_prior(prior, rest, ok, dt=dt, top_hz=top,
                                                    up_to_hz=LINES_UP_TO * top), seed=seed)
    band = band_part(rest, dt=dt, top_hz=top)
    w = fusion_weight(local_mean_square(band, window), v_k, threshold=threshold)
    w = np.where(ok, w, 0.0)
    out = np.where(w > 0, x - w * np.nan_to_num(band), x)
    return out, KnowledgeFusion(weight=w, band_top_hz=top, knowledge_band_rad2=v_k, added_rad2=w * v_k,
                                lines_kept_hz=tuple(float(f) / dt for f in freqs))
