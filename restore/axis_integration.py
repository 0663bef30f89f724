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
   moves a pixel per line and the lags reach several lines) is gone;
2. the method itself, with the per-line data it takes (weights, lags,
   sigmas: see :mod:`restore.integration.methods`);
3. high-pass of the estimate at ``highpass_hz`` (the AOCS knows the low
   frequencies: keep only what the images add).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import CubicSpline

from .integration import integrate
from .integration.methods import IntegrationMethod, integration_method
from .integration.wiener import blind_tones, tone_columns
from .synthesis import highpass_nan

__all__ = ["AxisIntegration", "PriorSpectrum", "integrate_axis", "lag_corrected_differentials", "periodic_highpass"]


@dataclass
class PriorSpectrum:
    """PSD prior and noise levels a data-adaptive method used (rad²/Hz two-sided, rad per sample)."""

    freq: np.ndarray
    psd: np.ndarray
    noise_std: np.ndarray
    #: a tone on a frequency every pair is blind to, found through the lags: ([Hz], prior sd [rad][, order]) or None
    tones: tuple | None = None


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
    and never meets an end. Gaps inside the record stay missing data
    (normalised convolution), as they are for :func:`highpass_nan`.
    """
    th = np.asarray(theta, dtype=np.float64)
    ext = np.asarray(grid, dtype=np.float64).copy()
    ok = np.isfinite(th)
    if ok.any():
        # the record's mean was removed over its estimable samples only: bring the padding to the same level,
        # or the joins would be steps that the wrapped low-pass spreads back into the record's ends
        ext += float(np.mean(th[ok] - ext[:th.size][ok]))
    ext[:th.size] = th                        # gaps of the record stay missing, as highpass_nan has them
    hp = highpass_nan(ext, dt=dt, cutoff_hz=cutoff_hz, mode="wrap")[:th.size]
    if np.isfinite(hp).any():
        hp -= np.nanmean(hp)
    return hp


def _prior_of(spectrum, n_pairs: int, tones=None) -> PriorSpectrum:
    """The :class:`PriorSpectrum` of a method's spectral estimate (noise level broadcast to every pair)."""
    return PriorSpectrum(np.asarray(spectrum.freq, dtype=np.float64), np.asarray(spectrum.psd, dtype=np.float64),
                         np.broadcast_to(np.asarray(spectrum.noise_std, dtype=np.float64), (n_pairs,)).copy(),
                         tones=tones)


def _with_blind_tone(res, prior, spec, diffs, measured, taus, dt, opts, data, lags, details):
    """The lag-aware MAP again with a tone on a common blind frequency when the lags show one
    (:func:`restore.integration.wiener.blind_tones`), its prior estimated again without the tone's
    sidebands (the first estimate took them for attitude); (res, prior) unchanged otherwise."""
    tones = blind_tones(measured, taus, dt, psd=(prior.freq, prior.psd), noise_std=prior.noise_std,
                        weights=data.get("weights"), lags=lags, base_objective=getattr(res, "objective", None))
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


def integrate_axis(diffs, taus, dt: float, *, method: str | None = None, options: dict | None = None,
                   lags=None, sigmas=None, weights=None, highpass_hz: float = 0.0,
                   psd_ceiling=None, first_stage_gcv: bool = True) -> AxisIntegration:
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

    Returns
    -------
    AxisIntegration
    """
    spec = integration_method(method)
    opts = dict(options or {})
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
    elif exact_lags:
        res = integrate(measured, taus, dt, method=spec.name, **opts, **data, lags=lags, **details)
    else:
        res = integrate(diffs, taus, dt, method=spec.name, **opts, **data, **details)
    theta = np.asarray(getattr(res, "theta", res), dtype=np.float64)
    if highpass_hz > 0:
        grid = getattr(res, "theta_grid", None)
        theta = (periodic_highpass(theta, grid, dt=dt, cutoff_hz=highpass_hz) if grid is not None
                 else highpass_nan(theta, dt=dt, cutoff_hz=highpass_hz))
    return AxisIntegration(theta=theta, method=spec, options=opts, spectrum=prior)
