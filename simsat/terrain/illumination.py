"""Sun illumination of the terrain: Lambert shading and cast shadows.

Convention: the sun azimuth is measured in the local ground plane from +x
(along-track) toward +y (across-track), i.e. counter-clockwise seen from above;
the sun elevation is measured from the horizontal plane. The unit vector toward the
sun is ``(cos e cos a, cos e sin a, sin e)``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .dem import Dem

__all__ = ["Sun", "sun_direction", "sun_irradiance", "cast_shadows", "sample_grid", "texel_centres"]


def sun_direction(elevation_deg: float, azimuth_deg: float) -> np.ndarray:
    """Unit vector toward the sun in the local frame, shape (3,).

    Parameters
    ----------
    elevation_deg : float
        Elevation above the horizon (deg, in (0, 90]).
    azimuth_deg : float
        Azimuth from +x toward +y (deg).
    """
    e = math.radians(elevation_deg)
    a = math.radians(azimuth_deg)
    return np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])


@dataclass(frozen=True)
class Sun:
    """Sun geometry and ambient (sky) light fraction.

    Parameters
    ----------
    elevation_deg : float
        Elevation above the horizon (deg, in (0, 90]).
    azimuth_deg : float
        Azimuth from +x (along-track) toward +y (across-track) (deg).
    ambient : float
        Fraction of the irradiance received by a surface in full shadow, in [0, 1].
    cast_shadows : bool
        Whether terrain casts shadows.
    irradiance_scale : float
        Scene brightness: the sun's irradiance relative to the reference scene
        (1: the built-in scenarios; 0.2: a dim scene, five times less signal).
    """

    elevation_deg: float = 45.0
    azimuth_deg: float = 135.0
    ambient: float = 0.2
    cast_shadows: bool = True
    irradiance_scale: float = 1.0

    def __post_init__(self):
        _check_sun(self.elevation_deg, self.azimuth_deg, self.ambient)
        if not (math.isfinite(self.irradiance_scale) and self.irradiance_scale > 0):
            raise ValueError(f"irradiance_scale: must be finite and > 0, got {self.irradiance_scale}")

    @property
    def direction(self) -> np.ndarray:
        """Unit vector toward the sun, shape (3,)."""
        return sun_direction(self.elevation_deg, self.azimuth_deg)


def _check_sun(elevation_deg, azimuth_deg, ambient):
    if not (math.isfinite(elevation_deg) and 0 < elevation_deg <= 90):
        raise ValueError(f"elevation_deg: must be in (0, 90], got {elevation_deg}")
    if not math.isfinite(azimuth_deg):
        raise ValueError(f"azimuth_deg: must be finite, got {azimuth_deg}")
    if not (math.isfinite(ambient) and 0 <= ambient <= 1):
        raise ValueError(f"ambient: must be in [0, 1], got {ambient}")


def _shifted(a: np.ndarray, ox: float, oy: float, fill: float) -> np.ndarray:
    """``a`` bilinearly sampled at (column + ox, row + oy); ``fill`` where that leaves the grid."""
    ny, nx = a.shape
    I, J = math.floor(ox), math.floor(oy)
    fx, fy = ox - I, oy - J
    out = np.full_like(a, fill)
    ap = np.pad(a, ((0, 1), (0, 1)), mode="edge")  # lets the bilinear read one past the last sample
    # targets whose shifted position lies inside [0, n-1]
    i0, i1 = max(0, -I), min(nx, nx - 1 - I + (1 if fx == 0 else 0))
    j0, j1 = max(0, -J), min(ny, ny - 1 - J + (1 if fy == 0 else 0))
    if i1 <= i0 or j1 <= j0:
        return out
    s00 = ap[j0 + J:j1 + J, i0 + I:i1 + I]
    s10 = ap[j0 + J:j1 + J, i0 + I + 1:i1 + I + 1]
    s01 = ap[j0 + J + 1:j1 + J + 1, i0 + I:i1 + I]
    s11 = ap[j0 + J + 1:j1 + J + 1, i0 + I + 1:i1 + I + 1]
    t = a.dtype.type
    out[j0:j1, i0:i1] = (s00 * t(1 - fx) + s10 * t(fx)) * t(1 - fy) + (s01 * t(1 - fx) + s11 * t(fx)) * t(fy)
    return out


def cast_shadows(dem: Dem, *, elevation_deg: float, azimuth_deg: float,
                 step_m: float | None = None, max_distance_m: float | None = None) -> np.ndarray:
    """Which DEM samples see the sun, by horizon marching toward it.

    A sample p is in shadow if the terrain rises above the sun ray from p:
    ``max_t [z(p + t s) − t tan e] > z(p)`` over ``t = step, 2 step, …, D``
    (``s``: horizontal unit vector toward the sun, bilinear heights). All samples
    march together, with doubling steps: ``H_{k+1}(p) = max(H_k(p),
    H_k(p + 2^k step s) − 2^k step tan e)``, so the cost is ``log2(D / step)``
    whole-grid passes. The shifted ``H_k`` is interpolated bilinearly, which can
    move shadow edges by a fraction of a sample. Terrain outside the DEM casts no
    shadow.

    Parameters
    ----------
    dem : Dem
    elevation_deg, azimuth_deg : float
        Sun position (deg), see the module docstring.
    step_m : float, optional
        Horizontal march step (m); default ``min(dx_m, dy_m)``.
    max_distance_m : float, optional
        Longest march (m); default the distance at which the ray rises by the
        DEM's full relief.

    Returns
    -------
    ndarray of bool, shape (ny, nx)
        True where the sample is lit.
    """
    _check_sun(elevation_deg, azimuth_deg, 0.0)
    if step_m is None:
        step_m = min(dem.dx_m, dem.dy_m)
    if not (math.isfinite(step_m) and step_m > 0):
        raise ValueError(f"step_m: must be > 0, got {step_m}")
    if max_distance_m is not None and not (math.isfinite(max_distance_m) and max_distance_m > 0):
        raise ValueError(f"max_distance_m: must be > 0, got {max_distance_m}")
    ny, nx = dem.shape
    relief = dem.z_max - dem.z_min
    if relief <= 0 or elevation_deg >= 90:
        return np.ones((ny, nx), dtype=bool)
    tan_e = math.tan(math.radians(elevation_deg))
    dist = min(relief / tan_e, math.hypot(nx * dem.dx_m, ny * dem.dy_m))
    if max_distance_m is not None:
        dist = min(dist, max_distance_m)
    a = math.radians(azimuth_deg)
    ux, uy = math.cos(a) / dem.dx_m, math.sin(a) / dem.dy_m   # samples per metre toward the sun
    z = (dem.z - dem.z_min).astype(np.float32)                  # float32 heights, relative
    low = np.float32(-1e9)
    # H: the highest (terrain − ray rise) seen so far along each sample's march
    h = _shifted(z, step_m * ux, step_m * uy, low) - np.float32(step_m * tan_e)
    reach = step_m
    while reach < dist:
        hs = _shifted(h, reach * ux, reach * uy, low)
        hs -= np.float32(reach * tan_e)
        np.maximum(h, hs, out=h)
        reach *= 2
    tol = np.float32(1e-6 * max(1.0, relief))
    return h <= z + tol


def sun_irradiance(dem: Dem, *, elevation_deg: float, azimuth_deg: float, ambient: float = 0.2,
                   shadows: bool = True, step_m: float | None = None) -> np.ndarray:
    """Relative irradiance of the terrain at the DEM samples.

    ``factor = ambient + (1 - ambient) * max(0, n·s) * lit``, with ``n`` the surface
    normal (central differences), ``s`` the unit vector toward the sun and ``lit``
    from :func:`cast_shadows`. 1 = a surface facing the sun; flat ground gets
    ``ambient + (1 - ambient) sin(e)``.

    Parameters
    ----------
    dem : Dem
    elevation_deg : float
        Sun elevation (deg, in (0, 90]).
    azimuth_deg : float
        Sun azimuth from +x toward +y (deg).
    ambient : float
        Sky-light fraction in [0, 1].
    shadows : bool
        Compute cast shadows (else ``lit = 1``).
    step_m : float, optional
        Shadow march step (m).

    Returns
    -------
    ndarray (ny, nx) float64, in [ambient, 1].
    """
    _check_sun(elevation_deg, azimuth_deg, ambient)
    s = sun_direction(elevation_deg, azimuth_deg)
    cos_i = np.maximum(dem.normals() @ s, 0.0)
    if shadows:
        cos_i = cos_i * cast_shadows(dem, elevation_deg=elevation_deg, azimuth_deg=azimuth_deg,
                                     step_m=step_m)
    return ambient + (1.0 - ambient) * cos_i


def texel_centres(x0_m: float, y0_m: float, texel_m: float, nx: int, ny: int):
    """Texel-centre coordinates of a texture grid (m): ``x0 + (i + ½) texel``.

    Returns
    -------
    x : ndarray (nx,), y : ndarray (ny,)
    """
    return (x0_m + (np.arange(nx) + 0.5) * texel_m, y0_m + (np.arange(ny) + 0.5) * texel_m)


def sample_grid(dem: Dem, values: np.ndarray, *, x0_m: float, y0_m: float, texel_m: float,
                nx: int, ny: int) -> np.ndarray:
    """Bilinearly sample a per-DEM-sample field at the centres of a texture grid.

    Uses the texture convention of :meth:`ProceduralTexture.grid`: texel (j, i) is
    centred at ``(x0_m + (i + ½) texel_m, y0_m + (j + ½) texel_m)``. Outside the
    DEM the nearest edge value is used. Typical use: bake
    :func:`sun_irradiance` into a texture strip.

    Parameters
    ----------
    dem : Dem
        Grid on which ``values`` is defined.
    values : ndarray (ny_dem, nx_dem)
    x0_m, y0_m : float
        Corner of the texture grid (m).
    texel_m : float
        Texel size (m, > 0).
    nx, ny : int
        Texture grid size.

    Returns
    -------
    ndarray (ny, nx) float32
    """
    values = np.asarray(values)
    if values.shape != dem.shape:
        raise ValueError(f"values: shape {values.shape} differs from the DEM's {dem.shape}")
    if not (math.isfinite(texel_m) and texel_m > 0):
        raise ValueError(f"texel_m: must be > 0, got {texel_m}")
    if nx < 1 or ny < 1:
        raise ValueError(f"nx, ny: must be >= 1, got {nx}, {ny}")
    x, y = texel_centres(x0_m, y0_m, texel_m, nx, ny)
    ndy, ndx = dem.shape
    fx = np.clip((x - dem.x0_m) / dem.dx_m, 0, ndx - 1)
    fy = np.clip((y - dem.y0_m) / dem.dy_m, 0, ndy - 1)
    i = np.minimum(np.floor(fx).astype(np.intp), ndx - 2)
    j = np.minimum(np.floor(fy).astype(np.intp), ndy - 2)
    tx = (fx - i).astype(np.float32)
    ty = (fy - j).astype(np.float32)[:, None]
    j0 = int(j.min())
    rows = values[j0:int(j.max()) + 2].astype(np.float32)
    a = rows[:, i]
    a = a + (rows[:, i + 1] - a) * tx
    lj = j - j0
    b = a[lj]
    return b + (a[lj + 1] - b) * ty
