"""Predicted 1-σ of the restored attitude, line by line, from the integration's own error model.

The restoration models each axis as a Gaussian stationary attitude of PSD
``S(f)`` (the prior the integration estimated from the differentials) seen by
pair ``j`` through ``θ(t + τ_j + λ_j(t)) − θ(t)`` plus independent noise of
σ_j(t) per line (the pair's noise level scaled by its per-line weight). The
error the integration makes under that model is measured by Monte Carlo
*through the integration itself* (perturbation sampling, "sample then
optimise"):

1. draw an attitude ``θ_s`` from the prior and noise ``b_s`` from the noise
   model;
2. form the differentials the pairs would have measured, with the record's
   gaps, per-line lags and weights;
3. integrate them with the frozen filter the restoration applied
   (:meth:`~restore.result.IntegrationRecord.rerun`; the least-squares
   first estimate that only corrects the per-line lags keeps its default
   curvature weight instead of a cross-validated one: 5× cheaper, and the
   lag correction it feeds is a few % of the delay);
4. the error ``θ̂_s − hp(θ_s)`` (``hp``: the restoration's high-pass, since below
   it the AOCS knowledge answers) is a draw of the estimation error.

For the exact Wiener / MAP integration the spread of those errors is the
posterior covariance (the Kalman/RTS variance of the same model); for any
other method it is that method's error under the model. Gaps, record ends,
short clear islands between clouds and per-line weights all show: no
stationarity is assumed.

The noise level is then checked against the data, frequency band by band:
the residual of the real differentials about the fit, ``d_j − (θ̂(t + τ_j) −
θ̂(t))``, is compared with the same residual on the simulated draws in
log-spaced bands. Matching errors that are larger or more correlated than the
white model (windows sharing rows, texture-dependent biases: 3-4× the white
level in power at 1-5 Hz on phr_cmg, where the integration amplifies noise
most) leave a larger residual in those bands; the draws are made again with
the noise's power scaled there by the ratio, as measured
(:func:`noise_colour_estimate`: unbiased, so a modest excess the record shows
counts too), so the prediction inherits neither an optimistic level nor an
optimistic colour. Which bands exceed the model significantly
(:func:`noise_colour_from_check`) is reported apart: decisions such as the
knowledge crossover take only those.

The pairs' noises are not independent: pair ``A/B`` compares band B's line
with band A's, so a band's own matching error (its image noise, its texture
through its own spectrum) enters every pair that uses the band. What the
bands' errors have in common moves all of them like an attitude would and
passes into the restored angle, unseen by the residual. The share of each
pair's noise that is a shared band's is measured from the real residuals
(:func:`shared_band_noise`) and the draws give each band one draw of it
(:func:`correlated_noise`).

Below the high-pass, the AOCS knowledge's own noise (recorded in the product)
adds ``σ_k² · 2 f_hp / f_k`` (white noise at the knowledge rate ``f_k``), or
what its smoothing leaves of it. Above it, the attitude error the integration
restores, ``θ − k``, holds that noise too whatever the attitude does: the
draws take it from the prior raised to the knowledge's white noise
(:func:`draw_psd`), so that where the estimated prior fell below it (nothing
seen there beyond the differentials' noise) the noise the filter leaves in the
restored angle is predicted rather than counted as zero.

A second prediction needs no model of the noise: the local part of the
matching error is measured by fitting the differentials again from two
interleaved halves of the swath (:mod:`restore.local_noise`), and that series,
with random phases common to the pairs (its spectra and cross-spectra kept),
is the noise of the draws (:func:`local_error_sigma`). It holds what moves
like an attitude, which the residual cannot show, but not an error every
point of a line shares, which the residual partly shows: the pipeline keeps,
line by line, the larger of the two (:func:`larger_sigma`).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from scipy.fft import irfft, next_fast_len, rfft
from scipy.interpolate import CubicSpline
from scipy.ndimage import uniform_filter1d

from .knowledge_check import tapered_power
from .knowledge_prior import knowledge_noise_floor
from .synthesis import highpass_gain, highpass_nan

__all__ = ["PosteriorSigma", "posterior_sigma", "noise_per_line", "prior_draw", "simulated_differentials",
           "fit_residual_rms", "fit_residuals", "band_power", "noise_colour_from_check", "noise_colour_estimate",
           "coloured_noise", "draw_differentials",
           "knowledge_noise_below", "draw_psd", "pair_bands", "SharedBandNoise", "shared_band_noise",
           "correlated_noise",
           "detrended", "detrended_rms", "detrended_rms_over", "local_error_sigma", "larger_sigma",
           "mean_error_power", "knowledge_error_moments", "KnowledgeErrorMoments", "detrended_rows", "knowledge_sample_times",
           "knowledge_noise_below_rows",
           "KNOWLEDGE_DRAWS"]


#: the real fit residual may exceed the simulated one by this factor before the noise is inflated
NOISE_CHECK_TOLERANCE = 1.05


@dataclass
class PosteriorSigma:
    """Result of :func:`posterior_sigma` for one axis.

    Attributes
    ----------
    sigma : ndarray (lines,)
        Predicted 1-σ of the restored angle [rad], NaN where not restored.
    noise_scale : float
        RMS of the significant factors of ``noise_colour`` (≥ 1; 1: the check found the model right).
    samples : int
        Monte Carlo draws.
    noise_colour : ndarray (pair, lines // 2 + 1) or None
        The factor on each pair's noise power, per frequency of
        ``rfftfreq(lines, Δt)``, where the band-by-band check found a
        significant excess (1 elsewhere); None without the check. The draws
        use the unbiased estimate of the same ratio.
    detrended_rms : float
        RMS of the draws' errors once each draw's least-squares line over the
        record is removed [rad]: the predicted error outside the record's
        trend, which no pair can see (:func:`restore.observability.record_trend`), over every line the draws
        reach.
        NaN when not computed.
    """

    sigma: np.ndarray
    noise_scale: float
    samples: int
    noise_colour: np.ndarray | None = None
    detrended_rms: float = float("nan")
    #: per line, the 1-σ of the draws' errors without their trend [rad] (NaN where not restored), so that the
    #: detrended RMS can be taken over the lines finally restored (:func:`detrended_rms_over`)
    detrended_sigma: np.ndarray | None = None
    #: per band two pairs share: the share of its pairs' noise power that is the band's own matching error
    #: (mean over the pairs that see it and over frequency; :func:`shared_band_noise`); empty when none
    band_shares: dict = field(default_factory=dict)
    #: the ratio of real to simulated fit-residual power the draws use (:func:`noise_colour_estimate`), per pair
    #: and frequency of ``rfftfreq(lines, Δt)``; None without the check
    colour_estimate: np.ndarray | None = None
    #: the predicted RMS without the record's trend with the measured local matching error as the noise
    #: (:func:`local_error_sigma`) when it was computed and kept where larger (:func:`larger_sigma`); NaN otherwise
    local_detrended_rms: float = float("nan")
    #: the model's σ per line before :func:`larger_sigma` raised it (None when not raised)
    model_sigma: np.ndarray | None = None
    #: mean periodogram of the draws' errors per bin of ``rfftfreq(lines)`` [rad², summing to about their mean
    #: square with the lines not restored as zeros; trend removed, Hann taper] (:func:`mean_error_power`); None
    #: when not kept
    error_power: np.ndarray | None = None


def detrended(errors: np.ndarray) -> np.ndarray:
    """Error draws (draw, line) less each draw's least-squares line (offset + slope) over its finite lines;
    a draw with fewer than 3 finite lines is NaN."""
    from .observability import record_trend

    e = np.atleast_2d(np.asarray(errors, dtype=np.float64))
    return np.array([row - record_trend(row) if np.isfinite(row).sum() >= 3 else np.full(row.shape, np.nan)
                     for row in e])


def detrended_rms(errors: np.ndarray) -> float:
    """RMS of error draws (draw, line) once each draw's least-squares line (offset + slope) is removed.

    NaN lines are left out of each draw's fit and of the mean; NaN when no draw
    has 3 finite lines.
    """
    d = detrended(errors)
    return float(np.sqrt(np.nanmean(d ** 2))) if np.isfinite(d).any() else float("nan")


def detrended_rms_over(ps: PosteriorSigma, restored: np.ndarray) -> float:
    """The predicted RMS error without the record's trend over the lines ``restored`` holds (finite), i.e.
    without the flagged ones; the all-line figure when the per-line one is missing."""
    if ps.detrended_sigma is None:
        return float(ps.detrended_rms)
    ok = np.isfinite(np.asarray(restored, dtype=np.float64)) & np.isfinite(ps.detrended_sigma)
    return float(np.sqrt(np.mean(ps.detrended_sigma[ok] ** 2))) if ok.any() else float("nan")


def noise_per_line(record) -> np.ndarray:
    """Noise σ of each pair's differential at each line [rad], NaN at gaps (pair, line).

    The integration's own model: the pair's noise level (from the prior it
    estimated) over the square root of the line's relative weight (mean 1 over
    the valid lines); a line of weight 0 (filled, ignored by the integration)
    gets the pair's level. A method that reports no noise level falls back on
    the per-line formal σ of the synthesis.
    """
    d = np.asarray(record.diffs, dtype=np.float64)
    valid = np.isfinite(d)
    if record.spectrum is not None:
        w = np.where(valid, np.asarray(record.weights, dtype=np.float64), np.nan)
        w = w / np.nanmean(w, axis=1, keepdims=True)
        w = np.where(w > 0, w, 1.0)
        sig = np.asarray(record.spectrum.noise_std, dtype=np.float64)[:, None] / np.sqrt(w)
    else:
        sig = np.asarray(record.sigmas, dtype=np.float64)
        fallback = np.nanmedian(np.where(valid, sig, np.nan), axis=1, keepdims=True)
        sig = np.where(np.isfinite(sig) & (sig > 0), sig, fallback)
    return np.where(valid, sig, np.nan)


def prior_draw(freq: np.ndarray, psd: np.ndarray, n: int, dt: float, rng: np.random.Generator, *,
               highpass_hz: float = 0.0) -> np.ndarray | tuple:
    """One draw of a stationary Gaussian signal of two-sided PSD ``psd`` on ``freq`` [rad²/Hz], ``n`` samples.

    With ``highpass_hz > 0``, returns ``(draw, high_passed)``: the same draw and its
    high-pass (gain ``1 − 2^(−(f/f_c)²/2)``, the restoration's) computed on the
    whole periodic signal it is cut from — what the images are meant to supply,
    with no end of record in the filter.
    """
    m = next_fast_len(2 * n)
    f = np.fft.rfftfreq(m, dt)
    s = np.interp(f, freq, psd, left=0.0, right=0.0)
    spec = rfft(rng.standard_normal(m)) * np.sqrt(s / dt)
    draw = irfft(spec, n=m)[:n]
    if highpass_hz <= 0:
        return draw
    return draw, irfft(spec * highpass_gain(f, highpass_hz), n=m)[:n]


def simulated_differentials(theta: np.ndarray, taus, lags, valid: np.ndarray, dt: float) -> np.ndarray:
    """``θ(t + τ_j + λ_j(t)) − θ(t)`` at the record's lines (pair, line), NaN where ``valid`` is False.

    ``theta`` is sampled at ``n dt`` over at least the record plus the longest lag.
    """
    n = valid.shape[1]
    spline = CubicSpline(np.arange(theta.size), theta)
    idx = np.arange(n, dtype=np.float64)
    out = np.empty(valid.shape)
    for j, (tau, lag) in enumerate(zip(taus, lags)):
        out[j] = spline(idx + (tau + np.nan_to_num(np.asarray(lag, dtype=np.float64))) / dt) - theta[:n]
    return np.where(valid, out, np.nan)


def fit_residual_rms(diffs: np.ndarray, theta: np.ndarray, taus, lags, dt: float, *, highpass_hz: float) -> float:
    """RMS of the differentials about the ones the estimate ``theta`` predicts (above the high-pass).

    Only lines where ``theta`` is known at both ends of the pair's delay count.
    """
    r = fit_residuals(diffs, theta, taus, lags, dt, highpass_hz=highpass_hz)
    ok = np.isfinite(r)
    return float(np.sqrt(np.mean(r[ok] ** 2))) if ok.any() else float("nan")


def fit_residuals(diffs: np.ndarray, theta: np.ndarray, taus, lags, dt: float, *, highpass_hz: float) -> np.ndarray:
    """The differentials minus the ones ``theta`` predicts, high-passed (pair, line); NaN where not both known."""
    d = np.asarray(diffs, dtype=np.float64)
    th = np.asarray(theta, dtype=np.float64)
    n = th.size
    known = np.isfinite(th)
    ext = np.concatenate([np.nan_to_num(th), np.zeros(int(np.ceil(max(taus) / dt)) + 8)])
    idx = np.arange(n, dtype=np.float64)
    ok = np.isfinite(d) & known[None, :]
    for j, (tau, lag) in enumerate(zip(taus, lags)):
        at = idx + (tau + np.nan_to_num(np.asarray(lag, dtype=np.float64))) / dt
        ahead = np.round(at).astype(np.int64)
        ok[j] &= (at <= n - 1) & known[np.clip(ahead, 0, n - 1)]
    r = d - simulated_differentials(ext, taus, lags, ok, dt)
    if highpass_hz > 0:
        r = np.array([highpass_nan(x, dt=dt, cutoff_hz=highpass_hz) for x in r])
    return r


#: fewest periodogram bins behind one band of the frequency-resolved noise check, above the lowest frequencies
CHECK_BAND_BINS = 16
#: log-spaced bands of the frequency-resolved noise check (before merging to CHECK_BAND_BINS bins)
CHECK_BANDS = 24
#: at the lowest frequencies a band spans this fraction of its start bin (at least one bin), up to CHECK_BAND_BINS
LOW_BAND_FRACTION = 0.5


def _band_edges(n: int, bands: int = CHECK_BANDS, min_bins: int = CHECK_BAND_BINS) -> list:
    """Bin indices splitting ``rfftfreq(n)`` (DC left out) into log-spaced bands.

    Above the lowest frequencies a band has at least ``min_bins`` bins; below,
    a band spans half its start bin (one bin, one, two, two, three, …): the
    integration amplifies noise as ``1 / (2π f τ)``, so the few lowest bins
    weigh most in the restored angle, and a slow excess of the matching error
    there would be diluted in a 16-bin band. A narrow band's excess must be
    larger to count (:func:`noise_colour_from_check`: ≈ 11 × in one bin).
    """
    nf = n // 2 + 1
    growth = (nf / min_bins) ** (1.0 / max(int(bands), 1))
    starts, i = [], 1
    while i < nf - min_bins // 2:
        starts.append(i)
        width = max(1, int(i * LOW_BAND_FRACTION))
        i += width if width < min_bins else max(min_bins, int(i * (growth - 1.0)))
    starts.append(nf)
    return starts if len(starts) > 1 else [1, max(nf, 2)]   # a very short record: one band of all its bins


def band_power(residuals: np.ndarray, edges: list) -> np.ndarray:
    """Mean periodogram of each pair's residuals (NaN → 0, scaled by the finite fraction) in the bands (pair, band)."""
    r = np.asarray(residuals, dtype=np.float64)
    ok = np.isfinite(r)
    per = np.abs(rfft(np.where(ok, r, 0.0), axis=-1)) ** 2 / np.maximum(ok.sum(1), 1)[:, None]
    return np.array([[per[j, a:b].mean() for a, b in zip(edges[:-1], edges[1:])] for j in range(r.shape[0])])


#: chance, per pair, that the check raises some band of a noise the white model describes (Bonferroni over its bands)
CHECK_FALSE_ALARM = 0.02


def noise_colour_from_check(real: np.ndarray, simulated: np.ndarray, edges: list, n: int, *,
                            limit: float = 64.0, draws: int = 8) -> np.ndarray:
    """Per pair and frequency of ``rfftfreq(n)``: the factor on the noise power that makes the white model's
    fit residuals as large as the real ones, band by band (≥ 1; 1 unless the excess is significant).

    A band of ``b`` periodogram bins averages ``b`` exponential variables, and
    the simulated power averages ``draws × b``: under the model their ratio
    follows Fisher's F(2b, 2·draws·b). A band counts when its ratio exceeds
    that law's quantile at :data:`CHECK_FALSE_ALARM` over the pair's bands
    (and ``NOISE_CHECK_TOLERANCE²``): a one-bin band must show ≈ 11 × the
    modelled power, a 16-bin one ≈ 2 ×.

    Matching errors are not white (they rise 3-4× in power towards 1-5 Hz on
    phr_cmg: windows that share rows, texture features seen by neighbouring
    lines), and differentials the model cannot fit (a line on a blind
    frequency) leave residual power the white model does not have: both are
    error the restored angle carries, so the draws get it too.
    """
    from scipy.stats import f as fisher

    bins = np.diff(np.asarray(edges, dtype=np.float64))
    quantile = fisher.isf(CHECK_FALSE_ALARM / max(bins.size, 1), 2.0 * bins, 2.0 * max(int(draws), 1) * bins)
    tolerance = np.maximum(NOISE_CHECK_TOLERANCE ** 2, quantile)[None, :]
    ratio = np.where(simulated > 0, real / np.maximum(simulated, 1e-300), 1.0)
    ratio = np.where(np.isfinite(ratio) & (ratio > tolerance), ratio, 1.0)
    return _colour_on_bins(np.clip(ratio, 1.0, limit), edges, n)


#: bounds of the noise colour the draws use (:func:`noise_colour_estimate`)
COLOUR_ESTIMATE_LIMITS = (0.25, 64.0)


def noise_colour_estimate(real: np.ndarray, simulated: np.ndarray, edges: list, n: int, *,
                          draws: int = 8, limits: tuple = COLOUR_ESTIMATE_LIMITS) -> np.ndarray:
    """Per pair and frequency of ``rfftfreq(n)``: the factor on the noise power that makes the white model's
    fit residual as large as the real one, band by band, *without* a significance test.

    :func:`noise_colour_from_check` keeps a band at 1 unless its excess is
    significant; that suits a decision (the knowledge crossover), but as an
    estimate of the error it is biased low: every excess below the test's
    quantile (≈ 11 × in a one-bin band) is dropped, and the predicted σ fell
    short on every stress scenario (×1.1-1.9). Here each band's ratio is
    taken as measured, divided by the mean of Fisher's F(2b, 2·draws·b) it
    follows under the model (``1 + 1 / (draws b − 1)``: the simulated power
    is itself an average of ``draws`` records), so that a noise the model
    describes gets factors of mean 1; the ratio is bounded by ``limits``.

    The factor is noisy in narrow bands (a one-bin band's ratio is
    exponential, and about a quarter of them meet the lower bound, which
    adds ≈ 0.03 to its mean): where a few low bins dominate the σ, one
    record's prediction scatters more than with the test. Unbiased, it is
    right on average, where the tested one is low on average.
    """
    bins = np.diff(np.asarray(edges, dtype=np.float64))
    d2 = 2.0 * max(int(draws), 1) * bins
    mean_f = np.where(d2 > 2.0, d2 / np.maximum(d2 - 2.0, 1e-12), 1.0)
    ratio = np.where(simulated > 0, real / np.maximum(simulated, 1e-300), 1.0) / mean_f[None, :]
    ratio = np.clip(np.where(np.isfinite(ratio), ratio, 1.0), limits[0], limits[1])
    return _colour_on_bins(ratio, edges, n)


def _colour_on_bins(ratio: np.ndarray, edges: list, n: int) -> np.ndarray:
    """Band factors (pair, band) interpolated in log-log on every bin of ``rfftfreq(n)`` (pair, n // 2 + 1)."""
    f_idx = np.arange(n // 2 + 1)
    centres = np.array([np.exp(np.mean(np.log(np.arange(a, b)))) for a, b in zip(edges[:-1], edges[1:])])
    return np.array([np.exp(np.interp(np.log(np.maximum(f_idx, 1)), np.log(centres), np.log(r))) for r in ratio])


def coloured_noise(sigma: np.ndarray, colour: np.ndarray | None, rng: np.random.Generator) -> np.ndarray:
    """Noise of per-line σ ``sigma`` (pair, line), white, or with the power spectrum scaled by ``colour``."""
    w = rng.standard_normal(sigma.shape)
    if colour is not None:
        w = irfft(rfft(w, axis=-1) * np.sqrt(colour), n=sigma.shape[1], axis=-1)
    return np.nan_to_num(sigma) * w


def pair_bands(pairs) -> list | None:
    """The (ahead, behind) band names of each pair ``"A/B"``; None for a pair that is not two different names."""
    out = []
    for p in pairs:
        ends = [e.strip() for e in str(p).split("/")]
        if len(ends) != 2 or not all(ends) or ends[0] == ends[1]:
            return None
        out.append(tuple(ends))
    return out


@dataclass
class SharedBandNoise:
    """The part of the pairs' noise that comes from a band two pairs share (see :func:`shared_band_noise`).

    Attributes
    ----------
    terms : list of (band, [(pair, sign, offset_lines)])
        Each shared band, with the pairs that see it, the sign it enters
        their differential with (+1 behind, −1 ahead) and where in the pair's
        record the band's sample lies [lines after the pair's line].
    fraction : ndarray (band, pair, lines // 2 + 1)
        Share of the pair's noise power that is the band's, per frequency of
        ``rfftfreq(lines, Δt)`` (0 where the pair does not see the band).
    """

    terms: list
    fraction: np.ndarray

    def band_shares(self) -> dict:
        """``{band: share}``: each band's share of its pairs' noise power, mean over those pairs and frequency."""
        return {band: float(np.mean([self.fraction[x, j].mean() for j, _, _ in seen]))
                for x, (band, seen) in enumerate(self.terms)}


#: lag window [lines] of the smoothed spectra behind :func:`shared_band_noise` (its frequency resolution is
#: ``1 / (SHARED_LAG_LINES Δt)``: matching errors of neighbouring lines are correlated over a few lines only)
SHARED_LAG_LINES = 16
#: the pairs' own noise keeps at least this share of their power
SHARED_MAX_FRACTION = 0.9


def shared_band_noise(residuals: np.ndarray, pairs, taus, dt: float, lags=None) -> SharedBandNoise | None:
    """How much of each pair's noise is the matching error of a band it shares with another pair.

    Pair ``A/B`` measures the location of B's sample against A's, so an error
    in band B's image (its noise, its texture seen through its own spectrum)
    enters every pair that uses B, at B's sample time: the pairs' noises are
    correlated. Across the bands such errors are partly common, and a common
    error is indistinguishable from the attitude: it passes into the restored
    angle, while the fit residual, which only sees what the pairs disagree
    on, cannot show it. Independent pair noise of the same level therefore
    predicts too small an error (measured on phr_cmg: the pairs that share
    their ahead band B1 correlate 0.35 in pitch at zero lag).

    Pair ``j`` samples its ahead band at its own line and its behind band
    ``(τ_j + mean λ_j) / Δt`` lines on (its own delay and mean lag: the
    recorded delays need not add up from pair to pair). The shared band's
    power is the cross-spectrum of two pairs' fit residuals (mean removed,
    zero-padded, so that the shift does not wrap) once each is moved to the
    band's sample and given the sign the band enters with (+ behind, −
    ahead), normalised by the lines both have at that shift; smoothed over
    ``n / SHARED_LAG_LINES`` bins (mirrored at 0 Hz, where the real part of a
    cross-spectrum is even) and averaged over the couples of pairs sharing
    the band, over each pair's own smoothed residual power, it is the share
    of that pair's noise. Negative estimates count as 0 (on independent noise
    the shares average ≈ 0.02).

    ``lags``: per pair and line [s] (the record's ``lags_s``), or None.
    Returns None when a pair's name is not ``"A/B"`` or no band is seen by
    two pairs.
    """
    r = np.asarray(residuals, dtype=np.float64)
    ends = pair_bands(pairs)
    if ends is None or r.shape[0] < 2:
        return None
    p, n = r.shape
    ok = np.isfinite(r)
    mean_lag = [float(np.nanmean(lg)) if lags is not None and np.isfinite(lg).any() else 0.0
                for lg in (lags if lags is not None else [None] * p)]
    offset = [(float(t) + ml) / dt for t, ml in zip(taus, mean_lag)]
    m = next_fast_len(n + int(np.ceil(max(abs(o) for o in offset))) + 2)
    x = np.where(ok, r - np.array([np.mean(row[k]) if k.any() else 0.0 for row, k in zip(r, ok)])[:, None], 0.0)
    spec = rfft(x, n=m, axis=-1)
    freq = np.fft.rfftfreq(m, dt)
    width = max(1, int(round(m / SHARED_LAG_LINES / 2)) * 2 + 1)

    def smooth(v):
        return uniform_filter1d(v, width, mode="mirror")

    own = np.array([smooth(np.abs(spec[j]) ** 2) / max(ok[j].sum(), 1) for j in range(p)])
    bands = list(dict.fromkeys(b for e in ends for b in e))
    terms, shares = [], []
    for band in bands:
        seen = [(j, 1.0 if b == band else -1.0, offset[j] if b == band else 0.0)
                for j, (a, b) in enumerate(ends) if band in (a, b)]
        if len(seen) < 2:
            continue
        cross = []
        for i in range(len(seen)):
            for k in range(i + 1, len(seen)):
                (j, sj, oj), (q, sq, oq) = seen[i], seen[k]
                shift = oj - oq                   # r_j(l) and r_q(l + shift) hold the same sample of the band
                c = spec[j] * np.conj(spec[q]) * np.exp(-2j * np.pi * freq * shift * dt) * sj * sq
                s_int = int(round(shift))
                both = (ok[j][max(0, -s_int):n - max(0, s_int)] & ok[q][max(0, s_int):n + min(0, s_int)]).sum()
                if both > 0:
                    cross.append(smooth(c.real) / both)
        if not cross:
            continue
        power = np.maximum(np.mean(cross, axis=0), 0.0)
        frac = np.zeros((p, freq.size))
        for j, _, _ in seen:
            frac[j] = np.where(own[j] > 0, power / np.maximum(own[j], 1e-300), 0.0)
        terms.append((band, seen))
        shares.append(frac)
    if not terms:
        return None
    on_record = np.fft.rfftfreq(n, dt)
    fraction = np.array([[np.interp(on_record, freq, fj) for fj in fr] for fr in shares])
    total = fraction.sum(axis=0)
    fraction *= np.where(total > SHARED_MAX_FRACTION, SHARED_MAX_FRACTION / np.maximum(total, 1e-300), 1.0)[None]
    return SharedBandNoise(terms=terms, fraction=fraction)


def correlated_noise(sigma: np.ndarray, colour: np.ndarray | None, shared: SharedBandNoise | None,
                     dt: float, rng: np.random.Generator) -> np.ndarray:
    """Noise of per-line σ ``sigma`` (pair, line) with the power spectrum scaled by ``colour`` and the share
    ``shared`` of it common to the pairs that see the same band (:func:`shared_band_noise`).

    Without ``shared`` it is :func:`coloured_noise`. Each band's part is one
    white draw, moved to the pair's sample of the band (a phase, so a
    fraction of a line is kept) and signed as the band enters the pair.
    """
    if shared is None:
        return coloured_noise(sigma, colour, rng)
    p, n = sigma.shape
    freq = np.fft.rfftfreq(n, dt)
    own = np.sqrt(np.clip(1.0 - shared.fraction.sum(axis=0), 0.0, 1.0))
    spec = rfft(rng.standard_normal((p, n)), axis=-1) * own
    for (_, seen), frac in zip(shared.terms, shared.fraction):
        u = rfft(rng.standard_normal(n))
        for j, sign, offset in seen:
            spec[j] += sign * np.sqrt(frac[j]) * u * np.exp(2j * np.pi * freq * offset * dt)
    if colour is not None:
        spec = spec * np.sqrt(colour)
    return np.nan_to_num(sigma) * irfft(spec, n=n, axis=-1)


def knowledge_sample_times(n: int, dt: float, rate_hz: float) -> np.ndarray:
    """Telemetry sample times [s] at ``rate_hz`` covering ``n`` lines of ``dt`` from the first line, two samples
    beyond each end (the spline's support)."""
    return (np.arange(int(np.ceil(n * dt * rate_hz)) + 4) - 2) / rate_hz


def knowledge_noise_below(n: int, dt: float, highpass_hz: float, noise_rad: float, rate_hz: float,
                          rng: np.random.Generator) -> np.ndarray:
    """One draw of the AOCS knowledge noise the images leave uncorrected: below the high-pass [rad].

    White noise of ``noise_rad`` per telemetry sample at ``rate_hz``,
    interpolated (cubic) at the ``n`` line times, minus its high-passed part
    (above the high-pass the images see, and correct, the knowledge's error).
    """
    return knowledge_noise_below_rows(1, n, dt, highpass_hz, noise_rad, rate_hz, rng)[0]


def knowledge_noise_below_rows(rows: int, n: int, dt: float, highpass_hz: float, noise_rad: float, rate_hz: float,
                               rng: np.random.Generator) -> np.ndarray:
    """``rows`` draws (row, line) of :func:`knowledge_noise_below` at once."""
    from .knowledge_smoothing import lowband_rows

    ts = knowledge_sample_times(n, dt, rate_hz)
    x = rng.standard_normal((int(rows), ts.size)) * noise_rad
    return lowband_rows(x, ts, np.arange(n) * dt, line_period_s=dt, highpass_hz=highpass_hz)


def posterior_sigma(record, *, samples: int = 8, seed: int = 0, smooth_lines: int = 31,
                    check_noise: bool = True, knowledge_noise_rad: float = 0.0,
                    knowledge_rate_hz: float | None = None, shared_bands: bool = True,
                    knowledge_smoothing=None) -> PosteriorSigma:
    """Predicted 1-σ per line of one axis's restored angle (see the module's docstring).

    Parameters
    ----------
    record : restore.result.IntegrationRecord
        The axis's last integration (from the pipeline or read back).
    samples : int
        Monte Carlo draws (the relative error of σ is about ``1 / √(2 · samples · smooth_lines)``).
    seed : int
        Seed of the draws (same seed, same bytes).
    smooth_lines : int
        The draws' squared errors are averaged over this many lines (σ varies
        over tens of lines, except at gap edges where a few lines blur).
    check_noise : bool
        Scale the noise, band by band, by the ratio of the real to the
        simulated fit residual's power, and model the share of the pairs'
        noise their bands have in common (``noise_scale`` reports the RMS of
        the significant factors).
    knowledge_noise_rad, knowledge_rate_hz : float
        The AOCS knowledge's white noise per sample and its rate (as the
        product records them): what of it lies below the high-pass stays in
        the restored angle. 0 / None: not counted.
    knowledge_smoothing : restore.knowledge_smoothing.KnowledgeSmoothing, optional
        The shrinkage the knowledge below the high-pass went through (its
        times from the record's first line): what it leaves of the noise is
        counted instead (:meth:`~restore.knowledge_smoothing.KnowledgeSmoothing.error_draw`).

    A record weighed by the noise its differentials show in the AOCS knowledge's band (``knowledge_band_hz``)
    has the draws' differentials carry an attitude-like offset of the size measured there
    (:func:`restore.knowledge_band_noise.knowledge_band_offset_psd`, its own random stream): the scene's band
    offset moves the pairs as an attitude does, so the MAP passes part of it, which no residual shows.

    Returns
    -------
    PosteriorSigma
    """
    from .knowledge_band_noise import knowledge_band_offset_psd

    d, valid, n, dt, taus, lags, freq, psd, ext = _draw_setup(record, samples, knowledge_noise_rad,
                                                              knowledge_rate_hz)
    noise = noise_per_line(record)
    rng = np.random.default_rng(seed)
    krng = _knowledge_rng(seed)
    offset = knowledge_band_offset_psd(record, samples=samples, seed=seed)
    orng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x4F46]))   # the offset's own stream

    def run(colour, k: int, check: bool, shared=None, offset=None):
        errs, resid = [], []
        for _ in range(k):
            th, ref = _prior_and_reference(record, freq, psd, ext, rng)
            ds = simulated_differentials(th, taus, lags, valid, dt) + correlated_noise(noise, colour, shared, dt, rng)
            if offset is not None:   # moves the pairs as an attitude would, but is none: all it leaves is error
                ds = ds + simulated_differentials(prior_draw(*offset, ext, dt, orng), taus, lags, valid, dt)
            est = record.rerun(ds, first_stage_gcv=False)
            errs.append(_draw_error(est, ref))
            if check:
                resid.append(band_power(fit_residuals(ds, est, taus, lags, dt, highpass_hz=record.highpass_hz),
                                        edges))
        return np.array(errs), resid

    edges = _band_edges(n)
    errs, sim = run(None, samples, check_noise)
    scale = 1.0
    colour = shared = estimate = None
    if check_noise:
        resid = fit_residuals(d, np.asarray(record.increment, dtype=np.float64), taus, record.lags_s, dt,
                              highpass_hz=record.highpass_hz)
        real = band_power(resid, edges)
        colour = noise_colour_from_check(real, np.mean(sim, axis=0), edges, n, draws=len(sim))
        scale = float(np.sqrt(np.mean(colour)))
        shared = (shared_band_noise(resid, record.pairs, taus, dt, lags=record.lags_s)
                  if shared_bands else None)
        if shared is not None:   # the residual of the model with shared bands is smaller: compare with that one
            _, sim = run(None, samples, True, shared)
        estimate = noise_colour_estimate(real, np.mean(sim, axis=0), edges, n, draws=len(sim))
    if check_noise or offset is not None:
        errs, _ = run(estimate, samples, False, shared, offset)
    kn = knowledge_error_moments(record, np.isfinite(errs).any(axis=0), krng,
                                 knowledge_noise_rad=knowledge_noise_rad, knowledge_rate_hz=knowledge_rate_hz,
                                 knowledge_smoothing=knowledge_smoothing)
    return PosteriorSigma(noise_scale=float(scale), samples=int(samples), noise_colour=colour,
                          band_shares=shared.band_shares() if shared is not None else {},
                          colour_estimate=estimate, **_summary(errs, kn, smooth_lines))


def _draw_setup(record, samples: int, knowledge_noise_rad: float = 0.0, knowledge_rate_hz: float | None = None
                ) -> tuple:
    """What the Monte Carlo draws of a record need: (diffs, valid, lines, Δt, delays, per-line lags, prior
    frequencies, PSD the attitudes are drawn from, lines drawn: the record plus the longest delay and lag).

    The draws' PSD is the record's prior raised to the AOCS knowledge's own white noise where that is
    known (:func:`draw_psd`), unless the record's prior is conditioned on the knowledge."""
    if samples < 2:
        raise ValueError(f"samples: must be >= 2, got {samples}")
    d = np.asarray(record.diffs, dtype=np.float64)
    n, dt = d.shape[1], float(record.line_period_s)
    taus = [float(t) for t in record.taus]
    # the draws see the recorded per-line lags: at large amplitude the time synchronisation's own error
    # is a good part of the total
    lags = [np.nan_to_num(np.asarray(lg, dtype=np.float64)) for lg in record.lags_s]
    freq, psd = _prior(record)
    if not getattr(record, "knowledge_conditioned", False):
        # a prior conditioned on the knowledge already holds what the knowledge's noise leaves
        psd = draw_psd(freq, psd, knowledge_noise_rad, knowledge_rate_hz)
    return d, np.isfinite(d), n, dt, taus, lags, freq, psd, extended_lines(n, taus, lags, dt)


def extended_lines(n: int, taus, lags, dt: float) -> int:
    """Lines an attitude series needs for a record of ``n`` lines' differentials: the record, its longest delay
    and per-line lag beyond it, and a margin of 8 lines (``lags``: per pair, (lines,) [s], no NaN)."""
    return n + int(np.ceil((max(float(t) for t in taus) + max(float(np.max(np.abs(lg))) for lg in lags)) / dt)) + 8


def draw_psd(freq, psd, knowledge_noise_rad: float = 0.0, knowledge_rate_hz: float | None = None) -> np.ndarray:
    """The PSD the draws take the remaining attitude error from [rad²/Hz, two-sided]: the integration's prior,
    at least the AOCS knowledge's own white noise (:func:`restore.knowledge_prior.knowledge_noise_floor`).

    What the integration restores is ``θ − k``, the knowledge's error, and that error holds the knowledge's
    noise whatever the attitude does. A prior estimated below it (the differentials showed nothing there
    beyond their noise, or a ceiling from the knowledge's filter clipped it) makes the filter leave that noise
    in the restored angle; drawing the attitude from the prior alone would predict that error as zero. The
    filter itself is not changed (``restoration.knowledge_noise_floor`` does that): only what its error is
    predicted on. Without a recorded noise (0 or no rate) the prior is returned as it is.
    """
    psd = np.asarray(psd, dtype=np.float64)
    if not (knowledge_noise_rad > 0 and knowledge_rate_hz):
        return psd
    return np.maximum(psd, knowledge_noise_floor(freq, rate_hz=float(knowledge_rate_hz),
                                                 noise_rad=float(knowledge_noise_rad)))


def draw_differentials(record, *, samples: int = 8, seed: int = 0) -> tuple[list, list]:
    """The record's differentials as its own model draws them: ``samples`` of (pair, line) each, an attitude
    from the record's prior through the pairs plus the integration's white noise, and those noises alone
    (NaN where the record has none). What :mod:`restore.knowledge_band_noise` holds the real ones against."""
    _, valid, _, dt, taus, lags, freq, psd, ext = _draw_setup(record, samples)
    noise = noise_per_line(record)
    rng = np.random.default_rng(seed)
    sims, noises = [], []
    for _ in range(samples):
        th, _ = _prior_and_reference(record, freq, psd, ext, rng)
        z = np.where(valid, correlated_noise(noise, None, None, dt, rng), np.nan)
        sims.append(simulated_differentials(th, taus, lags, valid, dt) + z)
        noises.append(z)
    return sims, noises


def _prior_and_reference(record, freq, psd, ext: int, rng) -> tuple:
    """One attitude drawn from the record's prior over ``ext`` lines, and what the images are meant to supply of
    it on the record's lines (its high-pass, or itself)."""
    n, dt = np.asarray(record.diffs).shape[1], float(record.line_period_s)
    if record.highpass_hz > 0:
        th, ref = prior_draw(freq, psd, ext, dt, rng, highpass_hz=record.highpass_hz)
        return th, ref[:n]
    th = prior_draw(freq, psd, ext, dt, rng)
    return th, th[:n]


def _knowledge_rng(seed: int) -> np.random.Generator:
    """The draws of the AOCS knowledge's noise: a stream of their own, so that how the knowledge is counted
    (raw, smoothed, not at all) leaves the attitude and noise draws — and the noise colour their check
    measures, which the colour weighting integrates with — the same bytes."""
    return np.random.default_rng(np.random.SeedSequence([int(seed), 0x4B4E]))


def _draw_error(est: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """A draw's error from the images: estimate − reference, mean removed (the knowledge's noise below the
    high-pass is drawn apart: :func:`knowledge_error_moments`)."""
    e = est - ref
    ok = np.isfinite(e)
    return e - np.mean(e[ok]) if ok.any() else e


#: draws of the AOCS knowledge's noise below the high-pass per prediction (:func:`knowledge_error_moments`): each
#: costs a spline and a low-pass, not an integration, so they are many more than the images' draws
KNOWLEDGE_DRAWS = 256
#: the knowledge's draws are made this many at a time (memory: rows × lines)
KNOWLEDGE_CHUNK = 32


@dataclass(frozen=True)
class KnowledgeErrorMoments:
    """What :func:`knowledge_error_moments` found of the knowledge's noise the restored angle keeps [rad, rad²]."""

    #: mean square per line over the draws (NaN off the restored lines)
    line_ms: np.ndarray
    #: the same once each draw's least-squares line over the restored lines is removed
    line_ms_detrended: np.ndarray
    #: mean over the draws and the restored lines of the detrended draws' square
    detrended_ms: float
    #: mean over the draws of :func:`restore.knowledge_check.tapered_power`
    error_power: np.ndarray
    draws: int


def knowledge_error_moments(record, lines: np.ndarray, rng: np.random.Generator, *, knowledge_noise_rad: float = 0.0,
                            knowledge_rate_hz: float | None = None, knowledge_smoothing=None,
                            draws: int = KNOWLEDGE_DRAWS) -> KnowledgeErrorMoments | None:
    """The moments of the AOCS knowledge's noise the restored angle keeps below the high-pass, from ``draws``
    draws: what its smoothing leaves (``knowledge_smoothing``,
    :meth:`~restore.knowledge_smoothing.KnowledgeSmoothing.error_draws`) or the raw white noise of
    ``knowledge_noise_rad`` per sample at ``knowledge_rate_hz`` (as :func:`knowledge_noise_below`), each draw's
    mean over ``lines`` (bool, the restored lines) removed. None when it is not counted (neither given, no
    high-pass, no line).

    The restored angle's error is the images' part plus this one, independent of it: its moments add to the
    images' draws'. Drawn apart, it is not held to the few draws an integration costs — on a short record the
    smoothing passes a few degrees of freedom of this noise whole (the polynomial it keeps), whose spread
    eight draws estimate to ± 25 % — and the draws are made many at a time (a spline and a low-pass on a block
    of rows).
    """
    from .knowledge_check import tapered_power_rows
    from .knowledge_smoothing import lowband_rows

    m = np.asarray(lines, dtype=bool)
    n, dt, hp = m.size, float(record.line_period_s), float(record.highpass_hz)
    t = np.arange(n) * dt
    if not hp > 0 or not m.any():
        return None
    if knowledge_smoothing is not None:
        def block(k):
            return lowband_rows(knowledge_smoothing.error_draws(rng, k), knowledge_smoothing.time, t,
                                line_period_s=dt, highpass_hz=hp)
    elif knowledge_noise_rad > 0 and knowledge_rate_hz:
        def block(k):
            return knowledge_noise_below_rows(k, n, dt, hp, knowledge_noise_rad, knowledge_rate_hz, rng)
    else:
        return None
    sq, sq_det, power, done = np.zeros(n), np.zeros(n), np.zeros(n // 2 + 1), 0
    while done < draws:
        k = min(KNOWLEDGE_CHUNK, int(draws) - done)
        x = block(k)
        x = x - x[:, m].mean(axis=1, keepdims=True)
        d = detrended_rows(x, m)
        sq += np.sum(np.where(m, x, 0.0) ** 2, axis=0)
        sq_det += np.sum(np.where(m, d, 0.0) ** 2, axis=0)
        power += tapered_power_rows(x, m)
        done += k
    line_ms = np.where(m, sq / done, np.nan)
    line_det = np.where(m, sq_det / done, np.nan)
    return KnowledgeErrorMoments(line_ms=line_ms, line_ms_detrended=line_det,
                                 detrended_ms=float(np.mean(line_det[m])), error_power=power / done, draws=int(done))


def detrended_rows(x: np.ndarray, lines: np.ndarray) -> np.ndarray:
    """Each row of ``x`` (row, line) less its least-squares line (offset + slope) over ``lines`` (bool, the same for
    every row, each row finite there; NaN elsewhere), as :func:`detrended` does row by row."""
    v = np.atleast_2d(np.asarray(x, dtype=np.float64))
    m = np.asarray(lines, dtype=bool)
    if np.count_nonzero(m) < 3:
        return detrended(v)
    a = np.vander(np.arange(m.size, dtype=np.float64), 2)
    coef, *_ = np.linalg.lstsq(a[m], v[:, m].T, rcond=None)
    return np.where(m, v - (a @ coef).T, np.nan)


def _summary(errs: np.ndarray, kn: KnowledgeErrorMoments | None, smooth_lines: int) -> dict:
    """The prediction's figures from the images' error draws and, independent of them, the knowledge's moments
    (:func:`knowledge_error_moments`, or None): variances, mean squares and mean periodograms add."""
    errs = np.asarray(errs, dtype=np.float64)
    det = detrended(errs)
    var, var_det = _line_variance(errs, smooth_lines), _line_variance(det, smooth_lines)
    ms_det = float(np.nanmean(det ** 2)) if np.isfinite(det).any() else float("nan")
    power = mean_error_power(errs)
    if kn is not None:
        var = var + _smooth_line_variance(kn.line_ms, smooth_lines)
        var_det = var_det + _smooth_line_variance(kn.line_ms_detrended, smooth_lines)
        ms_det += kn.detrended_ms
        power = power + kn.error_power
    return {"sigma": np.sqrt(var), "detrended_sigma": np.sqrt(var_det), "detrended_rms": float(np.sqrt(ms_det)),
            "error_power": power}


def local_error_sigma(record, local: np.ndarray, *, samples: int = 8, seed: int = 0, smooth_lines: int = 31,
                      knowledge_noise_rad: float = 0.0, knowledge_rate_hz: float | None = None,
                      knowledge_smoothing=None) -> PosteriorSigma:
    """Predicted 1-σ per line with the *measured* local matching error as the pairs' noise.

    ``local`` (pair, line) [rad] is the local part of each pair's
    differential error, measured from two interleaved halves of the swath
    (:func:`restore.local_noise.local_matching_error`; NaN: not measured,
    taken as 0 on the record's lines). The draws add to the differentials of
    an attitude drawn from the prior this series with random phases, the
    same for every pair (a surrogate: each pair's spectrum and the pairs'
    cross-spectra are the measured ones, the noise colour and the bands the
    pairs share included), and integrate them through the frozen filter, as
    :func:`posterior_sigma` does with its model.

    The two predictions miss different things: the residual's model does not
    see an error that moves like an attitude, the local one does not hold an
    error every point of a line shares. :func:`larger_sigma` keeps the larger.
    """
    d, valid, n, dt, taus, lags, freq, psd, ext = _draw_setup(record, samples, knowledge_noise_rad,
                                                              knowledge_rate_hz)
    loc = np.asarray(local, dtype=np.float64)
    if loc.shape != d.shape:
        raise ValueError(f"local: shape {loc.shape}, expected the record's (pair, line) {d.shape}")
    x = np.where(valid, np.nan_to_num(loc), 0.0)
    spec = rfft(x - x.mean(axis=1, keepdims=True), axis=-1)
    rng = np.random.default_rng(seed)
    krng = _knowledge_rng(seed)
    errs = []
    for _ in range(samples):
        th, ref = _prior_and_reference(record, freq, psd, ext, rng)
        phase = np.exp(2j * np.pi * rng.random(n // 2 + 1))
        phase[0] = 0.0
        noise = np.where(valid, irfft(spec * phase, n=n, axis=-1), np.nan)
        est = record.rerun(simulated_differentials(th, taus, lags, valid, dt) + noise, first_stage_gcv=False)
        errs.append(_draw_error(est, ref))
    errs = np.array(errs)
    kn = knowledge_error_moments(record, np.isfinite(errs).any(axis=0), krng,
                                 knowledge_noise_rad=knowledge_noise_rad, knowledge_rate_hz=knowledge_rate_hz,
                                 knowledge_smoothing=knowledge_smoothing)
    return PosteriorSigma(noise_scale=1.0, samples=int(samples), **_summary(errs, kn, smooth_lines))


def mean_error_power(errs: np.ndarray) -> np.ndarray:
    """Mean over the draws (rows) of :func:`restore.knowledge_check.tapered_power` on each draw's finite lines."""
    return np.mean([tapered_power(e, np.isfinite(e)) for e in np.asarray(errs, dtype=np.float64)], axis=0)


def larger_sigma(model: PosteriorSigma, local: PosteriorSigma) -> PosteriorSigma:
    """``model`` with its σ per line (and its σ without the record's trend) raised to ``local``'s where that is
    larger; what the model's noise check found (colour, shares, scale) is kept. ``local_detrended_rms`` records
    the local prediction, ``model_sigma`` the model's σ per line."""
    def up(a, b):
        if a is None or b is None:
            return a
        return np.where(np.isfinite(a) & np.isfinite(b), np.maximum(a, b), a)
    return replace(model, sigma=up(model.sigma, local.sigma),
                   detrended_sigma=up(model.detrended_sigma, local.detrended_sigma),
                   detrended_rms=max((v for v in (model.detrended_rms, local.detrended_rms) if np.isfinite(v)),
                                     default=float("nan")),
                   local_detrended_rms=float(local.detrended_rms), model_sigma=model.sigma,
                   error_power=up(model.error_power, local.error_power))


def _line_variance(errs: np.ndarray, smooth_lines: int) -> np.ndarray:
    """Mean square of the draws per line (NaN where no draw is finite), averaged over ``smooth_lines`` lines."""
    ok = np.isfinite(errs).any(axis=0)
    var = np.where(ok, np.nanmean(np.where(np.isfinite(errs), errs ** 2, 0.0), axis=0) * errs.shape[0]
                   / np.maximum(np.isfinite(errs).sum(axis=0), 1), np.nan)
    return _smooth_line_variance(var, smooth_lines)


def _smooth_line_variance(var: np.ndarray, smooth_lines: int) -> np.ndarray:
    """A variance per line (NaN: none) averaged over ``smooth_lines`` lines, NaN kept."""
    ok = np.isfinite(var)
    if smooth_lines > 1:
        num = uniform_filter1d(np.where(ok, var, 0.0), smooth_lines, mode="nearest")
        den = uniform_filter1d(ok.astype(np.float64), smooth_lines, mode="nearest")
        var = np.where(ok, num / np.maximum(den, 1e-12), np.nan)
    return var


def _prior(record) -> tuple[np.ndarray, np.ndarray]:
    if record.spectrum is not None:
        return np.asarray(record.spectrum.freq, dtype=np.float64), np.asarray(record.spectrum.psd, dtype=np.float64)
    from .integration.wiener import spectrum_for_lines

    sp = spectrum_for_lines(list(record.diffs), list(record.taus), record.line_period_s)
    return np.asarray(sp.freq, dtype=np.float64), np.asarray(sp.psd, dtype=np.float64)
