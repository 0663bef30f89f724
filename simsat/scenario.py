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

from .config import ScenarioError, Section
from .instrument import Instrument, instrument_from_config
from .platform import Platform, platform_from_config

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

    # -- derived geometry ----------------------------------------------------
    @property
    def line_period_s(self) -> float:
        return self.instrument.line_period_s

    @property
    def t0_s(self) -> float:
        return self.acquisition.t0_s

    @property
    def t_end_s(self) -> float:
        return self.t0_s + (self.acquisition.lines - 1) * self.line_period_s

    @property
    def line_times(self) -> np.ndarray:
        return self.t0_s + np.arange(self.acquisition.lines) * self.line_period_s

    def delay_s(self, ahead: str, behind: str) -> float:
        """Nominal delay τ [s] after which ``behind`` sees what ``ahead`` saw."""
        a = self.instrument.detector(ahead)
        b = self.instrument.detector(behind)
        h, v, f = self.platform.altitude_m, self.platform.ground_speed_m_s, self.instrument.focal_length_m
        return float(h * (a.along_m - b.along_m) / (f * v))

    def section(self, name: str) -> Section:
        """The raw ``[name]`` table as a :class:`Section` (for later stages)."""
        return Section(copy.deepcopy(self.raw.get(name, {})), name)

    # -- model builders (each builds on demand; deterministic per seed) --------
    def attitude_model(self):
        from .attitude import AttitudeModel
        nominal = (self.platform.off_nadir_roll_rad, self.platform.off_nadir_pitch_rad, 0.0)
        sec = self.section("attitude")
        margin = 0.05 + self.instrument.line_period_s * 4
        return AttitudeModel.from_config(sec, seed=self.seed, nominal=nominal,
                                         t_start=self.t0_s - margin, t_end=self.t_end_s + margin)

    def dems(self):
        """(true DEM, DEM known by the ground segment)."""
        from . import terrain
        sec = self.section("scene")
        dsec = sec.section("dem")
        dem = terrain.dem_from_config(dsec, base_dir=self.base_dir, seed=self.seed,
                                      x_range_m=self.x_range_m, y_range_m=self.y_range_m)
        _check_coverage(dem, self.x_range_m, self.y_range_m, dsec.key("path") if dsec.has("path") else dsec.path)
        ksec = sec.section("dem_knowledge")
        known = terrain.knowledge_dem_from_config(ksec, truth=dem, seed=self.seed)
        return dem, known

    def texture(self):
        from . import terrain
        sec = self.section("scene").section("texture")
        # synthesise only the bands the instrument has (texture synthesis is a large share of rendering)
        bands = {d.band for d in self.instrument.detectors}
        return terrain.texture_from_config(sec, base_dir=self.base_dir, seed=self.seed, sun=self.sun(),
                                           default_bands=bands)

    def sun(self):
        from . import terrain
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
        raw = _read_toml(path)
        base_dir = path.resolve().parent
    if overrides:
        _merge(raw, overrides)
    try:
        sc = _build(raw, path, base_dir)
        if check_models:
            _validate_models(sc)
    except ScenarioError as e:
        if path is not None and not str(e).startswith(str(path)):
            raise ScenarioError(f"{path}: {e}") from None
        raise
    return sc


def _merge(base: dict, over: dict) -> None:
    for k, v in over.items():
        if isinstance(v, dict) and isinstance(base.get(k), dict):
            _merge(base[k], v)
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
        requirement["max_rms_px"] = req.number("max_rms_px", None, gt=0)
        requirement["max_p997_px"] = req.number("max_p997_px", None, gt=0)
        req.finish()
    meta.finish()

    platform = platform_from_config(root.section("platform", required=True))
    instrument = instrument_from_config(root.section("instrument", required=True))

    acq = root.section("acquisition", required=True)
    lines = acq.integer("lines", gt=8)
    block = acq.integer("block_lines", 256, gt=0)
    ref = acq.string("reference_detector", instrument.detectors[0].name, choices=instrument.names)
    t0 = acq.number("start_time_s", 0.0)
    margin_m = acq.number("scene_margin_m", 300.0, ge=0)
    acq.finish()
    acquisition = Acquisition(lines=lines, block_lines=block, reference_detector=ref, t0_s=t0)

    # sections read by later stages: only their presence/type is checked here
    for k in ("scene", "attitude", "restoration", "report"):
        root.section(k, required=k in ("scene", "attitude"))
    root.finish()

    # centre the platform: the mean detector line of sight hits (0, 0) at mid-acquisition
    f = instrument.focal_length_m
    along = np.array([d.along_m for d in instrument.detectors])
    t_mid = t0 + 0.5 * (lines - 1) * instrument.line_period_s
    platform = platform.centred(t_mid_s=t_mid, along_angle_rad=float(np.arctan(along.mean() / f)))

    # ground footprint of the acquisition (nominal geometry) + margins for jitter / relief
    h = platform.altitude_m
    ang = np.arctan(along / f) - platform.off_nadir_pitch_rad
    t_first, t_last = t0, t0 + (lines - 1) * instrument.line_period_s
    xs = np.concatenate([platform.position(np.array([t_first, t_last]))[:, 0] + h * np.tan(a) for a in ang])
    ys = []
    for d in instrument.detectors:
        for u in (-0.5, d.pixels - 0.5):
            ys.append(platform.y_m + h * np.tan(platform.off_nadir_roll_rad + np.arctan(d.focal_plane_y(u) / f)))
    margin = margin_m + 0.0
    sc = Scenario(name=name, seed=seed, description=description, platform=platform, instrument=instrument,
                  acquisition=acquisition, raw=raw, source=path, base_dir=base_dir,
                  x_range_m=(float(xs.min() - margin), float(xs.max() + margin)),
                  y_range_m=(float(min(ys) - margin), float(max(ys) + margin)), requirement=requirement)
    return sc


def _validate_models(sc: Scenario) -> None:
    """Validate the tables built by other modules (attitude, terrain) without heavy work."""
    sc.attitude_model()
    scene = sc.section("scene")
    for k in ("dem", "dem_knowledge", "texture", "sun"):
        scene.section(k)
    scene.finish()
    sc.dems()
    sc.texture()
    sc.sun()
