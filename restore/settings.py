"""``[restoration]`` settings: the dataclass, its parser (every key optional) and its JSON form."""
from __future__ import annotations

from dataclasses import dataclass, field

from simsat.config import ScenarioError, Section
from simsat.validation import register_table_check

from .integration import check_options, integration_method
from .matching import MATCHING_METHODS
from .method_choice import AUTO_CANDIDATES, AUTO_METHOD
from .selection import SELECTION_METHODS
from .synthesis import AXES

__all__ = ["RestorationSettings", "restoration_settings", "settings_dict", "NOISE_MODELS"]

#: ``restoration.noise_model``: the images' noise in the texture criterion (point selection, window width):
#: "signal_dependent" (read + shot noise: the detector's calibration in product.nc, else fitted on the band,
#: :func:`restore.stages.band_noise`) or
#: "constant" (one σ per band, :func:`restore.selection.estimate_image_noise`)
NOISE_MODELS = ("signal_dependent", "constant")


@dataclass
class RestorationSettings:
    pairs: list | str = "auto"
    selection: str = "grid"
    points_per_line: int = 24
    texture_max_std_px: float = 0.4
    noise_model: str = "signal_dependent"
    window: tuple = (3, 31)
    window_columns: int | str = "auto"
    search: tuple = (3, 3)
    pilot_search: tuple = (8, 8)
    match_method: str = "ncc"
    min_quality: float = 0.6
    axes: tuple = ("roll", "pitch")
    n_sigma: float = 3.0
    despike_sigma: float = 10.0
    transient_factor: float = 4.0
    line_weighting: bool = True
    match_covariance: bool = True
    min_points_per_line: int = 3
    highpass_hz: float | str = "auto"
    max_gap_fill_lines: int = 8
    compensate_window: bool = True
    method: str | None = None
    integration_options: dict = field(default_factory=dict)
    iterations: int = 1
    pair_order: str = "fused"
    anchor_star_tracker: bool = True
    correct_images: bool = True
    correction_column_step: int = 64
    corrected_compression: str = "zlib"
    tdi_mean_attitude: bool = True
    min_coverage: float = 0.05
    posterior_samples: int = 8
    noise_colour_weighting: bool = True
    knowledge_noise_floor: bool = False
    knowledge_smoothing: bool = True
    knowledge_dephasing: bool = True
    knowledge_timing: bool = True
    deconvolve_exposure: bool = True
    highpass_per_axis: bool = False
    sigma_local_error: bool = True
    sigma_knowledge_check: bool = True
    knowledge_fusion: bool = True
    knowledge_prior: bool = True
    knowledge_conditioning: bool = True
    excess_shrink: bool = True
    knowledge_band_noise: bool = True
    rematch: int | str = "auto"
    rematch_search: tuple = (2, 2)
    max_sigma_px: float | str = "auto"


#: compression of the corrected images (corrected.nc) → netCDF4 createVariable keywords. "zlib" is
#: readable by every netCDF tool; "lz4" (Blosc LZ4 with byte shuffle, HDF5 filter 32001) compresses
#: about 12× faster for a file about 3 % larger, but a reader needs the HDF5 Blosc plugin (the
#: netCDF4-python wheels carry it); "none" writes raw float32 (about 30 % larger)
CORRECTED_COMPRESSION = {
    "zlib": {"zlib": True, "complevel": 4, "shuffle": True},
    "lz4": {"compression": "blosc_lz4", "complevel": 5, "blosc_shuffle": 1},
    "none": {},
}


def _parse_method(sec: Section, s: RestorationSettings) -> None:
    """``method`` and its ``[restoration.integration]`` options, into ``s``."""
    m = sec.raw("method", None)
    if m is not None:
        if not isinstance(m, str):
            raise sec.error("method", f"must be a method name (string), got {m!r}")
        if m != AUTO_METHOD:
            try:
                integration_method(m)
            except ValueError as e:
                raise sec.error("method", str(e).split(": ", 1)[1] + f" (or {AUTO_METHOD!r})") from None
    s.method = m
    opts = sec.section("integration")
    if m == AUTO_METHOD:
        if opts.data:
            raise sec.error("integration", f"takes no options with method = {AUTO_METHOD!r} (it chooses between "
                                           f"{', '.join(AUTO_CANDIDATES)} with their defaults); got "
                                           f"{', '.join(sorted(opts.data))}")
    else:
        try:
            s.integration_options = dict(check_options(m, dict(opts.data), where=opts.path))
        except ValueError as e:
            raise ScenarioError(str(e)) from None
    opts.finish(extra_allowed=opts.data.keys())


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
    s.selection = sec.string("selection", s.selection, choices=tuple(SELECTION_METHODS))
    s.points_per_line = sec.integer("points_per_line", s.points_per_line, ge=3, le=1000)
    s.texture_max_std_px = sec.number("texture_max_std_px", s.texture_max_std_px, gt=0)
    s.noise_model = sec.string("noise_model", s.noise_model, choices=NOISE_MODELS)
    wl = sec.integer("window_lines", s.window[0], ge=1, le=63)
    wc = sec.number_or("window_columns", "auto", ge=3, le=255)
    if wl % 2 == 0:
        raise sec.error("window_lines", f"must be odd, got {wl}")
    if wc != "auto" and (not float(wc).is_integer() or int(wc) % 2 == 0):
        raise sec.error("window_columns", f"must be an odd integer or \"auto\", got {wc}")
    s.window_columns = wc if wc == "auto" else int(wc)
    s.window = (wl, s.window[1] if wc == "auto" else int(wc))
    s.search = (sec.integer("search_lines", s.search[0], ge=0, le=64), sec.integer("search_columns", s.search[1], ge=0, le=64))
    s.pilot_search = (sec.integer("pilot_search_lines", s.pilot_search[0], ge=0, le=64),
                      sec.integer("pilot_search_columns", s.pilot_search[1], ge=0, le=64))
    s.match_method = sec.string("match_method", s.match_method, choices=tuple(MATCHING_METHODS))
    s.min_quality = sec.number("min_quality", s.min_quality, ge=-1, le=1)
    s.axes = tuple(sec.strings("axes", list(s.axes), choices=AXES))
    if not s.axes:
        raise sec.error("axes", f"must name at least one axis of {', '.join(AXES)}")
    if len(set(s.axes)) != len(s.axes):
        raise sec.error("axes", f"names an axis twice: {list(s.axes)}")
    s.n_sigma = sec.number("n_sigma", s.n_sigma, gt=0)
    s.despike_sigma = sec.number("despike_sigma", s.despike_sigma, ge=0)
    s.transient_factor = sec.number("transient_factor", s.transient_factor, ge=0)
    s.line_weighting = sec.boolean("line_weighting", s.line_weighting)
    s.match_covariance = sec.boolean("match_covariance", s.match_covariance)
    s.min_points_per_line = sec.integer("min_points_per_line", s.min_points_per_line, ge=2)
    s.highpass_hz = sec.number_or("highpass_hz", "auto", ge=0, le=1e4)
    s.max_gap_fill_lines = sec.integer("max_gap_fill_lines", s.max_gap_fill_lines, ge=0)
    s.compensate_window = sec.boolean("compensate_window", s.compensate_window)
    _parse_method(sec, s)
    s.iterations = sec.integer("iterations", s.iterations, ge=1, le=10)
    s.pair_order = sec.string("pair_order", s.pair_order, choices=("fused", "best_first"))
    s.anchor_star_tracker = sec.boolean("anchor_star_tracker", s.anchor_star_tracker)
    s.correct_images = sec.boolean("correct_images", s.correct_images)
    s.correction_column_step = sec.integer("correction_column_step", s.correction_column_step, ge=1)
    s.corrected_compression = sec.string("corrected_compression", s.corrected_compression,
                                         choices=tuple(CORRECTED_COMPRESSION))
    s.tdi_mean_attitude = sec.boolean("tdi_mean_attitude", s.tdi_mean_attitude)
    s.min_coverage = sec.number("min_coverage", s.min_coverage, ge=0, le=1)
    s.knowledge_prior = sec.boolean("knowledge_prior", s.knowledge_prior)
    s.knowledge_conditioning = sec.boolean("knowledge_conditioning", s.knowledge_conditioning)
    s.excess_shrink = sec.boolean("excess_shrink", s.excess_shrink)
    s.knowledge_band_noise = sec.boolean("knowledge_band_noise", s.knowledge_band_noise)
    s.noise_colour_weighting = sec.boolean("noise_colour_weighting", s.noise_colour_weighting)
    s.knowledge_noise_floor = sec.boolean("knowledge_noise_floor", s.knowledge_noise_floor)
    s.knowledge_smoothing = sec.boolean("knowledge_smoothing", s.knowledge_smoothing)
    s.knowledge_dephasing = sec.boolean("knowledge_dephasing", s.knowledge_dephasing)
    s.knowledge_timing = sec.boolean("knowledge_timing", s.knowledge_timing)
    s.deconvolve_exposure = sec.boolean("deconvolve_exposure", s.deconvolve_exposure)
    s.highpass_per_axis = sec.boolean("highpass_per_axis", s.highpass_per_axis)
    rm = sec.raw("rematch", "auto")
    if rm != "auto" and (isinstance(rm, bool) or not isinstance(rm, int) or not 0 <= rm <= 5):
        raise sec.error("rematch", f"must be \"auto\" or a number of passes from 0 to 5, got {rm!r}")
    s.rematch = rm
    s.rematch_search = (sec.integer("rematch_search_lines", s.rematch_search[0], ge=1, le=16),
                        sec.integer("rematch_search_columns", s.rematch_search[1], ge=1, le=16))

    s.posterior_samples = sec.integer("posterior_samples", s.posterior_samples, ge=0, le=1000)
    if s.posterior_samples == 1:
        raise sec.error("posterior_samples", "must be 0 (no predicted σ) or >= 2 Monte Carlo draws, got 1")
    s.sigma_local_error = sec.boolean("sigma_local_error", s.sigma_local_error)
    s.sigma_knowledge_check = sec.boolean("sigma_knowledge_check", s.sigma_knowledge_check)
    s.knowledge_fusion = sec.boolean("knowledge_fusion", s.knowledge_fusion)
    s.max_sigma_px = sec.number_or("max_sigma_px", "auto", gt=0)
    sec.finish()
    return s


def settings_dict(s: RestorationSettings) -> dict:
    """The settings as a JSON-serialisable dict (recorded in ``restoration.nc``)."""
    d = dict(s.__dict__)
    d["window"] = list(s.window)
    d["search"] = list(s.search)
    d["axes"] = list(s.axes)
    d["rematch_search"] = list(s.rematch_search)
    return d


register_table_check("restoration", restoration_settings)
