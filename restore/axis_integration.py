"""Integration of one axis from the pairs' differentials, as the restoration does it.

:func:`integrate_axis` is *the* integration step: the pipeline calls it on the
measured differentials, and the report calls it again with the inputs
``restoration.nc`` recorded (on true differentials, on noise) to split the
error budget. Both go through the same code, so the budget cannot drift from
what the pipeline did.

Steps:

1. time synchronisation — band B sees line ``l`` of A at ``t + τ + λ(l)``, not
   ``t + τ``; a method that models per-line lags gets them, any other gets
   differentials brought back to the nominal lag with a lag-aware estimate
   θ̂ (``lsq``): ``D_j − [θ̂(t + τ_j + λ_j) − θ̂(t + τ_j)]``. A method that
   models the lags once its prior is known (``prior_lags``: the MAP Wiener)
   estimates its prior on those corrected differentials, then runs again on
   the measured ones with the lags in its forward model: the correction's
   error (the first fit's error times the lag, large where the attitude
   moves a pixel per line and the lags reach several lines) is gone; its
   prior is then estimated once more on differentials corrected with that
   lag-aware estimate (``prior_passes``), and the MAP run again;
2. the method itself, with the per-line data it takes (weights, lags,
   sigmas: see :mod:`restore.integration.methods`);
3. high-pass of the estimate at ``highpass_hz`` (the AOCS knows the low
   frequencies: keep only what the images add).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.ndimage import generic_filter, maximum_filter1d, uniform_filter1d

from .integration import integrate
from .integration.methods import IntegrationMethod, integration_method
from .integration.wiener import blind_tones, tone_columns
from .synthesis import highpass_nan

__all__ = ["AXIS_OPTIONS", "AxisIntegration", "PriorSpectrum", "integrate_axis", "lag_corrected_differentials",
           "periodic_highpass", "running_misfit", "transient_windows", "explained_windows", "windows_beyond_noise",
           "transient_blend",
           "notch_residual", "significant_colour"]


@dataclass
class PriorSpectrum:
    """PSD prior and noise levels a data-adaptive method used (rad²/Hz two-sided, rad per sample)."""

    freq: np.ndarray
    psd: np.ndarray
    noise_std: np.ndarray
    #: a tone on a frequency every pair is blind to, found through the lags: ([Hz], prior sd [rad][, order]) or None
    tones: tuple | None = None
    #: each pair's noise power relative to white, (freq [Hz], colour (pair, freq)), the MAP weighs with; or None
    noise_colour: tuple | None = None
    #: bins of ``freq`` where the data's estimate reached the AOCS knowledge's ceiling (bool), or None
    above_ceiling: np.ndarray | None = None


@dataclass
class AxisIntegration:
    """Result of :func:`integrate_axis`.

    Attributes
    ----------
    theta : ndarray
        Estimate [rad] at the line times, high-passed, NaN where not estimated.
    method : IntegrationMethod
        The method's spec.
    options : dict
        The scenario's options the method ran with (per-line data excluded).
    spectrum : PriorSpectrum or None
        The prior the method estimated from the data (methods that report it),
        None otherwise or when the prior was given.
    """

    theta: np.ndarray
    method: IntegrationMethod
    options: dict = field(default_factory=dict)
    spectrum: PriorSpectrum | None = None

    def frozen_options(self) -> dict:
        """Options that make the method the fixed filter of this run (its estimated prior given)."""
        return self.method.frozen_options(self.options, self.spectrum)


def _shifted(x: np.ndarray, t_idx: np.ndarray) -> np.ndarray:
    """Cubic interpolation of a line-sampled signal at fractional line indices (0 outside / at NaN)."""
    x = np.nan_to_num(np.asarray(x, dtype=np.float64))
    return CubicSpline(np.arange(x.size), x)(np.clip(t_idx, 0, x.size - 1))


def lag_corrected_differentials(diffs, taus, dt: float, lags, estimate) -> list:
    """Differentials brought back to their nominal lag: ``D_j − [θ̂(t + τ_j + λ_j) − θ̂(t + τ_j)]``.

    Parameters
    ----------
    diffs : sequence of ndarray (N,)
        Measured differentials [rad], NaN at gaps.
    taus : sequence of float
        Nominal lag of each pair [s].
    dt : float
        Line period [s].
    lags : sequence of ndarray (N,)
        Extra lag of each pair at each line [s].
    estimate : ndarray (N,)
        Lag-aware estimate θ̂ [rad].
    """
    idx = np.arange(len(diffs[0]), dtype=np.float64)
    out = []
    for d, tau, lag in zip(diffs, taus, lags):
        base = idx + tau / dt
        out.append(d - (_shifted(estimate, base + np.asarray(lag) / dt) - _shifted(estimate, base)))
    return out


def periodic_highpass(theta: np.ndarray, grid: np.ndarray, *, dt: float, cutoff_hz: float) -> np.ndarray:
    """The high-pass of :func:`restore.synthesis.highpass_nan` (gain ``1 − 2^(−(f/f_c)²/2)``) applied to the
    estimate on the method's whole periodic grid, read back on the record (NaN where ``theta`` is NaN).

    On the record alone the Gaussian low-pass is truncated at the ends: there
    it averages a fraction of a period of the estimate's own oscillations and
    puts that average back as low-frequency error (a 2.5 px, 3–8 Hz correction
    under a 0.4 Hz high-pass: 0.07 px of pitch error, none with the true
    differentials and no high-pass). On the grid the MAP solved, the estimate
    continues over the padding back to its start: the filter wraps around it
    and never meets an end. The lines the method leaves NaN at the record's
    ends (before its first estimated line, after its last) keep the grid's
    value for the low-pass, as the padding does — the MAP's own estimate
    there, its conditional mean — and are NaN again in the output: taken as
    missing, they cut a hole between the record and its padding in the
    estimate's oscillations, which the normalised convolution averaged
    around into a slow drift (at 2.7 px of CMG jitter, with a dozen such
    lines at each end of large_amplitude's record, its posterior draws erred
    by 0.065 / 0.074 px roll / pitch over the last 90 lines, 0.032 / 0.040 px
    with the grid's values; 0.018 / 0.021 px in the middle either way). Gaps
    inside the record stay missing data (normalised convolution), as they are
    for :func:`highpass_nan`: over a long gap the grid holds little more than
    the prior's mean, and taking it as the estimate there biased the low-pass
    beside clouds (an unseen clouds + low sun scene: 0.0490 → 0.0515 px of
    pitch error on the same lines).
    """
    th = np.asarray(theta, dtype=np.float64)
    ext = np.asarray(grid, dtype=np.float64).copy()
    ok = np.isfinite(th)
    if not ok.any():
        return th.copy()
    # the record's mean was removed over its estimable samples only: bring the grid to the same level, or the
    # joins would be steps that the wrapped low-pass spreads back into the record's ends
    ext += float(np.mean(th[ok] - ext[:th.size][ok]))
    record = ext[:th.size]                    # a view: the record's lines of the grid
    record[ok] = th[ok]
    first, last = np.flatnonzero(ok)[[0, -1]]
    record[first:last + 1][~ok[first:last + 1]] = np.nan    # gaps inside the record stay missing
    hp = highpass_nan(ext, dt=dt, cutoff_hz=cutoff_hz, mode="wrap")[:th.size]
    hp[~ok] = np.nan
    return hp - np.mean(hp[ok])


def _prior_of(spectrum, n_pairs: int, tones=None) -> PriorSpectrum:
    """The :class:`PriorSpectrum` of a method's spectral estimate (noise level broadcast to every pair)."""
    return PriorSpectrum(np.asarray(spectrum.freq, dtype=np.float64), np.asarray(spectrum.psd, dtype=np.float64),
                         np.broadcast_to(np.asarray(spectrum.noise_std, dtype=np.float64), (n_pairs,)).copy(),
                         tones=tones, above_ceiling=getattr(spectrum, "above_ceiling", None))


def _with_blind_tone(res, prior, spec, diffs, measured, taus, dt, opts, data, lags, details):
    """The lag-aware MAP again with a tone on a common blind frequency when the lags show one
    (:func:`restore.integration.wiener.blind_tones`), its prior estimated again without the tone's
    sidebands (the first estimate took them for attitude); (res, prior) unchanged otherwise.

    Not redundant with :func:`_prior_again`, which follows: returning the MAP
    with the tone and the first prior, and leaving the re-estimation to it,
    took blind_frequencies' roll from 0.0306 to 0.0351 px (restore only; the
    other tone scenarios within ± 0.0004 px)."""
    tones = blind_tones(measured, taus, dt, psd=(prior.freq, prior.psd), noise_std=prior.noise_std,
                        weights=data.get("weights"), lags=lags, base_objective=getattr(res, "objective", None),
                        base_prediction=getattr(res, "predicted", None))
    if tones is None:
        return res, prior
    fixed = spec.frozen_options(opts, prior)
    first = integrate(measured, taus, dt, method=spec.name, **fixed, **data, lags=lags, tones=tones, **details)
    x, _ = tone_columns(tones, len(measured[0]), taus, dt, [np.nan_to_num(np.asarray(lg)) for lg in lags])
    sidebands = np.einsum("pnq,q->pn", x, first.tones)
    again = integrate([d - sb for d, sb in zip(diffs, sidebands)], taus, dt, method=spec.name, **opts, **data,
                      **details)
    prior = _prior_of(again.spectrum, len(taus), tones=tones)
    res = integrate(measured, taus, dt, method=spec.name, **spec.frozen_options(opts, prior), **data, lags=lags,
                    **details)
    return res, prior


#: the prior estimated again on differentials corrected with the lag-aware estimate, then the MAP again: this
#: many times (see :func:`_prior_again`)
PRIOR_PASSES = 1


def _prior_again(res, prior, spec, measured, taus, dt, opts, data, lags, details):
    """The prior estimated again on differentials corrected with the lag-aware estimate ``res``, and the
    lag-aware MAP again with it (tones found on a common blind frequency kept): (res, prior).

    The first prior comes from differentials corrected with the least-squares
    estimate, which has no prior: it fits part of the noise, so its
    correction takes part of the noise out of the differentials (a noise
    level near the blind frequencies 8-25 % low at 3 px of jitter), and its
    error times the lags leaves sidebands of the lines, which the prior takes
    for attitude (on a 3.2 px CMG run, 20-300 × the truth's PSD at
    150-600 Hz in pitch, where the restored error then exceeded the attitude
    itself). Corrected with the MAP's own estimate (its tones included), the
    differentials are closer to what the nominal delays would have seen.
    The estimate takes the noise's colour where the MAP's residual shows it
    at least doubled (:func:`significant_colour`).
    """
    corrected = lag_corrected_differentials(measured, taus, dt, lags, np.asarray(res.theta_full, dtype=np.float64))
    colour = significant_colour(res, measured, taus, dt, prior.noise_std)
    o = opts if colour is None else {**opts, "spectrum_options": {**dict(opts.get("spectrum_options") or {}),
                                                                  "noise_colour": colour}}
    again = integrate(corrected, taus, dt, method=spec.name, **o, **data, **details)
    prior = _prior_of(again.spectrum, len(taus), tones=prior.tones)
    res = integrate(measured, taus, dt, method=spec.name, **spec.frozen_options(opts, prior), **data, lags=lags,
                    **details)
    return res, prior


#: options this module reads or records in an axis's options, not the method's: a caller that runs the method
#: itself (:func:`restore.integration.integrate`) leaves them out
AXIS_OPTIONS = ("transient_lines", "transient_lsq", "notch_levels")

#: the prior is estimated again with the noise's colour (:func:`significant_colour`) where it exceeds this factor: a
#: colour that at least doubles the noise (a modest one, 1.2-1.6, is also what strong lines seen through large
#: per-line lags leave outside the attitude's direction, and taking it would lower the prior where a tone hides)
COLOUR_PRIOR_MIN = 2.0


def significant_colour(res, measured, taus, dt: float, noise_std):
    """The noise colour of the MAP ``res``'s residual where it exceeds :data:`COLOUR_PRIOR_MIN` (1 elsewhere), as
    ``(freq, colour)`` for :func:`restore.integration.spectrum.estimate_spectrum`'s ``noise_colour``; None where
    it nowhere does or the MAP gives no prediction.

    The white level is a median over the pairs' blind frequencies across the
    band; matching noise is coloured (at 12 px peak jitter 2.2-2.7 × that
    level at 80-400 Hz, 0.35 × at 900-1250 Hz), and where it exceeds the
    level the spectrum estimate read it as attitude: a prior of 0.11-0.22 px
    at 160-400 Hz where huge_amplitude's attitude has nothing, through which
    the MAP let noise pass and which the predicted σ drew as signal. The
    colour is read on the residual, where the MAP took the lines out, in the
    part no attitude can make (:func:`restore.integration.spectrum.null_space_colour`).
    """
    from .integration.spectrum import null_space_colour

    pred = getattr(res, "predicted", None)
    if pred is None:
        return None
    colour = null_space_colour(np.asarray(measured, dtype=np.float64) - np.asarray(pred, dtype=np.float64), taus, dt,
                               noise_std)
    if colour is None or not np.max(colour[1]) > COLOUR_PRIOR_MIN:
        return None
    return colour[0], np.where(colour[1] > COLOUR_PRIOR_MIN, colour[1], 1.0)


#: a notch's prior is raised to its own estimated level (:func:`_notch_prior`) when that level is detected and
#: exceeds the bridge by this factor (below it the MAP would barely change: not worth a solve)
NOTCH_RAISE = 2.0


def notch_residual(res, measured, taus, dt: float, lags, prior: PriorSpectrum) -> np.ndarray | None:
    """What the MAP ``res`` leaves of the measured differentials, with its field's part in the prior's notches
    added back: the differentials' content in the notches alone (pair, line), or None when ``res`` holds no
    grid or prediction.

    The residual takes out everything the MAP explained — the lines beside a
    notch, whose skirts leak into its flanks, and the tones it found on the
    blind frequencies or inside a notch — but the field's own in-notch part
    is explained in proportion to the prior there (a bridge a fraction of
    the true level still explains part of the flanks: on an unseen
    continuum the residual alone read a third of the level). That part,
    taken from the periodic grid (no record ends to leak), goes back
    through the pairs' forward model (delay and per-line lag).
    """
    from scipy.fft import irfft, rfft

    from .integration.spectrum import notch_mask
    from .integration.wiener import tone_chirps, tone_waves

    grid = getattr(res, "theta_grid", None)
    pred = getattr(res, "predicted", None)
    if grid is None or pred is None:
        return None
    grid = np.asarray(grid, dtype=np.float64)
    m = grid.size
    # the MAP's own grid, not the prior's: with per-line lags the grid is padded for the longest of them, and
    # a prior estimated without lags was read onto it
    f = np.fft.rfftfreq(m, dt)
    d = np.asarray(measured, dtype=np.float64)
    n = d.shape[1]
    field = grid
    coefs = getattr(res, "tones", None)
    if prior.tones is not None and coefs is not None:
        tones = prior.tones
        order = int(tones[2]) if len(tones) > 2 else 0
        field = grid - tone_waves(np.atleast_1d(np.asarray(tones[0], dtype=np.float64)), m, dt, order, n_record=n,
                                  chirps=tone_chirps(tones)) @ np.asarray(coefs, dtype=np.float64)
    nu = np.asarray(prior.noise_std, dtype=np.float64) ** 2 * dt
    inside = notch_mask(f, np.asarray(taus, dtype=np.float64), nu)
    part = irfft(np.where(inside, rfft(field), 0.0), n=m)
    idx = np.arange(n, dtype=np.float64)
    spline = CubicSpline(np.arange(m + 1, dtype=np.float64), np.r_[part, part[:1]], bc_type="periodic")
    out = np.empty_like(d)
    for j, tau in enumerate(taus):
        lag = 0.0 if lags is None else np.nan_to_num(np.asarray(lags[j], dtype=np.float64))
        out[j] = d[j] - np.asarray(pred[j], dtype=np.float64) + spline((idx + (tau + lag) / dt) % m) - part[:n]
    return out


def _notch_prior(res, prior, spec, measured, taus, dt, opts, data, lags, details):
    """The prior in each notch raised to the level its own differentials show, and the MAP again: (res, prior).

    The spectrum estimate bridges each notch from its edge bins (nothing in
    a notch can be estimated bin by bin); under a continuum the gated
    estimate's edge bin is as often 0 as the level, and the bridged prior
    then says there is nothing there — the filter gives back nothing of what
    the flanks see, and σ, drawn from that prior, holds none of it (an unseen
    0.6 px continuum: 0.117 px roll error, σ ratio 2.6). Over the whole
    notch the flanks do see it: :func:`restore.integration.spectrum.notch_levels`
    estimates one level per notch from what the MAP leaves
    (:func:`notch_residual`), and where it is detected and above the bridge
    (× :data:`NOTCH_RAISE`) the notch takes it; ``opts["notch_levels"]`` then
    records ``[first Hz, last Hz, level rad²/Hz]`` of each notch raised (for
    the record and the terminal: a frozen rerun takes the prior as it is).
    Unchanged when nothing is.
    """
    from dataclasses import replace

    from .integration.spectrum import notch_levels, notch_mask

    resid = notch_residual(res, measured, taus, dt, lags, prior)
    if resid is None:
        return res, prior
    m = np.asarray(res.theta_grid).size
    f = np.asarray(prior.freq, dtype=np.float64)
    df = float(f[1] - f[0])
    psd = np.asarray(prior.psd, dtype=np.float64).copy()
    # the prior's own notches (its grid may be shorter than the MAP's: see notch_residual)
    poor = notch_mask(f, np.asarray(taus, dtype=np.float64), np.asarray(prior.noise_std, dtype=np.float64) ** 2 * dt)
    raised = []
    for nl in notch_levels(resid, taus, dt, n_fft=m, noise_std=prior.noise_std, residual_of=(f, prior.psd)):
        sel = poor & (f >= nl.band_hz[0] - df) & (f <= nl.band_hz[1] + df)
        if nl.detected and sel.any() and nl.level > NOTCH_RAISE * float(np.median(psd[sel])):
            psd[sel] = np.maximum(psd[sel], nl.level)
            raised.append([nl.band_hz[0], nl.band_hz[1], nl.level])
    if not raised:
        return res, prior
    prior = replace(prior, psd=psd)
    kw = {} if lags is None else {"lags": lags}
    res = integrate(measured, taus, dt, method=spec.name, **spec.frozen_options(opts, prior), **data, **kw, **details)
    opts["notch_levels"] = raised
    return res, prior


#: running window of the transient detection [lines]
TRANSIENT_BLOCK_LINES = 100
#: a transient's window reaches this many lines beyond the lines that fail the prior (the MAP's estimate
#: rings ahead of an abrupt onset it cannot fit: on spot5_mirror its error starts 370 lines before)
TRANSIENT_MARGIN_LINES = 400
#: the lines judged for the least-squares estimate's fit: the failing lines and this many beyond them (a block)
TRANSIENT_JUDGED_MARGIN_LINES = 100
#: the least-squares estimate is blended in over a ramp of this many lines at a window's edges
TRANSIENT_RAMP_LINES = 50
#: a candidate window is kept when the least-squares estimate's running misfit stays within this many times its
#: own record median there: it fits the window as it fits the rest of the record (a transient: 0.8-1.6 × on
#: spot5_mirror and damped_chirp; data no estimate explains — clouds, folds, a poor stretch of texture — 3.3-61 ×
#: the MAP's median, more of its own, which is 0.6-0.9 × the MAP's). Against the MAP's median instead, the
#: least squares, which fit part of the noise, passed where they did not fit: at an unseen 2 px CMG scene's record
#: end (1.85 × the MAP's median, 3.2 × its own) they replaced a MAP 0.04 px off with an estimate 0.11 px off
TRANSIENT_LSQ_FIT = 2.0


def running_misfit(residuals, noise, *, block: int = TRANSIENT_BLOCK_LINES) -> np.ndarray:
    """The fit's normalised misfit ``(r/σ)²``, averaged over the pairs, then its running median over ``block``
    lines (NaN where fewer than a quarter of the block's lines are known).

    A median: a transient raises the misfit of most lines of the window; a few
    failed syntheses (a fold at several pixels of jitter) raise a few lines a
    lot and leave it alone.
    """
    z2 = np.asarray(residuals, dtype=np.float64) ** 2 / np.asarray(noise, dtype=np.float64) ** 2
    ok = np.isfinite(z2)
    per_line = np.where(ok.any(0), np.where(ok, z2, 0.0).sum(0) / np.maximum(ok.sum(0), 1), np.nan)
    # beyond the record the window holds NaN (not the edge line repeated: one bad first line is a few lines)
    return generic_filter(per_line, lambda v: np.nanmedian(v) if np.isfinite(v).sum() > v.size // 4 else np.nan,
                          size=int(block), mode="constant", cval=np.nan)


def failing_lines(misfit, *, factor: float, margin: int) -> np.ndarray:
    """The lines whose running misfit exceeds ``factor`` times its record median, grown by ``margin`` lines each
    side (boolean per line)."""
    run = np.asarray(misfit, dtype=np.float64)
    if not factor > 0 or not np.isfinite(run).any():
        return np.zeros(run.shape, dtype=bool)
    bad = np.isfinite(run) & (run > factor * float(np.nanmedian(run)))
    return maximum_filter1d(bad.astype(np.uint8), size=2 * int(margin) + 1, mode="constant", cval=0).astype(bool)


def transient_windows(misfit, *, factor: float, margin: int = TRANSIENT_MARGIN_LINES) -> list[list[int]]:
    """Candidate line windows where a stationary prior fails: the running misfit (:func:`running_misfit`)
    above ``factor`` times its record median, grown by ``margin`` lines each side, as ``[[first, stop), ...]``.

    Empty with ``factor <= 0`` or nothing standing out.
    """
    grown = failing_lines(misfit, factor=factor, margin=margin)
    if not grown.any():
        return []
    edges = np.diff(np.concatenate([[0], grown.astype(np.int8), [0]]))
    return [[int(a), int(b)] for a, b in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1))]


def explained_windows(windows, misfit_local, *, limit: float, baseline: float | None = None,
                      judged=None) -> list[list[int]]:
    """The candidate windows where the estimate without prior fits the data: its running misfit nowhere
    above ``limit × baseline`` inside, ``baseline`` by default its own record median (it fits the window as it
    fits the rest: see :data:`TRANSIENT_LSQ_FIT`). A transient the prior could not follow passes; data the
    model cannot explain either way (clouds, folds, a poorly textured stretch, a record end) does not.

    ``judged`` (boolean per line, optional): only those lines of a window are judged — the lines where the
    prior failed and a block around them (:data:`TRANSIENT_JUDGED_MARGIN_LINES`), not the window's whole
    margin, which is there for the MAP's ringing ahead of an onset and may hold a stretch the estimate
    without prior fits no better than the MAP (spot5_mirror's roll: 3.0 × its median 350 lines past the
    transient, 1.2 × at most over it)."""
    m = np.asarray(misfit_local, dtype=np.float64)
    if baseline is None:
        baseline = float(np.nanmedian(m)) if np.isfinite(m).any() else 0.0
    if judged is not None:
        m = np.where(np.asarray(judged, dtype=bool), m, np.nan)
    out = []
    for a, b in windows:
        seg = m[int(a):int(b)]
        if np.isfinite(seg).any() and float(np.nanmax(seg)) <= limit * baseline:
            out.append([int(a), int(b)])
    return out


def transient_blend(theta, theta_local, windows, *, ramp: int = TRANSIENT_RAMP_LINES) -> np.ndarray:
    """``theta`` with ``theta_local`` inside ``windows`` ([first, stop) lines), ramped over ``ramp`` lines."""
    th = np.asarray(theta, dtype=np.float64)
    loc = np.asarray(theta_local, dtype=np.float64)
    m = np.zeros(th.size)
    for a, b in windows:
        m[int(a):int(b)] = 1.0
    m[~np.isfinite(loc)] = 0.0          # where the local estimate has a gap the ramp goes back to the main one
    if ramp > 1:
        m = uniform_filter1d(m, int(ramp), mode="nearest")
    out = m * np.nan_to_num(loc) + (1.0 - m) * np.nan_to_num(th)
    known = (np.isfinite(loc) | (m == 0.0)) & (np.isfinite(th) | (m == 1.0))
    return np.where(known, out, np.nan)


def integrate_axis(diffs, taus, dt: float, *, method: str | None = None, options: dict | None = None,
                   lags=None, sigmas=None, weights=None, highpass_hz: float = 0.0,
                   psd_ceiling=None, first_stage_gcv: bool = True, transient_factor: float = 0.0,
                   prior_passes: int = PRIOR_PASSES) -> AxisIntegration:
    """Integrate one axis's differentials of every pair (time synchronisation, method, high-pass).

    Parameters
    ----------
    diffs : sequence of ndarray (N,)
        ``diffs[j][n] ≈ θ(n dt + τ_j + λ_j[n]) − θ(n dt)`` [rad], NaN at gaps.
    taus : sequence of float
        Lag of each pair [s].
    dt : float
        Line period [s].
    method : str, optional
        Integration method (default :data:`restore.integration.DEFAULT_METHOD`).
    options : dict, optional
        The method's options (as a scenario gives them, or frozen).
    lags : sequence of ndarray (N,), optional
        Extra lag per pair and line [s] (time synchronisation); None: constant lags.
    sigmas : sequence of ndarray (N,), optional
        Per-line formal σ of the differentials [rad].
    weights : sequence of ndarray (N,), optional
        Relative weight of each pair's line.
    highpass_hz : float
        Cut-off of the high-pass applied to the estimate (0: none).
    psd_ceiling : (freq, ceiling), optional
        Upper bound of the prior PSD, for the methods that estimate one
        (:mod:`restore.knowledge_prior`).
    first_stage_gcv : bool
        With per-line lags and a method that cannot take them, the first
        least-squares estimate (it only corrects the lags) picks its
        curvature weight by generalised cross-validation (five sparse
        factorisations); False uses the default weight (one solve).
    transient_factor : float
        For a method with an estimated stationary prior: where the fit's
        misfit exceeds this many times its record median
        (:func:`transient_windows`: an abrupt onset the prior's average power
        cannot fit, around which the MAP rings), the least-squares estimate
        (no prior) is blended in (:func:`transient_blend`); the windows are
        kept in the options (``transient_lines``) so that a frozen rerun
        applies the same. 0: off.
    prior_passes : int
        For a method that models the lags once its prior is known: how many
        times the prior is estimated again on differentials corrected with
        the lag-aware estimate, and the method run again with it
        (:func:`_prior_again`). 0: the prior of the least-squares correction.
        Never with a single pair: the MAP's estimate then follows that pair's
        own noise where the prior is high, and a correction with it takes
        noise out of the differentials as the least-squares one does
        (strip_two_lines 0.0266 / 0.0273 → 0.0278 / 0.0310 px with one pass).

    Returns
    -------
    AxisIntegration
    """
    spec = integration_method(method)
    opts = dict(options or {})
    windows = opts.pop("transient_lines", None)
    local_weights = opts.pop("transient_lsq", None)
    opts.pop("notch_levels", None)     # what :func:`_notch_prior` did, for the record: the prior holds it
    diffs = [np.asarray(d, dtype=np.float64) for d in diffs]
    taus = [float(t) for t in taus]
    timed = lags is not None and any(np.any(np.asarray(lg) != 0) for lg in lags)
    exact_lags = timed and spec.prior_lags
    measured = diffs
    if timed and not spec.line_lags and not (exact_lags and "psd" in opts):
        lsq = integration_method("lsq")
        first = lsq.function(diffs, taus, dt, **lsq.data_options(lags=lags, sigmas=sigmas), gcv=first_stage_gcv)
        diffs = lag_corrected_differentials(diffs, taus, dt, lags, first)
    data = spec.data_options(weights=weights, lags=lags if spec.line_lags else None, sigmas=sigmas,
                             psd_ceiling=None if "psd" in opts else psd_ceiling)
    prior = None
    details = {"return_details": True} if spec.reports_spectrum else {}
    if spec.reports_spectrum and "psd" not in opts:
        res = integrate(diffs, taus, dt, method=spec.name, **opts, **data, **details)
        prior = _prior_of(res.spectrum, len(taus))
        if exact_lags:
            fixed = spec.frozen_options(opts, prior)
            res = integrate(measured, taus, dt, method=spec.name, **fixed, **data, lags=lags, **details)
            if spec.blind_tones and "tones" not in opts:
                res, prior = _with_blind_tone(res, prior, spec, diffs, measured, taus, dt, opts, data, lags, details)
            for _ in range(int(prior_passes) if len(taus) > 1 else 0):
                res, prior = _prior_again(res, prior, spec, measured, taus, dt, opts, data, lags, details)
        if len(taus) > 1:  # on the differentials and lags the last MAP ran on
            res, prior = _notch_prior(res, prior, spec, measured if exact_lags else diffs, taus, dt, opts, data,
                                      lags if exact_lags else None, details)
    elif exact_lags:
        res = integrate(measured, taus, dt, method=spec.name, **opts, **data, lags=lags, **details)
    else:
        res = integrate(diffs, taus, dt, method=spec.name, **opts, **data, **details)
    theta = np.asarray(getattr(res, "theta", res), dtype=np.float64)
    if highpass_hz > 0:
        grid = getattr(res, "theta_grid", None)
        theta = (periodic_highpass(theta, grid, dt=dt, cutoff_hz=highpass_hz) if grid is not None
                 else highpass_nan(theta, dt=dt, cutoff_hz=highpass_hz))
    local = None
    if windows is None and spec.reports_spectrum and transient_factor > 0 and prior is not None:
        def misfit(th):
            return _running_misfit_of(th, measured, taus, dt, lags, weights, prior, highpass_hz)

        mw = misfit(theta)
        windows = transient_windows(mw, factor=transient_factor)
        if windows:
            local, local_weights = _lsq_estimate(measured, taus, dt, lags, sigmas, weights, highpass_hz)
            windows = explained_windows(windows, misfit(local), limit=TRANSIENT_LSQ_FIT,
                                        judged=failing_lines(mw, factor=transient_factor,
                                                             margin=TRANSIENT_JUDGED_MARGIN_LINES))
            if windows:
                noise = _lsq_noise_draws(measured, taus, dt, lags, sigmas, weights, highpass_hz, prior,
                                         local_weights)
                windows = windows_beyond_noise(windows, theta, local, noise)
    if windows:
        if local is None:
            local, local_weights = _lsq_estimate(measured, taus, dt, lags, sigmas, weights, highpass_hz,
                                                 fixed=local_weights)
        theta = transient_blend(theta, local, windows)
        opts["transient_lines"] = [list(map(int, w)) for w in windows]
        opts["transient_lsq"] = dict(local_weights)
    return AxisIntegration(theta=theta, method=spec, options=opts, spectrum=prior)


def _lsq_estimate(diffs, taus, dt, lags, sigmas, weights, highpass_hz, *, fixed=None) -> tuple[np.ndarray, dict]:
    """The least-squares estimate (no prior) of the same differentials, high-passed the same way, and the
    weights it used. Lines the main fit gives no weight (filled gaps) are left out; ``fixed`` weights
    (``{"alpha", "beta"}``, a frozen rerun) make it the same linear map as on the measured record."""
    d = [np.asarray(x, dtype=np.float64) for x in diffs]
    if weights is not None:
        d = [np.where(np.asarray(w, dtype=np.float64) > 0, x, np.nan) for x, w in zip(d, weights)]
    lsq = integration_method("lsq")
    kw = {"gcv": False, **fixed} if fixed else {"gcv": True}
    theta, used = lsq.function(d, taus, dt, **lsq.data_options(lags=lags, sigmas=sigmas), return_weights=True, **kw)
    if highpass_hz > 0:
        theta = highpass_nan(theta, dt=dt, cutoff_hz=highpass_hz)
    return theta, used


def _line_noise(d: np.ndarray, prior, weights) -> np.ndarray:
    """The prior's per-line noise of differentials ``d`` (pair, line): σ_j over √ relative weight."""
    sig = np.asarray(prior.noise_std, dtype=np.float64)[:, None] * np.ones(d.shape)
    if weights is not None:
        w = np.where(np.isfinite(d), np.asarray(weights, dtype=np.float64), np.nan)
        w = w / np.nanmean(w, axis=1, keepdims=True)
        sig = np.where(w > 0, sig / np.sqrt(np.where(w > 0, w, 1.0)), np.nan)
    return sig


def _running_misfit_of(theta, measured, taus, dt, lags, weights, prior, highpass_hz) -> np.ndarray:
    """:func:`running_misfit` of an estimate against the prior's per-line noise (σ_j over √ relative weight)."""
    from .posterior import fit_residuals

    d = np.asarray(measured, dtype=np.float64)
    lg = [np.zeros(d.shape[1]) for _ in taus] if lags is None else lags
    r = fit_residuals(d, theta, taus, lg, dt, highpass_hz=highpass_hz)
    return running_misfit(r, _line_noise(d, prior, weights))


#: a candidate window is kept only where the estimate without prior differs from the MAP's by more than this many
#: times the RMS of its own noise there (:func:`windows_beyond_noise`): damped_chirp's onsets 1.87 (the suite's
#: roll; 2.0 dropped it, 0.021 → 0.025 px) to 3.4 × on three seeds; a 12 px CMG scene's false window (its misfit
#: the matching's at that amplitude) 0.43 ×, where the least squares, blind near 125-130 Hz, took 820 lines of
#: pitch 0.04 → 0.5 px off
TRANSIENT_NOISE_FACTOR = 1.5
#: noise draws through the least-squares estimate for that comparison (a fixed seed: the same bytes)
TRANSIENT_NOISE_DRAWS = 4


def windows_beyond_noise(windows, theta, local, local_noise, *, factor: float = TRANSIENT_NOISE_FACTOR) -> list:
    """The candidate windows where ``local`` (the estimate without prior) differs from ``theta`` (the MAP's) by
    more than ``factor`` × the RMS of ``local_noise`` (draws, lines: what its noise alone gives), each less its
    mean over the window (the offset no pair sees).

    A transient the prior could not follow is signal in that difference, well above the least squares' noise;
    where the difference is no larger than that noise, nothing shows one, and blending the least squares in
    would only bring their noise (where every pair is blind, far larger than the MAP's error).
    """
    th = np.asarray(theta, dtype=np.float64)
    loc = np.asarray(local, dtype=np.float64)
    nz = np.atleast_2d(np.asarray(local_noise, dtype=np.float64))
    out = []
    for a, b in windows:
        d = th[int(a):int(b)] - loc[int(a):int(b)]
        z = nz[:, int(a):int(b)]
        ok = np.isfinite(d) & np.all(np.isfinite(z), axis=0)
        if np.count_nonzero(ok) < 2:
            continue
        d = d[ok] - np.mean(d[ok])
        z = z[:, ok] - np.mean(z[:, ok], axis=1, keepdims=True)
        if np.sqrt(np.mean(d * d)) > factor * np.sqrt(np.mean(z * z)):
            out.append([int(a), int(b)])
    return out


def _lsq_noise_draws(measured, taus, dt, lags, sigmas, weights, highpass_hz, prior, local_weights, *,
                     draws: int = TRANSIENT_NOISE_DRAWS, seed: int = 0) -> np.ndarray:
    """The least-squares estimate (frozen ``local_weights``) of the prior's white noise alone, ``draws`` times
    (draws, lines), on the lines ``measured`` holds."""
    d = np.asarray(measured, dtype=np.float64)
    sig = np.nan_to_num(_line_noise(d, prior, weights))
    rng = np.random.default_rng(seed)
    return np.array([_lsq_estimate(list(np.where(np.isfinite(d), sig * rng.standard_normal(d.shape), np.nan)),
                                   taus, dt, lags, sigmas, weights, highpass_hz, fixed=local_weights)[0]
                     for _ in range(int(draws))])
