"""Scenario files: load a TOML file, validate it, resolve it into model objects.

A scenario has the tables ``[scenario]`` (name, seed, description),
``[scene]`` (``dem``, ``dem_knowledge``, ``texture``, ``sun``), ``[platform]``,
``[attitude]`` (``jitter`` array, ``knowledge``, ``star_tracker``),
``[instrument]`` (``detectors`` array, ``noise``), ``[acquisition]``, and the
optional ``[restoration]`` and ``[report]`` tables read by later stages.

Every error is a :class:`~simsat.config.ScenarioError` whose one-line message
names the file and the TOML key.
"""
from __future__ import annotations

import copy
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import terrain
from .attitude import AttitudeModel
from .config import ScenarioError, Section
from .instrument import Instrument, instrument_from_config
from .platform import Platform, platform_from_config
from .sensor_model import flat_ground_delay_s, los_body
from .validation import run_table_checks

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

__all__ = ["Scenario", "load_scenario", "builtin_scenarios", "find_scenario", "SCENARIO_DIR"]

SCENARIO_DIR = (Path(__file__).resolve().parent / "scenarios").resolve()  # a link to the top-level scenarios/ in a checkout
TOP_LEVEL = ("scenario", "scene", "platform", "attitude", "instrument", "acquisition", "restoration", "report")


@dataclass
class Acquisition:
    lines: int
    block_lines: int
    reference_detector: str
    t0_s: float = 0.0
    #: > 0: a matrix detector takes a frame every ``frame_period_s`` and ``lines`` counts frames (simsat.frames)
    frame_period_s: float = 0.0

    @property
    def is_frames(self) -> bool:
        return self.frame_period_s > 0


@dataclass
class Scenario:
    """A validated, resolved scenario.

    Attributes hold the model objects; ``raw`` keeps the TOML tables as read,
    ``source`` the file it came from (None for dict input).
    """

    name: str
    seed: int
    description: str
    platform: Platform
    instrument: Instrument
    acquisition: Acquisition
    raw: dict
    source: Path | None
    base_dir: Path
    # resolved lazily / by resolve():
    x_range_m: tuple = (0.0, 0.0)
    y_range_m: tuple = (0.0, 0.0)
    requirement: dict = field(default_factory=dict)
    #: the imaged ground (nominal geometry, without the scene margin) [m]
    footprint_m: tuple = ((0.0, 0.0), (0.0, 0.0))

    # -- derived geometry ----------------------------------------------------
    @property
    def line_period_s(self) -> float:
        return self.instrument.line_period_s

    @property
    def t0_s(self) -> float:
        return self.acquisition.t0_s

    @property
    def sample_period_s(self) -> float:
        """Time between successive product lines: the line period, or the frame period of a matrix."""
        return self.acquisition.frame_period_s or self.line_period_s

    @property
    def t_end_s(self) -> float:
        return self.t0_s + (self.acquisition.lines - 1) * self.sample_period_s

    @property
    def line_times(self) -> np.ndarray:
        """Times of the product's lines (of its frames for a matrix detector) [s]."""
        return self.t0_s + np.arange(self.acquisition.lines) * self.sample_period_s

    def delay_s(self, ahead: str, behind: str) -> float:
        """Delay τ [s] after which ``behind`` sees what ``ahead`` saw, for the nominal viewing geometry
        (off-nadir pointing included: :func:`simsat.sensor_model.flat_ground_delay_s`)."""
        return flat_ground_delay_s(self.platform, self.instrument, ahead, behind)

    def section(self, name: str) -> Section:
        """The raw ``[name]`` table as a :class:`Section` (for later stages)."""
        return Section(copy.deepcopy(self.raw.get(name, {})), name)

    # -- model builders (each builds on demand; deterministic per seed) --------
    def attitude_model(self):
        nominal = (self.platform.off_nadir_roll_rad, self.platform.off_nadir_pitch_rad, 0.0)
        sec = self.section("attitude")
        margin = 0.05 + self.instrument.line_period_s * 4
        return AttitudeModel.from_config(sec, seed=self.seed, nominal=nominal,
                                         t_start=self.t0_s - margin, t_end=self.t_end_s + margin)

    def dems(self):
        """(true DEM, DEM known by the ground segment)."""
        sec = self.section("scene")
        dsec = sec.section("dem")
        dem = terrain.dem_from_config(dsec, base_dir=self.base_dir, seed=self.seed,
                                      x_range_m=self.x_range_m, y_range_m=self.y_range_m)
        _check_coverage(dem, self.x_range_m, self.y_range_m, dsec.key("path") if dsec.has("path") else dsec.path)
        ksec = sec.section("dem_knowledge")
        known = terrain.knowledge_dem_from_config(ksec, truth=dem, seed=self.seed)
        # over a round Earth (an orbit) both lie on the sphere, in the local frame tangent at the scene centre
        radius = self.platform.earth_radius_m
        return dem.on_sphere(radius), known.on_sphere(radius)

    def texture(self):
        sec = self.section("scene").section("texture")
        # synthesise only the bands the instrument has (texture synthesis is a large share of rendering)
        bands = {d.band for d in self.instrument.detectors}
        return terrain.texture_from_config(sec, base_dir=self.base_dir, seed=self.seed, sun=self.sun(),
                                           default_bands=bands, footprint_m=self.footprint_m)

    def sun(self):
        return terrain.sun_from_config(self.section("scene").section("sun"))

    def to_dict(self) -> dict:
        """The scenario as resolved (raw tables plus derived quantities)."""
        names = self.instrument.names
        delays = {}
        for i, a in enumerate(names):
            for b in names[i + 1:]:
                tau = self.delay_s(a, b)
                if tau < 0:
                    delays[f"{b}/{a}"] = -tau
                else:
                    delays[f"{a}/{b}"] = tau
        return {
            "raw": copy.deepcopy(self.raw),
            "source": str(self.source) if self.source else None,
            "derived": {
                "x_range_m": list(self.x_range_m),
                "y_range_m": list(self.y_range_m),
                "line_period_s": self.line_period_s,
                "duration_s": self.t_end_s - self.t0_s,
                "ifov_rad": {d.name: d.pitch_m / self.instrument.focal_length_m for d in self.instrument.detectors},
                "delays_s": delays,
                "platform_x_at_t0_m": self.platform.x_at_t0_m,
                "platform_y_m": self.platform.y_m,
            },
        }


def _check_coverage(dem, x_range, y_range, where: str) -> None:
    (x0, x1), (y0, y1) = dem.x_range, dem.y_range
    if x0 > x_range[0] or x1 < x_range[1] or y0 > y_range[0] or y1 < y_range[1]:
        raise ScenarioError(
            f"{where}: the DEM covers x ∈ [{x0:.0f}, {x1:.0f}] m, y ∈ [{y0:.0f}, {y1:.0f}] m but the acquisition "
            f"needs x ∈ [{x_range[0]:.0f}, {x_range[1]:.0f}] m, y ∈ [{y_range[0]:.0f}, {y_range[1]:.0f}] m; "
            "reduce acquisition.lines or instrument pixels, or use a larger DEM")


def _read_toml(path: Path) -> dict:
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise ScenarioError(f"{path}: scenario file not found") from None
    except IsADirectoryError:
        raise ScenarioError(f"{path}: is a directory, expected a .toml scenario file") from None
    except tomllib.TOMLDecodeError as e:
        raise ScenarioError(f"{path}: TOML syntax error: {e}") from None
    except UnicodeDecodeError as e:
        raise ScenarioError(f"{path}: not a UTF-8 text file ({e.reason})") from None


def builtin_scenarios() -> dict[str, Path]:
    """Name → path of the scenarios shipped with the package."""
    return {p.stem: p for p in sorted(SCENARIO_DIR.glob("*.toml"))}


def find_scenario(name_or_path: str | Path) -> Path:
    """A path to a scenario file, or the built-in scenario of that name.

    A bare name (no directory part, no ``.toml`` suffix, e.g. ``phr_cmg``)
    means the built-in scenario of that name; anything else is a path, which
    must exist -- a mistyped path is an error, never a silent fallback to a
    built-in of the same stem.
    """
    p = Path(name_or_path)
    builtin = builtin_scenarios()
    text = str(name_or_path)
    is_bare_name = p.suffix != ".toml" and len(p.parts) == 1 and not text.startswith(".")
    if is_bare_name and text in builtin:
        return builtin[text]
    if p.exists():
        if p.is_dir():
            raise ScenarioError(f"{p}: is a directory, expected a .toml scenario file")
        return p
    if is_bare_name:
        raise ScenarioError(f"{text}: no built-in scenario of that name and no such file "
                            f"(built-in scenarios: {', '.join(builtin)}; `simsat scenarios` lists them)")
    hint = ""
    if p.stem in builtin:
        hint = f"; the built-in scenario of that name is `{p.stem}` (or {builtin[p.stem]})"
    raise ScenarioError(f"{p}: scenario file not found{hint}")


def load_scenario(source: str | Path | dict, *, overrides: dict | None = None, check_models: bool = True) -> Scenario:
    """Load and validate a scenario.

    Parameters
    ----------
    source : str, Path or dict
        A TOML file, the name of a built-in scenario, or an already-parsed dict.
    overrides : dict, optional
        Nested dict merged over the file (e.g. ``{"acquisition": {"lines": 100}}``).
    check_models : bool
        Also build the attitude model, terrain and texture configs so that every
        key is validated (cheap; the DEM is not generated).

    Raises
    ------
    ScenarioError
        One line naming the file and the key at fault.
    """
    if isinstance(source, dict):
        raw = copy.deepcopy(source)
        path = None
        base_dir = Path.cwd()
    else:
        path = find_scenario(source)
        raw = _with_base(_read_toml(path), path)
        base_dir = path.resolve().parent
    if overrides:
        try:
            _merge(raw, overrides)
        except ScenarioError as e:
            raise ScenarioError(f"--set {e}") from None
    try:
        sc = _build(raw, path, base_dir)
        if check_models:
            _validate_models(sc)
    except ScenarioError as e:
        if path is not None and not str(e).startswith(str(path)):
            raise ScenarioError(f"{path}: {e}") from None
        raise
    return sc


def _with_base(raw: dict, path: Path, seen: tuple = ()) -> dict:
    """The scenario with ``[scenario] base`` resolved: the base's tables, overlaid by this file's.

    ``base`` is a built-in scenario's name or a path relative to this file.
    Tables merge key by key, except that a table naming another ``kind``
    replaces the base's; any other value, arrays of tables included
    (``[[attitude.jitter]]``), replaces the base's. Bases may have bases.
    """
    meta = raw.get("scenario")
    if not isinstance(meta, dict) or "base" not in meta:
        return raw
    base = meta.pop("base")
    if not isinstance(base, str) or not base:
        raise ScenarioError(f"{path}: scenario.base: must be a scenario name or a path, got {base!r}")
    p = Path(base)
    base_path = find_scenario(base) if (p.suffix != ".toml" and len(p.parts) == 1) else \
        find_scenario(str(path.resolve().parent / p))
    key = base_path.resolve()
    if key in seen or key == path.resolve():
        raise ScenarioError(f"{path}: scenario.base: {base!r} leads back to itself")
    if len(seen) >= 8:
        raise ScenarioError(f"{path}: scenario.base: more than 8 levels of bases")
    merged = _with_base(_read_toml(base_path), base_path, seen + (path.resolve(),))
    merged.get("scenario", {}).pop("requirement", None)  # a derived scenario states its own requirement
    _overlay(merged, raw)
    return merged


#: keys that say what kind of thing a table is: a table of another kind replaces the base's, whole
_KIND_KEYS = ("kind", "trajectory")


def _same_kind(base: dict, over: dict) -> bool:
    return all(over.get(k, base.get(k)) == base.get(k) for k in _KIND_KEYS)


def _overlay(base: dict, over: dict) -> None:
    """Tables merge key by key (a table of another ``kind`` or ``trajectory`` replaces the base's); every other
    value replaces it."""
    for k, v in over.items():
        if isinstance(v, dict) and isinstance(base.get(k), dict) and _same_kind(base[k], v):
            _overlay(base[k], v)
        else:
            base[k] = copy.deepcopy(v)


def _merge(base: dict | list, over: dict, where: str = "") -> None:
    """Merge overrides into a raw scenario; integer keys index arrays of tables (``jitter[0]``)."""
    for k, v in over.items():
        key = f"{where}[{k}]" if isinstance(k, int) else (f"{where}.{k}" if where else str(k))
        if isinstance(k, int):
            if not isinstance(base, list):
                raise ScenarioError(f"{key}: not an array in the scenario, cannot be indexed")
            if not 0 <= k < len(base):
                raise ScenarioError(f"{key}: index out of range (the array has {len(base)} entries)")
        elif isinstance(base, list):
            raise ScenarioError(f"{where}: is an array; index it as {where}[0].{k}")
        cur = base[k] if isinstance(k, int) else base.get(k)
        if isinstance(v, dict) and isinstance(cur, (dict, list)) and (isinstance(cur, dict) or
                                                                      all(isinstance(i, int) for i in v)):
            _merge(cur, v, key)
        elif isinstance(v, dict) and isinstance(cur, list):
            first = next(iter(v))
            raise ScenarioError(f"{key}: is an array of tables; index it, e.g. {key}[0].{first}")
        elif isinstance(v, dict) and any(isinstance(i, int) for i in v):
            raise ScenarioError(f"{key}: not an array in the scenario, cannot be indexed")
        else:
            base[k] = v


def _build(raw: dict, path: Path | None, base_dir: Path) -> Scenario:
    root = Section(raw, "")
    meta = root.section("scenario")
    name = meta.string("name", path.stem if path else "scenario")
    seed = meta.integer("seed", 0, ge=0, lt=2 ** 63)
    description = meta.string("description", "")
    requirement = {}
    req = meta.section("requirement")
    if req.data:
        requirement["max_rms_px"] = req.number("max_rms_px", None, gt=0, le=1000)
        requirement["max_p997_px"] = req.number("max_p997_px", None, gt=0, le=1000)
        req.finish()
    meta.finish()

    platform = platform_from_config(root.section("platform", required=True))
    instrument = instrument_from_config(root.section("instrument", required=True))

    acq = root.section("acquisition", required=True)
    lines = acq.integer("lines", gt=8, le=MAX_LINES)
    block = acq.integer("block_lines", 256, gt=0, le=65536)
    ref = acq.string("reference_detector", instrument.detectors[0].name, choices=instrument.names)
    t0 = acq.number("start_time_s", 0.0, ge=-1e9, le=1e9)
    margin_m = acq.number("scene_margin_m", 300.0, ge=0, le=1e5)
    frame_period = acq.number("frame_period_ms", 0.0, ge=0, le=1e5) * 1e-3
    acq.finish()
    acquisition = Acquisition(lines=lines, block_lines=block, reference_detector=ref, t0_s=t0,
                              frame_period_s=frame_period)
    _check_matrix(acq, instrument, acquisition)

    # sections read by later stages: only their presence/type is checked here
    for k in ("scene", "attitude", "restoration"):
        root.section(k, required=k in ("scene", "attitude"))
    root.section("report").finish()  # the report reads no key of it yet: any key is a mistake
    root.finish()

    # centre the platform: the mean detector line of sight hits (0, 0) at mid-acquisition
    f = instrument.focal_length_m
    along = np.array([d.along_m for d in instrument.detectors])
    t_mid = t0 + 0.5 * (lines - 1) * (frame_period or instrument.line_period_s)
    platform = platform.centred(t_mid_s=t_mid, along_angle_rad=float(np.arctan(along.mean() / f)))

    if acquisition.is_frames:
        from .frames import rows_per_frame
        det = instrument.detectors[0]
        adv = rows_per_frame(platform, det, f, frame_period)
        if not adv <= 0.75 * det.rows:
            raise ScenarioError(f"acquisition.frame_period_ms: the ground advances {adv:.1f} rows per frame, more than "
                                f"3/4 of the {det.rows}-row matrix: successive frames must overlap (the patent: "
                                f"generally by half); use a shorter frame period or more rows")
    # ground footprint of the acquisition (nominal geometry) + margins for jitter / relief
    t_first, t_last = t0, t0 + (lines - 1) * (frame_period or instrument.line_period_s)
    msg = platform.scan.check_span(t_first, t_last)
    if msg:
        raise ScenarioError(f"platform.scan: {msg}")
    corners = np.array([platform.nominal_ground_point(t, los_body(f, a, d.focal_plane_y(u)))
                        for t in (t_first, t_mid, t_last) for d in instrument.detectors
                        for a in (d.along_m + (d.rows - 1) / 2 * d.pitch_m, d.along_m - (d.rows - 1) / 2 * d.pitch_m)
                        for u in (-0.5, d.pixels - 0.5)])
    xs, ys = corners[:, 0], list(corners[:, 1])
    margin = margin_m + 0.0
    _check_extent(float(xs.max() - xs.min()), float(max(ys) - min(ys)))
    sc = Scenario(name=name, seed=seed, description=description, platform=platform, instrument=instrument,
                  acquisition=acquisition, raw=raw, source=path, base_dir=base_dir,
                  x_range_m=(float(xs.min() - margin), float(xs.max() + margin)),
                  y_range_m=(float(min(ys) - margin), float(max(ys) + margin)), requirement=requirement,
                  footprint_m=((float(xs.min()), float(xs.max())), (float(min(ys)), float(max(ys)))))
    run_table_checks(sc)  # the tables of later stages (restore registers [restoration])
    return sc


def _check_matrix(acq: Section, instrument, acquisition: Acquisition) -> None:
    """A matrix detector takes frames (``frame_period_ms``); frames need exactly one matrix detector."""
    matrices = [d for d in instrument.detectors if d.rows > 1]
    if acquisition.is_frames:
        if len(instrument.detectors) != 1 or not matrices:
            raise acq.error("frame_period_ms", "frames are taken by one matrix detector: give exactly one "
                            "[[instrument.detectors]] with rows > 1")
        if acquisition.frame_period_s < instrument.line_period_s:
            raise acq.error("frame_period_ms", f"a frame period of {acquisition.frame_period_s * 1e3:g} ms is shorter "
                            f"than the exposure (instrument.line_period_ms = {instrument.line_period_s * 1e3:g})")
    elif matrices:
        raise acq.error("frame_period_ms", f"detector {matrices[0].name!r} is a matrix (rows = {matrices[0].rows}): "
                        "set the frame period")


# --------------------------------------------------------------------------- resource budget
MAX_LINES = 10_000_000            #: acquisition.lines
MAX_ALONG_TRACK_M = 2.0e6         #: length of the imaged strip
MAX_SWATH_M = 1.0e6               #: width of the imaged swath
MAX_RAYS = 2.0e10                 #: rays traced by a render (about a day on 2 cores)
MAX_PRODUCT_BYTES = 32e9          #: raw images in product.nc (uint16)
MAX_DEM_SAMPLES = 16_000_000      #: samples of a generated DEM (memory: ~10 arrays of it)
MAX_PSD_WORK = 4e9                #: psd jitter: components × truth samples
MIN_TEXELS_PER_PIXEL = 1 / 16     #: texel no finer than 1/16 of the ground sample


def _check_extent(along_m: float, across_m: float) -> None:
    """Refuse a footprint no render could hold, naming the keys that make it."""
    if not along_m <= MAX_ALONG_TRACK_M:
        raise ScenarioError(f"acquisition.lines: the strip is {along_m / 1e3:.3g} km long (acquisition.lines × "
                            f"instrument.line_period_ms × platform.ground_speed_m_s), more than "
                            f"{MAX_ALONG_TRACK_M / 1e3:.0f} km")
    if not across_m <= MAX_SWATH_M:
        raise ScenarioError(f"instrument.pixels: the swath is {across_m / 1e3:.3g} km wide (pixels × "
                            f"pixel_pitch_um / focal_length_m × platform.altitude_m), more than "
                            f"{MAX_SWATH_M / 1e3:.0f} km")


def _check_resources(sc: Scenario) -> None:
    """Estimate what a render will allocate and trace before anything is built.

    Each limit names the key that drives it; the built-in scenarios (phr_full:
    4 × 7000 × 7000; a 50 000-line phr_cmg) are far inside them.
    """
    inst = sc.instrument
    lines = sc.acquisition.lines
    pixels = sum(d.pixels * d.rows * d.tdi_stages for d in inst.detectors)  # per product line (frame)
    rays = float(lines) * pixels * inst.time_subsamples * inst.spatial_subsamples ** 2
    if rays > MAX_RAYS:
        raise ScenarioError(f"acquisition.lines: {lines} lines × {pixels} pixels of all bands × "
                            f"instrument.time_subsamples {inst.time_subsamples} × spatial_subsamples² "
                            f"{inst.spatial_subsamples ** 2} = {rays:.3g} rays to trace (> {MAX_RAYS:.0e})")
    nbytes = 2.0 * lines * pixels
    if nbytes > MAX_PRODUCT_BYTES:
        raise ScenarioError(f"acquisition.lines: {lines} lines × {pixels} pixels of all bands make a "
                            f"{nbytes / 1e9:.3g} GB product (> {MAX_PRODUCT_BYTES / 1e9:.0f} GB)")
    scene = sc.raw.get("scene", {}) if isinstance(sc.raw.get("scene"), dict) else {}
    dem = scene.get("dem", {}) if isinstance(scene.get("dem"), dict) else {}
    res = dem.get("resolution_m", 10.0 if dem.get("kind", "fractal") == "fractal" else None)
    if isinstance(res, (int, float)) and not isinstance(res, bool) and res > 0:
        nx = (sc.x_range_m[1] - sc.x_range_m[0]) / res + 1
        ny = (sc.y_range_m[1] - sc.y_range_m[0]) / res + 1
        if nx * ny > MAX_DEM_SAMPLES:
            raise ScenarioError(f"scene.dem.resolution_m: {res:g} m over the {nx * res / 1e3:.3g} × "
                                f"{ny * res / 1e3:.3g} km scene gives {nx * ny:.3g} DEM samples "
                                f"(> {MAX_DEM_SAMPLES / 1e6:.0f} M); use a coarser resolution or a shorter "
                                f"acquisition (acquisition.lines)")
    tex = scene.get("texture", {}) if isinstance(scene.get("texture"), dict) else {}
    texel = tex.get("texel_m")
    gsd = inst.ifov_rad(sc.acquisition.reference_detector) * sc.platform.altitude_m
    if isinstance(texel, (int, float)) and not isinstance(texel, bool) and 0 < texel < gsd * MIN_TEXELS_PER_PIXEL:
        raise ScenarioError(f"scene.texture.texel_m: {texel:g} m is finer than 1/16 of the ground sample "
                            f"({gsd:.3g} m): the texture would be evaluated "
                            f"{(gsd / texel) ** 2:.3g} times per pixel; use >= {gsd / 16:.3g} m")
    att = sc.raw.get("attitude", {}) if isinstance(sc.raw.get("attitude"), dict) else {}
    jit = att.get("jitter", [])
    jit = [jit] if isinstance(jit, dict) else (jit if isinstance(jit, list) else [])
    samples = float(lines) * max(inst.time_subsamples, 2) + 1000
    for i, j in enumerate(jit):
        if isinstance(j, dict) and j.get("kind") == "psd":
            n = j.get("n_components", 400)
            if isinstance(n, (int, float)) and n * samples > MAX_PSD_WORK:
                raise ScenarioError(f"attitude.jitter[{i}].n_components: {n:g} components × {samples:.3g} truth "
                                    f"samples = {n * samples:.3g} sine evaluations (> {MAX_PSD_WORK:.0e}); "
                                    f"use fewer components")


def _validate_models(sc: Scenario) -> None:
    """Validate the tables built by other modules (attitude, terrain) without heavy work."""
    _check_resources(sc)
    sc.attitude_model()
    scene = sc.section("scene")
    for k in ("dem", "dem_knowledge", "texture", "sun"):
        scene.section(k)
    scene.finish()
    sc.dems()
    sc.texture()
    sc.sun()
