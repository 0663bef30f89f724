"""Build terrain objects from scenario sections.

Sections and keys (all optional unless marked)::

    [scene.dem]
    kind = "fractal"            # "fractal" | "geotiff" | "matplotlib_sample"
    resolution_m = 10.0         # fractal: grid spacing; others: resample to it if given
    relief_m = 150.0            # fractal: peak-to-peak height
    roughness = 0.7             # fractal: Hurst-like exponent in (0, 1] (small = rugged)
    path = "dem.tif"            # geotiff (required): relative to the scenario's folder
    nodata = -9999.0            # geotiff: no-data value (default from the file)

    [scene.dem_knowledge]       # the DEM the ground segment uses (default: the truth)
    noise_m = 0.0               # standard deviation of the height error
    bias_m = 0.0
    correlation_m = 0.0         # correlation length of the error

    [scene.texture]
    kind = "procedural"         # "procedural" | "orthoimage"
    texel_m = 1.0
    bands = ["blue", "green", "red", "nir", "pan"]   # default: all (orthoimage: its channels)
    water_fraction = 0.05       # procedural
    cloud_fraction = 0.0        # procedural
    urban_fraction = 0.08       # procedural
    forest_fraction = 0.25      # procedural
    field_size_m = 200.0        # procedural
    cloud_height_m = 1500.0     # procedural
    path = "ortho.tif"          # orthoimage (required), texel_m = its pixel size
    channels = {red = 0, green = 1, blue = 2, nir = 3}   # orthoimage (required)
    x0_m = -5000.0              # orthoimage: lower-left corner (default: centred)
    y0_m = -5000.0
    scale = 0.0001              # orthoimage: DN → reflectance

    [scene.sun]
    elevation_deg = 45.0
    azimuth_deg = 135.0         # from +x (along-track) toward +y (across-track)
    ambient = 0.2
    cast_shadows = true
"""
from __future__ import annotations

import os
import re
from dataclasses import dataclass
from typing import Callable

from ..config import ScenarioError, Section
from .dem import Dem, fractal_dem, load_geotiff_dem, matplotlib_sample_dem, resample
from .illumination import Sun
from .texture import BAND_NAMES, OrthoTexture, ProceduralTexture

__all__ = ["dem_from_config", "knowledge_dem_from_config", "texture_from_config", "sun_from_config",
           "TerrainSource", "DEM_SOURCES", "TEXTURE_SOURCES"]

_PARAM = re.compile(r"^([A-Za-z_][A-Za-z0-9_.\[\]]*): (.*)$")


def _reraise(section: Section, exc: ValueError, rename: dict | None = None) -> ScenarioError:
    """Turn a library ``ValueError('param: msg')`` into a ScenarioError naming the TOML key."""
    if isinstance(exc, ScenarioError):
        return exc
    msg = str(exc)
    m = _PARAM.match(msg)
    if m:
        name = m.group(1)
        for old, new in (rename or {}).items():
            if name == old or name.startswith(old + "."):
                name = new + name[len(old):]
                break
        return section.error(name, m.group(2))
    return ScenarioError(f"{section.path}: {msg}")


def _resolve(section: Section, name: str, base_dir) -> str:
    p = section.string(name)
    full = p if os.path.isabs(p) else os.path.join(os.fspath(base_dir), p)
    full = os.path.normpath(full)
    if not os.path.isfile(full):
        raise section.error(name, f"file not found: {full}")
    return full


def dem_from_config(section: Section, *, base_dir, seed: int, x_range_m, y_range_m) -> Dem:
    """The true DEM from ``[scene.dem]``, covering ``x_range_m`` × ``y_range_m`` (m).

    Real DEMs are re-centred on (0, 0), optionally resampled to ``resolution_m``,
    and cropped to the requested ranges, which they must cover.

    Parameters
    ----------
    section : Section
        The ``scene.dem`` table (may be empty: a default fractal DEM).
    base_dir : path-like
        Folder of the scenario file; relative paths start there.
    seed : int
        Scenario seed.
    x_range_m, y_range_m : (float, float)
        Ground extent the scene needs (m).

    Raises
    ------
    ScenarioError
        Naming the offending key.
    """
    source = DEM_SOURCES[section.string("kind", "fractal", choices=tuple(DEM_SOURCES))]
    return source.from_config(section, base_dir=base_dir, seed=seed, x_range_m=x_range_m, y_range_m=y_range_m)


def _fractal_dem(section: Section, *, base_dir, seed: int, x_range_m, y_range_m) -> Dem:
    """``kind = "fractal"``: fractional-Brownian relief over exactly the scene's extent."""
    res = section.number("resolution_m", 10.0, ge=0.1, le=10000.0)
    relief = section.number("relief_m", 150.0, ge=0, le=20000.0)  # Earth: < 9 km
    rough = section.number("roughness", 0.7, gt=0, le=1)
    section.finish()
    try:
        return fractal_dem(x_range_m=x_range_m, y_range_m=y_range_m, resolution_m=res, relief_m=relief,
                           roughness=rough, seed=seed)
    except ValueError as exc:
        raise _reraise(section, exc) from None


def _geotiff_dem(section: Section, *, base_dir, seed: int, x_range_m, y_range_m) -> Dem:
    """``kind = "geotiff"``: a DEM file, centred on the scene, optionally resampled."""
    res = section.number("resolution_m", None, gt=0)
    path = _resolve(section, "path", base_dir)
    nodata = section.number("nodata", None)
    section.finish()
    try:
        dem = load_geotiff_dem(path, nodata=nodata)
    except ValueError as exc:
        raise _reraise(section, exc) from None
    return _fit_to_scene(section, dem, res, "path", x_range_m, y_range_m)


def _sample_dem(section: Section, *, base_dir, seed: int, x_range_m, y_range_m) -> Dem:
    """``kind = "matplotlib_sample"``: matplotlib's sample DEM (Jacksboro), centred on the scene."""
    res = section.number("resolution_m", None, gt=0)
    section.finish()
    try:
        dem = matplotlib_sample_dem()
    except ValueError as exc:
        raise section.error("kind", str(exc)) from None
    return _fit_to_scene(section, dem, res, "kind", x_range_m, y_range_m)


def _fit_to_scene(section: Section, dem: Dem, res, where: str, x_range_m, y_range_m) -> Dem:
    """Resample a read DEM (when ``resolution_m`` is given), check it covers the scene, crop it."""
    if res is not None:
        try:
            dem = resample(dem, res)
        except ValueError as exc:
            raise _reraise(section, exc) from None
    try:
        covered = dem.covers(x_range_m, y_range_m)
    except ValueError as exc:
        raise ScenarioError(f"{section.path}: {exc}") from None
    if not covered:
        (a, b), (c, d) = dem.x_range, dem.y_range
        raise section.error(where, f"DEM covers x [{a:.0f}, {b:.0f}] m, y [{c:.0f}, {d:.0f}] m once centred; "
                                   f"the scene needs x [{x_range_m[0]:.0f}, {x_range_m[1]:.0f}] m, "
                                   f"y [{y_range_m[0]:.0f}, {y_range_m[1]:.0f}] m")
    return dem.crop(x_range_m, y_range_m)


@dataclass(frozen=True)
class TerrainSource:
    """One ``kind`` of ``[scene.dem]`` or ``[scene.texture]``: what it is and its builder from the table."""

    name: str
    description: str
    from_config: Callable


#: ``[scene.dem] kind`` → source
DEM_SOURCES: dict[str, TerrainSource] = {s.name: s for s in (
    TerrainSource("fractal", "fractional-Brownian relief (seeded)", _fractal_dem),
    TerrainSource("geotiff", "a GeoTIFF DEM file", _geotiff_dem),
    TerrainSource("matplotlib_sample", "matplotlib's sample DEM (Jacksboro, 10 m)", _sample_dem),
)}


def knowledge_dem_from_config(section: Section, *, truth: Dem, seed: int) -> Dem:
    """The DEM known to the ground segment, from ``[scene.dem_knowledge]``.

    Default (empty section): the true DEM itself.

    Parameters
    ----------
    section : Section
        The ``scene.dem_knowledge`` table.
    truth : Dem
        The true DEM.
    seed : int
        Scenario seed (the error uses its own random stream).
    """
    noise = section.number("noise_m", 0.0, ge=0, le=1000.0)
    bias = section.number("bias_m", 0.0, ge=-1e4, le=1e4)
    corr = section.number("correlation_m", 0.0, ge=0, le=1e6)
    section.finish()
    try:
        return truth.with_error(noise_m=noise, bias_m=bias, correlation_m=corr, seed=seed)
    except ValueError as exc:
        raise _reraise(section, exc) from None


def sun_from_config(section: Section) -> Sun:
    """Sun geometry from ``[scene.sun]``."""
    sun = Sun(elevation_deg=section.number("elevation_deg", 45.0, ge=1.0, le=90),  # below 1°: shadows unbounded
              azimuth_deg=section.number("azimuth_deg", 135.0, ge=-360, le=360),
              ambient=section.number("ambient", 0.2, ge=0, le=1),
              cast_shadows=section.boolean("cast_shadows", True),
              irradiance_scale=section.number("irradiance_scale", 1.0, gt=0, le=10.0))
    section.finish()
    return sun


def texture_from_config(section: Section, *, base_dir, seed: int, sun: Sun | None = None,
                        default_bands=None, footprint_m=None):
    """Ground reflectance texture from ``[scene.texture]``.

    Parameters
    ----------
    section : Section
        The ``scene.texture`` table.
    base_dir : path-like
        Folder of the scenario file.
    seed : int
        Scenario seed.
    sun : Sun, optional
        Sun for the procedural texture's building shadows (default ``Sun()``).
    default_bands : sequence of str, optional
        Bands to synthesise when the table has no ``bands`` key (e.g. the
        instrument's bands); default all of ``BAND_NAMES``.
    footprint_m : ((x0, x1), (y0, y1)), optional
        The imaged ground [m]: the procedural texture's cover fractions are
        realised there.

    Returns
    -------
    ProceduralTexture or OrthoTexture
    """
    kind = section.string("kind", "procedural", choices=tuple(TEXTURE_SOURCES))
    texel = section.number("texel_m", 1.0, ge=0.01, le=1000.0)
    bands = section.strings("bands", None, choices=BAND_NAMES)
    if bands is not None and len(set(bands)) != len(bands):
        raise section.error("bands", f"repeated band in {list(bands)}")
    if bands is None and default_bands is not None:
        bands = tuple(b for b in BAND_NAMES if b in set(default_bands))
    return TEXTURE_SOURCES[kind].from_config(section, base_dir=base_dir, seed=seed, sun=sun, bands=bands, texel=texel,
                                             footprint_m=footprint_m)


def _procedural_texture(section: Section, *, base_dir, seed: int, sun, bands, texel: float, footprint_m=None):
    """``kind = "procedural"``: land classes, fields, towns, water and clouds synthesised from the seed."""
    sun = sun or Sun()
    kw = dict(
        water_fraction=section.number("water_fraction", 0.05, ge=0, le=1),
        cloud_fraction=section.number("cloud_fraction", 0.0, ge=0, le=1),
        urban_fraction=section.number("urban_fraction", 0.08, ge=0, le=1),
        forest_fraction=section.number("forest_fraction", 0.25, ge=0, le=1),
        field_size_m=section.number("field_size_m", 200.0, gt=10, le=1e5),
        cloud_height_m=section.number("cloud_height_m", 1500.0, gt=0, le=20000.0),
    )
    section.finish()
    try:
        return ProceduralTexture(seed=seed, bands=BAND_NAMES if bands is None else bands, texel_m=texel,
                                 sun_elevation_deg=sun.elevation_deg, sun_azimuth_deg=sun.azimuth_deg,
                                 calibration_extent_m=footprint_m, **kw)
    except ValueError as exc:
        raise _reraise(section, exc) from None


def _ortho_texture(section: Section, *, base_dir, seed: int, sun, bands, texel: float, footprint_m=None):
    """``kind = "orthoimage"``: an image file whose channels are mapped to bands."""
    path = _resolve(section, "path", base_dir)
    ch = section.section("channels", required=True)
    channels = {}
    for name in list(ch.data):
        if name not in BAND_NAMES:
            raise ch.error(name, f"unknown band; choose from {', '.join(BAND_NAMES)}")
        channels[name] = ch.integer(name, ge=0)
    ch.finish()
    if not channels:
        raise section.error("channels", "must map at least one band to a channel index")
    x0 = section.number("x0_m", None)
    y0 = section.number("y0_m", None)
    scale = section.number("scale", None, gt=0)
    section.finish()
    try:
        return OrthoTexture(path, texel_m=texel, bands=channels, x0_m=x0, y0_m=y0, scale=scale,
                            output_bands=None if bands is None else tuple(bands))
    except ValueError as exc:
        raise _reraise(section, exc, {"bands": "channels", "output_bands": "bands"}) from None


#: ``[scene.texture] kind`` → source
TEXTURE_SOURCES: dict[str, TerrainSource] = {s.name: s for s in (
    TerrainSource("procedural", "synthesised land cover (seeded)", _procedural_texture),
    TerrainSource("orthoimage", "an orthoimage file", _ortho_texture),
)}
