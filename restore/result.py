"""What a restoration produces: per-pair matches, per-axis integration records, the restored attitude.

The same types come out of the pipeline (:class:`restore.restorer.Restorer`)
and out of the reader of ``restoration.nc``
(:func:`restore.restoration_io.read_restoration`): a consumer (the report, a
study) sees exactly what the pipeline did.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .axis_integration import PriorSpectrum, integrate_axis
from .integration.methods import integration_method
from .settings import RestorationSettings

__all__ = ["PairData", "IntegrationRecord", "RestorationResult"]


@dataclass
class PairData:
    """Matches of one band pair, with the synthesis of the last iteration.

    Coordinates are in pixels: ``line_a``/``col_a`` in band ``ahead``; the
    measured (``meas_*``) and predicted (``pred_*``, with the attitude of the
    last iteration) positions in band ``behind``.
    """

    name: str
    ahead: str
    behind: str
    tau_s: float
    line_a: np.ndarray
    col_a: np.ndarray
    meas_line_b: np.ndarray
    meas_col_b: np.ndarray
    quality: np.ndarray
    valid: np.ndarray
    pred_line_b: np.ndarray | None = None
    pred_col_b: np.ndarray | None = None
    sens: np.ndarray | None = None
    inlier: np.ndarray | None = None
    synthesis: object = None
    std_line: np.ndarray | None = None
    std_col: np.ndarray | None = None
    nominal_tau_s: float | None = None
    residual_rms_px: float = float("nan")
    #: correlation of each match's line and column errors (:attr:`restore.matching.MatchResult.corr_line_col`)
    corr_line_col: np.ndarray | None = None


@dataclass
class IntegrationRecord:
    """The last integration of one axis, as :func:`restore.axis_integration.integrate_axis` ran it.

    Arrays are over (pair, line) for the pairs of ``pairs`` (the pairs the
    last iteration used). ``increment`` is what that integration returned
    (shrunk where it held more than its knowledge-conditioned prior allows,
    :mod:`restore.conditioned_excess`, which :meth:`rerun` does not do),
    ``previous`` the estimate it was added to (zero with one iteration): the
    correction is ``previous + increment`` with the mean removed.
    """

    axis: str
    pairs: list
    diffs: np.ndarray
    sigmas: np.ndarray
    taus: np.ndarray
    lags_s: np.ndarray
    weights: np.ndarray
    line_period_s: float
    method: str
    options: dict
    highpass_hz: float
    spectrum: PriorSpectrum | None
    increment: np.ndarray
    previous: np.ndarray
    unobservable_rms_rad: float = float("nan")
    floor_rms_rad: float = float("nan")
    selection: dict | None = None  #: how ``method`` was chosen when restoration.method = "auto"
    #: the prior is the one given the AOCS knowledge and ``previous`` its conditional mean
    #: (:mod:`restore.knowledge_conditioning`): the draws take the attitude error from that prior as it is
    knowledge_conditioned: bool = False
    #: where the prior is conditioned: the attitude's PSD the conditioning read, ``S_θ`` on ``spectrum.freq`` where
    #: the knowledge's response counts (0 elsewhere) [rad²/Hz, two-sided]; what the knowledge's model error scales
    #: with (:data:`restore.conditioned_excess.KNOWLEDGE_MODEL_ERROR`). Not written to restoration.nc
    conditioned_attitude_psd: np.ndarray | None = None
    #: the band [Hz] where the noise colour the MAP weighs with was read from the differentials themselves
    #: (:mod:`restore.knowledge_band_noise`); None: not read
    knowledge_band_hz: tuple | None = None

    def rerun(self, diffs=None, *, frozen: bool = True, lags=None, first_stage_gcv: bool = True) -> np.ndarray:
        """Integrate other differentials (true ones, noisy ones) through this axis's integration.

        With ``frozen`` a data-adaptive method keeps the prior it estimated on
        the measured differentials: the filter is the one that was applied.
        ``lags`` (pair, line) [s] replaces the recorded per-line lags (zeros:
        differentials simulated at the nominal delays need no time
        synchronisation). ``first_stage_gcv=False``: the least-squares first
        estimate that corrects the lags takes its default curvature weight
        (see :func:`restore.axis_integration.integrate_axis`; 5× cheaper).
        """
        opts = integration_method(self.method).frozen_options(self.options, self.spectrum if frozen else None)
        d = self.diffs if diffs is None else np.asarray(diffs, dtype=np.float64)
        lg = self.lags_s if lags is None else np.asarray(lags, dtype=np.float64)
        return integrate_axis(list(d), list(self.taus), self.line_period_s, method=self.method, options=opts,
                              lags=list(lg), sigmas=list(self.sigmas), weights=list(self.weights),
                              highpass_hz=self.highpass_hz, first_stage_gcv=first_stage_gcv).theta

    def frozen_options(self) -> dict:
        """The method's options with its estimated prior fixed (see :meth:`rerun`)."""
        return integration_method(self.method).frozen_options(self.options, self.spectrum)


@dataclass
class RestorationResult:
    """The restored line-of-sight attitude and how it was obtained (angles in rad, times in s)."""

    run_dir: Path | None
    time: np.ndarray
    restored: dict
    knowledge: dict
    correction: dict
    coverage: dict
    pairs: list
    timings: dict
    misregistration: dict
    settings: RestorationSettings
    pixel_ifov_rad: float
    method: str
    integration: dict = field(default_factory=dict)
    anchored: bool = False
    path: Path | None = None
    corrected: object = None
    #: per restored axis: predicted 1-σ per line [rad] (NaN: not restored), see :mod:`restore.posterior`
    sigma: dict = field(default_factory=dict)
    #: per restored axis: lines not restored because their predicted σ exceeded ``max_sigma_px``
    flagged: dict = field(default_factory=dict)
    #: axis → (limit [rad], "model" or "reported"): the flag limit applied and the σ it judged
    #: (:func:`restore.stages.flag_uncertain`); empty when not recorded
    flag_limits: dict = field(default_factory=dict)
    #: per restored axis: factor the residual check applied to the modelled noise
    noise_scale: dict = field(default_factory=dict)
    #: per restored axis: predicted RMS error [rad] once the record's trend (offset and slope, which no
    #: pair sees) is removed (:attr:`restore.posterior.PosteriorSigma.detrended_rms`)
    detrended_rms: dict = field(default_factory=dict)
    #: per restored axis: ``{band: share}`` of its pairs' noise that is the band's own matching error
    #: (:attr:`restore.posterior.PosteriorSigma.band_shares`)
    band_shares: dict = field(default_factory=dict)
    #: along-track motion of a yaw relative to a pitch (tan of the off-nadir roll): the restored pitch is
    #: pitch + this × the yaw the AOCS knowledge misses (:func:`restore.stages.yaw_pitch_coupling`)
    yaw_pitch_coupling: float = 0.0
    #: across-track motion of a yaw relative to a roll (≈ sin of the along-track tilt): the restored roll is
    #: roll + this × the yaw the AOCS knowledge misses (:func:`restore.stages.yaw_coupling`)
    yaw_roll_coupling: float = 0.0
    #: per restored axis: what the smoothing of the AOCS knowledge below the high-pass added to the correction
    #: [rad] (:mod:`restore.knowledge_smoothing`); empty when it was off or not recorded
    knowledge_smoothing: dict = field(default_factory=dict)
    #: ``{axis: (line,)}``: the part of ``correction`` that takes a causal AOCS filter's phase out of the knowledge
    #: [rad] (:mod:`restore.knowledge_dephasing`); empty when it was off or the filter has no phase
    knowledge_dephasing: dict = field(default_factory=dict)
    #: the AOCS knowledge's latency as the images measured it (:meth:`restore.knowledge_timing.LatencyEstimate.to_dict`;
    #: taken out of the knowledge, in ``knowledge_dephasing``, where ``significant``); empty when not measured
    knowledge_latency: dict = field(default_factory=dict)
    #: per axis checked: the restored angle against the smoothed knowledge
    #: (:class:`restore.knowledge_check.KnowledgeCheck`); its ``excess_rad2`` is in ``sigma``
    knowledge_checks: dict = field(default_factory=dict)
    #: per axis the fusion could be tried on: the knowledge's band taken where the estimate's proved astray
    #: (:class:`restore.knowledge_fusion.KnowledgeFusion`); the fusion's error is in ``sigma``
    knowledge_fusion: dict = field(default_factory=dict)
    #: per axis whose prior is conditioned on the knowledge: the estimate against what that prior allows
    #: (:class:`restore.conditioned_excess.ConditionedExcess`); a diagnostic, not in ``sigma``
    conditioned_excess: dict = field(default_factory=dict)

    def yaw_coupling(self, axis: str) -> float:
        """The yaw seen as ``axis`` per radian of missed yaw (0 for yaw or an axis without one)."""
        return {"pitch": self.yaw_pitch_coupling, "roll": self.yaw_roll_coupling}.get(axis, 0.0)

    def summary(self) -> str:
        """A few lines for the terminal: pairs, matches, coverage, correction, misregistration, speed."""
        px = self.pixel_ifov_rad
        lines = [f"restoration ({self.method}, {len(self.pairs)} pairs: "
                 f"{', '.join(f'{p.name} {p.tau_s * 1e3:.1f} ms' for p in self.pairs)})"]
        for p in self.pairs:
            n_ok = int(np.count_nonzero(p.valid))
            lines.append(f"  {p.name}: {n_ok} / {p.valid.size} matches valid, "
                         f"{int(np.count_nonzero(p.inlier)) if p.inlier is not None else 0} inliers, "
                         f"synthesis residual {p.residual_rms_px:.3f} px")
        cov = ", ".join(f"{a} {self.coverage[a] * 100:.1f} %" for a in self.settings.axes)
        lines.append(f"  coverage: {cov}")
        if self.sigma:
            pred = ", ".join(f"{a} {np.sqrt(np.nanmean(self.sigma[a] ** 2)) / px:.3f} px"
                             + (f" ({int(self.flagged[a].sum())} lines flagged: predicted σ above the limit)"
                                if a in self.flagged and self.flagged[a].any() else "")
                             for a in self.settings.axes if a in self.sigma)
            lines.append(f"  predicted error (1σ RMS): {pred}")
        fused = {a: fu for a, fu in (self.knowledge_fusion or {}).items() if fu.lines_fused}
        if fused:
            lines.append("  knowledge fusion: " + ", ".join(
                f"{a} {fu.lines_fused} lines took the AOCS knowledge below {fu.band_top_hz:.1f} Hz (their own band "
                f"ran astray)" for a, fu in sorted(fused.items())))
        corr = ", ".join(f"{a} {np.nanstd(self.correction[a]) / px:.3f} px rms" for a in self.settings.axes)
        lines.append(f"  correction applied: {corr}")
        for k, v in (self.misregistration or {}).items():
            weak = (f" (in no pair, corrected from the restored attitude; gradient matching against "
                    f"{v.get('reference_band')}, {100 * v.get('valid_fraction', 0):.0f} % of points)"
                    if v.get("weakly_correlated") else "")
            lines.append(f"  misregistration {k}{weak}: before {v['before_px']:.3f} px, after {v['after_px']:.3f} px "
                         f"measured (line {v['after_line_px']:.3f}, column {v['after_col_px']:.3f}; matching "
                         f"noise {v['after_noise_px']:.3f} px); without the noise {v['after_signal_px']:.3f} px "
                         f"(line {v['after_line_signal_px']:.3f}, column {v['after_col_signal_px']:.3f})")
        t = self.timings
        lines.append(f"  time: {t.get('total_s', 0):.1f} s ({t.get('lines_per_s', 0):.0f} lines/s, "
                     f"{t.get('matches_per_s', 0):.0f} matches/s)")
        if self.path:
            lines.append(f"  wrote {self.path}")
        return "\n".join(lines)
