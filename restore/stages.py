"""The stages of the restoration, each a function with explicit inputs and outputs.

select → match (per pair) → synthesise → integrate (per axis, over the pairs)
→ anchor → correct. :class:`restore.restorer.Restorer` composes them; each
can be called alone (tests, studies). Never reads ``truth.nc``.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from scipy.ndimage import maximum_filter1d

from simsat.attitude import AttitudeSeries
from simsat.config import ScenarioError
from simsat.product import Product, clamped_attitude

from .axis_integration import integrate_axis
from .correction import correct_bands, line_median, misregistration, rank_within_line, weak_band_misregistration
from .errors import RestorationError
from .integration.methods import integration_method
from .integration.transfer import pair_snr
from .integration.wiener import ceiling_on_grid, colour_on_grid, spectrum_for_lines
from .matching import match_points, support_margin
from .method_choice import predicted_differential, resolve_method
from .observability import observability
from .knowledge_prior import knowledge_noise_floor, knowledge_psd_ceiling, knowledge_response
from .exposure import exposure_deconvolution
from .knowledge_check import knowledge_check, smoothed_knowledge_at
from .knowledge_conditioning import knowledge_conditioning
from .knowledge_fusion import fuse_with_knowledge
from .knowledge_smoothing import knowledge_smoothing, lowband_correction
from .line_weights import gap_distance, residual_weight_factors, window_stretch
from .local_noise import local_matching_error
from .posterior import (extended_lines, fit_residuals, larger_sigma, local_error_sigma, posterior_sigma,
                        simulated_differentials)
from .rematch import rematch_pair
from .result import IntegrationRecord, PairData
from .selection import (NoiseLevel, estimate_image_noise, expected_matching_std, noise_level_function,
                        select_points_in_blocks)
from .settings import RestorationSettings
from .synthesis import (
    AXES,
    drop_sparse,
    fill_short_gaps,
    highpass_nan,
    instant_synthesis,
    match_weights,
    spikes,
    window_compensation,
)

__all__ = ["visible_pairs", "auto_pairs", "resolve_pairs", "pilot_shift", "Candidates", "shared_columns", "select_candidates", "match_candidates",
           "match_pair", "valid_fraction", "line_rate_px", "rematch_passes", "estimate_change_px", "rematch_moved", "rematch_pairs", "synthesise_pair", "line_lag", "PairDifferentials", "pair_differentials",
           "knowledge_ceilings", "knowledge_error_prior", "conditioned_excesses", "shrunk_excesses", "offset_shared_excesses", "raised_uniformly", "raise_by_excess_shrink", "knowledge_filter_errors", "knowledge_latency_errors", "raise_by_knowledge_filter", "knowledge_proves_excess", "knowledge_crossover_hz", "yaw_pitch_coupling", "yaw_coupling", "integrate_differentials", "noise_share_of_excess", "excess_the_knowledge_proves_noise", "colour_weighted", "dephased_knowledge", "knowledge_latency", "advanced_knowledge", "knowledge_smoothings", "knowledge_smoothing_correction", "undo_exposure", "predicted_sigma", "knowledge_conditioned", "knowledge_band_weighted", "band_noise", "raise_by_local_error", "raise_by_knowledge_check", "local_errors", "sigma_limit", "flag_uncertain", "remove_mean", "restored_from", "anchor_on_star_tracker", "anchoring_sigma", "add_anchoring_sigma", "check_coverage", "correct_images",
           "attitude_series"]


# --------------------------------------------------------------------------- pairs, select, match
def visible_pairs(detectors) -> list[tuple[str, str]]:
    """All (ahead, behind) pairs of the visible bands (most correlated; every band if fewer than two are
    visible), skipping bands at the same along-track position."""
    dets = list(detectors)
    vis = [d for d in dets if d.band in ("blue", "green", "red")]
    use = vis if len(vis) >= 2 else dets
    pairs = []
    for i, a in enumerate(use):
        for b in use[i + 1:]:
            if a.along_m == b.along_m:
                continue
            ahead, behind = (a, b) if a.along_m > b.along_m else (b, a)
            pairs.append((ahead.name, behind.name))
    return pairs


def auto_pairs(product: Product) -> list[tuple[str, str]]:
    """All pairs of the visible bands (most correlated), ordered ahead/behind (:func:`visible_pairs`)."""
    pairs = visible_pairs(product.instrument.detectors)
    if not pairs:
        raise RestorationError("no band pair with different along-track positions: differentials are impossible")
    return pairs


def resolve_pairs(product: Product, settings: RestorationSettings) -> list[tuple[str, str]]:
    """The (ahead, behind) band pairs of ``restoration.pairs`` ("auto": :func:`auto_pairs`)."""
    if settings.pairs == "auto":
        return auto_pairs(product)
    names = product.band_names
    out = []
    for p in settings.pairs:
        a, b = p.split("/")
        for n in (a, b):
            if n not in names:
                raise ScenarioError(f"restoration.pairs: unknown band {n!r} in {p!r} (bands: {', '.join(names)})")
        da, db = product.instrument.detector(a), product.instrument.detector(b)
        if da.along_m == db.along_m:
            raise ScenarioError(f"restoration.pairs: {p!r} has no delay (same along-track position)")
        out.append((a, b) if da.along_m > db.along_m else (b, a))
    return out




#: pilot matching: every how many lines, and at most how many points per line
_PILOT_LINE_STEP = 2
_PILOT_POINTS = 6


def pilot_shift(img_a, img_b, lines_a, cols_a, pred_l, pred_c, n_lines: int, settings: RestorationSettings):
    """Per-line shift of band B with respect to the knowledge prediction [px], from a sparse wide search.

    The knowledge prediction can be off by more than the matcher's search
    half-range where the jitter differential peaks (beats of the CMG lines).
    A pilot pass matches a few points of every other line with the wide
    ``settings.pilot_search``; the median shift of each line (interpolated
    between lines) re-centres the search of every point, so that the
    search area follows the predictor's actual accuracy while staying small
    (few false peaks on periodic textures).

    Returns
    -------
    (shift_lines, shift_cols) : ndarray (n_lines,) each
        Zero where nothing could be measured (and everywhere when the pilot
        search is not wider than the search).
    """
    zero = (np.zeros(n_lines), np.zeros(n_lines))
    ps = settings.pilot_search
    if lines_a.size == 0 or (ps[0] <= settings.search[0] and ps[1] <= settings.search[1]):
        return zero
    ps = (max(ps[0], settings.search[0]), max(ps[1], settings.search[1]))
    li = np.rint(lines_a).astype(np.int64)
    # a few points spread along each pilot line (every k-th of its points in column order)
    rank, count = rank_within_line(li, cols_a)
    keep = (rank % np.maximum(count // _PILOT_POINTS, 1) == 0) & (li % _PILOT_LINE_STEP == 0)
    ml, mc = support_margin(window=settings.window, search=ps)
    nb = img_b.shape
    keep &= (pred_l > ml) & (pred_l < nb[0] - 1 - ml) & (pred_c > mc) & (pred_c < nb[1] - 1 - mc)
    if not keep.any():
        return zero
    m = match_points(img_a, img_b, lines_a[keep], cols_a[keep], pred_l[keep], pred_c[keep], window=settings.window,
                     search=ps, method="ncc", min_quality=settings.min_quality)
    ok = np.asarray(m.valid, bool)
    if ok.sum() < 2:
        return zero
    lk = li[keep][ok]
    few = np.bincount(lk, minlength=n_lines)[:n_lines] < 2  # a line's shift needs two points at least
    out = []
    for d in (m.line_b[ok] - pred_l[keep][ok], m.col_b[ok] - pred_c[keep][ok]):
        med = line_median(lk, d, np.ones(d.size, dtype=bool), n_lines)
        med[few] = np.nan
        have = np.flatnonzero(np.isfinite(med))
        out.append(np.interp(np.arange(n_lines), have, med[have]) if have.size else np.zeros(n_lines))
    return out[0], out[1]




@dataclass
class Candidates:
    """Points selected in band ``ahead`` and their knowledge prediction in band ``behind`` [px]."""

    ahead: str
    behind: str
    nominal_tau_s: float
    line_a: np.ndarray
    col_a: np.ndarray
    pred_line_b: np.ndarray
    pred_col_b: np.ndarray

    @property
    def name(self) -> str:
        return f"{self.ahead}/{self.behind}"


def shared_columns(sm, ahead: str, behind: str, shape_a: tuple, shape_b: tuple, *, lines, margin_cols: int
                   ) -> tuple[int, int]:
    """First and last column of band ``ahead`` whose ground band ``behind`` also sees (knowledge geometry).

    Every column of A is located on the ground at a few ``lines`` and back in B;
    the columns that land inside B (``margin_cols`` from its edges) on all of
    them are shared. The main strip and a small dedicated detector share only
    the columns the small one covers (claim 20).
    """
    n_a, n_b = int(shape_a[1]), int(shape_b[1])
    cols = np.arange(n_a, dtype=float)
    ok = np.ones(n_a, dtype=bool)
    for ln in np.asarray(lines, dtype=float):
        g = sm.direct_location(ahead, np.full(n_a, ln), cols)
        _, pc = sm.inverse_location(behind, g)
        ok &= np.isfinite(pc) & (pc > margin_cols) & (pc < n_b - 1 - margin_cols)
    if not ok.any():
        raise RestorationError(f"pair {ahead}/{behind}: the two detectors share no columns (band {behind} sees "
                               f"none of band {ahead}'s ground); check instrument.detectors[].across_track_mm and "
                               f"pixels, or restoration.pairs")
    idx = np.flatnonzero(ok)
    return int(idx[0]), int(idx[-1])


def select_candidates(img_a: np.ndarray, shape_b: tuple, ahead: str, behind: str, settings: RestorationSettings,
                      sm, noise=None) -> Candidates:
    """Select points in band ``ahead`` (a-priori criterion) and predict them in ``behind`` with the knowledge.

    Only lines whose homologues fall inside band B (with the matcher's support
    margin) are used, and only the columns B shares (:func:`shared_columns`);
    points predicted outside B are dropped. ``noise``: band A's noise
    (:func:`band_noise`); None: estimated on the image.
    """
    n_lines = img_a.shape[0]
    tau = sm.nominal_delay_s(ahead, behind)
    shift_lines = tau / sm.instrument.line_period_s
    ml, mc = support_margin(window=settings.window, search=settings.search)
    usable = np.zeros(n_lines, dtype=bool)
    lo = ml + 1
    hi = int(np.floor(n_lines - 1 - shift_lines - ml - 2))
    if hi <= lo:
        raise RestorationError(f"pair {ahead}/{behind}: image too short ({n_lines} lines) for a delay of "
                               f"{shift_lines:.1f} lines")
    usable[lo:hi] = True
    c0, c1 = shared_columns(sm, ahead, behind, img_a.shape, shape_b, lines=np.linspace(lo, hi, 5), margin_cols=mc)
    # select only where band B sees the same ground (a small detector shares a few of A's columns):
    # the crop keeps the matcher's support margin on both sides, so the feasible points are the same
    a0, a1 = max(c0 - mc, 0), min(c1 + mc + 1, img_a.shape[1])
    if (c1 - c0 + 1) >= 0.9 * (img_a.shape[1] - 2 * mc):
        # B sees (nearly) all of A: no crop, the selection as it always was. (Cropping even one column
        # changes which points the selection spreads over the lines, and on stress_large_amplitude that
        # alone doubled the error — measured, not understood yet: the crop is kept for small detectors.)
        a0, a1 = 0, img_a.shape[1]
    crop = img_a if (a0, a1) == (0, img_a.shape[1]) else np.ascontiguousarray(img_a[:, a0:a1])
    lines_a, cols_a = select_points_in_blocks(crop, method=settings.selection,
                                              per_line=settings.points_per_line, window=settings.window,
                                              search=settings.search, margin=(ml, mc), line_mask=usable,
                                              max_std=settings.texture_max_std_px,
                                              noise_std=band_noise(crop, settings.noise_model) if noise is None
                                              else noise)
    cols_a = cols_a + a0
    if lines_a.size == 0:
        return Candidates(ahead, behind, tau, lines_a, cols_a, lines_a.copy(), cols_a.copy())
    g = sm.direct_location(ahead, lines_a, cols_a)
    pl, pc = sm.inverse_location(behind, g)
    nb_cols = shape_b[1]
    inside = np.isfinite(pl) & np.isfinite(pc) & (pl > ml) & (pl < n_lines - 1 - ml) & (pc > mc) & \
        (pc < nb_cols - 1 - mc)
    return Candidates(ahead, behind, tau, lines_a[inside], cols_a[inside], pl[inside], pc[inside])


def match_candidates(img_a: np.ndarray, img_b: np.ndarray, cand: Candidates, settings: RestorationSettings
                     ) -> PairData:
    """Match the candidates in band B, each search centred on the pilot's per-line shift.

    The residuals stay relative to the knowledge prediction (``pred_*``).
    """
    n_lines = img_a.shape[0]
    lines_a, cols_a, pl, pc = cand.line_a, cand.col_a, cand.pred_line_b, cand.pred_col_b
    if lines_a.size == 0:
        return PairData(name=cand.name, ahead=cand.ahead, behind=cand.behind, tau_s=cand.nominal_tau_s,
                        line_a=lines_a, col_a=cols_a, meas_line_b=lines_a.copy(), meas_col_b=cols_a.copy(),
                        quality=lines_a.copy(), valid=np.zeros(0, dtype=bool), nominal_tau_s=cand.nominal_tau_s)
    sh_l, sh_c = pilot_shift(img_a, img_b, lines_a, cols_a, pl, pc, n_lines, settings)
    li = np.clip(np.rint(lines_a).astype(np.int64), 0, n_lines - 1)
    m = match_points(img_a, img_b, lines_a, cols_a, pl + sh_l[li], pc + sh_c[li], window=settings.window,
                     search=settings.search, method=settings.match_method, min_quality=settings.min_quality)
    return PairData(name=cand.name, ahead=cand.ahead, behind=cand.behind, tau_s=cand.nominal_tau_s, line_a=lines_a,
                    col_a=cols_a, meas_line_b=m.line_b, meas_col_b=m.col_b, quality=m.quality,
                    valid=np.asarray(m.valid, bool), pred_line_b=pl, pred_col_b=pc,
                    std_line=np.asarray(m.std_line, float), std_col=np.asarray(m.std_col, float),
                    corr_line_col=np.asarray(m.corr_line_col, float), nominal_tau_s=cand.nominal_tau_s)


def match_pair(product: Product, ahead: str, behind: str, settings: RestorationSettings, sm=None) -> PairData:
    """Select points in band ``ahead``, predict them in ``behind``, match them."""
    sm = sm or product.sensor_model()
    img_a = product.image(ahead)
    img_b = product.image(behind)
    cand = select_candidates(img_a, img_b.shape, ahead, behind, settings, sm,
                             noise=band_noise(img_a, settings.noise_model, product.radiometry))
    return match_candidates(img_a, img_b, cand, settings)


# --------------------------------------------------------------------------- rematch (coarse to fine)
#: "auto" rematch: one pass when the estimate moves by more than this between consecutive lines (RMS) [px]:
#: then band B is sheared within a matching window by a good part of a pixel
REMATCH_RATE_PX_PER_LINE = 0.3


def line_rate_px(estimate: dict, axes, pixel_ifov_rad: float) -> float:
    """RMS change of the estimate from one line to the next, worst restored axis [px per line]."""
    steps = {a: np.diff(np.asarray(estimate[a], dtype=np.float64)) for a in axes}
    return _worst_axis_rms_px(steps, axes, pixel_ifov_rad, centre=False)


#: "auto" rematch: another pass while the estimate moves by more than this between passes (RMS, worst axis) [px]
REMATCH_CONVERGED_PX = 0.01
#: "auto" rematch: at most this many passes
MAX_AUTO_REMATCH = 2


def _worst_axis_rms_px(series: dict, axes, pixel_ifov_rad: float, *, centre: bool) -> float:
    """RMS over the finite samples, worst of ``axes`` [px] (``centre``: mean removed first)."""
    out = 0.0
    for a in axes:
        d = np.asarray(series[a], dtype=np.float64)
        d = d[np.isfinite(d)]
        if d.size:
            out = max(out, float(np.sqrt(np.mean((d - d.mean() if centre else d) ** 2))) / pixel_ifov_rad)
    return out


def estimate_change_px(before: dict, after: dict, axes, pixel_ifov_rad: float) -> float:
    """RMS change between two estimates over the lines both restore, worst axis [px] (means removed)."""
    diff = {a: np.asarray(after[a], dtype=np.float64) - np.asarray(before[a], dtype=np.float64) for a in axes}
    return _worst_axis_rms_px(diff, axes, pixel_ifov_rad, centre=True)


def rematch_moved(before: dict, after: dict, axes, pixel_ifov_rad: float) -> bool:
    """Whether a rematch pass still moved the estimate by more than :data:`REMATCH_CONVERGED_PX` ("auto")."""
    return estimate_change_px(before, after, axes, pixel_ifov_rad) > REMATCH_CONVERGED_PX


def rematch_passes(setting, estimate: dict, axes, pixel_ifov_rad: float) -> int:
    """Passes of rematching: the number given, or for "auto" one when :func:`line_rate_px` exceeds
    :data:`REMATCH_RATE_PX_PER_LINE` (large amplitude), else none. With "auto" the restorer adds
    passes, up to :data:`MAX_AUTO_REMATCH`, while the last one moved the estimate by more than
    :data:`REMATCH_CONVERGED_PX` (:func:`estimate_change_px`)."""
    if setting != "auto":
        return int(setting)
    return int(line_rate_px(estimate, axes, pixel_ifov_rad) > REMATCH_RATE_PX_PER_LINE)


def valid_fraction(pairs: list) -> float:
    """The worst pair's fraction of valid matches."""
    return min((float(np.mean(p.valid)) if p.valid.size else 0.0) for p in pairs) if pairs else 0.0


def rematch_pairs(product: Product, pairs: list, attitude: dict, settings: RestorationSettings) -> list:
    """Every pair matched again in B resampled into A's geometry with ``attitude`` (:mod:`restore.rematch`)."""
    sm = product.sensor_model(attitude=clamped_attitude(attitude_series(product.time, attitude)))
    return [rematch_pair(p, product.image(p.ahead), product.image(p.behind), sm, window=settings.window,
                         search=settings.rematch_search, method=settings.match_method,
                         min_quality=settings.min_quality) for p in pairs]


# --------------------------------------------------------------------------- synthesise
def synthesise_pair(pair: PairData, sm, settings: RestorationSettings, n_lines: int, *, sens=None) -> PairData:
    """Instant synthesis of one pair with the sensor model ``sm`` (the current attitude).

    Returns a new :class:`PairData` with the prediction of the valid matches in
    band B, the sensitivities (``sens`` when given: computed once, on the first
    iteration), the inliers, the synthesis and the actual delay τ′ (median over
    the points of the predicted line offset × line period: off nadir, over
    relief or with pitch, τ′ differs from the nominal delay).
    """
    v = pair.valid
    la, ca = pair.line_a[v], pair.col_a[v]
    g = sm.direct_location(pair.ahead, la, ca)
    pl, pc = sm.inverse_location(pair.behind, g)
    if sens is None:
        sens = sm.sensitivities(pair.behind, g)
    pred_l = np.full(v.shape, np.nan)
    pred_c = np.full(v.shape, np.nan)
    pred_l[v], pred_c[v] = pl, pc
    w, rho = match_weights(pair, v, covariance=settings.match_covariance)
    res = instant_synthesis(np.rint(la).astype(np.int64), pair.meas_line_b[v] - pl, pair.meas_col_b[v] - pc, sens,
                            n_lines=n_lines, weights=w, correlation=rho, axes=settings.axes,
                            min_points=settings.min_points_per_line, n_sigma=settings.n_sigma)
    inl = np.zeros(v.shape, dtype=bool)
    inl[v] = res.inlier
    tau_pts = (pl - la) * sm.instrument.line_period_s
    tau = float(np.median(tau_pts)) if tau_pts.size else pair.tau_s
    return replace(pair, pred_line_b=pred_l, pred_col_b=pred_c, sens=sens, inlier=inl, synthesis=res, tau_s=tau,
                   residual_rms_px=float(res.residual_rms_px))


def line_lag(pair: PairData, n_lines: int, max_gap: int, line_period_s: float) -> np.ndarray:
    """Per-line extra delay of the pair [lines]: mean over the line's inliers of the matched line offset less τ′.

    Band B sees a point of line l of A at ``t + (l_B − l)·Te``, ``l_B`` its matched line: with ``τ′`` the pair's
    delay (:attr:`PairData.tau_s`), the extra delay is ``Δl = l_B − l − τ′/Te`` (pitch jitter changes the actual
    delay) and the differential of that line is ``δ(t + τ′ + Δl Te) − δ(t)``, not ``δ(t + τ′) − δ(t)``.

    The offset is measured from the delay, not from the prediction the residual was taken about: the AOCS
    knowledge's prediction moves with the knowledge's own differential, which at its rate is mostly its noise
    (phr_cmg's 0.3 µrad per 64 Hz sample: 0.05-0.10 lines RMS over 7-22 ms). Measured from that prediction, the
    lag missed it, and at large amplitude the far end of every differential was misplaced by it times the jitter's
    rate (a 1.9 px CMG scene: the error of pitch's integrated matching noise 0.0259 → 0.0204 px with it).
    """
    inl = pair.inlier if pair.inlier is not None else pair.valid
    li = np.rint(pair.line_a[inl]).astype(np.int64)
    dl = (pair.meas_line_b - pair.line_a)[inl] - float(pair.tau_s) / float(line_period_s)
    ok = np.isfinite(dl)
    n = np.bincount(li[ok], minlength=n_lines)
    sm = np.bincount(li[ok], dl[ok], minlength=n_lines)
    lag = np.where(n > 0, sm / np.maximum(n, 1), np.nan)
    lag = fill_short_gaps(lag, max_gap=max(max_gap, 64))
    return np.nan_to_num(lag)


@dataclass
class PairDifferentials:
    """One pair's differentials of one iteration, as they are integrated.

    ``diffs``/``sigmas``: axis → (N,) [rad] (gaps dropped/filled, window
    compensated); ``lag_s``: extra delay per line [s]; ``weight``: relative
    weight per line (matched points, at least ``min_points_per_line``; 0 on
    filled lines); ``axis_factor``: axis → (N,) factor on ``weight`` for that
    axis (:func:`line_weight_factors`), none by default.
    """

    tau_s: float
    diffs: dict
    sigmas: dict
    lag_s: np.ndarray
    weight: np.ndarray
    axis_factor: dict = field(default_factory=dict)

    def weight_for(self, axis: str) -> np.ndarray:
        """The line weights ``axis`` is integrated with."""
        f = self.axis_factor.get(axis)
        return self.weight if f is None else self.weight * f


def pair_differentials(pair: PairData, settings: RestorationSettings, n_lines: int,
                       line_period_s: float, *, drop: dict | None = None) -> PairDifferentials:
    """Condition a synthesised pair's differentials for the integration (gaps, window, lags, weights).

    Short gaps are filled (cubic) for the methods and filters that need
    uniform samples; the filled lines, and the neighbours the window
    compensation mixes them into, get weight 0 (a method that weighs its
    samples treats them as missing).

    ``drop``: axis → lines (boolean mask) whose synthesis is a gross error
    (:func:`differential_spikes`): dropped before the gaps are handled, so
    that an isolated one is filled as a short gap.
    """
    res = pair.synthesis
    diffs, sigmas = {}, {}
    filled = np.zeros(res.diff.shape[0], dtype=bool)
    for k, a in enumerate(AXES):
        d = res.diff[:, k]
        if drop and a in drop:
            d = np.where(drop[a], np.nan, d)
        d = drop_sparse(d, half_window=max(settings.max_gap_fill_lines, 1))
        gaps = ~np.isfinite(d)
        d = fill_short_gaps(d, max_gap=settings.max_gap_fill_lines)
        filled |= gaps & np.isfinite(d)
        if settings.compensate_window:
            d = window_compensation(d, window_lines=settings.window[0])
        diffs[a] = d
        sigmas[a] = res.sigma[:, k]
    weight = np.where(res.n_points >= settings.min_points_per_line, res.n_points,
                      settings.min_points_per_line).astype(np.float64)
    # a filled line is an interpolation, not a measurement: it serves the spectrum estimate and the window
    # compensation (whose taps reach its neighbours) but carries no weight (where a fold of the band at
    # several pixels of jitter makes the differential jump, a cubic through the gap is pixels off)
    h = settings.window[0] // 2 if settings.compensate_window else 0
    if h and filled.any():
        filled = maximum_filter1d(filled.astype(np.uint8), 2 * h + 1).astype(bool)
    weight = np.where(filled, 0.0, weight)
    lag = line_lag(pair, n_lines, settings.max_gap_fill_lines, line_period_s) * line_period_s
    return PairDifferentials(tau_s=pair.tau_s, diffs=diffs, sigmas=sigmas, lag_s=lag, weight=weight)


def differential_spikes(pair: PairData, differentials: PairDifferentials, increments: dict,
                        settings: RestorationSettings, line_period_s: float) -> dict:
    """Axis → lines of the pair whose synthesised differential is a gross error (:func:`restore.synthesis.spikes`).

    The residual is the synthesised differential (before gap filling and
    window compensation) minus the differential that ``increments`` (what
    the last integration added, per axis) predicts at the pair's delay and
    per-line lags. Empty with ``settings.despike_sigma = 0``.
    """
    if settings.despike_sigma <= 0:
        return {}
    out = {}
    for k, a in enumerate(AXES):
        if a not in increments:
            continue
        # NaN where the increment is unknown (long gaps): no residual there, rather than one against zeros
        pred = predicted_differential(increments[a], differentials.tau_s, line_period_s, differentials.lag_s)
        mask = spikes(pair.synthesis.diff[:, k] - pred, n_sigma=settings.despike_sigma)
        if mask.any():
            out[a] = mask
    return out


def line_weight_factors(differentials: list, records: dict, settings: RestorationSettings,
                        line_period_s: float) -> list:
    """Per pair, axis → the weight factor of each line for what makes its matches worse (:mod:`restore.line_weights`).

    Each axis's fit residual (the pair's differentials minus those its last
    integration predicts), normalised by the line weights, is binned first by
    the stretch of B's window against A's ``|dλ/dl|``, then by the distance
    to the nearest gap; the two factors multiply. Returns one dict per pair of
    ``differentials`` (empty with ``restoration.line_weighting`` off, or for
    a single pair: nothing to measure its noise against).
    """
    out = [dict() for _ in differentials]
    if not settings.line_weighting or len(differentials) < 2:
        # one pair's residual is no measure of its noise: the fit, with one unknown per line, absorbs it but
        # where the prior holds the signal back, which grows with the stretch too (small_detector's roll
        # 0.035 → 0.044 px weighted)
        return out
    for a, rec in records.items():
        if not integration_method(rec.method).line_weights:
            continue                    # a method that ignores line weights: nothing to gain
        d = np.asarray(rec.diffs, dtype=np.float64)
        base = np.asarray(rec.weights, dtype=np.float64)     # what the residual was fitted with
        res = fit_residuals(d, np.asarray(rec.increment, dtype=np.float64), [float(t) for t in rec.taus],
                            rec.lags_s, line_period_s, highpass_hz=rec.highpass_hz)
        usable = np.isfinite(res) & np.isfinite(d) & (base > 0)
        # no lag is measured in a gap (line_lag's zeros there are no stretch)
        lag_lines = np.asarray(rec.lags_s, dtype=np.float64) / line_period_s     # the record holds the pairs' lags
        f = residual_weight_factors(res, window_stretch(np.where(np.isfinite(d), lag_lines, np.nan)), usable, base)
        # the gaps are the stretches left unfilled (cloud, water, no texture), not a failed line filled over
        f = f * residual_weight_factors(res, gap_distance(np.isfinite(d)), usable, base * f, increasing=False)
        if np.all(f == 1.0):
            continue
        for j in range(len(differentials)):
            out[j][a] = f[j]
    return out


# --------------------------------------------------------------------------- integrate
#: "auto" high-pass: this fraction of the AOCS knowledge's cut-off (10 Hz knowledge → 2 Hz)
HIGHPASS_FRACTION_OF_KNOWLEDGE = 0.2
#: "auto" high-pass of a product that does not record its knowledge's cut-off [Hz]
HIGHPASS_WITHOUT_KNOWLEDGE_SPEC_HZ = 2.0


#: "auto" matching window: the candidate widths [columns], narrowest first
WINDOW_COLUMN_CANDIDATES = (31, 47, 63)
#: "auto" matching window: widen until the median a-priori matching σ is at most this [px]
WINDOW_TARGET_STD_PX = 0.1


def band_noise(image: np.ndarray, model: str = "signal_dependent", radiometry=None):
    """The band's noise for the texture criterion: its :class:`~restore.selection.NoiseLevel` (σ² = a + b ×
    level: shot noise grows with the signal), or one σ for the band (``model = "constant"``).

    The level function is the detector's calibration when the product records it (``radiometry``,
    :attr:`simsat.product.Product.radiometry`), else fitted on the image
    (:func:`~restore.selection.noise_level_function`; the texture inflates it on bright ground)."""
    if model == "constant":
        return estimate_image_noise(image)
    if radiometry is not None:
        return NoiseLevel.from_radiometry(radiometry)
    return noise_level_function(image)


def window_columns_for(image: np.ndarray, *, window_lines: int, max_lines: int = 1000,
                       noise_model: str = "signal_dependent", radiometry=None) -> int:
    """The narrowest window width whose median a-priori matching σ (Delon–Rougé) reaches the target.

    A wider window averages more texture against the noise (σ ∝ 1/√width) but
    follows the geometry less closely; on well-lit textured ground the
    narrowest one already matches to better than ``WINDOW_TARGET_STD_PX``, on
    a dim or flat scene the window widens (to the widest candidate at most).
    Estimated on the first ``max_lines`` lines of the band.
    """
    img = np.asarray(image[:max_lines], dtype=np.float64)
    noise = band_noise(img, noise_model, radiometry)
    for w in WINDOW_COLUMN_CANDIDATES:
        sl, sc = expected_matching_std(img, window=(window_lines, w), noise_std=noise)
        s = np.maximum(sl, sc)
        s = s[np.isfinite(s)]
        if s.size and float(np.median(s)) <= WINDOW_TARGET_STD_PX:
            return w
    return WINDOW_COLUMN_CANDIDATES[-1]


def highpass_from_product(setting, product: Product) -> float:
    """The high-pass cut-off [Hz]: ``restoration.highpass_hz``, or with "auto" derived from the product.

    The AOCS knowledge follows the attitude below its cut-off ``f_c``
    (``knowledge_cutoff_hz`` in product.nc); the images must supply what lies
    above. Differentials observe low frequencies badly (``|G| ≈ 2π f τ``), so
    the estimate is high-passed at ``0.2 f_c``: every frequency the knowledge
    misses is kept, and the band ``0.2 f_c … f_c`` is covered by both (the
    differentials measure what the knowledge got wrong there, not the attitude
    twice).
    """
    if setting != "auto":
        return float(setting)
    cutoff = product.ds.attrs.get("knowledge_cutoff_hz")
    if cutoff is None:
        return HIGHPASS_WITHOUT_KNOWLEDGE_SPEC_HZ
    return HIGHPASS_FRACTION_OF_KNOWLEDGE * float(cutoff)


#: "auto" high-pass: lowered to the knowledge crossover only when that lies below this fraction of the default.
#: The images' error below a few Hz is modelled optimistically — a slow error common to all the points of a
#: line, which neither the noise model nor the residual check sees, 2-4× the modelled power (measured on
#: phr_cmg, low_frequencies and a 15° forward view, whose crossover at 0.49 × the default lowered the high-pass
#: and took pitch from 0.037 to 0.050 px); with the images' error ∝ 1/f², a crossover at a quarter of the
#: default keeps them ≥ 4× better than the knowledge over the upper three quarters of the band it opens
CROSSOVER_FRACTION = 0.25


def knowledge_crossover_hz(records: dict, sigma: dict, product: Product, highpass_hz: float) -> float | None:
    """Where the images' error falls below the AOCS knowledge's noise, worst restored axis [Hz]; None if unknown.

    Below the high-pass the restored angle is the knowledge's, whose white
    noise of ``σ_k`` per sample at ``f_k`` (recorded in product.nc) has the PSD
    ``E_k = σ_k² / f_k``; above, the images' error at low frequency is
    ``1 / Σ_j |G_j(f)|² / N_j`` with ``|G_j| ≈ 2π f τ_j`` and ``N_j`` each
    pair's noise PSD there — its white level ``σ_j² Δt`` times the colour the
    predicted σ's band-by-band check measured at the current high-pass
    (matching noise rises towards low frequencies). The two cross at

        f* = 1 / (2π √(E_k Σ_j τ_j² / N_j)).

    The larger crossover of the restored axes is returned (a high-pass both
    can afford). None without the knowledge's noise in the product or without
    the measured colour (``posterior_samples = 0``): the white level alone
    underestimates the low-frequency noise 3-4× and would put the crossover
    too low.
    """
    spec = product.knowledge_noise
    if spec is None:
        return None
    e_k = spec[0] ** 2 / spec[1]
    if e_k <= 0:
        return None
    out = None
    for a, rec in records.items():
        ps = sigma.get(a)
        if ps is None or ps.noise_colour is None or rec.spectrum is None:
            return None
        dt = float(rec.line_period_s)
        n = np.asarray(rec.diffs).shape[1]
        f = np.fft.rfftfreq(n, dt)
        k = int(np.clip(np.searchsorted(f, max(highpass_hz, f[1])), 0, f.size - 1))
        noise = np.asarray(rec.spectrum.noise_std, dtype=np.float64) ** 2 * dt * ps.noise_colour[:, k]
        taus = np.asarray(rec.taus, dtype=np.float64)
        ok = np.isfinite(noise) & (noise > 0)           # a pair without a noise level does not count
        s = float(np.sum(taus[ok] ** 2 / noise[ok]))
        if not np.isfinite(s) or s <= 0:
            return None
        # (below the record's resolution 1/(n Δt) the high-pass only takes the record's slow trend out:
        # on geo_noisy_knowledge's 0.8 s record 0.23 Hz gives 0.062 / 0.048 px, 1.25 Hz 0.083 / 0.054)
        fx = 1.0 / (2 * np.pi * np.sqrt(e_k * s))
        out = fx if out is None else max(out, fx)
    return out


def knowledge_proves_excess(record: IntegrationRecord, lo_hz: float, hi_hz: float) -> bool:
    """Whether the axis's differentials showed, somewhere in ``[lo_hz, hi_hz)``, more than the attitude can have.

    The prior estimated from the differentials is clipped to the AOCS
    knowledge's ceiling (:func:`knowledge_ceilings`); where the estimate
    reached it (``PriorSpectrum.above_ceiling``), the knowledge proves the
    differentials hold power that is not attitude: a band's own error that
    every point of a line shares, which no residual shows (phr_cmg's pitch at
    0.6–3 Hz). True also when nothing is known (no ceiling, no spectrum): the
    high-pass is then not lowered on that evidence.
    """
    spec = record.spectrum
    above = None if spec is None else spec.above_ceiling
    if above is None:
        return True
    f = np.asarray(spec.freq, dtype=np.float64)
    band = (f >= lo_hz) & (f < hi_hz)
    return bool(np.any(np.asarray(above, dtype=bool)[band]))


def knowledge_ceilings(product: Product, knowledge: dict, settings: RestorationSettings) -> dict:
    """Per axis, the ceiling the AOCS knowledge puts on the prior PSD (:mod:`restore.knowledge_prior`):
    ``(freq, ceiling)``, or with ``knowledge_noise_floor`` ``(freq, ceiling, floor)``, the floor its own
    white noise puts under it (:func:`~restore.knowledge_prior.knowledge_noise_floor`).

    Empty when ``knowledge_prior`` is off or the product does not record its
    knowledge's filter (cut-off, order, rate, noise).
    """
    attrs = product.ds.attrs
    if not settings.knowledge_prior or "knowledge_cutoff_hz" not in attrs or "knowledge_filter_order" not in attrs \
            or product.knowledge_noise is None:
        return {}
    dt = product.instrument.line_period_s
    noise_rad, rate_hz = product.knowledge_noise
    out = {a: knowledge_psd_ceiling(knowledge[a], dt, cutoff_hz=float(attrs["knowledge_cutoff_hz"]),
                                    order=int(attrs["knowledge_filter_order"]), rate_hz=rate_hz, noise_rad=noise_rad,
                                    kind=str(attrs.get("knowledge_filter", "butterworth_zero_phase")))
           for a in settings.axes}
    if settings.knowledge_noise_floor:
        out = {a: (f, c, knowledge_noise_floor(f, rate_hz=rate_hz, noise_rad=noise_rad)) for a, (f, c) in out.items()}
    return out


def integrate_differentials(axis: str, used: list, differentials: list, previous: np.ndarray,
                            settings: RestorationSettings, line_period_s: float, *, where="",
                            psd_ceiling=None, no_blind_tone: bool = False) -> IntegrationRecord:
    """Integrate one axis's differentials of the pairs ``used`` (:func:`integrate_axis`), recorded.

    ``psd_ceiling`` (freq, ceiling): what the AOCS knowledge already knows
    (:func:`knowledge_ceilings`), for methods that estimate a prior.
    ``no_blind_tone``: skip the search for a tone on a common blind frequency
    (an integration of the same differentials, reweighted, found none).
    """
    diffs = [d.diffs[axis] for d in differentials]
    if all(np.all(~np.isfinite(d)) for d in diffs):
        counts = "; ".join(f"{p.name}: {int(np.count_nonzero(p.valid))} valid of {p.valid.size} candidates over "
                           f"{previous.size} lines" for p in used)
        raise RestorationError(
            f"{where}: no line could be synthesised on {axis}: fewer than restoration.min_points_per_line = "
            f"{settings.min_points_per_line} good matches on every line ({counts}); the bands are too noisy or "
            f"too poorly textured for the a-priori criterion (restoration.texture_max_std_px = "
            f"{settings.texture_max_std_px}) and restoration.min_quality = {settings.min_quality}")
    taus = [d.tau_s for d in differentials]
    lags = [d.lag_s for d in differentials]
    sigmas = [d.sigmas[axis] for d in differentials]
    weights = [d.weight_for(axis) for d in differentials]
    method, selection = resolve_method(settings.method, diffs, taus, line_period_s, lags=lags, sigmas=sigmas,
                                       weights=weights, psd_ceiling=psd_ceiling)
    options = settings.integration_options if selection is None else {}
    if no_blind_tone and integration_method(method).blind_tones and "tones" not in options:
        options = {**options, "tones": None}
    res = integrate_axis(diffs, taus, line_period_s, method=method,
                         options=options,
                         lags=lags, sigmas=sigmas, weights=weights, highpass_hz=settings.highpass_hz,
                         psd_ceiling=psd_ceiling, transient_factor=settings.transient_factor)
    prior = res.spectrum or spectrum_for_lines(diffs, taus, line_period_s)
    obs = observability(prior.freq, prior.psd, prior.noise_std, taus, line_period_s, highpass_hz=settings.highpass_hz)
    return IntegrationRecord(axis=axis, pairs=[p.name for p in used], diffs=np.array(diffs), sigmas=np.array(sigmas),
                             taus=np.array(taus), lags_s=np.array(lags), weights=np.array(weights),
                             line_period_s=line_period_s, method=res.method.name, options=res.options,
                             highpass_hz=settings.highpass_hz, spectrum=res.spectrum, increment=res.theta,
                             previous=np.nan_to_num(previous), unobservable_rms_rad=obs.unobservable_rms_rad,
                             floor_rms_rad=obs.floor_rms_rad, selection=selection)


# --------------------------------------------------------------------------- coupled yaw
#: the image coordinate (row of the sensitivities) each axis moves: pitch lines, roll columns
_AXIS_ROW = {"pitch": (0, 1), "roll": (1, 0)}


def yaw_coupling(pairs: list, axis: str) -> float:
    """How much a yaw moves band B along ``axis``'s image direction, relative to the same ``axis`` angle.

    Pitch: ``Σ ∂l/∂ψ / Σ ∂l/∂θ`` (:func:`yaw_pitch_coupling`); roll: ``Σ ∂c/∂ψ / Σ ∂c/∂φ`` — tilted
    along track by θ₀ the line looks ahead, and a yaw sweeps it across track by tan θ₀ × yaw, the
    signature of a roll (coupling ≈ sin θ₀: the roll turns about the tilted body axis). Signed: the
    restored ``axis`` is off by ``coupling × (ψ − ψ_knowledge)``.
    """
    row, col = _AXIS_ROW[axis]
    num = den = 0.0
    for p in pairs:
        if p.sens is None or not len(p.sens):
            continue
        num += float(np.nansum(p.sens[:, row, 2]))
        den += float(np.nansum(p.sens[:, row, col]))
    return num / den if den else 0.0


def yaw_pitch_coupling(pairs: list) -> float:
    """How much a yaw moves band B along track, relative to the same pitch: ``Σ ∂l/∂ψ / Σ ∂l/∂θ``.

    At nadir a yaw turns the line about its centre (no mean along-track
    motion: 0); rolled off nadir by φ it shifts the whole line along track
    by tan φ × yaw (a pitch by 1 × pitch), the signature of a pitch: across a narrow field the
    images cannot tell them apart (the turn about the centre moves the line's
    ends by a few thousandths of a pixel per µrad), so the restored pitch is
    the along-track line-of-sight motion, pitch + coupling × (yaw the AOCS
    knowledge misses). Signed: the restored pitch is off by ``coupling × (ψ − ψ_knowledge)``.
    Looking ahead or behind (a pitch tilt), the same happens across track with roll
    (:func:`yaw_coupling`).
    """
    return yaw_coupling(pairs, "pitch")


# --------------------------------------------------------------------------- uncertainty
def noise_share_of_excess(colour: np.ndarray, freq: np.ndarray, spectrum, taus, dt: float) -> np.ndarray:
    """The part of a residual's excess over white that is the noise's: ``1 + (c − 1) ν / (ν + |G|² S)``.

    A fit residual above the white model's is noise the model lacks, or a
    signal the prior underrates (a chirp's onset, a transient), in proportion
    to how much of the pair's power each holds there: where the attitude seen
    through the pair, ``|G_j|² S``, dwarfs the noise ``ν_j = σ_j² Δt``, a few
    % of misfit make the excess, and weighing the residual down would lose
    the signal; where the noise dominates it is the noise's.
    """
    snr = pair_snr(freq, np.interp(freq, spectrum.freq, spectrum.psd), spectrum.noise_std, taus, dt)
    return 1.0 + (np.asarray(colour, dtype=np.float64) - 1.0) / (1.0 + snr)


def excess_the_knowledge_proves_noise(colour: np.ndarray, freq: np.ndarray, spectrum, taus, dt: float,
                                      ceiling) -> np.ndarray:
    """The part of a residual's excess over white that the AOCS knowledge proves is noise:
    ``1 + max(c − 1 − |G_j|² (C − S) / ν_j, 0)``.

    A fit residual above the white model's (``c × ν_j``, ν_j the pair's white
    noise density) is noise the model lacks, or a signal the prior ``S``
    underrates. The signal the MAP leaves in pair ``j``'s residual is at
    most what the prior misses of it seen through the pair, ``|G_j|² (S_true −
    S)``, and where the AOCS knowledge bounds the attitude it must restore
    (its ceiling ``C ≥ S_true``, :mod:`restore.knowledge_prior`) that is at
    most ``|G_j|² (C − S)``, in units of ν_j ``SNR_j (C/S − 1)`` (``SNR_j = |G_j|² S / ν_j``,
    :func:`~restore.integration.transfer.pair_snr`). What exceeds it can only
    be noise. Where the knowledge says nothing (``C`` infinite: well above its
    cut-off) nothing is proven and the colour is 1, unless the pair sees no
    signal there at all (``|G_j| = 0``: its residual is its noise). ``colour`` (pair, freq);
    ``ceiling`` (freq, ceiling) as :func:`knowledge_ceilings` gives it.
    """
    f = np.asarray(freq, dtype=np.float64)
    col = np.maximum(np.asarray(colour, dtype=np.float64), 1.0)
    room = np.maximum(ceiling_on_grid(ceiling, f) - np.interp(f, spectrum.freq, spectrum.psd), 0.0)
    gain = pair_snr(f, np.ones_like(f), spectrum.noise_std, taus, dt)          # |G_j|² / ν_j
    with np.errstate(invalid="ignore"):
        # a pair blind at f (|G_j| = 0) sees no signal there: its excess is all noise
        misfit = np.where(gain > 0, gain * room[None, :], 0.0)
    return 1.0 + np.maximum(col - 1.0 - misfit, 0.0)


def colour_weighted(record: IntegrationRecord, colour, ceiling=None) -> IntegrationRecord | None:
    """The axis's integration again, its prior frozen, weighing each pair's residual by the inverse of the
    noise colour the predicted σ's check measured; None where the method cannot or there is no colour.

    The prior and the white noise levels are estimated on the assumption of
    white matching noise, but the fit residual shows more at low frequencies
    (a band's own error common to a line's points; :mod:`restore.posterior`):
    there the MAP trusted the differentials too much. ``colour`` (pair,
    ``rfftfreq(lines, Δt)``) is :attr:`restore.posterior.PosteriorSigma.colour_estimate`,
    taken ≥ 1: it lowers the weight where the noise exceeds the white model,
    never raises it (the white level is measured where the pairs are blind,
    below it the ratio is the estimate's own scatter), and only by the
    noise's share of the excess (:func:`noise_share_of_excess`).

    ``ceiling`` (freq, ceiling): the AOCS knowledge's bound on the attitude
    (:func:`knowledge_ceilings`); given, only the excess it proves is noise
    counts (:func:`excess_the_knowledge_proves_noise`), and where that leaves
    nothing the record is not integrated again (None). The pipeline always
    gives it: an excess that could be a signal the prior underrates (a chirp's
    onset) is not weighed down.
    """
    if colour is None or record.spectrum is None or not integration_method(record.method).noise_colour:
        return None
    n = np.asarray(record.diffs).shape[1]
    col = np.maximum(np.asarray(colour, dtype=np.float64), 1.0)
    if col.shape != (len(record.taus), n // 2 + 1) or not np.all(np.isfinite(col)):
        return None
    f = np.fft.rfftfreq(n, record.line_period_s)
    if ceiling is not None:
        col = excess_the_knowledge_proves_noise(col, f, record.spectrum, record.taus, record.line_period_s, ceiling)
        if np.all(col == 1.0):
            return None
    col = noise_share_of_excess(col, f, record.spectrum, record.taus, record.line_period_s)
    spectrum = replace(record.spectrum, noise_colour=(f, col))
    weighted = replace(record, spectrum=spectrum)
    return replace(weighted, increment=weighted.rerun())


def dephased_knowledge(product: Product, settings: RestorationSettings) -> tuple[Product, dict]:
    """The product with its AOCS knowledge's causal phase taken out (:mod:`restore.knowledge_dephasing`), and
    ``{axis: (line,)}``, the dephased knowledge less the recorded one at the lines [rad], to add to the
    correction (the restored angle is the recorded knowledge plus the correction).

    The returned product's knowledge is the dephased series and its ``knowledge_filter`` reads
    ``butterworth_dephased`` (a zero-phase filter of gain ``|F|``), so that everything after — the matches'
    prediction, the prior's ceiling, the conditioning, the checks, the fusion, σ — reads a zero-phase knowledge.
    Unchanged (and ``{}``) with ``knowledge_dephasing`` off, a filter with no phase to take out, a product that
    does not record its filter, or knowledge samples not on a regular grid.
    """
    from .knowledge_dephasing import DEPHASABLE_KINDS, dephase_samples

    attrs = product.ds.attrs
    kind = str(attrs.get("knowledge_filter", "butterworth_zero_phase"))
    if not settings.knowledge_dephasing or kind not in DEPHASABLE_KINDS or "knowledge_cutoff_hz" not in attrs \
            or "knowledge_filter_order" not in attrs:
        return product, {}
    kn = product.knowledge
    tk = np.asarray(kn.time, dtype=np.float64)
    if tk.size < 3:
        return product, {}
    step = np.diff(tk)
    dt = float(np.median(step))
    if not np.all(np.abs(step - dt) <= 1e-6 * dt):
        return product, {}
    cutoff, order = float(attrs["knowledge_cutoff_hz"]), int(attrs["knowledge_filter_order"])
    series = AttitudeSeries(tk, *(dephase_samples(getattr(kn, a), dt, cutoff_hz=cutoff, order=order, kind=kind)
                                  for a in AXES))
    ds = product.ds.copy(deep=False)
    ds.attrs = {**dict(attrs), "knowledge_filter": DEPHASABLE_KINDS[kind], "knowledge_filter_recorded": kind}
    return _with_knowledge(replace(product, ds=ds), series)


def _with_knowledge(product: Product, series: AttitudeSeries) -> tuple[Product, dict]:
    """The product with ``series`` for its knowledge, and ``{axis: (line,)}``: the new knowledge less the old at
    the lines [rad]."""
    t = product.time
    before, after = product.knowledge.at(t), series.at(t)
    return replace(product, knowledge=series), {a: np.asarray(after[i] - before[i], dtype=np.float64)
                                                 for i, a in enumerate(AXES)}


def knowledge_latency(records: dict, knowledge: dict, product: Product, settings: RestorationSettings):
    """The AOCS knowledge's latency as the images measure it (:func:`restore.knowledge_timing.knowledge_latency`,
    in the band from the records' high-pass to where the knowledge's filter, through its spline, passes less
    than 90 %), or None: ``knowledge_timing`` off, no restored axis, a product that does not record its filter,
    or no such band."""
    from .knowledge_prior import spline_response
    from .knowledge_timing import knowledge_latency as latency_of
    from .knowledge_timing import latency_band

    attrs = product.ds.attrs
    recs = {a: r for a, r in records.items() if a != "yaw"}
    if not settings.knowledge_timing or not recs or "knowledge_cutoff_hz" not in attrs \
            or "knowledge_filter_order" not in attrs:
        return None
    cutoff, order = float(attrs["knowledge_cutoff_hz"]), int(attrs["knowledge_filter_order"])
    kind = str(attrs.get("knowledge_filter", "butterworth_zero_phase"))
    rate = product.knowledge_noise[1] if product.knowledge_noise is not None else None

    def gain(f):
        g = np.abs(knowledge_response(f, cutoff, order, kind))
        return g * np.abs(spline_response(f, rate)) if rate else g
    dt = float(next(iter(recs.values())).line_period_s)
    band = latency_band(max(float(r.highpass_hz) for r in recs.values()), gain, top_hz=0.5 / dt)
    if band is None:
        return None
    noise = None
    if product.knowledge_noise is not None:
        from .knowledge_prior import knowledge_noise_floor
        noise_rad, rate_hz = product.knowledge_noise

        def noise(f):
            return knowledge_noise_floor(f, rate_hz=rate_hz, noise_rad=noise_rad)
    return latency_of(recs, knowledge, band, noise_psd=noise)


def advanced_knowledge(product: Product, delay_s: float) -> tuple[Product, dict]:
    """The product with its knowledge samples advanced by ``delay_s`` (the knowledge at t then describes t:
    :func:`restore.knowledge_dephasing.advance_samples`), and ``{axis: (line,)}``, the advanced knowledge less
    the given one at the lines [rad]."""
    from .knowledge_dephasing import advance_samples, prediction_memory_s

    kn = product.knowledge
    tk = np.asarray(kn.time, dtype=np.float64)
    dt = float(np.median(np.diff(tk)))
    cutoff = product.ds.attrs.get("knowledge_cutoff_hz")
    memory = prediction_memory_s(float(cutoff)) if cutoff is not None and np.isfinite(float(cutoff)) \
        and float(cutoff) > 0 else None
    return _with_knowledge(product, AttitudeSeries(tk, *(advance_samples(getattr(kn, a), dt, delay_s, memory_s=memory)
                                                         for a in AXES)))


def knowledge_smoothings(product: Product, settings: RestorationSettings, axes) -> dict:
    """``{axis: KnowledgeSmoothing}`` of the AOCS knowledge samples of ``axes`` (times from the record's first
    line; :mod:`restore.knowledge_smoothing`); empty with ``knowledge_smoothing`` off or a product that does
    not record its knowledge's noise, and an axis with too few samples is left out."""
    if not settings.knowledge_smoothing or product.knowledge_noise is None:
        return {}
    noise_rad, _ = product.knowledge_noise
    kn = product.knowledge
    t = np.asarray(kn.time, dtype=np.float64) - float(product.time[0])
    out = {}
    for a in axes:
        sm = knowledge_smoothing(t, getattr(kn, a), noise_rad)
        if sm is not None:
            out[a] = sm
    return out


def knowledge_smoothing_correction(product: Product, smoothings: dict, records: dict) -> dict:
    """``{axis: (line,)}`` to add to the correction so that the restored angle's band below each axis's
    high-pass is the smoothed knowledge's (:func:`restore.knowledge_smoothing.lowband_correction`) [rad]."""
    t = np.asarray(product.time, dtype=np.float64)
    out = {}
    for a, sm in smoothings.items():
        rec = records.get(a)
        if rec is None:
            continue
        out[a] = lowband_correction(sm, getattr(product.knowledge, a), t - t[0], line_period_s=float(t[1] - t[0]),
                                    highpass_hz=float(rec.highpass_hz))
    return out


def undo_exposure(estimate: dict, product: Product, settings: RestorationSettings) -> dict:
    """The estimate of each restored axis with its line's exposure (the line period) undone
    (:func:`restore.exposure.exposure_deconvolution`); unchanged with ``deconvolve_exposure`` off."""
    if not settings.deconvolve_exposure:
        return estimate
    t = np.asarray(product.time, dtype=np.float64)
    if t.size < 3:
        return estimate
    exposure = float(product.ds.attrs["line_period_s"])
    dt = float(np.median(np.diff(t)))
    return {a: exposure_deconvolution(v, dt=dt, exposure_s=exposure) if a in settings.axes else v
            for a, v in estimate.items()}


def predicted_sigma(records: dict, product: Product, settings: RestorationSettings) -> dict:
    """Predicted 1-σ per line of each restored axis [rad] (:func:`restore.posterior.posterior_sigma`).

    The AOCS knowledge's noise, as the product records it, counts below the
    high-pass. Returns ``{axis: PosteriorSigma}`` for the axes of
    ``records``, each with its own seed whichever others are given; empty with
    ``posterior_samples = 0``. :func:`raise_by_local_error` completes it.
    """
    if settings.posterior_samples < 2:
        return {}
    noise, rate = product.knowledge_noise or (0.0, None)
    order = sorted(set(settings.axes) | set(records))
    smooth = knowledge_smoothings(product, settings, records)
    return {a: posterior_sigma(rec, samples=settings.posterior_samples, seed=order.index(a),
                               knowledge_noise_rad=noise, knowledge_rate_hz=rate, knowledge_smoothing=smooth.get(a))
            for a, rec in sorted(records.items())}


def knowledge_conditioned(record: IntegrationRecord, sigma, product: Product, knowledge: np.ndarray,
                          estimate: np.ndarray, settings: RestorationSettings) -> IntegrationRecord | None:
    """One axis integrated again with the prior given the AOCS knowledge (:mod:`restore.knowledge_conditioning`).

    ``sigma`` (:class:`restore.posterior.PosteriorSigma`) gives the restored angle's predicted error power,
    ``knowledge`` and ``estimate`` (lines,) [rad] the knowledge and the integration's estimate at the lines.
    The conditional mean ``μ = h k`` (over the record and the longest delay beyond it, high-passed as the
    integration's output) is taken off the differentials, the integration runs with its method's frozen options
    and the conditional prior, and the new record has ``previous = μ``. None where it does not apply:
    ``knowledge_conditioning`` off, a method with no spectral prior, no predicted error power, a product that
    does not record its knowledge's filter and noise, or a record already holding an earlier estimate.
    """
    attrs = product.ds.attrs
    if not settings.knowledge_conditioning or record.spectrum is None or sigma is None \
            or sigma.error_power is None or product.knowledge_noise is None \
            or "knowledge_cutoff_hz" not in attrs or "knowledge_filter_order" not in attrs \
            or np.any(np.asarray(record.previous) != 0):
        return None
    noise_rad, rate_hz = product.knowledge_noise
    if not (noise_rad > 0 and rate_hz > 0):
        return None
    dt = float(record.line_period_s)
    n = np.asarray(record.diffs).shape[1]
    cond = knowledge_conditioning(record.spectrum.freq, record.spectrum.psd, knowledge + estimate,
                                  sigma.error_power, dt, cutoff_hz=float(attrs["knowledge_cutoff_hz"]),
                                  order=int(attrs["knowledge_filter_order"]),
                                  kind=str(attrs.get("knowledge_filter", "butterworth_zero_phase")),
                                  rate_hz=rate_hz, noise_rad=noise_rad)
    lags = [np.nan_to_num(np.asarray(lg, dtype=np.float64)) for lg in record.lags_s]
    ext = extended_lines(n, record.taus, lags, dt)
    t = product.time[0] + np.arange(ext) * dt
    series = product.knowledge
    k_ext = series.at(np.clip(t, series.time[0], series.time[-1]))[AXES.index(record.axis)]
    mu = cond.mean(k_ext, dt)
    if record.highpass_hz > 0:
        mu = highpass_nan(mu, dt=dt, cutoff_hz=record.highpass_hz)
    diffs = np.asarray(record.diffs) - simulated_differentials(mu, record.taus, lags, np.isfinite(record.diffs), dt)
    new = replace(record, diffs=diffs, spectrum=replace(record.spectrum, psd=cond.variance), previous=mu[:n],
                  knowledge_conditioned=True,
                  conditioned_attitude_psd=np.where(np.abs(cond.mean_filter) > 0, cond.psd_theta, 0.0))
    return replace(new, increment=new.rerun())   # the method's frozen options, with the conditional prior


def knowledge_band_weighted(record: IntegrationRecord, product: Product, settings: RestorationSettings
                            ) -> tuple[IntegrationRecord, float] | None:
    """A knowledge-conditioned axis integrated again, each pair's noise weighed by the colour its differentials
    show in the knowledge's band (:mod:`restore.knowledge_band_noise`), and the largest factor they showed.

    The band runs from the record's high-pass to :data:`restore.conditioned_excess.BAND_FRACTION` of the
    knowledge's cut-off (its filter's flat part, where the conditioned prior holds); there the colour replaces
    the record's own where larger, and the new record's ``knowledge_band_hz`` says where. σ's draws keep the
    residual's colour (see :mod:`restore.knowledge_band_noise` on why not this one). None where it does not
    apply (``knowledge_band_noise`` off, a record not conditioned on the knowledge, a method that cannot weigh by
    a colour, no cut-off recorded) or where the differentials show no excess.
    """
    from .conditioned_excess import BAND_FRACTION
    from .knowledge_band_noise import knowledge_band_colour

    cutoff = product.ds.attrs.get("knowledge_cutoff_hz")
    if not settings.knowledge_band_noise or not record.knowledge_conditioned or record.spectrum is None \
            or cutoff is None or not integration_method(record.method).noise_colour:
        return None
    band = (float(record.highpass_hz), BAND_FRACTION * float(cutoff))
    colour = knowledge_band_colour(record, band, samples=max(int(settings.posterior_samples), 2),
                                   seed=AXES.index(record.axis))
    if colour is None or not np.any(colour > 1.0):
        return None
    largest = float(np.max(colour))    # what the differentials showed, before the record's own colour joins it
    n = np.asarray(record.diffs).shape[1]
    f = np.fft.rfftfreq(n, record.line_period_s)
    if record.spectrum.noise_colour is not None:
        colour = np.maximum(colour, colour_on_grid(record.spectrum.noise_colour, f, len(record.taus)))
    weighted = replace(record, spectrum=replace(record.spectrum, noise_colour=(f, colour)), knowledge_band_hz=band)
    return replace(weighted, increment=weighted.rerun()), largest


def raise_by_local_error(sigma: dict, records: dict, pairs: list, product: Product,
                         settings: RestorationSettings) -> dict:
    """With ``sigma_local_error``: each axis's σ raised, line by line, to the prediction with the local
    matching error measured from ``pairs`` (as last synthesised; :func:`local_errors`,
    :func:`restore.posterior.local_error_sigma`, :func:`restore.posterior.larger_sigma`), through the axis's
    record; an axis already raised, or whose pairs have no measurement, is kept. Returns a new dict."""
    if not settings.sigma_local_error or not sigma:
        return sigma
    todo = [a for a, ps in sorted(sigma.items()) if a in records and not np.isfinite(ps.local_detrended_rms)]
    local = local_errors(pairs, settings, product.time.size) if todo else {}
    noise, rate = product.knowledge_noise or (0.0, None)
    order = sorted(set(settings.axes) | set(records))
    smooth = knowledge_smoothings(product, settings, todo)
    out = dict(sigma)
    for a in todo:
        rec = records[a]
        if any(p not in local for p in rec.pairs):
            continue
        measured = np.array([local[p][:, AXES.index(a)] for p in rec.pairs])
        out[a] = larger_sigma(sigma[a], local_error_sigma(rec, measured, samples=settings.posterior_samples,
                                                          seed=order.index(a), knowledge_noise_rad=noise,
                                                          knowledge_rate_hz=rate,
                                                          knowledge_smoothing=smooth.get(a)))
    return out


def raise_by_knowledge_check(sigma: dict, records: dict, product: Product, settings: RestorationSettings,
                             restored: dict, smoothings: dict) -> tuple[dict, dict]:
    """Each axis's restored angle checked against its smoothed AOCS knowledge between 1.25 × its high-pass and
    0.7 × the knowledge's cut-off (:func:`restore.knowledge_check.knowledge_check`); with
    ``sigma_knowledge_check`` its σ is raised in quadrature by the images' share of the disagreement neither
    prediction holds (:attr:`~restore.knowledge_check.KnowledgeCheck.booked_rad2`; ``model_sigma`` keeps the σ
    before it, which "auto" flags judge: a raise common to every line does not say where σ rises).

    ``restored``: the restored angle per axis before flagging [rad]; ``smoothings``: :func:`knowledge_smoothings`.
    Needs the knowledge's noise and filter in product.nc. Returns ``(sigma, checks)`` with ``checks[axis]`` a
    :class:`~restore.knowledge_check.KnowledgeCheck` for each axis checked (recorded whether or not σ takes it)."""
    attrs = product.ds.attrs
    if not sigma or product.knowledge_noise is None \
            or "knowledge_cutoff_hz" not in attrs or "knowledge_filter_order" not in attrs:
        return sigma, {}
    noise, rate = product.knowledge_noise
    t = np.asarray(product.time, dtype=np.float64)
    order = sorted(set(settings.axes) | set(records))
    out, checks = dict(sigma), {}
    for a, ps in sorted(sigma.items()):
        rec, sm = records.get(a), smoothings.get(a)
        if rec is None or sm is None or ps.error_power is None:
            continue
        k = np.asarray(getattr(product.knowledge, a), dtype=np.float64)
        chk = knowledge_check(restored[a], smoothed_knowledge_at(sm, k, t - t[0]), np.asarray(
            product.knowledge.at(t)[AXES.index(a)]), ps.error_power, sm, line_period_s=float(t[1] - t[0]),
            highpass_hz=float(rec.highpass_hz), cutoff_hz=float(attrs["knowledge_cutoff_hz"]),
            order=int(attrs["knowledge_filter_order"]), kind=str(attrs.get("knowledge_filter",
                                                                            "butterworth_zero_phase")),
            noise_rad=float(noise), rate_hz=float(rate), seed=order.index(a))
        if chk is None:
            continue
        checks[a] = chk
        if settings.sigma_knowledge_check and chk.booked_rad2 > 0:
            b = chk.booked_rad2
            out[a] = replace(ps, sigma=np.sqrt(ps.sigma ** 2 + b), detrended_sigma=None
                             if ps.detrended_sigma is None else np.sqrt(ps.detrended_sigma ** 2 + b),
                             detrended_rms=float(np.sqrt(ps.detrended_rms ** 2 + b)),
                             # the same excess on every line says nothing of where σ rises: "auto" flags keep
                             # judging the σ before it
                             model_sigma=ps.sigma if ps.model_sigma is None else ps.model_sigma)
    return out, checks


def conditioned_excesses(records: dict, product: Product) -> dict:
    """``{axis: ConditionedExcess}`` of each record whose prior is conditioned on the AOCS knowledge
    (:func:`restore.conditioned_excess.record_conditioned_excess`); empty when the product does not record
    the knowledge's cut-off."""
    from .conditioned_excess import record_conditioned_excess

    cutoff = product.ds.attrs.get("knowledge_cutoff_hz")
    if cutoff is None:
        return {}
    out = {}
    for a, rec in sorted(records.items()):
        ex = record_conditioned_excess(rec, float(cutoff))
        if ex is not None:
            out[a] = ex
    return out


def knowledge_filter_errors(records: dict, product: Product) -> dict:
    """``{axis: rad}``: the RMS of the AOCS filter's own error that stays in each restored axis below its high-pass
    (:func:`restore.observability.knowledge_filter_error_below`, from the knowledge at the lines); empty when the
    product does not record the knowledge's filter."""
    from .observability import knowledge_filter_error_below

    attrs = product.ds.attrs
    if "knowledge_cutoff_hz" not in attrs or "knowledge_filter_order" not in attrs:
        return {}
    knowledge = dict(zip(AXES, product.knowledge.at(product.time)))
    return {a: knowledge_filter_error_below(knowledge[a], float(rec.line_period_s), highpass_hz=float(rec.highpass_hz),
                                            cutoff_hz=float(attrs["knowledge_cutoff_hz"]),
                                            order=int(attrs["knowledge_filter_order"]),
                                            kind=str(attrs.get("knowledge_filter", "butterworth_zero_phase")))
            for a, rec in sorted(records.items())}


def knowledge_latency_errors(records: dict, product: Product, latency) -> dict:
    """``{axis: rad}``: the RMS error the knowledge's latency leaves where the restoration leans on the knowledge
    in the latency's band (:mod:`restore.knowledge_timing`): what is still unknown of it, ``√(δ_left² + σ_δ²)``
    (``δ_left`` the part of the estimate not taken out, ``δ − LatencyEstimate.applied_s``; nothing where the
    regression measured no latency: ``LatencyEstimate.measured``), times the RMS of the knowledge's
    derivative in that band, the share of it that is the attitude's (``1 − 1 / signal_to_noise``: its noise does
    not move with a latency). Empty without an estimate."""
    from .knowledge_timing import _band_derivative

    if latency is None or not latency.measured:
        return {}
    left = float(latency.delay_s) - latency.applied_s
    # the attitude's share of the derivative's power in the band: the knowledge's noise is not moved by a latency
    share = max(0.0, 1.0 - 1.0 / latency.signal_to_noise) if latency.signal_to_noise > 0 else 0.0
    unknown = float(np.hypot(left, latency.sigma_s)) * np.sqrt(share)
    t = np.asarray(product.time, dtype=np.float64)
    knowledge = dict(zip(AXES, product.knowledge.at(t)))
    return {a: unknown * float(np.sqrt(np.mean(_band_derivative(np.asarray(knowledge[a], dtype=np.float64),
                                                                   float(rec.line_period_s), latency.band_hz) ** 2)))
            for a, rec in sorted(records.items()) if a in latency.axes}


def raise_by_knowledge_filter(sigma: dict, records: dict, product: Product, latency=None) -> dict:
    """Each axis's σ raised in quadrature by the AOCS filter's own error below its high-pass
    (:func:`knowledge_filter_errors`): below the high-pass the restored angle is the knowledge, whose noise the
    draws hold but not its filter's error — nothing for a zero-phase filter well below its cut-off, the lag of a
    causal one (an unseen scene under a 4 Hz causal knowledge: 0.062 / 0.066 px predicted, 0.062 / 0.095 px of
    the restored angle's error in that band). With ``latency`` (:class:`restore.knowledge_timing.LatencyEstimate`)
    also what is still unknown of the knowledge's latency (:func:`knowledge_latency_errors`). Like the knowledge
    check's raise, the same on every line (``model_sigma`` keeps the σ before it). Returns a new dict."""
    late = knowledge_latency_errors(records, product, latency)
    errors = knowledge_filter_errors(records, product)
    return raised_uniformly(sigma, {a: float(np.hypot(errors.get(a, 0.0), late.get(a, 0.0)))
                                    for a in set(errors) | set(late)})


def raised_uniformly(sigma: dict, errors: dict) -> dict:
    """Each axis's σ raised in quadrature by ``errors[axis]`` [rad], the same on every line (``model_sigma``
    keeps the σ before the first such raise). Returns a new dict."""
    out = dict(sigma)
    for a, e in errors.items():
        ps = out.get(a)
        if ps is None or not e > 0:
            continue
        b = e * e

        def up(x):
            return None if x is None else np.sqrt(np.asarray(x) ** 2 + b)
        out[a] = replace(ps, sigma=up(ps.sigma), detrended_sigma=up(ps.detrended_sigma),
                         detrended_rms=float(np.sqrt(ps.detrended_rms ** 2 + b)),
                         model_sigma=ps.sigma if ps.model_sigma is None else ps.model_sigma)
    return out


def raise_by_excess_shrink(sigma: dict, excesses: dict) -> dict:
    """Each axis's σ raised in quadrature by the error its excess shrink still leaves
    in its band and above it (``ConditionedExcess.booked_rad``, :func:`shrunk_excesses`), where one ran, or the
    offset another axis's shrink measured brings to it (:func:`offset_shared_excesses`); a new dict."""
    return raised_uniformly(sigma, {a: ex.booked_rad for a, ex in excesses.items() if ex.booked_rad is not None})


def shrunk_excesses(records: dict, product: Product, settings: RestorationSettings) -> dict:
    """``{axis: ExcessShrink}`` of each record whose prior is conditioned on the AOCS knowledge
    (:func:`restore.conditioned_excess.shrunk_excess`): its estimate with the band's excess over the Wiener output
    shrunk. Empty with ``excess_shrink`` off or when the product does not record the knowledge's cut-off."""
    from .conditioned_excess import shrunk_excess
    from .observability import scene_offset_band

    cutoff = product.ds.attrs.get("knowledge_cutoff_hz")
    if not settings.excess_shrink or cutoff is None:
        return {}
    out = {}
    for a, rec in sorted(records.items()):
        if not rec.knowledge_conditioned or rec.spectrum is None:
            continue
        sp = rec.spectrum
        top = scene_offset_band(rec.taus, float(cutoff))
        sh = shrunk_excess(rec.increment, sp.freq, sp.psd, sp.noise_std, rec.taus, float(rec.line_period_s),
                           highpass_hz=float(rec.highpass_hz), cutoff_hz=float(cutoff),
                           model_psd=rec.conditioned_attitude_psd, top_hz=top[1] if top is not None else None)
        if sh is not None:
            out[a] = sh
    return out


def offset_shared_excesses(excesses: dict, product: Product) -> dict:
    """``excesses`` (``{axis: ConditionedExcess}``) with ``shared_above_rad`` set where the scene's band offset
    shrunk on one axis reaches another by the sun's split (:func:`restore.conditioned_excess.offset_shared_by_sun`,
    :func:`restore.observability.sun_offset_shares` at the track's azimuth); as given when the product records no
    sun or is not a push-broom acquisition, or when no axis booked an offset above the band. A new dict."""
    from .conditioned_excess import offset_shared_by_sun
    from .observability import sun_offset_shares, track_azimuth_deg

    attrs = product.ds.attrs
    above = {a: ex.above_error_rad for a, ex in excesses.items() if ex.above_error_rad}
    if not above or "sun_azimuth_deg" not in attrs or attrs.get("acquisition", "pushbroom") != "pushbroom":
        return dict(excesses)
    variables = getattr(product.ds, "variables", {})
    track = track_azimuth_deg(product.ds["ephemeris"].values if "ephemeris" in variables else None)
    shares = {a: v for a, v in sun_offset_shares(float(attrs["sun_azimuth_deg"]), track).items() if a in excesses}
    shared = offset_shared_by_sun(above, shares)
    return {a: replace(ex, shared_above_rad=shared[a]) if shared.get(a, 0.0) > 0 else ex
            for a, ex in excesses.items()}


#: :func:`knowledge_error_prior` reads the knowledge's own ceiling where its filter passes at least this
KNOWLEDGE_ERROR_MIN_GAIN = 0.5


def knowledge_error_prior(product: Product, knowledge: np.ndarray, record: IntegrationRecord) -> tuple | None:
    """``(freq, two-sided PSD)`` of the AOCS knowledge's error on one axis, as the knowledge fusion needs it: the
    ceiling the knowledge's own periodogram and its recorded filter put on it
    (:func:`restore.knowledge_prior.knowledge_psd_ceiling`: its filter's error ``|1 − F|² S_θ`` plus its noise)
    where the filter passes at least :data:`KNOWLEDGE_ERROR_MIN_GAIN` of the attitude, and the restoration's prior
    beyond, where the knowledge says little; the prior alone when the product does not record the filter.

    Not the record's prior: a record conditioned on the knowledge (:func:`knowledge_conditioned`) holds the
    variance of the knowledge's error *given* the knowledge, which is its noise alone where the filter is
    known — a causal filter's error in its own band (86° of lag at half its cut-off) is known there, and is
    large: taken for the knowledge's error power, that variance made every line of a 4 Hz causal knowledge's
    scene look astray (an unseen scene: 60 % of the lines fused, then flagged)."""
    prior = None if record.spectrum is None else (np.asarray(record.spectrum.freq, dtype=np.float64),
                                                  np.asarray(record.spectrum.psd, dtype=np.float64))
    attrs = product.ds.attrs
    if product.knowledge_noise is None or "knowledge_cutoff_hz" not in attrs or "knowledge_filter_order" not in attrs:
        return prior
    noise_rad, rate_hz = product.knowledge_noise
    cutoff, order = float(attrs["knowledge_cutoff_hz"]), int(attrs["knowledge_filter_order"])
    kind = str(attrs.get("knowledge_filter", "butterworth_zero_phase"))
    f, ceiling = knowledge_psd_ceiling(knowledge, float(record.line_period_s), cutoff_hz=cutoff, order=order,
                                       rate_hz=rate_hz, noise_rad=noise_rad, kind=kind)
    # where the filter passes less than half the attitude the ceiling divides the knowledge's noise by |F|²: the
    # restoration's prior says more there
    weak = ~np.isfinite(ceiling) | (np.abs(knowledge_response(f, cutoff, order, kind)) < KNOWLEDGE_ERROR_MIN_GAIN)
    if weak.any():
        ceiling = np.where(weak, 0.0 if prior is None else np.interp(f, prior[0], prior[1], right=0.0), ceiling)
    return f, ceiling


def fuse_knowledge_band(estimate: dict, sigma: dict, records: dict, product: Product,
                        settings: RestorationSettings) -> tuple[dict, dict, dict]:
    """With ``knowledge_fusion``: each restored axis's estimate takes the AOCS knowledge's band (between its
    high-pass and 0.7 × the knowledge's cut-off) where its own band power proves it astray
    (:func:`restore.knowledge_fusion.fuse_with_knowledge`), and its σ takes the fusion's error (``w v_k``) in
    quadrature on those lines. Needs the knowledge's noise and cut-off in product.nc.

    Returns ``(estimate, sigma, fusions)``: new dicts; ``fusions[axis]`` a
    :class:`~restore.knowledge_fusion.KnowledgeFusion` for each axis the fusion could be tried on."""
    attrs = product.ds.attrs
    if not settings.knowledge_fusion or product.knowledge_noise is None or "knowledge_cutoff_hz" not in attrs:
        return estimate, sigma, {}
    noise, rate = product.knowledge_noise
    dt = float(product.time[1] - product.time[0])
    order = sorted(set(settings.axes) | set(records))
    estimate, sigma, fusions = dict(estimate), dict(sigma), {}
    knowledge = dict(zip(AXES, product.knowledge.at(product.time)))
    for a in sorted(records):
        rec = records[a]
        prior = knowledge_error_prior(product, knowledge[a], rec)
        new, fu = fuse_with_knowledge(estimate[a], dt=dt, highpass_hz=float(rec.highpass_hz),
                                      cutoff_hz=float(attrs["knowledge_cutoff_hz"]), noise_rad=float(noise),
                                      rate_hz=float(rate), prior=prior, seed=order.index(a))
        if fu is None:
            continue
        fusions[a] = fu
        estimate[a] = new
        ps = sigma.get(a)
        if ps is None or not fu.lines_fused:
            continue
        add = fu.added_rad2

        def up(x):
            return None if x is None else np.sqrt(np.asarray(x) ** 2 + add)
        extra = float(np.mean(add[np.isfinite(np.asarray(new))])) if np.isfinite(new).any() else 0.0
        sigma[a] = replace(ps, sigma=up(ps.sigma), detrended_sigma=up(ps.detrended_sigma),
                           detrended_rms=float(np.sqrt(ps.detrended_rms ** 2 + extra)),
                           model_sigma=up(ps.model_sigma))
    return estimate, sigma, fusions


def local_errors(pairs: list, settings: RestorationSettings, n_lines: int) -> dict:
    """``{pair: (lines, 3)}``: the local part of each synthesised pair's differential error
    (:func:`restore.local_noise.local_matching_error`, blocks of two matching windows' width); a pair without
    its synthesis (sensitivities, predictions, of its current matches) is left out."""
    out = {}
    for p in pairs:
        if p.sens is None or p.pred_line_b is None or np.shape(p.sens)[0] != int(np.count_nonzero(p.valid)):
            continue
        out[p.name] = local_matching_error(p, p.sens, n_lines=n_lines, axes=settings.axes,
                                           block_columns=2 * int(settings.window[1]),
                                           min_points=max(2, settings.min_points_per_line // 2),
                                           n_sigma=settings.n_sigma,
                                           window_lines=settings.window[0] if settings.compensate_window else 0,
                                           covariance=settings.match_covariance)
    return out


#: "auto" ``max_sigma_px``: a line is flagged when its predicted σ exceeds this many times the axis's median
AUTO_SIGMA_LIMIT_FACTOR = 3.0


def sigma_limit(sigma: np.ndarray, setting, pixel_ifov_rad: float) -> float:
    """The σ above which a line is flagged [rad]: ``max_sigma_px`` in pixels, or "auto" (3 × the median σ)."""
    if setting == "auto":
        s = sigma[np.isfinite(sigma)]
        return float(AUTO_SIGMA_LIMIT_FACTOR * np.median(s)) if s.size else float("inf")
    return float(setting) * pixel_ifov_rad


def flag_uncertain(correction: dict, sigma: dict, setting, pixel_ifov_rad: float,
                   limits: dict | None = None) -> tuple[dict, dict]:
    """Lines whose predicted σ exceeds the limit (:func:`sigma_limit`) are not restored (NaN), and flagged.

    Short clear islands between clouds and the lines at a gap's edge are
    where σ rises: they are reported as flagged, not silently valid. With
    "auto" (3 × the median σ) a σ raised by the local matching error
    (:func:`restore.posterior.larger_sigma`) is judged by the model's σ: the
    surrogate's random phases spread the local error over the whole record,
    so it sets the level, not where σ rises. Returns ``(correction,
    flagged)`` with ``flagged[axis]`` a boolean per line; ``limits``, when
    given, receives ``{axis: (limit [rad], "model" or "reported")}``: the
    limit applied and the σ it was applied to.
    """
    out, flagged = dict(correction), {}
    for a, ps in sigma.items():
        # "auto" looks for lines where σ rises above the axis's own level: the shape of the model's σ, which knows
        # the per-line weights, gaps and ends (the local error's draws spread its series over the record)
        on_model = setting == "auto" and ps.model_sigma is not None
        sig = ps.model_sigma if on_model else ps.sigma
        limit = sigma_limit(sig, setting, pixel_ifov_rad)
        if limits is not None:
            limits[a] = (limit, "model" if on_model else "reported")
        f = np.isfinite(out[a]) & ~(sig <= limit)
        out[a] = np.where(f, np.nan, out[a])
        flagged[a] = f
    return out, flagged


# --------------------------------------------------------------------------- anchor
def remove_mean(estimate: dict, axes) -> dict:
    """The correction with its (unobservable) mean removed on the restored axes."""
    out = dict(estimate)
    for a in axes:
        m = np.isfinite(out[a])
        if m.any():
            out[a] = out[a] - np.mean(out[a][m])
    return out


def restored_from(knowledge: dict, estimate: dict, parts, axes) -> tuple[dict, dict]:
    """``(correction, restored)``: the estimate plus each of ``parts`` (``{axis: (line,)}``: the knowledge's
    smoothing, its dephasing), its mean removed on ``axes`` (:func:`remove_mean`), and the recorded
    ``knowledge`` plus that correction [rad]."""
    correction = remove_mean({a: estimate[a] + sum(p.get(a, 0.0) for p in parts) for a in AXES}, axes)
    return correction, {a: knowledge[a] + correction[a] for a in AXES}


def _anchor_samples(values: np.ndarray, t_line: np.ndarray, star_tracker, axis: str):
    """The star-tracker samples an axis is anchored on: ``(ts, residuals, tc, fit_slope)`` or None.

    Samples inside the restored span; a slope is fitted with at least 3
    samples spanning half the record or more (``tc``: the span's centre).
    """
    m = np.isfinite(values)
    if not m.any():
        return None
    t0, t1 = t_line[m].min(), t_line[m].max()
    sel = (star_tracker.time >= t0) & (star_tracker.time <= t1)
    if sel.sum() < 1:
        return None
    ts = star_tracker.time[sel]
    resid = getattr(star_tracker, axis)[sel] - np.interp(ts, t_line[m], values[m])
    fit_slope = bool(sel.sum() >= 3 and ts.max() - ts.min() >= 0.5 * (t1 - t0))
    return ts, resid, 0.5 * (t0 + t1), fit_slope


def anchor_on_star_tracker(restored: dict, t_line: np.ndarray, star_tracker, axes) -> tuple[dict, bool]:
    """Absolute anchoring on the star tracker: what the images cannot see, the slowest part of the error.

    Per restored axis, the star-tracker samples inside the restored span are
    compared with the restored attitude there. With at least 3 samples
    spanning half the record or more, their residuals are fitted by an offset
    and a slope (a drifting AOCS knowledge leaves a trend the image
    restoration, which trusts the knowledge at low frequency, does not
    remove); otherwise by their mean. Returns the anchored attitude and
    whether any axis was anchored.
    """
    out = dict(restored)
    anchored = False
    if star_tracker is None:
        return out, anchored
    for a in axes:
        got = _anchor_samples(out[a], t_line, star_tracker, a)
        if got is None:
            continue
        ts, resid, tc, fit_slope = got
        if fit_slope:
            slope, offset = np.polyfit(ts - tc, resid, 1)
            out[a] = out[a] + offset + slope * (t_line - tc)
        else:
            out[a] = out[a] + float(np.mean(resid))
        anchored = True
    return out, anchored


def anchoring_sigma(restored: dict, t_line: np.ndarray, star_tracker, axes, *, noise_rad: float | None) -> dict:
    """Per axis and line, the 1-σ the star-tracker anchoring adds to the restored angle [rad].

    The anchoring's slope is fitted on a few noisy samples: its error ``s``
    tilts the whole record, ``s (t − t̄)`` once the mean is removed (the
    metric's convention: the offset's error is the unobservable constant). The
    slope's 1-σ is ``σ_st / √Σ(tᵢ − t̄ₛ)²`` with ``σ_st`` the star tracker's
    noise as the product records it (``noise_rad``), or, without it, estimated
    from the fit's residuals (4 samples or more). Axes anchored by their mean
    only, or not at all, get 0 (a drift left in the knowledge is not known).
    ``restored`` is the attitude before anchoring (its finite lines).
    """
    out = {}
    if star_tracker is None:
        return out
    for a in axes:
        got = _anchor_samples(restored[a], t_line, star_tracker, a)
        sig = np.zeros(t_line.shape)
        if got is not None and got[3]:
            ts, resid, tc, _ = got
            sxx = float(np.sum((ts - ts.mean()) ** 2))
            noise = noise_rad
            if noise is None and ts.size >= 4:
                slope, offset = np.polyfit(ts - tc, resid, 1)
                noise = float(np.sqrt(np.sum((resid - offset - slope * (ts - tc)) ** 2) / (ts.size - 2)))
            if noise is not None and sxx > 0:
                m = np.isfinite(restored[a])
                sig = noise / np.sqrt(sxx) * np.abs(t_line - t_line[m].mean())
        out[a] = np.where(np.isfinite(restored[a]), sig, np.nan)
    return out


def add_anchoring_sigma(sigma: dict, anchor: dict) -> dict:
    """The predicted σ of each axis with the anchoring's own (:func:`anchoring_sigma`) added in quadrature."""
    out = dict(sigma)
    for a, ps in sigma.items():
        if a in anchor:
            out[a] = replace(ps, sigma=np.sqrt(ps.sigma ** 2 + anchor[a] ** 2))
    return out


def check_coverage(restored: dict, settings: RestorationSettings, where, flagged: dict | None = None) -> dict:
    """Fraction of lines restored per axis; refuses a restored axis below ``min_coverage``."""
    coverage = {a: float(np.mean(np.isfinite(restored[a]))) for a in AXES}
    for a in settings.axes:
        if coverage[a] < settings.min_coverage:
            n_flag = int(np.count_nonzero(flagged[a])) if flagged and a in flagged else 0
            why = (f"; {n_flag} lines were flagged for a predicted σ above restoration.max_sigma_px = "
                   f"{settings.max_sigma_px}" if n_flag else "")
            raise RestorationError(f"{where}: coverage on {a} is {coverage[a] * 100:.1f} % "
                                   f"(< restoration.min_coverage = {settings.min_coverage * 100:.0f} %): "
                                   f"not enough texture to restore{why}")
    return coverage


# --------------------------------------------------------------------------- correct
def correct_images(product: Product, t_line, restored: dict, knowledge: dict, pairs: list,
                   settings: RestorationSettings, *, path=None, attrs=None) -> tuple:
    """Bands resampled with the restored attitude, and the band-to-band misregistration before / after.

    Lines without restoration keep the knowledge. Returns ``(corrected, misregistration)``.
    """
    rest_fill = {a: np.where(np.isfinite(restored[a]), restored[a], knowledge[a]) for a in AXES}
    valid = np.all([np.isfinite(restored[a]) for a in settings.axes], axis=0)
    corrected = correct_bands(product, restored=attitude_series(t_line, rest_fill), valid=valid,
                              column_step=settings.correction_column_step, path=path, attrs=attrs,
                              compression=settings.corrected_compression, tdi_mean=settings.tdi_mean_attitude)
    mis = misregistration(product, corrected, pairs, settings)
    mis.update(weak_band_misregistration(product, corrected, pairs, settings))
    return corrected, mis


def attitude_series(time, values: dict) -> AttitudeSeries:
    """An :class:`~simsat.attitude.AttitudeSeries` from axis → samples [rad] at ``time`` [s]."""
    return AttitudeSeries(time=np.asarray(time, dtype=np.float64), roll=np.asarray(values["roll"], dtype=np.float64),
                          pitch=np.asarray(values["pitch"], dtype=np.float64),
                          yaw=np.asarray(values["yaw"], dtype=np.float64))


def ncc_kernel_cold() -> bool:
    """Whether the compiled NCC kernel is not loaded yet in this process (first use: cache load or compile)."""
    from ._ncc_kernel import (
        match_ncc,  # Numba: heavy, imported only when matching with it
    )

    return not match_ncc.signatures
