"""Restoration pipeline: product → restored line-of-sight attitude (patent claims 9–11).

Stages, for each band pair (A ahead, B behind, delay τ):

1. colocalisation — predicted position in B of points of A (sensor model with
   the *knowledge* attitude and the product's DEM);
2. point selection (a-priori radiometric criterion) and sub-pixel matching;
3. instant synthesis — per-line attitude differentials ΔR, ΔT, ΔL;

then, over all pairs,

4. temporal integration of the differentials (``restore.integration``);
5. iteration — re-predict with the refined attitude, re-synthesise, integrate
   the remaining differentials, until the update is negligible;
6. optional absolute anchoring on star-tracker samples;
7. outputs — ``restoration.nc`` (attitude, differentials, matches, coverage)
   and ``corrected.nc`` (bands resampled to the knowledge geometry using the
   restored attitude) with band-to-band misregistration before / after.

Never reads ``truth.nc``.
"""
from __future__ import annotations

import json
import os
import sys
import time as _time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from simsat.config import ScenarioError, Section
from simsat.product import (Product, ProductError, atomic_write_dataset, clamped_attitude, read_product,
                            temporary_path)
from simsat.rundir import RunLock, content_id

from .synthesis import AXES, drop_sparse, fill_short_gaps, highpass_nan, instant_synthesis, window_compensation

__all__ = ["RestorationSettings", "restoration_settings", "restore_product", "restore_run", "RestorationResult",
           "RestorationError", "PairData"]


class RestorationError(RuntimeError):
    """Restoration cannot proceed (e.g. no usable texture); the message says why."""


@dataclass
class RestorationSettings:
    pairs: list | str = "auto"
    selection: str = "grid"
    points_per_line: int = 24
    texture_max_std_px: float = 0.4
    window: tuple = (3, 31)
    search: tuple = (3, 3)
    pilot_search: tuple = (8, 8)
    match_method: str = "ncc"
    min_quality: float = 0.6
    axes: tuple = ("roll", "pitch")
    n_sigma: float = 3.0
    min_points_per_line: int = 3
    highpass_hz: float = 2.0
    max_gap_fill_lines: int = 8
    compensate_window: bool = True
    method: str | None = None
    integration_options: dict = field(default_factory=dict)
    iterations: int = 1
    pair_order: str = "fused"
    anchor_star_tracker: bool = True
    correct_images: bool = True
    correction_column_step: int = 64
    min_coverage: float = 0.05


def restoration_settings(sec: Section | dict | None) -> RestorationSettings:
    """Parse the ``[restoration]`` table (every key optional)."""
    if not isinstance(sec, Section):
        sec = Section(sec or {}, "restoration")
    s = RestorationSettings()
    pairs = sec.raw("pairs", "auto")
    if pairs != "auto":
        if isinstance(pairs, str):
            pairs = [pairs]
        if not isinstance(pairs, list) or not all(isinstance(p, str) and p.count("/") == 1 for p in pairs):
            raise sec.error("pairs", f"must be \"auto\" or an array of \"AHEAD/BEHIND\" band names, got {pairs!r}")
    s.pairs = pairs
    s.selection = sec.string("selection", s.selection, choices=("grid", "double_gradient", "spread"))
    s.points_per_line = sec.integer("points_per_line", s.points_per_line, ge=3, le=1000)
    s.texture_max_std_px = sec.number("texture_max_std_px", s.texture_max_std_px, gt=0)
    wl = sec.integer("window_lines", s.window[0], ge=1, le=63)
    wc = sec.integer("window_columns", s.window[1], ge=3, le=255)
    if wl % 2 == 0:
        raise sec.error("window_lines", f"must be odd, got {wl}")
    if wc % 2 == 0:
        raise sec.error("window_columns", f"must be odd, got {wc}")
    s.window = (wl, wc)
    s.search = (sec.integer("search_lines", s.search[0], ge=0, le=64), sec.integer("search_columns", s.search[1], ge=0, le=64))
    s.pilot_search = (sec.integer("pilot_search_lines", s.pilot_search[0], ge=0, le=64),
                      sec.integer("pilot_search_columns", s.pilot_search[1], ge=0, le=64))
    s.match_method = sec.string("match_method", s.match_method, choices=("ncc", "phase"))
    s.min_quality = sec.number("min_quality", s.min_quality, ge=-1, le=1)
    s.axes = tuple(sec.strings("axes", list(s.axes), choices=AXES))
    if not s.axes:
        raise sec.error("axes", f"must name at least one axis of {', '.join(AXES)}")
    if len(set(s.axes)) != len(s.axes):
        raise sec.error("axes", f"names an axis twice: {list(s.axes)}")
    s.n_sigma = sec.number("n_sigma", s.n_sigma, gt=0)
    s.min_points_per_line = sec.integer("min_points_per_line", s.min_points_per_line, ge=2)
    s.highpass_hz = sec.number("highpass_hz", s.highpass_hz, ge=0)
    s.max_gap_fill_lines = sec.integer("max_gap_fill_lines", s.max_gap_fill_lines, ge=0)
    s.compensate_window = sec.boolean("compensate_window", s.compensate_window)
    m = sec.raw("method", None)
    if m is not None:
        from .integration import METHODS
        allowed = sorted(METHODS)
        if not isinstance(m, str) or m not in allowed:
            raise sec.error("method", f"must be one of {', '.join(allowed)}; got {m!r}")
    s.method = m
    opts = sec.section("integration")
    from .integration import check_options
    try:
        s.integration_options = dict(check_options(m, dict(opts.data), where=opts.path))
    except ValueError as e:
        raise ScenarioError(str(e)) from None
    opts.finish(extra_allowed=opts.data.keys())
    s.iterations = sec.integer("iterations", s.iterations, ge=1, le=10)
    s.pair_order = sec.string("pair_order", s.pair_order, choices=("fused", "best_first"))
    s.anchor_star_tracker = sec.boolean("anchor_star_tracker", s.anchor_star_tracker)
    s.correct_images = sec.boolean("correct_images", s.correct_images)
    s.correction_column_step = sec.integer("correction_column_step", s.correction_column_step, ge=1)
    s.min_coverage = sec.number("min_coverage", s.min_coverage, ge=0, le=1)
    sec.finish()
    return s


@dataclass
class PairData:
    """Matches of one band pair and their geometry."""

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


@dataclass
class RestorationResult:
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
    path: Path | None = None

    def summary(self) -> str:
        px = self.pixel_ifov_rad
        lines = [f"restoration ({self.method}, {len(self.pairs)} pairs: "
                 f"{', '.join(f'{p.name} {p.tau_s * 1e3:.1f} ms' for p in self.pairs)})"]
        for p in self.pairs:
            n_ok = int(np.count_nonzero(p.valid))
            lines.append(f"  {p.name}: {n_ok} / {p.valid.size} matches valid, "
                         f"{int(np.count_nonzero(p.inlier)) if p.inlier is not None else 0} inliers, "
                         f"synthesis residual {p.synthesis.residual_rms_px:.3f} px")
        cov = ", ".join(f"{a} {self.coverage[a] * 100:.1f} %" for a in self.settings.axes)
        lines.append(f"  coverage: {cov}")
        corr = ", ".join(f"{a} {np.nanstd(self.correction[a]) / px:.3f} px rms" for a in self.settings.axes)
        lines.append(f"  correction applied: {corr}")
        if self.misregistration:
            for k, v in self.misregistration.items():
                lines.append(f"  misregistration {k}: before {v['before_px']:.3f} px, after {v['after_px']:.3f} px "
                             f"measured (line {v['after_line_px']:.3f}, column {v['after_col_px']:.3f}; matching "
                             f"noise {v['after_noise_px']:.3f} px); without the noise {v['after_signal_px']:.3f} px "
                             f"(line {v['after_line_signal_px']:.3f}, column {v['after_col_signal_px']:.3f})")
        t = self.timings
        lines.append(f"  time: {t.get('total_s', 0):.1f} s ({t.get('lines_per_s', 0):.0f} lines/s, "
                     f"{t.get('matches_per_s', 0):.0f} matches/s)")
        if self.path:
            lines.append(f"  wrote {self.path}")
        return "\n".join(lines)


# --------------------------------------------------------------------------- helpers
def _auto_pairs(product: Product) -> list[tuple[str, str]]:
    """All pairs of the visible bands (most correlated), ordered ahead/behind."""
    dets = list(product.instrument.detectors)
    vis = [d for d in dets if d.band in ("blue", "green", "red")]
    use = vis if len(vis) >= 2 else dets
    pairs = []
    for i, a in enumerate(use):
        for b in use[i + 1:]:
            if a.along_m == b.along_m:
                continue
            ahead, behind = (a, b) if a.along_m > b.along_m else (b, a)
            pairs.append((ahead.name, behind.name))
    if not pairs:
        raise RestorationError("no band pair with different along-track positions: differentials are impossible")
    return pairs


def _resolve_pairs(product: Product, settings: RestorationSettings) -> list[tuple[str, str]]:
    if settings.pairs == "auto":
        return _auto_pairs(product)
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


def _series(time, values: dict):
    from simsat.attitude import AttitudeSeries
    return AttitudeSeries(time=np.asarray(time, dtype=np.float64), roll=np.asarray(values["roll"], dtype=np.float64),
                          pitch=np.asarray(values["pitch"], dtype=np.float64), yaw=np.asarray(values["yaw"], dtype=np.float64))


class _Progress:
    def __init__(self, enabled: bool, total: int):
        self.bar = None
        if enabled:
            from tqdm import tqdm
            self.bar = tqdm(total=total, desc="restore", unit="stage", file=sys.stderr, dynamic_ncols=True)

    def step(self, label: str):
        if self.bar is not None:
            self.bar.set_postfix_str(label)
            self.bar.update(1)

    def note(self, label: str):
        """Say what the current stage is doing, without advancing."""
        if self.bar is not None:
            self.bar.set_postfix_str(label)

    def close(self):
        if self.bar is not None:
            self.bar.close()


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
    from .matching import match_points, support_margin

    zero = (np.zeros(n_lines), np.zeros(n_lines))
    ps = settings.pilot_search
    if lines_a.size == 0 or (ps[0] <= settings.search[0] and ps[1] <= settings.search[1]):
        return zero
    ps = (max(ps[0], settings.search[0]), max(ps[1], settings.search[1]))
    li = np.rint(lines_a).astype(np.int64)
    from .correction import line_median, rank_within_line

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


def _line_lag(pair: PairData, n_lines: int, max_gap: int) -> np.ndarray:
    """Per-line extra delay of the pair [lines]: mean line residual of its inliers.

    Band B sees a point of line l of A at t + τ + Δl·Te where Δl is the
    measured line residual (pitch jitter changes the actual delay): the
    differential of that line is δ(t + τ + Δl Te) − δ(t), not δ(t + τ) − δ(t).
    """
    inl = pair.inlier if pair.inlier is not None else pair.valid
    li = np.rint(pair.line_a[inl]).astype(np.int64)
    dl = (pair.meas_line_b - pair.pred_line_b)[inl]
    ok = np.isfinite(dl)
    n = np.bincount(li[ok], minlength=n_lines)
    sm = np.bincount(li[ok], dl[ok], minlength=n_lines)
    lag = np.where(n > 0, sm / np.maximum(n, 1), np.nan)
    lag = fill_short_gaps(lag, max_gap=max(max_gap, 64))
    return np.nan_to_num(lag)


def _shifted(x: np.ndarray, t_idx: np.ndarray) -> np.ndarray:
    """Cubic interpolation of a line-sampled signal at fractional line indices (0 outside / at NaN)."""
    from scipy.interpolate import CubicSpline

    x = np.nan_to_num(np.asarray(x, dtype=np.float64))
    cs = CubicSpline(np.arange(x.size), x)
    out = cs(np.clip(t_idx, 0, x.size - 1))
    return out


def _integrate_time_sync(diffs, taus, lags, te, *, method, settings, sigmas=None, weights=None) -> np.ndarray:
    """Integrate differentials whose actual lag varies line by line (time synchronisation).

    ``lsq`` models the per-line lags exactly (each line is an equation
    θ(t + τ_j + λ_j(t)) − θ(t) = D_j(t)). Other methods assume constant lags:
    the differentials are first brought back to the nominal lag with the
    ``lsq`` estimate θ̂ — D_j − [θ̂(t + τ_j + λ_j) − θ̂(t + τ_j)] — then
    integrated by the chosen method. (Recomputing the correction with that
    estimate was tried: it feeds its errors at the common blind frequency
    back, and is worse.)
    """
    from .integration import integrate
    from .integration.lsq import integrate_lsq

    # the differentials are integrated as measured; the high-pass is applied to the
    # estimate only: high-passing the differentials first does not commute with the
    # τ-differencing near the ends of the record and of long gaps (a slow transient
    # of ~0.05-0.1 px over ~100 lines even with exact differentials)
    hp = settings.highpass_hz
    est = integrate_lsq(diffs, taus, te, lags=lags, sigmas=sigmas)
    if method != "lsq":
        n = len(diffs[0])
        idx = np.arange(n, dtype=np.float64)
        corrected = []
        for d, tau, lag in zip(diffs, taus, lags):
            base = idx + tau / te
            corrected.append(d - (_shifted(est, base + lag / te) - _shifted(est, base)))
        opts = dict(settings.integration_options)
        if method == "wiener" and weights is not None and "weights" not in opts:
            opts["weights"] = weights  # lines resting on more matched points weigh more
        est = np.asarray(integrate(corrected, taus, te, method=method, **opts), dtype=np.float64)
    if hp > 0:
        # the AOCS knows the low frequencies: keep only what the images add
        est = highpass_nan(est, dt=te, cutoff_hz=hp)
    return est


# --------------------------------------------------------------------------- main
def match_pair(product: Product, ahead: str, behind: str, settings: RestorationSettings, sm=None) -> PairData:
    """Select points in band ``ahead``, predict them in ``behind``, match them."""
    from .matching import match_points, support_margin
    from .selection import select_points_in_blocks

    sm = sm or product.sensor_model()
    img_a = product.image(ahead)
    img_b = product.image(behind)
    n_lines, n_cols = img_a.shape
    tau = sm.nominal_delay_s(ahead, behind)
    shift_lines = tau / product.instrument.line_period_s
    ml, mc = support_margin(window=settings.window, search=settings.search)
    # lines of A whose homologues fall inside B (with the matcher's support margin)
    usable = np.zeros(n_lines, dtype=bool)
    lo = ml + 1
    hi = int(np.floor(n_lines - 1 - shift_lines - ml - 2))
    if hi <= lo:
        raise RestorationError(f"pair {ahead}/{behind}: image too short ({n_lines} lines) for a delay of "
                               f"{shift_lines:.1f} lines")
    usable[lo:hi] = True
    lines_a, cols_a = select_points_in_blocks(img_a, method=settings.selection, per_line=settings.points_per_line,
                                              window=settings.window, search=settings.search, margin=(ml, mc),
                                              line_mask=usable, max_std=settings.texture_max_std_px)
    name = f"{ahead}/{behind}"
    if lines_a.size == 0:
        return PairData(name=name, ahead=ahead, behind=behind, tau_s=tau, line_a=lines_a, col_a=cols_a,
                        meas_line_b=lines_a.copy(), meas_col_b=cols_a.copy(), quality=lines_a.copy(),
                        valid=np.zeros(0, dtype=bool))
    g = sm.direct_location(ahead, lines_a, cols_a)
    pl, pc = sm.inverse_location(behind, g)
    inside = np.isfinite(pl) & np.isfinite(pc) & (pl > ml) & (pl < n_lines - 1 - ml) & (pc > mc) & \
        (pc < img_b.shape[1] - 1 - mc)
    lines_a, cols_a, pl, pc = lines_a[inside], cols_a[inside], pl[inside], pc[inside]
    # centre each point's search on the pilot's per-line shift (the residuals stay relative to pl, pc)
    sh_l, sh_c = pilot_shift(img_a, img_b, lines_a, cols_a, pl, pc, n_lines, settings)
    li = np.clip(np.rint(lines_a).astype(np.int64), 0, n_lines - 1)
    m = match_points(img_a, img_b, lines_a, cols_a, pl + sh_l[li], pc + sh_c[li], window=settings.window,
                     search=settings.search, method=settings.match_method, min_quality=settings.min_quality)
    return PairData(name=name, ahead=ahead, behind=behind, tau_s=tau, line_a=lines_a, col_a=cols_a,
                    meas_line_b=m.line_b, meas_col_b=m.col_b, quality=m.quality, valid=np.asarray(m.valid, bool),
                    pred_line_b=pl, pred_col_b=pc, std_line=np.asarray(m.std_line, float),
                    std_col=np.asarray(m.std_col, float))


def _synthesise(product: Product, pair: PairData, sm, settings: RestorationSettings, n_lines: int, *,
                recompute_sens: bool):
    v = pair.valid
    la, ca = pair.line_a[v], pair.col_a[v]
    g = sm.direct_location(pair.ahead, la, ca)
    pl, pc = sm.inverse_location(pair.behind, g)
    if recompute_sens or pair.sens is None:
        pair.sens = sm.sensitivities(pair.behind, g)
    pred_l = np.full(pair.valid.shape, np.nan)
    pred_c = np.full(pair.valid.shape, np.nan)
    pred_l[v], pred_c[v] = pl, pc
    pair.pred_line_b, pair.pred_col_b = pred_l, pred_c
    rl = pair.meas_line_b[v] - pl
    rc = pair.meas_col_b[v] - pc
    if pair.std_line is not None:
        # inverse variance of each matched coordinate (matcher's estimate, floored)
        floor = 0.02
        w = np.stack([1.0 / (pair.std_line[v] ** 2 + floor ** 2), 1.0 / (pair.std_col[v] ** 2 + floor ** 2)], axis=1)
    else:
        w = np.clip(pair.quality[v], 0.05, 1.0) ** 2
    res = instant_synthesis(np.rint(la).astype(np.int64), rl, rc, pair.sens, n_lines=n_lines, weights=w,
                            axes=settings.axes, min_points=settings.min_points_per_line, n_sigma=settings.n_sigma)
    inl = np.zeros(pair.valid.shape, dtype=bool)
    inl[v] = res.inlier
    pair.inlier = inl
    pair.synthesis = res
    # actual delay τ' (time synchronisation): median over the points
    tau_pts = (pl - la) * product.instrument.line_period_s
    if tau_pts.size:
        pair.tau_s = float(np.median(tau_pts))
    return res


def restore_product(product: Product, settings: RestorationSettings | None = None, *, progress: bool = False,
                    run_dir: Path | None = None, corrected_path: Path | None = None,
                    corrected_attrs: dict | None = None) -> RestorationResult:
    """Restore the line-of-sight attitude of a product (never reads truth).

    With ``corrected_path``, the corrected images are written there block by
    block (memory bounded by one band) and ``result.corrected`` is that file
    opened lazily; otherwise they are kept in memory.
    """
    from .integration import DEFAULT_METHOD

    settings = settings or RestorationSettings()
    t_all = _time.perf_counter()
    timings = {}
    pairs_ab = _resolve_pairs(product, settings)
    # best_first (patent claims 9-11): the best-correlated pair alone first, then the next ones
    # folded in one per iteration, re-predicting with the refined attitude, then all of them
    # until the increment is immaterial (at most `iterations` passes after the last pair)
    n_iter = settings.iterations if settings.pair_order == "fused" else len(pairs_ab) - 1 + settings.iterations
    n_stages = len(pairs_ab) + n_iter + 2
    bar = _Progress(progress, n_stages)
    t_line = product.time
    n_lines = t_line.size
    te = product.instrument.line_period_s
    sm = product.sensor_model()
    try:
        # 1-2. matching
        t = _time.perf_counter()
        pairs = []
        if settings.match_method == "ncc":
            from ._ncc_kernel import match_ncc
            if not match_ncc.signatures:  # first use in this process: loaded from Numba's cache, or compiled
                bar.note("loading the matching kernel (compiled on first use, ~10-15 s, cached after)")
        for a, b in pairs_ab:
            pairs.append(match_pair(product, a, b, settings, sm))
            bar.step(f"matched {a}/{b}")
        timings["matching_s"] = _time.perf_counter() - t
        n_matches = sum(p.valid.size for p in pairs)
        n_valid = sum(int(np.count_nonzero(p.valid)) for p in pairs)
        if n_valid < settings.min_points_per_line * 10:
            raise RestorationError(
                f"{product.path}: no usable texture — only {n_valid} valid matches out of {n_matches} candidates over "
                f"{len(pairs)} pairs (water, clouds, flat areas or noise everywhere? candidates pass the a-priori "
                f"criterion restoration.texture_max_std_px = {settings.texture_max_std_px}, matches "
                f"restoration.min_quality = {settings.min_quality}); nothing to restore")

        kn = product.knowledge
        kr, kp, ky = kn.at(t_line)
        knowledge = {"roll": kr, "pitch": kp, "yaw": ky}
        estimate = {a: np.zeros(n_lines) for a in AXES}
        method = settings.method or DEFAULT_METHOD
        t_syn = t_int = 0.0
        valid_est = {a: np.ones(n_lines, dtype=bool) for a in AXES}
        # correlation ranking of the pairs: valid matches x their mean quality
        score = [float(np.count_nonzero(p.valid)) * float(np.nanmean(p.quality[p.valid])) if p.valid.any() else 0.0
                 for p in pairs]
        ranked = sorted(range(len(pairs)), key=lambda j: -score[j])
        for it in range(n_iter):
            ts = _time.perf_counter()
            if settings.pair_order == "best_first":
                used = [pairs[j] for j in sorted(ranked[:it + 1])]
            else:
                used = pairs
            if it == 0:
                sm_it = sm
            else:
                cur = {a: knowledge[a] + np.nan_to_num(estimate[a]) for a in AXES}
                sm_it = product.sensor_model(attitude=clamped_attitude(_series(t_line, cur)))
            diffs = {a: [] for a in AXES}
            sigmas = {a: [] for a in AXES}
            points = []
            taus = []
            lags = []
            for p in used:
                res = _synthesise(product, p, sm_it, settings, n_lines, recompute_sens=(p.sens is None or it == 0))
                taus.append(p.tau_s)
                lags.append(_line_lag(p, n_lines, settings.max_gap_fill_lines) * te)
                # relative weight of each line's differential: its matched points (filled lines: the minimum)
                points.append(np.where(res.n_points >= settings.min_points_per_line, res.n_points,
                                       settings.min_points_per_line).astype(np.float64))
                for k, a in enumerate(AXES):
                    d = drop_sparse(res.diff[:, k], half_window=max(settings.max_gap_fill_lines, 1))
                    d = fill_short_gaps(d, max_gap=settings.max_gap_fill_lines)
                    if settings.compensate_window:
                        d = window_compensation(d, window_lines=settings.window[0])
                    diffs[a].append(d)
                    sigmas[a].append(res.sigma[:, k])
            t_syn += _time.perf_counter() - ts
            ti = _time.perf_counter()
            change = 0.0
            for a in settings.axes:
                if all(np.all(~np.isfinite(d)) for d in diffs[a]):
                    counts = "; ".join(f"{p.name}: {int(np.count_nonzero(p.valid))} valid of {p.valid.size} "
                                       f"candidates over {n_lines} lines" for p in pairs)
                    raise RestorationError(
                        f"{product.path}: no line could be synthesised on {a}: fewer than "
                        f"restoration.min_points_per_line = {settings.min_points_per_line} good matches on every "
                        f"line ({counts}); the bands are too noisy or too poorly textured for the "
                        f"a-priori criterion (restoration.texture_max_std_px = {settings.texture_max_std_px}) "
                        f"and restoration.min_quality = {settings.min_quality}")
                inc = _integrate_time_sync(diffs[a], taus, lags, te, method=method, settings=settings,
                                           sigmas=sigmas[a], weights=points)
                valid_est[a] = np.isfinite(inc)
                new_est = np.where(np.isfinite(inc), np.nan_to_num(estimate[a]) + inc, np.nan)
                if np.isfinite(new_est).any():
                    change = max(change, float(np.sqrt(np.nanmean(inc ** 2)) /
                                               max(np.sqrt(np.nanmean(new_est ** 2)), 1e-300)))
                estimate[a] = new_est
            t_int += _time.perf_counter() - ti
            bar.step(f"iteration {it + 1}" + (f" ({len(used)} pair{'s' * (len(used) > 1)})"
                                              if settings.pair_order == "best_first" else ""))
            if settings.pair_order == "best_first" and len(used) == len(pairs) and it > 0 and change < 0.02:
                break  # converged: the last pass changed the estimate by < 2 % RMS
        timings["synthesis_s"] = t_syn
        timings["integration_s"] = t_int
        for a in AXES:
            if a not in settings.axes:
                estimate[a] = np.zeros(n_lines)
        # remove the (unobservable) mean of the correction
        for a in settings.axes:
            m = np.isfinite(estimate[a])
            if m.any():
                estimate[a] = estimate[a] - np.mean(estimate[a][m])
        restored = {a: knowledge[a] + estimate[a] for a in AXES}
        # 6. star-tracker anchoring (absolute constant)
        anchored = False
        if settings.anchor_star_tracker and product.star_tracker is not None:
            st = product.star_tracker
            for a in settings.axes:
                m = np.isfinite(restored[a])
                sel = (st.time >= t_line[m].min()) & (st.time <= t_line[m].max()) if m.any() else np.zeros(0, bool)
                if sel.sum() >= 1:
                    r_at = np.interp(st.time[sel], t_line[m], restored[a][m])
                    offset = float(np.mean(getattr(st, a)[sel] - r_at))
                    restored[a] = restored[a] + offset
                    anchored = True
        coverage = {a: float(np.mean(np.isfinite(restored[a]))) for a in AXES}
        for a in settings.axes:
            if coverage[a] < settings.min_coverage:
                raise RestorationError(f"{product.path}: coverage on {a} is {coverage[a] * 100:.1f} % "
                                       f"(< restoration.min_coverage = {settings.min_coverage * 100:.0f} %): "
                                       "not enough texture to restore")
        bar.step("integrated")

        # 7. misregistration before/after and corrected images
        t = _time.perf_counter()
        misreg = {}
        corrected = None
        if settings.correct_images:
            from .correction import correct_bands, misregistration
            rest_fill = {a: np.where(np.isfinite(restored[a]), restored[a], knowledge[a]) for a in AXES}
            rest_series = _series(t_line, rest_fill)
            corrected = correct_bands(product, restored=rest_series, valid=np.all(
                [np.isfinite(restored[a]) for a in settings.axes], axis=0), column_step=settings.correction_column_step,
                path=corrected_path, attrs=corrected_attrs)
            misreg = misregistration(product, corrected, pairs, settings)
        timings["correction_s"] = _time.perf_counter() - t
        bar.step("corrected")
    finally:
        bar.close()
    timings["total_s"] = _time.perf_counter() - t_all
    timings["lines_per_s"] = n_lines / timings["total_s"]
    timings["matches_per_s"] = n_matches / max(timings["matching_s"], 1e-9)
    timings["matches"] = n_matches
    result = RestorationResult(run_dir=run_dir, time=t_line, restored=restored, knowledge=knowledge,
                               correction=estimate, coverage=coverage, pairs=pairs, timings=timings,
                               misregistration=misreg, settings=settings, pixel_ifov_rad=product.pixel_ifov_rad,
                               method=method)
    result.anchored = anchored
    result.corrected = corrected
    return result


def restoration_dataset(res: RestorationResult):
    """The ``restoration.nc`` dataset of a result."""
    import xarray as xr

    data = {}
    for a in AXES:
        data[a] = ("time", res.restored[a], {"units": "rad", "long_name": f"restored line-of-sight {a}",
                                             "coverage": res.coverage[a]})
        data[f"knowledge_{a}"] = ("time", res.knowledge[a], {"units": "rad"})
        data[f"correction_{a}"] = ("time", res.correction[a], {"units": "rad"})
    names = [p.name for p in res.pairs]
    for k, a in enumerate(AXES):
        data[f"diff_{a}"] = (("pair", "time"), np.stack([p.synthesis.diff[:, k] for p in res.pairs]),
                             {"units": "rad", "long_name": f"per-line {a} differential θ(t+τ)−θ(t) (remaining error)"})
        data[f"diff_sigma_{a}"] = (("pair", "time"), np.stack([p.synthesis.sigma[:, k] for p in res.pairs]),
                                   {"units": "rad", "long_name": "formal 1-sigma of the differential"})
    w = np.stack([p.synthesis.n_points for p in res.pairs]).astype(np.int32)
    data["diff_points"] = (("pair", "time"), w, {"long_name": "inlier matches per line (synthesis weight)"})
    data["tau_s"] = ("pair", np.array([p.tau_s for p in res.pairs]), {"units": "s"})
    # matches, all pairs concatenated
    mp, cols = [], {k: [] for k in ("line_a", "col_a", "meas_line_b", "meas_col_b", "pred_line_b", "pred_col_b",
                                     "quality")}
    valid, inl = [], []
    for i, p in enumerate(res.pairs):
        mp.append(np.full(p.valid.size, i, dtype=np.int16))
        for k in cols:
            v = getattr(p, k)
            cols[k].append(np.full(p.valid.size, np.nan) if v is None else np.asarray(v, dtype=np.float64))
        valid.append(p.valid)
        inl.append(p.inlier if p.inlier is not None else np.zeros(p.valid.size, bool))
    data["match_pair"] = ("match", np.concatenate(mp) if mp else np.zeros(0, np.int16))
    for k, v in cols.items():
        attrs = ({"units": "1", "long_name": "normalised correlation of the match"} if k == "quality"
                 else {"units": "px"})
        data[f"match_{k}"] = ("match", np.concatenate(v) if v else np.zeros(0), attrs)
    data["match_valid"] = ("match", np.concatenate(valid).astype(np.int8))
    data["match_inlier"] = ("match", np.concatenate(inl).astype(np.int8))
    data["match_residual_line"] = ("match", data["match_meas_line_b"][1] - data["match_pred_line_b"][1], {"units": "px"})
    data["match_residual_col"] = ("match", data["match_meas_col_b"][1] - data["match_pred_col_b"][1], {"units": "px"})
    attrs = {"title": "simsat restoration", "method": res.method, "pixel_ifov_rad": res.pixel_ifov_rad,
             "pairs": ",".join(names), "settings": json.dumps(_settings_dict(res.settings), sort_keys=True),
             "timings": json.dumps(res.timings, sort_keys=True),
             "misregistration": json.dumps(res.misregistration, sort_keys=True),
             "anchored_on_star_tracker": int(getattr(res, "anchored", False))}
    for a in AXES:
        attrs[f"coverage_{a}"] = res.coverage[a]
    return xr.Dataset(data, coords={"time": ("time", res.time, {"units": "s"}), "pair": ("pair", np.array(names))},
                      attrs=attrs)


def _settings_dict(s: RestorationSettings) -> dict:
    d = dict(s.__dict__)
    d["window"] = list(s.window)
    d["search"] = list(s.search)
    d["axes"] = list(s.axes)
    return d


def _restoration_table(run_json: Path) -> dict:
    """The ``[restoration]`` table of the scenario recorded in ``run.json``."""
    try:
        info = json.loads(run_json.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ProductError(f"{run_json}: not a readable JSON file ({e}); render the run again or remove it") from None
    if not isinstance(info, dict):
        raise ProductError(f"{run_json}: must hold a JSON object (simsat's run record), got {type(info).__name__}")
    table = info.get("scenario", {})
    for k in ("raw", "restoration"):
        table = table.get(k, {}) if isinstance(table, dict) else None
    if table is None or not isinstance(table, dict):
        raise ProductError(f"{run_json}: scenario.raw.restoration must be a table, got {type(table).__name__}")
    return table


def restore_run(run_dir: str | Path, *, overrides: dict | None = None, progress: bool = True) -> RestorationResult:
    """``simsat restore RUN_DIR``: read the product, restore, write restoration.nc (+ corrected.nc)."""
    run_dir = Path(run_dir)
    if run_dir.exists() and not run_dir.is_dir():
        raise ProductError(f"{run_dir}: is a file; expected a run directory (the one holding product.nc)")
    product = read_product(run_dir)
    table = {}
    run_json = run_dir / "run.json"
    if run_json.exists():
        table = _restoration_table(run_json)
    if overrides:
        ov = overrides.get("restoration", overrides)
        table = {**table, **ov}
    settings = restoration_settings(Section(table, "restoration"))
    # provenance: which product and settings the outputs come from (checked by the report)
    pid = str(product.ds.attrs.get("product_id", "")) or content_id(str(product.path))
    rid = content_id(pid, _settings_dict(settings))
    with RunLock(run_dir, "restore"):
        part = temporary_path(run_dir / "corrected.nc")  # written block by block, renamed when complete
        try:
            res = restore_product(product, settings, progress=progress, run_dir=run_dir, corrected_path=part,
                                  corrected_attrs={"product_id": pid, "restoration_id": rid})
            ds = restoration_dataset(res)
            ds.attrs.update(product_id=pid, restoration_id=rid)
            # corrected.nc first: a restore killed between the two writes leaves a corrected.nc whose
            # restoration_id no longer matches restoration.nc, which the report refuses
            corrected = getattr(res, "corrected", None)
            if corrected is not None:
                corrected.close()
                os.replace(part, run_dir / "corrected.nc")
                res.corrected = None
            elif (run_dir / "corrected.nc").is_file():
                (run_dir / "corrected.nc").unlink()  # simsat's own output of an earlier restoration: stale now
        finally:
            part.unlink(missing_ok=True)
        res.path = atomic_write_dataset(ds, run_dir / "restoration.nc")
    return res
