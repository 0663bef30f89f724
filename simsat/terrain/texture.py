"""Multi-band ground reflectance textures: procedural (tileable) and orthoimage.

Both classes share one interface::

    tex.bands                                  # band names, e.g. ("blue", "green", "red", "nir", "pan")
    tex.grid(x0_m, y0_m, texel_m, nx, ny)      # (nbands, ny, nx) float32 reflectance in [0, 1]
    tex.land_cover(x, y)                       # uint8 class codes (LandCover)

Texel (j, i) of ``grid`` is centred at ``(x0_m + (i + ½) texel_m, y0_m + (j + ½) texel_m)``
(x along-track, y across-track, m), so a grid covers ``[x0, x0 + nx texel) × [y0, y0 + ny texel)``.
Values are point samples at the texel centres (no area averaging: features finer than a
texel alias).

:class:`ProceduralTexture` also offers ``land_cover_grid`` and ``grid_and_land_cover``
(same grid convention). Its values depend only on the texel centre, quantised to
1/1024 m, so a strip or tile computed alone equals the same texels of a larger block
bit for bit (tiles must be offset by whole texels). Internally ``grid`` works in
256 × 256 tiles spread over ``workers`` threads; coarse land-use fields live on a
16-m node lattice (cached by blocks) and are bilinearly upsampled.
"""
from __future__ import annotations

import math
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from enum import IntEnum
from typing import Mapping, Sequence

import numpy as np

from . import _noise as nz
from ._noise import Coords, Lookup, quantise, value_noise, lattice_interp, fbm_lattice, fbm_points

__all__ = ["BAND_NAMES", "PAN_WEIGHTS", "LandCover", "ProceduralTexture", "OrthoTexture"]

BAND_NAMES = ("blue", "green", "red", "nir", "pan")
#: Pan = weighted mean of blue, green, red, nir (PHR pan ~480–830 nm).
PAN_WEIGHTS = (0.15, 0.30, 0.30, 0.25)

_F32 = np.float32


class LandCover(IntEnum):
    """Land-cover class codes returned by ``land_cover`` (uint8)."""

    WATER = 0
    CROPLAND = 1
    FOREST = 2
    GRASSLAND = 3
    ROAD = 4
    BUILDING = 5
    URBAN_OPEN = 6   # yards, pavements, gardens, parks inside built-up areas
    CLOUD = 7
    UNKNOWN = 255


# -----------------------------------------------------------------------------
# Materials: surface reflectance (blue, green, red, nir)
# -----------------------------------------------------------------------------
_MATERIALS = [
    ("deep_water", (0.045, 0.050, 0.030, 0.012)),
    ("shallow_water", (0.060, 0.080, 0.060, 0.020)),
    ("green_crop", (0.035, 0.075, 0.035, 0.480)),
    ("mature_crop", (0.070, 0.110, 0.140, 0.320)),
    ("light_soil", (0.110, 0.150, 0.200, 0.260)),
    ("dark_soil", (0.060, 0.080, 0.100, 0.150)),
    ("pasture", (0.045, 0.085, 0.055, 0.380)),
    ("dry_grass", (0.080, 0.110, 0.130, 0.270)),
    ("broadleaf_crown", (0.035, 0.070, 0.035, 0.420)),
    ("conifer_crown", (0.025, 0.045, 0.025, 0.260)),
    ("canopy_gap", (0.015, 0.025, 0.015, 0.100)),
    ("shrub", (0.030, 0.055, 0.035, 0.250)),
    ("concrete", (0.220, 0.240, 0.260, 0.280)),
    ("asphalt", (0.090, 0.100, 0.110, 0.130)),
    ("gravel", (0.170, 0.190, 0.220, 0.250)),
    ("roof_grey", (0.260, 0.270, 0.280, 0.300)),
    ("roof_tile", (0.070, 0.090, 0.200, 0.300)),
    ("roof_dark", (0.070, 0.070, 0.080, 0.090)),
    ("roof_white", (0.450, 0.470, 0.480, 0.470)),
    ("pavement", (0.150, 0.160, 0.170, 0.190)),
    ("lawn", (0.040, 0.080, 0.050, 0.400)),
    ("hedge", (0.030, 0.060, 0.035, 0.350)),
]
_M = {name: k for k, (name, _) in enumerate(_MATERIALS)}
_REFL = np.array([r for _, r in _MATERIALS], dtype=_F32).T.copy()   # (4, n_materials)
_CLOUD_REFL = np.array([0.78, 0.79, 0.79, 0.76], dtype=_F32)
#: Fraction of irradiance left in a shadow (diffuse sky light, bluish), per band.
_SHADOW_K = np.array([0.40, 0.32, 0.27, 0.22], dtype=_F32)

# Field parcel types: (veg material, soil material, base cover, row amplitude, furrow amplitude, class)
_CROPS = [
    ("green_crop", "light_soil", 0.75, 0.35, 0.00, LandCover.CROPLAND),
    ("mature_crop", "light_soil", 0.85, 0.20, 0.00, LandCover.CROPLAND),
    ("light_soil", "light_soil", 0.00, 0.00, 0.12, LandCover.CROPLAND),
    ("dark_soil", "dark_soil", 0.00, 0.00, 0.20, LandCover.CROPLAND),
    ("pasture", "dry_grass", 0.70, 0.00, 0.00, LandCover.CROPLAND),
    ("pasture", "shrub", 0.55, 0.00, 0.00, LandCover.GRASSLAND),      # natural meadow
    ("broadleaf_crown", "dry_grass", 0.40, 1.30, 0.00, LandCover.CROPLAND),  # orchard / vineyard
    ("green_crop", "dark_soil", 0.55, 0.50, 0.00, LandCover.CROPLAND),  # young crop in rows
]
_CROP_P = np.array([0.22, 0.15, 0.13, 0.10, 0.15, 0.10, 0.07, 0.08])
_CROP_BY_BYTE = np.searchsorted(np.cumsum(_CROP_P) / _CROP_P.sum() * 256, np.arange(256) + 0.5).astype(np.intp)
_CROP_M1 = np.array([_M[c[0]] for c in _CROPS], dtype=np.uint8)
_CROP_M2 = np.array([_M[c[1]] for c in _CROPS], dtype=np.uint8)
_CROP_A0 = np.array([c[2] for c in _CROPS], dtype=_F32)
_CROP_AMP = np.array([c[3] for c in _CROPS], dtype=_F32)
_CROP_FAMP = np.array([c[4] for c in _CROPS], dtype=_F32)
_CROP_CLS = np.array([c[5] for c in _CROPS], dtype=np.uint8)
_NSUB_BY_BYTE = np.array([1] * 180 + [2] * 30 + [3] * 24 + [4] * 14 + [6] * 8, dtype=_F32)

# Forest stands: (crown, gap, base cover, fine-crown weight)
_STANDS = [("broadleaf_crown", "canopy_gap", 0.65, 0.45), ("conifer_crown", "canopy_gap", 0.55, 0.8),
           ("shrub", "light_soil", 0.45, 0.3)]
_STAND_BY_BYTE = np.array([0] * 140 + [1] * 80 + [2] * 36, dtype=np.intp)
_STAND_M1 = np.array([_M[s[0]] for s in _STANDS], dtype=np.uint8)
_STAND_M2 = np.array([_M[s[1]] for s in _STANDS], dtype=np.uint8)
_STAND_A0 = np.array([s[2] for s in _STANDS], dtype=_F32)
_STAND_W2 = np.array([s[3] for s in _STANDS], dtype=_F32)

_ROOFS_SMALL = np.array([_M["roof_tile"]] * 5 + [_M["roof_grey"]] * 4 + [_M["roof_dark"]] * 3
                        + [_M["roof_white"]] * 1 + [_M["roof_tile"]] * 3, dtype=np.uint8)
_ROOFS_LARGE = np.array([_M["roof_grey"]] * 7 + [_M["roof_white"]] * 5 + [_M["roof_dark"]] * 4, dtype=np.uint8)

# Macro (land-use) fields: fBm octaves (m) on a coarse 16-m node lattice
_NODE_M = 16.0
_OCT_WATER = ((4096, 2048, 1024, 512, 256), (1, .5, .25, .125, .0625))
_OCT_URBAN = ((2400, 1200, 600, 300), (1, .5, .25, .125))
_OCT_FOREST = ((2048, 1024, 512, 256, 128), (1, .55, .3, .16, .08))
_OCT_DOMAIN = ((6000, 3000), (1, .5))
_OCT_CLOUD = ((4096, 2048, 1024, 512, 256, 128), (1, .5, .25, .125, .0625, .03))
_OCT_WROAD = ((1600, 800), (1, .4))

_U8 = np.uint8
_U32 = np.uint32


def _check_fraction(name, v):
    if not (isinstance(v, (int, float)) and math.isfinite(v) and 0 <= v <= 1):
        raise ValueError(f"{name}: must be in [0, 1], got {v!r}")
    return float(v)


def _check_bands(bands) -> tuple:
    if isinstance(bands, str):
        bands = (bands,)
    bands = tuple(bands)
    if not bands:
        raise ValueError("bands: must name at least one band")
    for b in bands:
        if b not in BAND_NAMES:
            raise ValueError(f"bands: unknown band {b!r}; choose from {', '.join(BAND_NAMES)}")
    if len(set(bands)) != len(bands):
        raise ValueError(f"bands: repeated band in {bands}")
    return bands


def _check_grid_args(x0_m, y0_m, texel_m, nx, ny):
    for name, v in (("x0_m", x0_m), ("y0_m", y0_m)):
        if not math.isfinite(v):
            raise ValueError(f"{name}: must be finite, got {v}")
    if not (math.isfinite(texel_m) and texel_m > 0):
        raise ValueError(f"texel_m: must be > 0, got {texel_m}")
    for name, v in (("nx", nx), ("ny", ny)):
        if int(v) != v or v < 1:
            raise ValueError(f"{name}: must be a positive integer, got {v}")


def _put(dst, mask, value):
    """``dst[mask] = value`` (value: scalar or array of dst's shape)."""
    np.copyto(dst, value, where=mask, casting="unsafe")


def _smooth(t):
    return t * t * (_F32(3.0) - _F32(2.0) * t)


def _clip01(a):
    return np.clip(a, _F32(0.0), _F32(1.0), out=a)


@dataclass
class _Fields:
    """Noise fields (~[-1, 1]) and frames of one evaluation: the layout's (u, v) and the fields' (uf, vf)."""

    n2: np.ndarray
    n5: np.ndarray
    n12: np.ndarray
    n40: np.ndarray
    nw: np.ndarray
    nf: np.ndarray
    u: np.ndarray
    v: np.ndarray
    uf: np.ndarray
    vf: np.ndarray
    domb: np.ndarray
    n: int


@dataclass
class _Canvas:
    """What the layers paint per texel: two materials, their mixing, a gain, the land-cover class."""

    m1: np.ndarray
    m2: np.ndarray
    alpha: np.ndarray
    gain: np.ndarray
    cls: np.ndarray


def _check_extent(extent):
    """``((x0, x1), (y0, y1))`` [m] with x0 < x1, y0 < y1, or None."""
    if extent is None:
        return None
    try:
        (x0, x1), (y0, y1) = ((float(a), float(b)) for a, b in extent)
    except (TypeError, ValueError):
        raise ValueError(f"calibration_extent_m: expected ((x0, x1), (y0, y1)) [m], got {extent!r}") from None
    if not (np.isfinite([x0, x1, y0, y1]).all() and x0 < x1 and y0 < y1):
        raise ValueError(f"calibration_extent_m: expected finite ranges with x0 < x1, y0 < y1, got {extent!r}")
    return (x0, x1), (y0, y1)


class ProceduralTexture:
    """Deterministic, tileable multi-band reflectance of a synthetic landscape.

    Reflectance is a pure function of absolute ground coordinates (hashed integer
    lattices, value noise, jittered-grid parcels and blocks), so any window can be
    generated on its own and tiles match bit for bit. The landscape has:
    agricultural parcels (crops with row texture, bare soil with furrows, pasture,
    orchards, hedge margins and gravel tracks), roads (main straight network of
    bright concrete/asphalt, winding secondary roads), built-up areas (street grid,
    houses with ridged roofs, large flat-roofed buildings, gardens, parks, and the
    buildings' shadows on the anti-sun side), forest stands (tree-crown texture
    with sun-side shading), texture-poor water (lakes / sea, dark and nearly
    uniform) and optional clouds (bright, smooth, with their shadows).

    Parameters
    ----------
    seed : int
        Everything derives from it; same seed, same bytes.
    bands : sequence of str
        Output bands, in order, from ``BAND_NAMES``; ``pan`` is the
        ``PAN_WEIGHTS`` mean of blue, green, red and nir.
    water_fraction, cloud_fraction, urban_fraction, forest_fraction : float
        Target area fractions in [0, 1] (water + urban + forest <= 1). They hold
        on average over large areas (≫ 5 km); a 20 km scene deviates by tens of
        percent of the target because land use varies on km scales.
    field_size_m : float
        Typical agricultural parcel size (m, > 10).
    sun_elevation_deg, sun_azimuth_deg : float
        Sun for building/cloud shadows and crown shading (deg; azimuth from +x toward +y).
    texel_m : float
        Nominal texel size (m) for the renderer; ``grid`` accepts any.
    cloud_height_m : float
        Cloud altitude above the ground for cloud shadows (m, > 0).
    workers : int, optional
        Threads used by ``grid`` (default: CPU count, at most 8).
    """

    def __init__(self, *, seed: int = 0, bands: Sequence[str] = BAND_NAMES, water_fraction: float = 0.05,
                 cloud_fraction: float = 0.0, urban_fraction: float = 0.08, forest_fraction: float = 0.25,
                 field_size_m: float = 200.0, sun_elevation_deg: float = 45.0, sun_azimuth_deg: float = 135.0,
                 texel_m: float = 1.0, cloud_height_m: float = 1500.0, workers: int | None = None,
                 calibration_extent_m=None):
        self._init_kwargs = dict(seed=seed, bands=bands, water_fraction=water_fraction,
                                 cloud_fraction=cloud_fraction, urban_fraction=urban_fraction,
                                 forest_fraction=forest_fraction, field_size_m=field_size_m,
                                 sun_elevation_deg=sun_elevation_deg, sun_azimuth_deg=sun_azimuth_deg,
                                 texel_m=texel_m, cloud_height_m=cloud_height_m, workers=workers,
                                 calibration_extent_m=calibration_extent_m)
        self._extent = _check_extent(calibration_extent_m)
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
            raise ValueError(f"seed: must be an integer, got {seed!r}")
        self.seed = int(seed)
        self.bands = _check_bands(bands)
        self.water_fraction = _check_fraction("water_fraction", water_fraction)
        self.cloud_fraction = _check_fraction("cloud_fraction", cloud_fraction)
        self.urban_fraction = _check_fraction("urban_fraction", urban_fraction)
        self.forest_fraction = _check_fraction("forest_fraction", forest_fraction)
        if self.water_fraction + self.urban_fraction + self.forest_fraction > 1 + 1e-9:
            raise ValueError("forest_fraction: water_fraction + urban_fraction + forest_fraction must be <= 1, got "
                             f"{self.water_fraction + self.urban_fraction + self.forest_fraction:g}")
        if not (math.isfinite(field_size_m) and field_size_m > 10):
            raise ValueError(f"field_size_m: must be > 10, got {field_size_m}")
        if not (math.isfinite(sun_elevation_deg) and 0 < sun_elevation_deg <= 90):
            raise ValueError(f"sun_elevation_deg: must be in (0, 90], got {sun_elevation_deg}")
        if not math.isfinite(sun_azimuth_deg):
            raise ValueError(f"sun_azimuth_deg: must be finite, got {sun_azimuth_deg}")
        if not (math.isfinite(texel_m) and texel_m > 0):
            raise ValueError(f"texel_m: must be > 0, got {texel_m}")
        if not (math.isfinite(cloud_height_m) and cloud_height_m > 0):
            raise ValueError(f"cloud_height_m: must be > 0, got {cloud_height_m}")
        if workers is None:
            workers = min(8, os.cpu_count() or 1)
        if int(workers) != workers or workers < 1:
            raise ValueError(f"workers: must be a positive integer, got {workers}")
        self.field_size_m = float(field_size_m)
        self.sun_elevation_deg = float(sun_elevation_deg)
        self.sun_azimuth_deg = float(sun_azimuth_deg)
        self.texel_m = float(texel_m)
        self.cloud_height_m = float(cloud_height_m)
        self.workers = int(workers)
        self._tile = 256
        self._setup()

    def __getstate__(self):
        # rebuilt from its parameters (the caches hold closures)
        return self._init_kwargs

    def __setstate__(self, state):
        self.__init__(**state)

    def fingerprint(self) -> str:
        """A digest of every parameter :meth:`grid`'s values depend on (not ``workers``)."""
        import hashlib
        params = {k: v for k, v in self._init_kwargs.items() if k != "workers"}
        return hashlib.sha256(repr(("ProceduralTexture", sorted(params.items()))).encode()).hexdigest()

    def __repr__(self) -> str:
        return (f"ProceduralTexture(seed={self.seed}, bands={self.bands}, water_fraction={self.water_fraction}, "
                f"cloud_fraction={self.cloud_fraction}, urban_fraction={self.urban_fraction}, "
                f"forest_fraction={self.forest_fraction}, field_size_m={self.field_size_m})")

    # -- set-up ----------------------------------------------------------------
    def _setup(self):
        s = self.seed & 0xFFFFFFFF
        salts = nz.unit(nz.hash2(np.arange(32), np.full(32, s), 0x5EED)) * _F32(2 ** 24)
        self._salt = [int(v) * 97 + k for k, v in enumerate(salts)]
        r = nz.unit(nz.hash2(np.arange(8), np.full(8, s), 0xA11)).astype(np.float64)
        self._theta = 2 * math.pi * r[0]                           # urban grid / main roads / field domain A
        self._theta_b = self._theta + math.radians(20 + 50 * r[1])  # field domain B
        self._cu, self._su = _F32(math.cos(self._theta)), _F32(math.sin(self._theta))
        self._cb, self._sb = _F32(math.cos(self._theta_b)), _F32(math.sin(self._theta_b))
        e = math.radians(self.sun_elevation_deg)
        a = math.radians(self.sun_azimuth_deg)
        self._tan_e = math.tan(e)
        self._sun_xy = (math.cos(a), math.sin(a))
        # sun horizontal direction in the urban (u, v) frame
        self._sun_uv = (math.cos(a - self._theta), math.sin(a - self._theta))
        # layout sizes
        self._Sv = 0.8 * self.field_size_m        # strip spacing
        self._Lu, self._Lv, self._nlu, self._nlv, self._Wst = 24.0, 20.0, 4, 2, 12.0
        self._Bu = self._nlu * self._Lu + self._Wst
        self._Bv = self._nlv * self._Lv + self._Wst
        self._Sr = 1300.0                         # main road spacing
        self._hmax = 28.0                         # tallest building (m)
        # neighbouring lots (toward the sun) whose shadows can reach a texel
        lmax = self._hmax / self._tan_e
        self._na = int(math.ceil(lmax * abs(self._sun_uv[0]) / self._Lu)) + 1
        self._nb = int(math.ceil(lmax * abs(self._sun_uv[1]) / self._Lv)) + 1
        cached = nz.CachedLattice
        self._macro = {
            "water": cached(fbm_lattice(_NODE_M, *_OCT_WATER, self._salt[0])),
            "forest": cached(fbm_lattice(_NODE_M, *_OCT_FOREST, self._salt[1])),
            "domain": cached(fbm_lattice(_NODE_M, *_OCT_DOMAIN, self._salt[2])),
            "cloud": cached(fbm_lattice(_NODE_M, *_OCT_CLOUD, self._salt[3])),
            "wroad": cached(self._wroad_lattice()),
        }
        self._block_code_cached = cached(self._block_code, block=32)
        self._calibrate()

    def _wroad_lattice(self):
        """Node function: signed distance (m) to the zero contour of a low-frequency fBm."""
        node_q = int(round(_NODE_M * nz.QUANTA_PER_M))
        h_q = 2 * nz.QUANTA_PER_M
        salt = self._salt[4]

        def fn(ix, iy):
            ix = np.asarray(ix, np.int64)
            iy = np.asarray(iy, np.int64)
            grid = nz._is_grid(ix, iy)
            if not grid:
                ix, iy = np.broadcast_arrays(ix, iy)
            qx, qy = ix * node_q, iy * node_q

            def f(dx, dy):
                return nz.fbm(Coords(qx + dx, qy + dy, grid), *_OCT_WROAD, salt)
            n0 = f(0, 0)
            gx = (f(h_q, 0) - f(-h_q, 0)) / _F32(4.0)
            gy = (f(0, h_q) - f(0, -h_q)) / _F32(4.0)
            g = np.sqrt(gx * gx + gy * gy) + _F32(1e-9)
            return np.clip(n0 / g, _F32(-1e4), _F32(1e4))
        return fn

    def _calibrate(self):
        """Thresholds on the macro fields that give the requested area fractions.

        Water and cloud fractions are realised over ``calibration_extent_m``
        (the imaged footprint: the keys mean what lands in the image); urban and
        forest fractions, and water and cloud without an extent, on average over
        a 400 km square.
        """
        rng = np.random.default_rng([self.seed & 0xFFFFFFFF, 7])
        n = 60000
        qx = quantise(rng.uniform(-2e5, 2e5, n))
        qy = quantise(rng.uniform(-2e5, 2e5, n))
        nw = fbm_points(qx, qy, *_OCT_WATER, self._salt[0])
        nu = fbm_points(qx, qy, *_OCT_URBAN, self._salt[5])
        nf = fbm_points(qx, qy, *_OCT_FOREST, self._salt[1])
        wf, uf, ff = self.water_fraction, self.urban_fraction, self.forest_fraction
        inf = np.float32(np.inf)
        t_water_wide = _F32(np.quantile(nw, wf)) if 0 < wf < 1 else (-inf if wf == 0 else inf)
        land = nw >= t_water_wide
        if uf > 0 and land.any():
            q = 1 - min(1.0, uf / max(1e-9, 1 - wf))
            self._t_urban = _F32(np.quantile(nu[land], q)) if q > 0 else -inf
        else:
            self._t_urban = inf
        rest = land & (nu <= self._t_urban)
        if ff > 0 and rest.any():
            q = 1 - min(1.0, ff / max(1e-9, 1 - wf - uf))
            self._t_forest = _F32(np.quantile(nf[rest], q)) if q > 0 else -inf
        else:
            self._t_forest = inf
        if self._extent is not None:  # water and cloud: what lands in the footprint
            (x0, x1), (y0, y1) = self._extent
            frng = np.random.default_rng([self.seed & 0xFFFFFFFF, 8])
            qx = quantise(frng.uniform(x0, x1, n))
            qy = quantise(frng.uniform(y0, y1, n))
            nw = fbm_points(qx, qy, *_OCT_WATER, self._salt[0])
        self._t_water = _F32(np.quantile(nw, wf)) if 0 < wf < 1 else (-inf if wf == 0 else inf)
        self._t_shore = _F32(self._t_water + 0.03) if wf > 0 else -inf
        cf = self.cloud_fraction
        if cf > 0:
            nc = fbm_points(qx, qy, *_OCT_CLOUD, self._salt[3])
            self._t_cloud = _F32(np.quantile(nc, 1 - cf)) if cf < 1 else -inf
        else:
            self._t_cloud = inf

    # -- public API ------------------------------------------------------------
    def grid(self, x0_m: float, y0_m: float, texel_m: float, nx: int, ny: int, *, ground_irradiance=None,
             cloud_irradiance: float = 1.0) -> np.ndarray:
        """Reflectance on a regular texel grid.

        Parameters
        ----------
        x0_m, y0_m : float
            Lower corner of the grid (m); texel (j, i) is centred at
            ``(x0_m + (i + ½) texel_m, y0_m + (j + ½) texel_m)``.
        texel_m : float
            Texel size (m, > 0).
        nx, ny : int
            Number of texels along x and y.

        ground_irradiance : ndarray (ny, nx), optional, keyword-only
            Relative sun irradiance of the ground at the texels (terrain
            shading and cast shadows, e.g. from
            :func:`~simsat.terrain.illumination.sun_irradiance`). Given, the
            result is reflectance × irradiance: the ground is shaded by it,
            cloud tops (which float above the relief) by ``cloud_irradiance``.
        cloud_irradiance : float, keyword-only
            Relative irradiance of cloud tops (used with ``ground_irradiance``).

        Returns
        -------
        ndarray (nbands, ny, nx) float32
            Reflectance in [0, 1] (× irradiance when given), bands in
            ``self.bands`` order. A texel's value depends only on its centre
            (to 1/1024 m), so tiles offset by whole texels reproduce a big
            block exactly.
        """
        shading = None
        if ground_irradiance is not None:
            shading = np.asarray(ground_irradiance, dtype=_F32)
            if shading.shape != (int(ny), int(nx)):
                raise ValueError(f"ground_irradiance: expected shape ({int(ny)}, {int(nx)}), got {shading.shape}")
        return self._tiled(x0_m, y0_m, texel_m, nx, ny, want_bands=True, want_classes=False, shading=shading,
                           cloud_irradiance=float(cloud_irradiance))[0]

    def grid_and_land_cover(self, x0_m: float, y0_m: float, texel_m: float, nx: int, ny: int):
        """:meth:`grid` and :meth:`land_cover_grid` in one pass: ``(reflectance, classes)``."""
        return self._tiled(x0_m, y0_m, texel_m, nx, ny, want_bands=True, want_classes=True)

    def _tiled(self, x0_m, y0_m, texel_m, nx, ny, *, want_bands: bool, want_classes: bool, shading=None,
               cloud_irradiance: float = 1.0):
        _check_grid_args(x0_m, y0_m, texel_m, nx, ny)
        nx, ny = int(nx), int(ny)
        qx = quantise(x0_m + (np.arange(nx) + 0.5) * texel_m)[None, :]
        qy = quantise(y0_m + (np.arange(ny) + 0.5) * texel_m)[:, None]
        out = np.empty((len(self.bands), ny, nx), dtype=_F32) if want_bands else None
        cls_out = np.empty((ny, nx), dtype=_U8) if want_classes else None
        # square-ish tiles keep the per-tile lookup tables (rotated layouts) small and in cache
        tw = min(nx, self._tile)
        th = min(ny, max(16, self._tile * self._tile // tw))
        chunks = [(j, min(ny, j + th), i, min(nx, i + tw)) for j in range(0, ny, th) for i in range(0, nx, tw)]

        def work(c):
            j0, j1, i0, i1 = c
            cls, refl = self._evaluate(Coords(qx[:, i0:i1], qy[j0:j1], True), want_bands=want_bands,
                                       shading=None if shading is None else shading[j0:j1, i0:i1],
                                       cloud_irradiance=cloud_irradiance)
            if want_bands:
                out[:, j0:j1, i0:i1] = refl
            if want_classes:
                cls_out[j0:j1, i0:i1] = cls

        if self.workers > 1 and len(chunks) > 1:
            with ThreadPoolExecutor(max_workers=min(self.workers, len(chunks))) as ex:
                list(ex.map(work, chunks))
        else:
            for c in chunks:
                work(c)
        return out, cls_out

    def land_cover(self, x, y) -> np.ndarray:
        """Land-cover class (``LandCover`` codes, uint8) at ground points (m).

        Clouds are reported as ``CLOUD`` where their opacity exceeds ½. At texel
        centres this equals the classes behind :meth:`grid`.
        """
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        x, y = np.broadcast_arrays(x, y)
        shape = x.shape
        if x.size == 0:
            return np.zeros(shape, dtype=_U8)
        if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
            raise ValueError("x, y: must be finite")
        c = Coords(quantise(x.ravel()), quantise(y.ravel()), False)
        cls, _ = self._evaluate(c, want_bands=False)
        return cls.reshape(shape)

    def land_cover_grid(self, x0_m: float, y0_m: float, texel_m: float, nx: int, ny: int) -> np.ndarray:
        """Land-cover classes on the texel grid of :meth:`grid`, shape (ny, nx) uint8."""
        return self._tiled(x0_m, y0_m, texel_m, nx, ny, want_bands=False, want_classes=True)[1]

    # -- the landscape ---------------------------------------------------------
    def _macro_field(self, c: Coords, name: str) -> np.ndarray:
        return lattice_interp(c, _NODE_M, self._macro[name], smooth=False, table=True)

    def _block_code(self, bu, bv):
        """Urban block code: 0 not built-up, 1 residential, 2 large buildings, 3 park."""
        bu, bv = np.broadcast_arrays(np.asarray(bu, np.int64), np.asarray(bv, np.int64))
        uc = (bu + 0.5) * self._Bu
        vc = (bv + 0.5) * self._Bv
        ct, st = math.cos(self._theta), math.sin(self._theta)
        qx = quantise(ct * uc - st * vc)
        qy = quantise(st * uc + ct * vc)
        nu = fbm_points(qx, qy, *_OCT_URBAN, self._salt[5])
        nw = fbm_points(qx, qy, *_OCT_WATER, self._salt[0])
        urban = (nu > self._t_urban) & (nw > self._t_water + _F32(0.04))
        t = nz.unit(nz.hash2(bu, bv, self._salt[6]))
        code = np.where(t < 0.62, 1, np.where(t < 0.85, 2, 3)).astype(_U8)
        return np.where(urban, code, 0).astype(_U8)

    def _building(self, gu, gv, blocks: Lookup):
        """Building of lot (gu, gv): (u0, u1, v0, v1, height, roof material, present), u/v in m."""
        nlu, nlv = self._nlu, self._nlv
        bu = gu // nlu
        bv = gv // nlv
        ku = gu - bu * nlu
        kv = gv - bv * nlv
        code = blocks.take(0, blocks.index(bu, bv))
        h = nz.hash2(gu, gv, self._salt[7])
        b0 = (h & 0xFF).astype(_F32) * _F32(1 / 255)
        b1 = ((h >> 8) & 0xFF).astype(_F32) * _F32(1 / 255)
        b2 = ((h >> 16) & 0xFF).astype(_F32) * _F32(1 / 255)
        b3 = (h >> 24).astype(np.intp)
        lu0 = (bu * self._Bu + self._Wst + ku * self._Lu).astype(_F32)
        lv0 = (bv * self._Bv + self._Wst + kv * self._Lv).astype(_F32)
        large = code == 2
        # residential: a house inset in its lot
        u0 = lu0 + _F32(2.0) + _F32(6.0) * b0
        u1 = lu0 + _F32(self._Lu - 2.0) - _F32(6.0) * b1
        v0 = lv0 + _F32(2.0) + _F32(4.0) * b1
        v1 = lv0 + _F32(self._Lv - 2.0) - _F32(5.0) * b2
        hgt = _F32(3.0) + _F32(9.0) * b2
        roof = _ROOFS_SMALL[b3 % _ROOFS_SMALL.size]
        present = (code == 1) & (b0 < _F32(0.88))
        if np.any(large):
            bu0 = (bu * self._Bu + self._Wst).astype(_F32)
            bv0 = (bv * self._Bv + self._Wst).astype(_F32)
            hb = nz.hash2(bu, bv, self._salt[8])
            c0 = (hb & 0xFF).astype(_F32) * _F32(1 / 255)
            c1 = ((hb >> 8) & 0xFF).astype(_F32) * _F32(1 / 255)
            u0 = np.where(large, bu0 + _F32(3.0) + _F32(6.0) * c0, u0)
            u1 = np.where(large, bu0 + _F32(self._Bu - self._Wst - 3.0) - _F32(8.0) * c1, u1)
            v0 = np.where(large, bv0 + _F32(3.0) + _F32(4.0) * c1, v0)
            v1 = np.where(large, bv0 + _F32(self._Bv - self._Wst - 3.0) - _F32(4.0) * c0, v1)
            hgt = np.where(large, _F32(8.0) + _F32(self._hmax - 8.0) * c1 * c1, hgt)
            roof = np.where(large, _ROOFS_LARGE[(hb >> 24).astype(np.intp) % _ROOFS_LARGE.size], roof)
            present = present | large
        return u0, u1, v0, v1, hgt, roof, present

    # lattice functions of the layout (elementwise in their integer arguments)
    def _strip_b(self, k2, _j=None):
        """Lower boundary (m, in the field frame) of strip k2 = 2 k + domain."""
        k2 = np.asarray(k2, np.int64)
        k = k2 >> 1
        h = nz.unit(nz.hash2(k, k2 & 1, self._salt[14])).astype(np.float64)
        return (k * self._Sv + 0.8 * self._Sv * (h - 0.5)).astype(_F32)

    def _track_flag(self, k2, _j=None):
        return (nz.unit(nz.hash2(k2, 3, self._salt[16])) < _F32(0.3)).astype(_U8)

    def _strip_su(self, k2, _j=None):
        """Nominal parcel length (m) and column offset (fraction) in strip k2."""
        return _F32(self.field_size_m * 0.7) + _F32(self.field_size_m * 1.5) * nz.unit(nz.hash2(k2, 1, self._salt[15]))

    def _strip_off(self, k2, _j=None):
        return nz.unit(nz.hash2(k2, 2, self._salt[15]))

    def _col_b(self, m, k2):
        """Lower boundary (m, shifted field frame) of parcel m in strip k2."""
        su = self._strip_su(k2).astype(np.float64)
        h = nz.unit(nz.hash2(m, k2, self._salt[15] + 3)).astype(np.float64)
        return (np.asarray(m, np.int64) * su + 0.8 * su * (h - 0.5)).astype(_F32)

    def _parcel_attrs(self, m, k2):
        """Attributes of parcel m of strip k2: (crop byte, sub-strips, 1/row period (1/m),
        rows along u, brightness gain, margin width (m), hedge, forest stand type)."""
        h = nz.hash2(m, k2, self._salt[17])
        g = nz.rehash(h, 5)
        byte = lambda a, s: ((a >> _U32(s)) & _U32(0xFF)).astype(np.intp)  # noqa: E731
        return (byte(h, 0),
                _NSUB_BY_BYTE[byte(h, 8)],
                _F32(1.0) / (_F32(3.0) + byte(h, 16).astype(_F32) * _F32(9.0 / 255)),
                (h & _U32(0x01000000)) != 0,
                _F32(0.9) + byte(g, 8).astype(_F32) * _F32(0.2 / 255),
                _F32(0.6) + ((h >> _U32(26)) & _U32(3)).astype(_F32) * _F32(0.6),
                (h & _U32(0x02000000)) != 0,
                _STAND_BY_BYTE[byte(g, 0)])

    def _road_pos(self, k, d):
        h = nz.unit(nz.hash2(k, d, self._salt[18])).astype(np.float64)
        return (np.asarray(k, np.int64) * self._Sr + 0.3 * self._Sr * (h - 0.5)).astype(_F32)

    def _road_hw(self, k, seg, d):
        h = nz.hash3(k, seg, d, self._salt[18] + 1)
        present = nz.unit(h) < _F32(0.6)
        hw = _F32(2.5) + _F32(2.5) * nz.unit(nz.rehash(h, 1))
        return np.where(present, hw, _F32(0.0))

    def _evaluate(self, c: Coords, *, want_bands: bool, shading=None, cloud_irradiance: float = 1.0):
        """Land-cover classes and (``want_bands``) reflectance per band at the points of ``c``.

        Layers painted in order over the default agricultural parcels: forest
        and natural shores, roads, built-up blocks, water, then clouds and
        their shadows over everything.
        """
        f = self._fields(c)
        cv, track, p_stand = self._parcels(f)
        water, shore, urban, forest, blocks = self._land_masks(c, f)
        if forest.any():
            self._paint_forest(c, f, cv, forest, p_stand)
        if shore.any():                              # natural banks around water
            _put(cv.m1, shore, _M["pasture"])
            _put(cv.m2, shore, _M["shrub"])
            _put(cv.alpha, shore, _clip01(_F32(0.5) + _F32(0.8) * f.n5 + _F32(0.3) * f.n12))
            _put(cv.cls, shore, LandCover.GRASSLAND)
        self._paint_roads(c, f, cv, track, water, urban)
        shadow = None
        if urban.any():
            shadow = np.zeros(c.shape, dtype=_F32)
            bu, bv, bcode, blk = blocks
            self._urban(urban, f.u, f.v, bu, bv, bcode, blk, f.n2, f.n5, f.n12, cv.m1, cv.m2, cv.alpha, cv.gain,
                        shadow, cv.cls, want_shadows=want_bands)
        if water.any():                              # dark, nearly uniform; a little brighter near the shore
            _put(cv.m1, water, _M["shallow_water"])
            _put(cv.m2, water, _M["deep_water"])
            _put(cv.alpha, water, np.clip((f.nw - self._t_water) * _F32(12.0) + _F32(0.6), _F32(0), _F32(0.6)))
            _put(cv.gain, water, _F32(1.0) + _F32(0.01) * f.n40)
            _put(cv.cls, water, LandCover.WATER)
        clouds = self._clouds(c, cv) if self.cloud_fraction > 0 else None
        if not want_bands:
            return cv.cls, None
        return cv.cls, self._reflectance(cv, c.shape, shadow, shading, clouds, cloud_irradiance)

    def _fields(self, c: Coords) -> "_Fields":
        """Noise fields shared by the classes (values in ~[-1, 1]) and the rotated frames of the layout."""
        S = self._salt
        x, y = c.x, c.y
        nd = self._macro_field(c, "domain")
        u = self._cu * x + self._su * y
        v = self._cu * y - self._su * x
        domb = nd > _F32(0.0)
        return _Fields(n2=value_noise(c, 2.0, S[10]), n5=value_noise(c, 5.0, S[11]), n12=value_noise(c, 12.0, S[12]),
                       n40=value_noise(c, 40.0, S[13]), nw=self._macro_field(c, "water"),
                       nf=self._macro_field(c, "forest"), u=u, v=v, domb=domb,
                       uf=np.where(domb, self._cb * x + self._sb * y, u), vf=np.where(domb, self._cb * y - self._sb * x, v),
                       n=int(np.prod(c.shape)))

    def _parcels(self, f: "_Fields") -> tuple:
        """Agricultural parcels (the default land): the canvas, the gravel tracks, the forest stand of each texel.

        Strips along the field frame's u axis with jittered boundaries b(k) in
        v; parcels along each strip with jittered boundaries c(m) in u; a crop
        per sub-strip with its row pattern; margins (hedges, grass strips).
        """
        i32 = np.intp  # index arrays: intp gathers are several times faster than int32
        uf, vf, n = f.uf, f.vf, f.n
        kn = np.floor(vf * _F32(1.0 / self._Sv) + _F32(0.5)).astype(i32)
        kn *= 2
        kn += f.domb                                # key = 2 k + domain
        strips = Lookup.around([self._strip_b, self._track_flag, self._strip_su, self._strip_off],
                               kn, 0, n, margin_i=4)
        ik = strips.index(kn, 0)
        bn = strips.take(0, ik)
        below = vf < bn
        ik = strips.shift_i(ik, -2 * below.astype(i32))   # strip index of the texel
        ks = kn - 2 * below.astype(i32)
        ik_hi = strips.shift_i(ik, 2)
        lo = strips.take(0, ik)
        hi = strips.take(0, ik_hi)
        su = strips.take(2, ik)
        up = uf + strips.take(3, ik) * su
        mn = np.floor(up / su + _F32(0.5)).astype(i32)
        cols = Lookup.around([self._col_b, self._parcel_attrs], mn, ks, n, margin_i=2)
        ic = cols.index(mn, ks)
        left = up < cols.take(0, ic)
        ic = cols.shift_i(ic, -left.astype(i32))
        ulo = cols.take(0, ic)
        uhi = cols.take(0, cols.shift_i(ic, 1))
        # per-parcel attributes (outputs 1.. of the table)
        p_byte, p_nsub, p_iper, p_along_u, p_gain, p_wmarg, p_hedge, p_stand = (cols.take(k, ic) for k in range(1, 9))
        du = np.minimum(up - ulo, uhi - up)
        dv = np.minimum(vf - lo, hi - vf)
        sub = np.minimum(np.floor((up - ulo) / (uhi - ulo) * p_nsub), p_nsub - _F32(1.0)).astype(np.intp)
        sub *= 97
        sub += p_byte
        sub &= 0xFF
        ctype = _CROP_BY_BYTE[sub]                  # crop of the parcel's sub-strip
        w = np.where(p_along_u, up, vf)
        w *= p_iper
        cv = self._crops(f, ctype, w, p_gain)
        margin = np.minimum(du, dv) < p_wmarg
        if margin.any():
            _put(cv.m1, margin, _M["dry_grass"])
            _put(cv.m2, margin, _M["pasture"])
            _put(cv.m1, margin & p_hedge, _M["hedge"])
            _put(cv.alpha, margin, 0.5)
        track = ((strips.take(1, ik) != 0) & (vf - lo < _F32(1.7))) | \
                ((strips.take(1, ik_hi) != 0) & (hi - vf < _F32(1.7)))
        return cv, track, p_stand

    @staticmethod
    def _crops(f: "_Fields", ctype, w, p_gain) -> "_Canvas":
        """The canvas of the crops: materials, mixing, gain with the row pattern (triangle wave of ``w``)."""
        tri = w - np.floor(w)
        tri -= _F32(0.5)
        np.abs(tri, out=tri)
        tri *= _F32(4.0)
        tri -= _F32(1.0)                             # row pattern: triangle wave in [-1, 1]
        alpha = _CROP_A0[ctype] + _CROP_AMP[ctype] * tri + _F32(0.15) * f.n40 + _F32(0.08) * f.n5
        _clip01(alpha)
        gain = _CROP_FAMP[ctype] * tri
        gain += _F32(1.0)
        gain += _F32(0.03) * f.n2 + _F32(0.04) * f.n12
        gain *= p_gain
        return _Canvas(m1=_CROP_M1[ctype], m2=_CROP_M2[ctype], alpha=alpha, gain=gain, cls=_CROP_CLS[ctype])

    def _land_masks(self, c: Coords, f: "_Fields") -> tuple:
        """Water, shores, built-up blocks and forest; the block lookup ``(bu, bv, bcode, blocks)`` for the towns."""
        i32 = np.intp
        water = f.nw + _F32(0.012) * f.n12 < self._t_water
        shore = ~water & (f.nw < self._t_shore)
        bu = np.floor(f.u * _F32(1.0 / self._Bu)).astype(i32)
        bv = np.floor(f.v * _F32(1.0 / self._Bv)).astype(i32)
        blocks = Lookup.around([self._block_code_cached], bu, bv, f.n, margin_i=self._na // self._nlu + 2,
                               margin_j=self._nb // self._nlv + 2)
        bcode = blocks.take(0, blocks.index(bu, bv))
        urban = (bcode > 0) & ~water
        forest = f.nf + _F32(0.04) * f.n12 > self._t_forest
        forest &= ~water & ~urban & ~shore
        return water, shore, urban, forest, (bu, bv, bcode, blocks)

    def _paint_forest(self, c: Coords, f: "_Fields", cv: "_Canvas", forest, p_stand) -> None:
        """Forest stands: round crowns, brighter on their sunny side."""
        S = self._salt
        dx, dy = 1.5 * self._sun_xy[0], 1.5 * self._sun_xy[1]
        n5s = value_noise(c.shifted(dx, dy), 5.0, S[11])
        n37 = value_noise(c, 3.7, S[19])         # a second, incommensurate lattice: rounder crowns
        crown = _STAND_W2[p_stand] * f.n2
        crown += f.n5
        crown += n37
        crown *= _F32(0.8)
        crown += _STAND_A0[p_stand] + _F32(0.2) * f.n12
        _put(cv.alpha, forest, _clip01(crown))
        n5s -= f.n5
        n5s += value_noise(c.shifted(dx, dy), 3.7, S[19])
        n5s -= n37
        n5s *= _F32(-0.9)
        n5s += _F32(1.0)                         # crowns brighter on their sunny side
        n5s *= _F32(1.0) + _F32(0.06) * f.n40
        _put(cv.gain, forest, n5s)
        _put(cv.m1, forest, _STAND_M1[p_stand])
        _put(cv.m2, forest, _STAND_M2[p_stand])
        _put(cv.cls, forest, LandCover.FOREST)

    def _paint_roads(self, c: Coords, f: "_Fields", cv: "_Canvas", track, water, urban) -> None:
        """Straight roads on two grids (every other one bright concrete), winding roads, the gravel tracks."""
        i32 = np.intp
        road = track.copy()
        bright = track.copy()
        for d, a_coord, b_coord in ((0, f.u, f.v), (1, f.v, f.u)):
            kr = np.floor(a_coord * _F32(1.0 / self._Sr) + _F32(0.5)).astype(i32)
            seg = np.floor(b_coord * _F32(1.0 / self._Sr)).astype(i32)
            look = Lookup.around([lambda k, s, d=d: self._road_pos(k, d), lambda k, s, d=d: self._road_hw(k, s, d)],
                                 kr, seg, f.n)
            ir = look.index(kr, seg)
            dist = a_coord - look.take(0, ir)
            np.abs(dist, out=dist)
            on = dist < look.take(1, ir)
            road |= on
            on &= (kr & 1) == 0
            bright |= on
        winding = np.abs(self._macro_field(c, "wroad")) < _F32(2.6)
        road |= winding
        bright |= winding
        road &= ~water
        road &= ~urban
        if road.any():
            mat = np.where(bright, np.where(track, _U8(_M["gravel"]), _U8(_M["concrete"])), _U8(_M["asphalt"]))
            _put(cv.m1, road, mat)
            _put(cv.alpha, road, 1.0)
            _put(cv.gain, road, _F32(1.0) + _F32(0.04) * f.n2)
            _put(cv.cls, road, LandCover.ROAD)

    def _clouds(self, c: Coords, cv: "_Canvas") -> tuple:
        """Cloud opacity, the opacity of the clouds whose shadow falls here, cloud brightness; cloud classes."""
        nc = self._macro_field(c, "cloud")
        cloud = _smooth(np.clip((nc - self._t_cloud) * _F32(15.0) + _F32(0.5), _F32(0), _F32(1)))
        L = self.cloud_height_m / self._tan_e
        ncs = self._macro_field(c.shifted(L * self._sun_xy[0], L * self._sun_xy[1]), "cloud")
        cshadow = _smooth(np.clip((ncs - self._t_cloud) * _F32(15.0) + _F32(0.5), _F32(0), _F32(1)))
        _put(cv.cls, cloud >= _F32(0.5), LandCover.CLOUD)
        cloud_bright = _F32(0.88) + _F32(0.12) * np.clip((nc - self._t_cloud) * _F32(2.0), _F32(0), _F32(1))
        return cloud, cshadow, cloud_bright

    def _reflectance(self, cv: "_Canvas", shape, shadow, shading, clouds, cloud_irradiance: float) -> np.ndarray:
        """Reflectance per output band: the two materials mixed, building and cloud shadows, terrain shading,
        clouds on top; PAN as the weighted sum of the visible and NIR bands."""
        i1 = cv.m1.astype(np.intp)
        i2 = cv.m2.astype(np.intp)
        beta = _F32(1.0) - cv.alpha
        vis_nir = []
        for b in range(4):
            t = _REFL[b]
            r = t[i1]
            r *= cv.alpha
            r += t[i2] * beta
            r *= cv.gain
            k = _SHADOW_K[b]
            if shadow is not None:
                r *= _F32(1.0) - shadow * (_F32(1.0) - k)
            if shading is not None:  # terrain shading lights the ground, not the clouds above it
                r *= shading
            if clouds is not None:
                cloud, cshadow, cloud_bright = clouds
                r *= _F32(1.0) - _F32(0.85) * cshadow * (_F32(1.0) - k)
                top = _CLOUD_REFL[b] * cloud_bright
                if shading is not None:
                    top = top * _F32(cloud_irradiance)
                r += (top - r) * cloud
            vis_nir.append(_clip01(r))
        out = np.empty((len(self.bands),) + shape, dtype=_F32)
        for o, name in enumerate(self.bands):
            if name == "pan":
                p = out[o]
                np.multiply(vis_nir[0], _F32(PAN_WEIGHTS[0]), out=p)
                for b in range(1, 4):
                    p += vis_nir[b] * _F32(PAN_WEIGHTS[b])
            else:
                out[o] = vis_nir[BAND_NAMES.index(name)]
        return out

    def _urban(self, urban, u, v, bu, bv, bcode, blocks, n2, n5, n12, m1, m2, alpha, gain, shadow, cls, *,
               want_shadows=True):
        """Streets, lots, buildings, gardens, parks and building shadows (in place, on the urban texels)."""
        idx = np.flatnonzero(urban)
        pu, pv, gbu, gbv, code, n2u, n5u, n12u = (np.take(a, idx) for a in (u, v, bu, bv, bcode, n2, n5, n12))
        Wst, Lu, Lv = _F32(self._Wst), _F32(self._Lu), _F32(self._Lv)
        ru = pu - (gbu * self._Bu).astype(_F32)
        rv = pv - (gbv * self._Bv).astype(_F32)
        ku = np.minimum(np.floor((ru - Wst) / Lu).astype(np.intp), self._nlu - 1)
        kv = np.minimum(np.floor((rv - Wst) / Lv).astype(np.intp), self._nlv - 1)
        gu = gbu * self._nlu + ku      # lot indices (a street texel gets the lot before the street)
        gv = gbv * self._nlv + kv
        street = (ru < Wst) | (rv < Wst)
        n = pu.size
        # streets: asphalt carriageway with pavements along the kerbs
        kerb = _F32(2.2)
        lane = ((ru >= kerb) & (ru <= Wst - kerb)) | ((rv >= kerb) & (rv <= Wst - kerb))
        M1 = np.where(lane, _U8(_M["asphalt"]), _U8(_M["pavement"]))
        M2 = M1.copy()
        A = np.ones(n, _F32)
        G = _F32(1.0) + _F32(0.04) * n2u
        C = np.full(n, LandCover.ROAD, _U8)
        # lots: gardens / yards and trees; parks
        lot = ~street
        garden = nz.unit(nz.hash2(gu, gv, self._salt[9])) * _F32(0.9)
        park = code == 3
        green = (_F32(0.5) + _F32(0.5) * n12u) < garden + park.astype(_F32)
        tree = lot & (n5u > np.where(park, _F32(0.15), _F32(0.55))) & (green | park)
        M1[lot] = np.where(green[lot], _U8(_M["lawn"]), _U8(_M["pavement"]))
        M2[lot] = _M["dry_grass"]
        A[lot] = np.where(green[lot], _F32(0.85), _F32(1.0))
        C[lot] = LandCover.URBAN_OPEN
        M1[tree] = _M["broadleaf_crown"]
        M2[tree] = _M["canopy_gap"]
        A[tree] = np.clip(_F32(0.4) + _F32(1.5) * (n5u[tree] - _F32(0.5)) + _F32(0.5) * n2u[tree], _F32(0), _F32(1))
        # the lot's own building: ridged roofs for houses, flat roofs for large buildings
        na, nb = self._na, self._nb
        lots = Lookup.around([lambda i, j: self._building(i, j, blocks)], gu, gv, n)
        il = lots.index(gu, gv)
        u0, u1, v0, v1 = (lots.take(k, il) for k in range(4))
        roof, present = lots.take(5, il), lots.take(6, il)
        onroof = lot & present & (pu >= u0) & (pu < u1) & (pv >= v0) & (pv < v1)
        M1[onroof] = roof[onroof]
        M2[onroof] = roof[onroof]
        A[onroof] = 1.0
        su, sv = _F32(self._sun_uv[0]), _F32(self._sun_uv[1])
        ridge_along_v = (u1 - u0) < (v1 - v0)      # the ridge runs along the long side
        facing = np.where(ridge_along_v, (pu - _F32(0.5) * (u0 + u1)) * su, (pv - _F32(0.5) * (v0 + v1)) * sv) > 0
        ridge_g = np.where(facing, _F32(1.12), _F32(0.82))
        G = np.where(onroof, np.where(code == 2, _F32(1.0) + _F32(0.03) * n2u, ridge_g), G)
        C[onroof] = LandCover.BUILDING
        # shadows cast on the ground by this and neighbouring buildings (anti-sun side):
        # texel p is shaded by a building B of height h if p + t s (s: horizontal unit
        # vector toward the sun) enters B for some 0 < t <= h / tan(e). Per building
        # the lot table holds B's bounds already divided by s's components.
        if not want_shadows:
            na = nb = -1
        sgu = 1 if self._sun_uv[0] >= 0 else -1
        sgv = 1 if self._sun_uv[1] >= 0 else -1
        ground = ~onroof
        sh = np.zeros(n, dtype=bool)
        if na >= 0:
            isu = _F32(1.0 / (su if abs(su) > 1e-6 else 1e-6))
            isv = _F32(1.0 / (sv if abs(sv) > 1e-6 else 1e-6))
            inv_tan = _F32(1.0 / self._tan_e)

            def shadow_params(i, j):
                bu0, bu1, bv0, bv1, hgt, _, pres = self._building(i, j, blocks)
                if isu < 0:
                    bu0, bu1 = bu1, bu0
                if isv < 0:
                    bv0, bv1 = bv1, bv0
                reach = np.where(pres, hgt * inv_tan, _F32(-1.0))
                return bu0 * isu, bu1 * isu, bv0 * isv, bv1 * isv, reach

            slots = Lookup.around([shadow_params], gu, gv, n, margin_i=na, margin_j=nb)
            P = pu * isu
            Q = pv * isv
            for a in range(na + 1):
                for b in range(nb + 1):
                    ic = slots.index(gu + a * sgu, gv + b * sgv)
                    t_lo = slots.take(0, ic) - P
                    np.maximum(t_lo, slots.take(2, ic) - Q, out=t_lo)
                    np.maximum(t_lo, _F32(0.0), out=t_lo)
                    t_hi = slots.take(1, ic) - P
                    np.minimum(t_hi, slots.take(3, ic) - Q, out=t_hi)
                    np.minimum(t_hi, slots.take(4, ic), out=t_hi)
                    sh |= t_lo <= t_hi
        sh &= ground
        for dst, val in ((m1, M1), (m2, M2), (alpha, A), (gain, G), (shadow, sh), (cls, C)):
            np.put(dst, idx, val)

# -----------------------------------------------------------------------------
# Orthoimage
# -----------------------------------------------------------------------------
class OrthoTexture:
    """A real orthoimage as a texture, resampled bilinearly on request.

    Parameters
    ----------
    path : str or path-like
        PNG/JPEG (read with OpenCV; colour channels reordered to R, G, B[, A]) or
        TIFF (read with tifffile, channels in file order). North-up: image row 0 is
        the +y edge.
    texel_m : float
        Ground size of one image pixel (m, > 0).
    bands : mapping of str to int
        Band name → channel index, e.g. ``{"red": 0, "green": 1, "blue": 2, "nir": 3}``.
        A requested ``pan`` not in the mapping is the ``PAN_WEIGHTS`` mean of the
        available blue/green/red/nir (renormalised).
    x0_m, y0_m : float, optional
        Ground coordinates (m) of the image's lower-left corner (last row, first
        column, outer edge); default: image centred on (0, 0).
    scale : float, optional
        Digital number → reflectance factor; default 1/255 for 8-bit, 1/65535
        for 16-bit, 1 for floating-point images.
    output_bands : sequence of str, optional
        Bands returned by :meth:`grid`, in order; default: the mapping's names.

    Outside the image, :meth:`grid` returns the nearest edge pixel.
    """

    def __init__(self, path, *, texel_m: float, bands: Mapping[str, int], x0_m: float | None = None,
                 y0_m: float | None = None, scale: float | None = None,
                 output_bands: Sequence[str] | None = None):
        p = os.fspath(path)
        if not os.path.isfile(p):
            raise ValueError(f"path: file not found: {p}")
        if not (isinstance(texel_m, (int, float)) and math.isfinite(texel_m) and texel_m > 0):
            raise ValueError(f"texel_m: must be > 0, got {texel_m!r}")
        img = self._read(p)
        if img.ndim == 2:
            img = img[:, :, None]
        if img.ndim != 3 or img.shape[0] < 2 or img.shape[1] < 2:
            raise ValueError(f"path: {p} is not a 2-D image (shape {img.shape})")
        if not isinstance(bands, Mapping) or not bands:
            raise ValueError("bands: must map band names to channel indices")
        for name, ch in bands.items():
            if name not in BAND_NAMES:
                raise ValueError(f"bands: unknown band {name!r}; choose from {', '.join(BAND_NAMES)}")
            if isinstance(ch, bool) or not isinstance(ch, (int, np.integer)) or not 0 <= ch < img.shape[2]:
                raise ValueError(f"bands.{name}: must be a channel index in [0, {img.shape[2] - 1}], got {ch!r}")
        if scale is None:
            if img.dtype == np.uint8:
                scale = 1 / 255
            elif img.dtype == np.uint16:
                scale = 1 / 65535
            else:
                scale = 1.0
        if not (math.isfinite(scale) and scale > 0):
            raise ValueError(f"scale: must be > 0, got {scale}")
        self.path = p
        self.texel_m = float(texel_m)
        nrow, ncol = img.shape[:2]
        self.x0_m = -0.5 * ncol * texel_m if x0_m is None else float(x0_m)
        self.y0_m = -0.5 * nrow * texel_m if y0_m is None else float(y0_m)
        # flip rows: internal row j is at y = y0 + (j + 1/2) texel
        self._img = {name: np.ascontiguousarray(img[::-1, :, ch], dtype=_F32) * _F32(scale)
                     for name, ch in bands.items()}
        self.bands = _check_bands(tuple(bands) if output_bands is None else output_bands)
        for b in self.bands:
            if b not in self._img and not (b == "pan" and any(k in self._img for k in BAND_NAMES[:4])):
                raise ValueError(f"output_bands: band {b!r} is not in the bands mapping")

    @staticmethod
    def _read(p):
        ext = os.path.splitext(p)[1].lower()
        try:
            if ext in (".tif", ".tiff"):
                import tifffile
                img = np.asarray(tifffile.imread(p))
                if img.ndim == 3 and img.shape[0] < min(img.shape[1:]) and img.shape[0] <= 8:
                    img = np.moveaxis(img, 0, -1)  # planar → interleaved
                return img
            import cv2
            img = cv2.imread(p, cv2.IMREAD_UNCHANGED)
            if img is None:
                raise ValueError("OpenCV could not decode it")
            if img.ndim == 3 and img.shape[2] >= 3:
                img = img[:, :, [2, 1, 0] + list(range(3, img.shape[2]))]
            return img
        except Exception as exc:
            raise ValueError(f"path: cannot read image {p}: {exc}") from None

    def fingerprint(self) -> str:
        """A digest of the image's bands, placement and output bands (what :meth:`grid` depends on)."""
        fp = getattr(self, "_fingerprint", None)
        if fp is None:
            import hashlib
            h = hashlib.sha256(repr(("OrthoTexture", self.x0_m, self.y0_m, self.texel_m, self.bands)).encode())
            for name in sorted(self._img):
                h.update(name.encode())
                h.update(np.ascontiguousarray(self._img[name]).tobytes())
            fp = self._fingerprint = h.hexdigest()
        return fp

    @property
    def shape(self):
        """(rows, columns) of the image."""
        return next(iter(self._img.values())).shape

    def _sample(self, arr, x, y):
        nrow, ncol = arr.shape
        fx = np.clip((x - self.x0_m) / self.texel_m - 0.5, 0, ncol - 1)
        fy = np.clip((y - self.y0_m) / self.texel_m - 0.5, 0, nrow - 1)
        i = np.minimum(np.floor(fx).astype(np.intp), ncol - 2)
        j = np.minimum(np.floor(fy).astype(np.intp), nrow - 2)
        tx = (fx - i).astype(_F32)
        ty = (fy - j).astype(_F32)[:, None]
        j0 = int(j.min())
        rows = arr[j0:int(j.max()) + 2]
        a = rows[:, i]
        a = a + (rows[:, i + 1] - a) * tx
        lj = j - j0
        b = a[lj]
        return b + (a[lj + 1] - b) * ty

    def grid(self, x0_m: float, y0_m: float, texel_m: float, nx: int, ny: int, *, ground_irradiance=None,
             cloud_irradiance: float = 1.0) -> np.ndarray:
        """Reflectance on a texel grid (same convention as :meth:`ProceduralTexture.grid`).

        ``ground_irradiance`` (ny, nx), when given, multiplies the result (an
        orthoimage has no separate cloud layer: ``cloud_irradiance`` is unused).

        Returns
        -------
        ndarray (nbands, ny, nx) float32, clipped to [0, 1] (× irradiance when given).
        """
        _check_grid_args(x0_m, y0_m, texel_m, nx, ny)
        x = x0_m + (np.arange(int(nx)) + 0.5) * texel_m
        y = y0_m + (np.arange(int(ny)) + 0.5) * texel_m
        cache = {}

        def band(name):
            if name not in cache:
                cache[name] = self._sample(self._img[name], x, y)
            return cache[name]

        out = np.empty((len(self.bands), int(ny), int(nx)), dtype=_F32)
        for k, name in enumerate(self.bands):
            if name in self._img:
                out[k] = band(name)
            else:  # pan from the available spectral bands
                acc, wsum = None, 0.0
                for b, wgt in zip(BAND_NAMES[:4], PAN_WEIGHTS):
                    if b in self._img:
                        term = band(b) * _F32(wgt)
                        acc = term if acc is None else acc + term
                        wsum += wgt
                out[k] = acc / _F32(wsum)
        out = _clip01(out)
        if ground_irradiance is not None:
            irr = np.asarray(ground_irradiance, dtype=_F32)
            if irr.shape != (int(ny), int(nx)):
                raise ValueError(f"ground_irradiance: expected shape ({int(ny)}, {int(nx)}), got {irr.shape}")
            out *= irr[None]
        return out

    def land_cover(self, x, y) -> np.ndarray:
        """Unknown for a real image: ``LandCover.UNKNOWN`` everywhere (uint8)."""
        x, y = np.broadcast_arrays(np.asarray(x), np.asarray(y))
        return np.full(x.shape, LandCover.UNKNOWN, dtype=_U8)
