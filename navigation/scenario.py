"""Navigation scenarios: a TOML kind of their own, validated key by key like simsat's.

Every error is a :class:`~simsat.config.ScenarioError` naming the TOML key
(``camera.hfov_deg: must be in (1, 150), got 200``) or the file. Built-in
scenarios live in ``navigation/scenarios``; ``kind = "navigation"`` at the top
of a file says it is one (a satellite scenario given to ``simsat navigate`` is
refused with that hint).
"""
from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from simsat.config import ScenarioError, Section

from .aided import InitialErrors
from .camera import PinholeCamera
from .frames import SensorSettings
from .imu import ImuModel
from .measurement import AidingSettings
from .world import WorldSpec

__all__ = ["NavigationScenario", "load_navigation_scenario", "builtin_navigation_scenarios", "SCENARIO_DIR"]

SCENARIO_DIR = Path(__file__).parent / "scenarios"


@dataclass
class Degraded:
    from_m: float
    to_m: float
    kind: str              # "desert" | "fog"
    visibility_m: float


@dataclass
class NavigationScenario:
    name: str
    seed: int
    seeds: int
    length_m: float
    speed_mps: float
    agl_m: tuple
    turns: int
    max_bank_deg: float
    relief_m: float
    dem_resolution_m: float
    roughness: float
    world: WorldSpec
    camera: PinholeCamera
    frame_rate_hz: float
    sensor: SensorSettings
    imu: ImuModel
    interval_s: float
    frames: int
    frame_step: int
    first_s: float
    aiding: AidingSettings
    map_sigma_m: float
    map_bias_m: tuple
    map_keep_fraction: float
    initial: InitialErrors
    degraded: list = field(default_factory=list)
    requirement: dict = field(default_factory=dict)
    source: dict = field(default_factory=dict)

    def fog_at(self, distance_m: float) -> float | None:
        """Visibility (m) of a fog stretch at this along-route distance, else None."""
        for d in self.degraded:
            if d.kind == "fog" and d.from_m <= distance_m <= d.to_m:
                return d.visibility_m
        return None


def builtin_navigation_scenarios() -> dict[str, Path]:
    return {p.stem: p for p in sorted(SCENARIO_DIR.glob("*.toml"))}


def _read(source) -> tuple[dict, str]:
    if isinstance(source, dict):
        return source, "scenario"
    p = Path(source)
    builtin = builtin_navigation_scenarios()
    if p.suffix != ".toml" and len(p.parts) == 1 and str(source) in builtin:
        p = builtin[str(source)]
    elif not p.exists():
        raise ScenarioError(f"{p}: navigation scenario not found (built-in: {', '.join(builtin)})")
    if p.is_dir():
        raise ScenarioError(f"{p}: is a directory, expected a .toml navigation scenario")
    try:
        with open(p, "rb") as fh:
            return tomllib.load(fh), str(p)
    except tomllib.TOMLDecodeError as e:
        raise ScenarioError(f"{p}: TOML syntax error: {e}") from None
    except UnicodeDecodeError as e:
        raise ScenarioError(f"{p}: not a UTF-8 text file ({e.reason})") from None


def load_navigation_scenario(source, *, overrides: dict | None = None) -> NavigationScenario:
    """Read and validate a navigation scenario (a built-in name, a path or a dict)."""
    data, where = _read(source)
    for key, value in (overrides or {}).items():
        d = data
        parts = key.split(".")
        for part in parts[:-1]:
            d = d.setdefault(part, {})
            if not isinstance(d, dict):
                raise ScenarioError(f"--set {key}: {part} is not a table")
        d[parts[-1]] = value
    try:
        return _parse(data)
    except ScenarioError as e:
        raise ScenarioError(f"{where}: {e}") from None
    except ValueError as e:   # a dataclass's own check: name the table it came from
        raise ScenarioError(f"{where}: {e}") from None


def _parse(data: dict) -> NavigationScenario:
    """Long: one reader per table, in file order, so the key reference reads like the file."""
    root = Section(data)
    kind = root.string("kind", "navigation", choices=["navigation"])
    del kind
    nav = root.section("navigation", required=True)
    name = nav.string("name")
    seed = nav.integer("seed", 0, ge=0)
    seeds = nav.integer("seeds", 20, ge=1, le=1000)
    nav.finish()
    r = root.section("route")
    length_m = 1000.0 * r.number("length_km", 100.0, gt=0.5, le=2000.0)
    speed = r.number("speed_mps", 250.0, gt=20.0, le=1000.0)
    agl = (r.number("agl_min_m", 200.0, gt=20.0), r.number("agl_max_m", 500.0, gt=20.0))
    if agl[1] < agl[0]:
        raise r.error("agl_max_m", f"must be >= route.agl_min_m ({agl[0]:g}), got {agl[1]:g}")
    turns = r.integer("turns", 6, ge=0, le=100)
    bank = r.number("max_bank_deg", 30.0, gt=0.0, lt=75.0)
    r.finish()
    t = root.section("terrain")
    relief = t.number("relief_m", 250.0, ge=0.0, le=5000.0)
    dem_res = t.number("resolution_m", 40.0, gt=1.0, le=500.0)
    rough = t.number("roughness", 0.7, gt=0.0, le=1.0)
    t.finish()
    w = root.section("world")
    fmin = w.number("field_size_min_m", 150.0, gt=20.0)
    fmax = w.number("field_size_max_m", 450.0, gt=20.0)
    if fmax < fmin:
        raise w.error("field_size_max_m", f"must be >= world.field_size_min_m ({fmin:g}), got {fmax:g}")
    degraded = []
    for d in root.sections("degraded"):
        a, b = 1000.0 * d.number("from_km", ge=0.0), 1000.0 * d.number("to_km", gt=0.0)
        if b <= a:
            raise d.error("to_km", f"must be > from_km ({a / 1000:g}), got {b / 1000:g}")
        if b > length_m + 1e-6:
            raise d.error("to_km", f"beyond the route's end (route.length_km = {length_m / 1000:g}), got {b / 1000:g}")
        kind = d.string("kind", choices=["desert", "fog"])
        vis = d.number("visibility_m", 400.0, gt=10.0)
        d.finish()
        degraded.append(Degraded(a, b, kind, vis))
    world = WorldSpec(field_size_m=(fmin, fmax), edge_contrast=w.number("edge_contrast", 0.05, gt=0.0, lt=0.3),
                      road_spacing_m=w.number("road_spacing_m", 4000.0, gt=200.0),
                      road_width_m=w.number("road_width_m", 9.0, gt=1.0, le=60.0),
                      lakes_per_100km=w.number("lakes_per_100km", 6.0, ge=0.0, le=200.0),
                      villages_per_100km=w.number("villages_per_100km", 8.0, ge=0.0, le=200.0),
                      background_weight=w.number("background_weight", 0.35, ge=0.0, le=1.0),
                      deserts=tuple((d.from_m, d.to_m) for d in degraded if d.kind == "desert"))
    w.finish()
    c = root.section("camera")
    camera = PinholeCamera(width=c.integer("width", 640, ge=64, le=4096), height=c.integer("height", 480, ge=48, le=4096),
                           hfov_deg=c.number("hfov_deg", 50.0, gt=1.0, lt=150.0),
                           depression_deg=c.number("depression_deg", 12.0, ge=-30.0, le=80.0))
    fps = c.number("frame_rate_hz", 25.0, gt=0.5, le=1000.0)
    sensor = SensorSettings(band=c.string("band", "visible", choices=["visible", "ir"]),
                            visibility_m=c.number("visibility_m", 8000.0, gt=10.0),
                            max_range_m=c.number("max_range_m", 7000.0, gt=100.0, le=50000.0),
                            supersample=c.integer("supersample", 2, ge=1, le=4),
                            snr=c.number("snr", 80.0, gt=0.0), texel_m=c.number("texel_m", 2.0, gt=0.1, le=20.0),
                            sun_elevation_deg=c.number("sun_elevation_deg", 40.0, gt=0.0, le=90.0),
                            sun_azimuth_deg=c.number("sun_azimuth_deg", 135.0))
    c.finish()
    i = root.section("imu")
    imu = ImuModel(gyro_bias_deg_h=i.number("gyro_bias_deg_h", 5.0, ge=0.0),
                   accel_bias_mg=i.number("accel_bias_mg", 3.0, ge=0.0),
                   gyro_arw_deg_sqrt_h=i.number("gyro_arw_deg_sqrt_h", 0.1, ge=0.0),
                   accel_vrw_m_s_sqrt_h=i.number("accel_vrw_m_s_sqrt_h", 0.05, ge=0.0),
                   gyro_scale_ppm=i.number("gyro_scale_ppm", 300.0, ge=0.0),
                   accel_scale_ppm=i.number("accel_scale_ppm", 300.0, ge=0.0),
                   rate_hz=i.number("rate_hz", 200.0, ge=10.0, le=2000.0))
    i.finish()
    if abs(imu.rate_hz / fps - round(imu.rate_hz / fps)) > 1e-9:
        raise c.error("frame_rate_hz", f"must divide imu.rate_hz ({imu.rate_hz:g}) so that frames fall on IMU "
                                       f"samples, got {fps:g}")
    a = root.section("aiding")
    interval = a.number("interval_s", 10.0, gt=0.5)
    frames = a.integer("frames", 8, ge=3, le=200)
    frame_step = a.integer("frame_step", 3, ge=1, le=100)
    first = a.number("first_s", interval, ge=0.0)
    aid = AidingSettings(min_views=a.integer("min_views", 5, ge=2), line_sigma_px=a.number("line_sigma_px", 0.4, gt=0.0),
                         map_sigma_m=0.0, min_lines=a.integer("min_lines", 5, ge=3),
                         common_sigma_m=a.number("common_sigma_m", 1.0, ge=0.0),
                         max_range_m=a.number("max_range_m", 5000.0, gt=100.0))
    if aid.min_views > frames:
        raise a.error("min_views", f"must be <= aiding.frames ({frames}), got {aid.min_views}")
    a.finish()
    m = root.section("reference_map")
    map_sigma = m.number("segment_sigma_m", 2.0, ge=0.0, le=100.0)
    bias = tuple(m.numbers("bias_m", [0.0, 0.0], length=2))
    keep = m.number("keep_fraction", 0.85, gt=0.0, le=1.0)
    m.finish()
    aid = AidingSettings(**{**aid.__dict__, "map_sigma_m": map_sigma})
    n = root.section("initial")
    init = InitialErrors(position_m=n.number("position_sigma_m", 5.0, ge=0.0),
                         velocity_mps=n.number("velocity_sigma_mps", 0.1, ge=0.0),
                         attitude_mrad=n.number("attitude_sigma_mrad", 0.3, ge=0.0),
                         heading_mrad=n.number("heading_sigma_mrad", 1.0, ge=0.0))
    n.finish()
    q = root.section("requirement")
    req = {"final_horizontal_m": q.number("final_horizontal_m", 30.0, gt=0.0),
           "improvement": q.number("improvement", 10.0, gt=0.0),
           "nees_inside": q.number("nees_inside", 0.9, gt=0.0, le=1.0)}
    q.finish()
    root.finish()
    return NavigationScenario(name=name, seed=seed, seeds=seeds, length_m=length_m, speed_mps=speed, agl_m=agl,
                              turns=turns, max_bank_deg=bank, relief_m=relief, dem_resolution_m=dem_res,
                              roughness=rough, world=world, camera=camera, frame_rate_hz=fps, sensor=sensor, imu=imu,
                              interval_s=interval, frames=frames, frame_step=frame_step, first_s=first, aiding=aid, map_sigma_m=map_sigma,
                              map_bias_m=bias, map_keep_fraction=keep, initial=init, degraded=degraded,
                              requirement=req, source=data)
