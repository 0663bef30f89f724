"""Digital elevation models on a regular grid in the local scene frame.

Local frame: x along-track (m), y across-track (m), z up (m); the scene is centred
near (0, 0). Real DEMs are mapped with x = east, y = north.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from typing import Tuple

import numpy as np
from scipy import ndimage

__all__ = ["Dem", "fractal_dem", "load_geotiff_dem", "matplotlib_sample_dem", "resample",
           "degrees_to_metres"]

# WGS84 ellipsoid
_WGS84_A = 6378137.0
_WGS84_E2 = 6.69437999014e-3


def degrees_to_metres(lat_deg: float) -> Tuple[float, float]:
    """Length in m of one degree of longitude and of latitude at ``lat_deg`` (WGS84).

    Returns
    -------
    (m_per_deg_lon, m_per_deg_lat) : tuple of float
    """
    phi = math.radians(lat_deg)
    s2 = math.sin(phi) ** 2
    n = _WGS84_A / math.sqrt(1.0 - _WGS84_E2 * s2)              # prime vertical radius
    m = _WGS84_A * (1.0 - _WGS84_E2) / (1.0 - _WGS84_E2 * s2) ** 1.5  # meridian radius
    return math.radians(1.0) * n * math.cos(phi), math.radians(1.0) * m


def _range(name: str, r) -> Tuple[float, float]:
    try:
        a, b = (float(v) for v in r)
    except Exception:
        raise ValueError(f"{name}: must be a pair (min, max) in m, got {r!r}") from None
    if not (math.isfinite(a) and math.isfinite(b) and b > a):
        raise ValueError(f"{name}: must be finite with max > min, got ({a}, {b})")
    return a, b


@dataclass(frozen=True, eq=False)
class Dem:
    """Heights on a regular grid.

    Sample ``z[j, i]`` lies at ``x = x0_m + i * dx_m``, ``y = y0_m + j * dy_m``.

    Parameters
    ----------
    x0_m, y0_m : float
        Coordinates of sample ``z[0, 0]`` (m).
    dx_m, dy_m : float
        Grid spacing along x and y (m, > 0).
    z : ndarray, shape (ny, nx)
        Heights (m), finite; stored as a read-only float64 copy. At least 2 × 2.
    """

    x0_m: float
    y0_m: float
    dx_m: float
    dy_m: float
    z: np.ndarray = field(repr=False)

    def __post_init__(self):
        for name in ("x0_m", "y0_m", "dx_m", "dy_m"):
            v = float(getattr(self, name))
            if not math.isfinite(v):
                raise ValueError(f"{name}: must be finite, got {v}")
            object.__setattr__(self, name, v)
        for name in ("dx_m", "dy_m"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name}: must be > 0, got {getattr(self, name)}")
        z = np.array(self.z, dtype=np.float64, copy=True)
        if z.ndim != 2 or z.shape[0] < 2 or z.shape[1] < 2:
            raise ValueError(f"z: must be a 2-D array of at least 2 x 2 samples, got shape {z.shape}")
        if not np.all(np.isfinite(z)):
            raise ValueError("z: must be finite everywhere (fill no-data first)")
        z.setflags(write=False)
        object.__setattr__(self, "z", z)

    def __repr__(self) -> str:
        return (f"Dem(x0_m={self.x0_m:g}, y0_m={self.y0_m:g}, dx_m={self.dx_m:g}, dy_m={self.dy_m:g}, "
                f"shape={self.shape}, z=[{self.z_min:.1f}, {self.z_max:.1f}] m)")

    # -- geometry --------------------------------------------------------------
    @property
    def shape(self) -> Tuple[int, int]:
        """(ny, nx)."""
        return self.z.shape

    @property
    def x(self) -> np.ndarray:
        """Sample x coordinates (m), shape (nx,)."""
        return self.x0_m + self.dx_m * np.arange(self.shape[1])

    @property
    def y(self) -> np.ndarray:
        """Sample y coordinates (m), shape (ny,)."""
        return self.y0_m + self.dy_m * np.arange(self.shape[0])

    @property
    def x_range(self) -> Tuple[float, float]:
        """(x of first column, x of last column) in m."""
        return self.x0_m, self.x0_m + self.dx_m * (self.shape[1] - 1)

    @property
    def y_range(self) -> Tuple[float, float]:
        """(y of first row, y of last row) in m."""
        return self.y0_m, self.y0_m + self.dy_m * (self.shape[0] - 1)

    @property
    def z_max(self) -> float:
        return float(self.z.max())

    @property
    def z_min(self) -> float:
        return float(self.z.min())

    # -- interpolation ---------------------------------------------------------
    def _cell(self, x, y, outside: str):
        if outside not in ("nan", "clamp"):
            raise ValueError(f"outside: must be 'nan' or 'clamp', got {outside!r}")
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        x, y = np.broadcast_arrays(x, y)
        ny, nx = self.shape
        fx = (x - self.x0_m) / self.dx_m
        fy = (y - self.y0_m) / self.dy_m
        tol = 1e-9
        out = ~((fx >= -tol) & (fx <= nx - 1 + tol) & (fy >= -tol) & (fy <= ny - 1 + tol))
        fx = np.clip(fx, 0.0, nx - 1.0)
        fy = np.clip(fy, 0.0, ny - 1.0)
        i = np.minimum(np.floor(fx), nx - 2).astype(np.intp)
        j = np.minimum(np.floor(fy), ny - 2).astype(np.intp)
        return i, j, fx - i, fy - j, out

    def height(self, x, y, *, outside: str = "nan") -> np.ndarray:
        """Bilinearly interpolated height (m) at ground points.

        Parameters
        ----------
        x, y : array_like
            Ground coordinates (m), broadcastable.
        outside : {'nan', 'clamp'}
            Outside the grid: NaN, or the height at the nearest point of the grid.

        Returns
        -------
        ndarray (float64), broadcast shape of ``x`` and ``y``.
        """
        i, j, tx, ty, out = self._cell(x, y, outside)
        z = self.z
        z00 = z[j, i]
        z10 = z[j, i + 1]
        z01 = z[j + 1, i]
        z11 = z[j + 1, i + 1]
        h = (z00 * (1 - tx) + z10 * tx) * (1 - ty) + (z01 * (1 - tx) + z11 * tx) * ty
        if outside == "nan" and np.any(out):
            h = np.where(out, np.nan, h)
        return h

    def gradient(self, x, y, *, outside: str = "nan") -> Tuple[np.ndarray, np.ndarray]:
        """Slopes (dz/dx, dz/dy) of the bilinear surface at ground points (m/m).

        Parameters as :meth:`height`.
        """
        i, j, tx, ty, out = self._cell(x, y, outside)
        z = self.z
        z00 = z[j, i]
        z10 = z[j, i + 1]
        z01 = z[j + 1, i]
        z11 = z[j + 1, i + 1]
        gx = ((z10 - z00) * (1 - ty) + (z11 - z01) * ty) / self.dx_m
        gy = ((z01 - z00) * (1 - tx) + (z11 - z10) * tx) / self.dy_m
        if outside == "nan" and np.any(out):
            gx = np.where(out, np.nan, gx)
            gy = np.where(out, np.nan, gy)
        return gx, gy

    def normals(self) -> np.ndarray:
        """Unit upward surface normals at the samples (central differences), shape (ny, nx, 3)."""
        gy, gx = np.gradient(self.z, self.dy_m, self.dx_m)
        n = np.stack([-gx, -gy, np.ones_like(gx)], axis=-1)
        n /= np.linalg.norm(n, axis=-1, keepdims=True)
        return n

    # -- derived DEMs ----------------------------------------------------------
    def crop(self, x_range, y_range) -> "Dem":
        """The smallest sub-grid whose samples enclose ``x_range`` × ``y_range`` (m).

        Raises
        ------
        ValueError
            If the ranges are malformed or do not overlap the grid.
        """
        xa, xb = _range("x_range", x_range)
        ya, yb = _range("y_range", y_range)
        ny, nx = self.shape
        eps = 1e-9
        i0 = max(0, int(math.floor((xa - self.x0_m) / self.dx_m + eps)))
        i1 = min(nx - 1, int(math.ceil((xb - self.x0_m) / self.dx_m - eps)))
        j0 = max(0, int(math.floor((ya - self.y0_m) / self.dy_m + eps)))
        j1 = min(ny - 1, int(math.ceil((yb - self.y0_m) / self.dy_m - eps)))
        if i1 - i0 < 1 or j1 - j0 < 1:
            raise ValueError(f"x_range/y_range: ({xa:g}, {xb:g}) x ({ya:g}, {yb:g}) m does not overlap "
                             f"the DEM {self.x_range} x {self.y_range} m by at least one cell")
        return Dem(self.x0_m + i0 * self.dx_m, self.y0_m + j0 * self.dy_m, self.dx_m, self.dy_m,
                   self.z[j0:j1 + 1, i0:i1 + 1])

    def covers(self, x_range, y_range) -> bool:
        """True if the grid covers ``x_range`` × ``y_range`` (m)."""
        (xa, xb), (ya, yb) = _range("x_range", x_range), _range("y_range", y_range)
        (ga, gb), (ha, hb) = self.x_range, self.y_range
        tol = 1e-6
        return ga <= xa + tol and gb >= xb - tol and ha <= ya + tol and hb >= yb - tol

    def on_sphere(self, radius_m: float) -> "Dem":
        """The heights drawn on a sphere of ``radius_m`` whose top is the local frame's origin.

        The local frame is tangent to the Earth at the scene centre: a point
        at horizontal distance ``r`` lies ``R − sqrt(R² − r²)`` (≈ r² / 2R)
        below the tangent plane. ``inf`` returns the DEM unchanged (flat Earth).
        """
        if not np.isfinite(radius_m):
            return self
        if not radius_m > 0:
            raise ValueError(f"radius_m: must be > 0, got {radius_m}")
        xx, yy = np.meshgrid(self.x, self.y)
        r2 = xx ** 2 + yy ** 2
        if np.any(r2 >= radius_m ** 2):
            raise ValueError("radius_m: the DEM extends beyond the sphere")
        sag = r2 / (radius_m + np.sqrt(radius_m ** 2 - r2))  # R − sqrt(R² − r²), without cancellation
        return Dem(self.x0_m, self.y0_m, self.dx_m, self.dy_m, self.z - sag)

    def with_error(self, *, noise_m: float = 0.0, bias_m: float = 0.0, correlation_m: float = 0.0,
                   seed: int = 0) -> "Dem":
        """A perturbed copy: the DEM a ground segment knows, as opposed to the truth.

        Parameters
        ----------
        noise_m : float
            Standard deviation of the random height error (m, >= 0).
        bias_m : float
            Constant height offset (m).
        correlation_m : float
            Correlation length of the error (m, >= 0): white noise low-passed by a
            Gaussian of this standard deviation, then rescaled to ``noise_m``.
            0 = independent per sample.
        seed : int
            Random seed.

        Returns
        -------
        Dem
            Same grid; ``self`` itself when both ``noise_m`` and ``bias_m`` are 0.
        """
        for name, v in (("noise_m", noise_m), ("bias_m", bias_m), ("correlation_m", correlation_m)):
            if not math.isfinite(float(v)):
                raise ValueError(f"{name}: must be finite, got {v}")
        if noise_m < 0:
            raise ValueError(f"noise_m: must be >= 0, got {noise_m}")
        if correlation_m < 0:
            raise ValueError(f"correlation_m: must be >= 0, got {correlation_m}")
        if noise_m == 0 and bias_m == 0:
            return self
        err = np.full(self.shape, float(bias_m))
        if noise_m > 0:
            rng = np.random.default_rng([int(seed) & 0xFFFFFFFFFFFFFFFF, 12])
            e = rng.standard_normal(self.shape)
            if correlation_m > 0:
                e = ndimage.gaussian_filter(e, sigma=(correlation_m / self.dy_m, correlation_m / self.dx_m),
                                            mode="reflect")
            sd = e.std()
            if sd > 0:
                e *= noise_m / sd
            err += e
        return Dem(self.x0_m, self.y0_m, self.dx_m, self.dy_m, self.z + err)

    def mesh(self) -> Tuple[np.ndarray, np.ndarray]:
        """Triangle mesh of the grid for the renderer.

        Returns
        -------
        vertices : ndarray (ny*nx, 3) float64
            (x, y, z) in m; vertex ``j * nx + i`` is sample ``z[j, i]``.
        faces : ndarray (2*(ny-1)*(nx-1), 3) int32
            Two triangles per cell, counter-clockwise seen from +z (normals point up).
        """
        ny, nx = self.shape
        if ny * nx > np.iinfo(np.int32).max:
            raise ValueError(f"z: too many samples for int32 faces ({ny} x {nx})")
        X, Y = np.meshgrid(self.x, self.y)
        vertices = np.stack([X.ravel(), Y.ravel(), self.z.ravel()], axis=1)
        k = (np.arange(ny - 1, dtype=np.int32)[:, None] * nx + np.arange(nx - 1, dtype=np.int32)[None, :]).ravel()
        t1 = np.stack([k, k + 1, k + nx + 1], axis=1)
        t2 = np.stack([k, k + nx + 1, k + nx], axis=1)
        faces = np.empty((2 * k.size, 3), dtype=np.int32)
        faces[0::2] = t1
        faces[1::2] = t2
        return vertices, faces


# -----------------------------------------------------------------------------
# Synthetic relief
# -----------------------------------------------------------------------------
def _grid_for(x_range_m, y_range_m, resolution_m):
    xa, xb = _range("x_range_m", x_range_m)
    ya, yb = _range("y_range_m", y_range_m)
    if not (math.isfinite(resolution_m) and resolution_m > 0):
        raise ValueError(f"resolution_m: must be > 0, got {resolution_m}")
    nx = int(math.ceil((xb - xa) / resolution_m - 1e-9)) + 1
    ny = int(math.ceil((yb - ya) / resolution_m - 1e-9)) + 1
    # centre the (slightly larger) grid on the requested range
    x0 = 0.5 * (xa + xb) - 0.5 * (nx - 1) * resolution_m
    y0 = 0.5 * (ya + yb) - 0.5 * (ny - 1) * resolution_m
    return x0, y0, nx, ny


def fractal_dem(*, x_range_m, y_range_m, resolution_m: float, relief_m: float,
                roughness: float = 0.7, seed: int = 0) -> Dem:
    """Seeded fractal relief by spectral synthesis, with gentle large-scale hills.

    Parameters
    ----------
    x_range_m, y_range_m : (float, float)
        Extent to cover (m); the grid is centred on it and covers it.
    resolution_m : float
        Grid spacing (m, > 0).
    relief_m : float
        Peak-to-peak height (m, >= 0); heights span [0, relief_m].
    roughness : float
        Hurst-like exponent H in (0, 1]: amplitude spectrum ∝ k^-(1+H).
        Small H (0.2–0.4) = rugged small-scale relief; H near 1 = smooth.
    seed : int
        Random seed; the same arguments give the same bytes.

    Returns
    -------
    Dem
    """
    x0, y0, nx, ny = _grid_for(x_range_m, y_range_m, resolution_m)
    if not (math.isfinite(relief_m) and relief_m >= 0):
        raise ValueError(f"relief_m: must be >= 0, got {relief_m}")
    if not (math.isfinite(roughness) and 0 < roughness <= 1):
        raise ValueError(f"roughness: must be in (0, 1], got {roughness}")
    if nx * ny > 64_000_000:
        raise ValueError(f"resolution_m: {resolution_m:g} m gives {nx} x {ny} samples (> 64 M)")
    if relief_m == 0:
        return Dem(x0, y0, resolution_m, resolution_m, np.zeros((ny, nx)))
    rng = np.random.default_rng([int(seed) & 0xFFFFFFFFFFFFFFFF, 11])
    # synthesise on a padded grid so the FFT periodicity does not show
    px, py = int(nx * 1.25) + 8, int(ny * 1.25) + 8
    kx = np.fft.rfftfreq(px, d=resolution_m)
    ky = np.fft.fftfreq(py, d=resolution_m)
    kmin = 1.0 / (max(px, py) * resolution_m)
    amp = np.hypot(kx[None, :], ky[:, None])
    np.maximum(amp, kmin, out=amp)
    np.power(amp, -(1.0 + roughness), out=amp)
    amp[0, 0] = 0.0
    spec = rng.standard_normal(amp.shape) + 1j * rng.standard_normal(amp.shape)
    spec *= amp
    del amp
    fr = np.fft.irfft2(spec, s=(py, px))[:ny, :nx]
    del spec
    # gentle hills: a few broad Gaussian bumps and dips, a few km across
    X = x0 + resolution_m * np.arange(nx)
    Y = y0 + resolution_m * np.arange(ny)
    width = max(X[-1] - X[0], Y[-1] - Y[0], 10 * resolution_m)
    hills = np.zeros((ny, nx))
    nh = 6
    cx = rng.uniform(X[0], X[-1], nh)
    cy = rng.uniform(Y[0], Y[-1], nh)
    sig = rng.uniform(0.12, 0.3, nh) * width
    sgn = rng.choice([-1.0, 1.0], nh) * rng.uniform(0.5, 1.0, nh)
    for a, b, s, g in zip(cx, cy, sig, sgn):
        hills += g * np.exp(-0.5 * ((X[None, :] - a) / s) ** 2) * np.exp(-0.5 * ((Y[:, None] - b) / s) ** 2)

    def ptp(a):
        r = float(a.max() - a.min())
        return r if r > 0 else 1.0

    z = fr / ptp(fr) + 0.6 * hills / ptp(hills)
    z -= z.min()
    z *= relief_m / ptp(z)
    return Dem(x0, y0, resolution_m, resolution_m, z)


# -----------------------------------------------------------------------------
# Real DEMs
# -----------------------------------------------------------------------------
def _fill_nodata(z: np.ndarray, name: str) -> np.ndarray:
    bad = ~np.isfinite(z)
    if bad.all():
        raise ValueError(f"{name}: DEM holds no valid height")
    if bad.any():
        idx = ndimage.distance_transform_edt(bad, return_distances=False, return_indices=True)
        z = z[tuple(idx)]
    return z


def _geokeys(page) -> dict:
    tag = page.tags.get(34735)
    if tag is None:
        return {}
    v = list(tag.value)
    keys = {}
    for n in range(v[3]):
        kid, loc, count, off = v[4 + 4 * n: 8 + 4 * n]
        if loc == 0:
            keys[kid] = off
    return keys


def load_geotiff_dem(path, *, band: int = 0, nodata: float | None = None,
                     pixel_size_m: float | None = None, geographic: bool | None = None) -> Dem:
    """Load a GeoTIFF DEM, convert spacing to metres and re-centre it on (0, 0).

    x = east, y = north; rows are flipped if the file stores north at the top.

    Parameters
    ----------
    path : str or path-like
    band : int
        Sample (channel) to read for multi-band files.
    nodata : float, optional
        No-data value; default from the GDAL_NODATA tag (42113) if present.
        No-data samples are filled with the nearest valid height.
    pixel_size_m : float, optional
        Spacing to use when the file has no ModelPixelScaleTag (33550).
    geographic : bool, optional
        Force the interpretation of the pixel scale as degrees (True) or metres
        (False); default from the GeoKey GTModelTypeGeoKey (1024 = 2 → degrees).

    Returns
    -------
    Dem
    """
    import tifffile

    p = os.fspath(path)
    if not os.path.isfile(p):
        raise ValueError(f"path: file not found: {p}")
    try:
        with tifffile.TiffFile(p) as tif:
            page = tif.pages[0]
            arr = page.asarray()
            scale = page.tags.get(33550)
            scale = tuple(scale.value) if scale is not None else None
            tie = page.tags.get(33922)
            tie = tuple(tie.value) if tie is not None else None
            nd_tag = page.tags.get(42113)
            geokeys = _geokeys(page)
    except Exception as exc:  # tifffile raises various types for broken files
        raise ValueError(f"path: cannot read GeoTIFF {p}: {exc}") from None
    arr = np.asarray(arr)
    if arr.ndim == 3:
        # (rows, cols, samples) for contiguous, (samples, rows, cols) for planar
        ax = int(np.argmin(arr.shape))
        if not 0 <= band < arr.shape[ax]:
            raise ValueError(f"band: must be in [0, {arr.shape[ax] - 1}], got {band}")
        arr = np.take(arr, band, axis=ax)
    if arr.ndim != 2:
        raise ValueError(f"path: {p} holds an array of shape {arr.shape}, not a 2-D DEM")
    z = arr.astype(np.float64)
    if nodata is None and nd_tag is not None:
        try:
            nodata = float(str(nd_tag.value).strip().strip("\x00"))
        except ValueError:
            nodata = None
    if nodata is not None:
        z[z == nodata] = np.nan
    z = _fill_nodata(z, "path")

    if scale is None:
        if pixel_size_m is None:
            raise ValueError(f"path: {p} has no ModelPixelScaleTag (33550); pass pixel_size_m")
        sx = sy = float(pixel_size_m)
        geographic = False
    else:
        sx, sy = float(scale[0]), float(scale[1])
    if geographic is None:
        geographic = geokeys.get(1024) == 2
    if not (sx > 0 and sy > 0):
        raise ValueError(f"path: {p} has a non-positive pixel scale ({sx}, {sy})")
    if geographic:
        ny = z.shape[0]
        lat = 0.0
        if tie is not None and len(tie) >= 6:
            lat = float(tie[4]) + (float(tie[1]) - 0.5 * ny) * sy  # latitude of the centre
        mx, my = degrees_to_metres(lat)
        sx, sy = sx * mx, sy * my
    # GeoTIFF rows run from north (top) to south: flip so that y grows with the row
    z = z[::-1]
    ny, nx = z.shape
    return Dem(-0.5 * (nx - 1) * sx, -0.5 * (ny - 1) * sy, sx, sy, z)


def matplotlib_sample_dem() -> Dem:
    """The Jacksboro fault DEM shipped with matplotlib, in metres, centred on (0, 0).

    ``jacksboro_fault_dem.npz`` holds ``elevation`` (344 × 403, m, int16) on a
    3-arc-second grid (``dx``, ``dy`` in degrees; ~74 m east × 93 m north at 36.6° N)
    with row 0 at the north edge. Returned with x = east, y = north.
    """
    from matplotlib import cbook

    try:
        with cbook.get_sample_data("jacksboro_fault_dem.npz") as d:
            z = np.asarray(d["elevation"], dtype=np.float64)
            dx_deg, dy_deg = float(d["dx"]), float(d["dy"])
            lat = 0.5 * (float(d["ymin"]) + float(d["ymax"]))
    except Exception as exc:
        raise ValueError(f"matplotlib sample DEM: cannot load jacksboro_fault_dem.npz: {exc}") from None
    mx, my = degrees_to_metres(lat)
    dx, dy = dx_deg * mx, dy_deg * my
    z = z[::-1]  # row 0 is north in the file
    ny, nx = z.shape
    return Dem(-0.5 * (nx - 1) * dx, -0.5 * (ny - 1) * dy, dx, dy, z)


def resample(dem: Dem, resolution_m: float) -> Dem:
    """Resample a DEM to a square grid of ``resolution_m`` (bilinear, anti-aliased).

    The new grid is centred on the old one and lies inside it. When coarsening,
    the heights are low-passed first (Gaussian, sigma = sqrt(f² − 1) / 2 samples
    for a coarsening factor f; odd reflection at the edges, so planes stay exact).

    Parameters
    ----------
    dem : Dem
    resolution_m : float
        New spacing (m, > 0).
    """
    if not (math.isfinite(resolution_m) and resolution_m > 0):
        raise ValueError(f"resolution_m: must be > 0, got {resolution_m}")
    (xa, xb), (ya, yb) = dem.x_range, dem.y_range
    nx = int(math.floor((xb - xa) / resolution_m + 1e-9)) + 1
    ny = int(math.floor((yb - ya) / resolution_m + 1e-9)) + 1
    if nx < 2 or ny < 2:
        raise ValueError(f"resolution_m: {resolution_m:g} m is coarser than the DEM extent")
    z = dem.z
    fx, fy = resolution_m / dem.dx_m, resolution_m / dem.dy_m
    if fx > 1 or fy > 1:
        sig = (0.5 * math.sqrt(max(fy * fy - 1, 0.0)), 0.5 * math.sqrt(max(fx * fx - 1, 0.0)))
        # odd reflection at the edges (linear extrapolation) keeps planes exact
        pad = tuple((int(math.ceil(4 * s)) + 1,) * 2 for s in sig)
        zp = np.pad(z, pad, mode="reflect", reflect_type="odd")
        zp = ndimage.gaussian_filter(zp, sigma=sig, mode="nearest", truncate=4.0)
        z = zp[pad[0][0]:pad[0][0] + z.shape[0], pad[1][0]:pad[1][0] + z.shape[1]]
        src = Dem(dem.x0_m, dem.y0_m, dem.dx_m, dem.dy_m, z)
    else:
        src = dem
    x0 = 0.5 * (xa + xb) - 0.5 * (nx - 1) * resolution_m
    y0 = 0.5 * (ya + yb) - 0.5 * (ny - 1) * resolution_m
    X = x0 + resolution_m * np.arange(nx)
    Y = y0 + resolution_m * np.arange(ny)
    zn = src.height(X[None, :], Y[:, None], outside="clamp")
    return Dem(x0, y0, resolution_m, resolution_m, zn)
