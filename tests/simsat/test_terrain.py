"""Tests for simsat.terrain: DEMs, textures, illumination, scenario sections."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import ndimage

from simsat.config import ScenarioError, Section
from simsat.terrain import (BAND_NAMES, PAN_WEIGHTS, Dem, LandCover, OrthoTexture, ProceduralTexture, Sun,
                            cast_shadows, degrees_to_metres, dem_from_config, fractal_dem,
                            knowledge_dem_from_config, load_geotiff_dem, matplotlib_sample_dem, resample,
                            sample_grid, sun_direction, sun_from_config, sun_irradiance, texel_centres,
                            texture_from_config)


def plane_dem(a=0.3, b=-0.2, c=12.0, *, x0=-105.0, y0=40.0, dx=5.0, dy=7.5, nx=41, ny=23):
    x = x0 + dx * np.arange(nx)
    y = y0 + dy * np.arange(ny)
    return Dem(x0, y0, dx, dy, c + a * x[None, :] + b * y[:, None])


# -----------------------------------------------------------------------------
# Dem
# -----------------------------------------------------------------------------
def test_height_and_gradient_exact_on_plane():
    a, b, c = 0.3, -0.2, 12.0
    dem = plane_dem(a, b, c)
    rng = np.random.default_rng(0)
    (xa, xb), (ya, yb) = dem.x_range, dem.y_range
    x = rng.uniform(xa, xb, 1000)
    y = rng.uniform(ya, yb, 1000)
    np.testing.assert_allclose(dem.height(x, y), c + a * x + b * y, rtol=0, atol=1e-9)
    gx, gy = dem.gradient(x, y)
    np.testing.assert_allclose(gx, a, atol=1e-12)
    np.testing.assert_allclose(gy, b, atol=1e-12)
    # the grid corners are inside, points beyond are NaN or clamped
    assert np.isfinite(dem.height(xb, yb))
    assert np.isnan(dem.height(xb + 1.0, 0.5 * (ya + yb)))
    assert np.isnan(dem.height(0.0, ya - 1e-3))
    assert dem.height(xb + 50.0, yb, outside="clamp") == pytest.approx(c + a * xb + b * yb)
    # broadcasting
    assert dem.height(x[:5, None], y[None, :3]).shape == (5, 3)


def test_dem_properties_and_crop():
    dem = plane_dem()
    assert dem.shape == (23, 41)
    assert dem.x_range == (-105.0, -105.0 + 40 * 5.0)
    assert dem.y_range == (40.0, 40.0 + 22 * 7.5)
    assert dem.z_max == pytest.approx(dem.z.max()) and dem.z_min == pytest.approx(dem.z.min())
    with pytest.raises(ValueError):
        dem.z[0, 0] = 1.0                      # read-only
    sub = dem.crop((-52.0, 3.0), (61.0, 100.0))
    assert sub.x_range[0] <= -52.0 and sub.x_range[1] >= 3.0
    assert sub.y_range[0] <= 61.0 and sub.y_range[1] >= 100.0
    assert sub.x_range[1] - sub.x_range[0] < 55.0 + 2 * dem.dx_m
    p = (np.array([-50.0, 0.0, 2.5]), np.array([62.0, 99.0, 80.0]))
    np.testing.assert_allclose(sub.height(*p), dem.height(*p), atol=1e-9)
    with pytest.raises(ValueError, match="x_range"):
        dem.crop((1000.0, 2000.0), (61.0, 100.0))


@pytest.mark.parametrize("kwargs, name", [
    (dict(dx_m=0.0), "dx_m"), (dict(dy_m=-1.0), "dy_m"), (dict(x0_m=float("nan")), "x0_m"),
    (dict(z=np.zeros(5)), "z"), (dict(z=np.full((3, 3), np.nan)), "z"),
])
def test_dem_validation_names_the_field(kwargs, name):
    args = dict(x0_m=0.0, y0_m=0.0, dx_m=1.0, dy_m=1.0, z=np.zeros((3, 3)))
    args.update(kwargs)
    with pytest.raises(ValueError, match=f"^{name}:"):
        Dem(**args)


def test_mesh_faces_valid():
    dem = plane_dem(nx=7, ny=5)
    v, f = dem.mesh()
    ny, nx = dem.shape
    assert v.shape == (nx * ny, 3) and v.dtype == np.float64
    assert f.shape == (2 * (nx - 1) * (ny - 1), 3) and f.dtype == np.int32
    assert f.min() == 0 and f.max() == nx * ny - 1
    assert np.all((f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2]))
    # vertex j*nx+i is sample z[j, i]
    np.testing.assert_allclose(v[:, 2], dem.z.ravel())
    np.testing.assert_allclose(dem.height(v[:, 0], v[:, 1]), v[:, 2], atol=1e-9)
    # every triangle is non-degenerate and counter-clockwise from above (normal up)
    e1 = v[f[:, 1]] - v[f[:, 0]]
    e2 = v[f[:, 2]] - v[f[:, 0]]
    n = np.cross(e1, e2)
    assert np.all(n[:, 2] > 0)
    # the two triangles of a cell cover it exactly: projected area = cell area
    assert 0.5 * n[:, 2].sum() == pytest.approx((nx - 1) * (ny - 1) * dem.dx_m * dem.dy_m)
    # each interior edge is shared by exactly two triangles (a watertight sheet)
    edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert set(counts) <= {1, 2}
    assert (counts == 1).sum() == 2 * (nx - 1) + 2 * (ny - 1)


def test_with_error_statistics_and_determinism():
    dem = Dem(0.0, 0.0, 10.0, 10.0, np.zeros((200, 220)))
    assert dem.with_error(noise_m=0.0, bias_m=0.0, correlation_m=50.0, seed=1) is dem
    e1 = dem.with_error(noise_m=2.0, bias_m=-3.0, correlation_m=100.0, seed=4)
    e2 = dem.with_error(noise_m=2.0, bias_m=-3.0, correlation_m=100.0, seed=4)
    e3 = dem.with_error(noise_m=2.0, bias_m=-3.0, correlation_m=100.0, seed=5)
    np.testing.assert_array_equal(e1.z, e2.z)
    assert not np.array_equal(e1.z, e3.z)
    err = e1.z - dem.z
    assert err.std() == pytest.approx(2.0, rel=1e-6)
    assert err.mean() == pytest.approx(-3.0, abs=0.6)
    # correlated: neighbours agree far more than for white noise
    white = dem.with_error(noise_m=2.0, correlation_m=0.0, seed=4).z
    r_corr = np.corrcoef(err[:, :-1].ravel(), err[:, 1:].ravel())[0, 1]
    r_white = np.corrcoef(white[:, :-1].ravel(), white[:, 1:].ravel())[0, 1]
    assert r_corr > 0.9 and abs(r_white) < 0.05
    with pytest.raises(ValueError, match="^noise_m:"):
        dem.with_error(noise_m=-1.0)
    with pytest.raises(ValueError, match="^correlation_m:"):
        dem.with_error(noise_m=1.0, correlation_m=-1.0)


# -----------------------------------------------------------------------------
# Synthetic and real DEMs
# -----------------------------------------------------------------------------
def test_fractal_dem_deterministic_and_scaled():
    kw = dict(x_range_m=(-1000.0, 1500.0), y_range_m=(-800.0, 800.0), resolution_m=10.0, relief_m=120.0,
              roughness=0.6)
    a = fractal_dem(seed=3, **kw)
    b = fractal_dem(seed=3, **kw)
    c = fractal_dem(seed=4, **kw)
    assert a.z.tobytes() == b.z.tobytes()
    assert not np.array_equal(a.z, c.z)
    assert a.z_min == pytest.approx(0.0, abs=1e-9) and a.z_max == pytest.approx(120.0)
    assert a.covers((-1000.0, 1500.0), (-800.0, 800.0))
    assert a.dx_m == a.dy_m == 10.0
    flat = fractal_dem(seed=3, **{**kw, "relief_m": 0.0})
    assert flat.z_max == flat.z_min == 0.0


def test_fractal_roughness_controls_small_scale_relief():
    kw = dict(x_range_m=(0.0, 4000.0), y_range_m=(0.0, 4000.0), resolution_m=10.0, relief_m=100.0, seed=8)

    def small_scale(dem):
        return np.std(dem.z - ndimage.gaussian_filter(dem.z, 3.0))
    assert small_scale(fractal_dem(roughness=0.2, **kw)) > 2.0 * small_scale(fractal_dem(roughness=0.9, **kw))


@pytest.mark.parametrize("kwargs, name", [
    (dict(resolution_m=0.0), "resolution_m"), (dict(relief_m=-1.0), "relief_m"),
    (dict(roughness=0.0), "roughness"), (dict(roughness=1.5), "roughness"),
    (dict(x_range_m=(5.0, 1.0)), "x_range_m"),
])
def test_fractal_validation(kwargs, name):
    kw = dict(x_range_m=(0.0, 100.0), y_range_m=(0.0, 100.0), resolution_m=10.0, relief_m=10.0,
              roughness=0.5, seed=0)
    kw.update(kwargs)
    with pytest.raises(ValueError, match=f"^{name}:"):
        fractal_dem(**kw)


def test_matplotlib_sample_dem_loads():
    dem = matplotlib_sample_dem()
    assert dem.shape == (344, 403)
    mx, my = degrees_to_metres(36.59)
    assert dem.dx_m == pytest.approx(mx / 1200, rel=1e-3)   # 3 arc-seconds
    assert dem.dy_m == pytest.approx(my / 1200, rel=1e-3)
    assert 70 < dem.dx_m < 80 and 90 < dem.dy_m < 95
    assert dem.z_min == 236.0 and dem.z_max == 1076.0
    (xa, xb), (ya, yb) = dem.x_range, dem.y_range
    assert xa == pytest.approx(-xb) and ya == pytest.approx(-yb)
    # north is +y: the file's first row (north edge) is the last row here
    from matplotlib import cbook
    with cbook.get_sample_data("jacksboro_fault_dem.npz") as d:
        raw = d["elevation"]
    np.testing.assert_array_equal(dem.z[-1], raw[0])


def test_degrees_to_metres():
    mx, my = degrees_to_metres(0.0)
    assert mx == pytest.approx(111319.49, abs=0.1) and my == pytest.approx(110574.4, abs=1.0)
    mx, my = degrees_to_metres(60.0)
    assert mx == pytest.approx(55800.0, rel=2e-3)


def _write_geotiff(path, z, *, scale, tie, model_type, nodata=None):
    import tifffile
    geokeys = (1, 1, 0, 1, 1024, 0, 1, model_type)
    extratags = [(33550, "d", 3, (scale[0], scale[1], 0.0), False),
                 (33922, "d", 6, (0.0, 0.0, 0.0, tie[0], tie[1], 0.0), False),
                 (34735, "H", len(geokeys), geokeys, False)]
    if nodata is not None:
        extratags.append((42113, "s", 0, str(nodata), False))
    tifffile.imwrite(path, z, extratags=extratags)


def test_load_geotiff_projected(tmp_path):
    z = np.arange(12 * 9, dtype=np.float32).reshape(12, 9)
    z[3, 4] = -9999.0
    p = tmp_path / "dem.tif"
    _write_geotiff(p, z, scale=(30.0, 25.0), tie=(500000.0, 4100000.0), model_type=1, nodata=-9999)
    dem = load_geotiff_dem(p)
    assert (dem.dx_m, dem.dy_m) == (30.0, 25.0)
    assert dem.shape == (12, 9)
    assert dem.x_range == pytest.approx((-120.0, 120.0)) and dem.y_range == pytest.approx((-137.5, 137.5))
    np.testing.assert_array_equal(dem.z[-1], z[0])          # north up → flipped
    assert np.all(dem.z > -1000)                              # no-data filled
    assert dem.z[-4, 4] in (z[3, 3], z[3, 5], z[2, 4], z[4, 4])


def test_load_geotiff_geographic(tmp_path):
    z = np.random.default_rng(0).uniform(0, 100, (20, 30))
    p = tmp_path / "geo.tif"
    res = 1.0 / 3600.0
    _write_geotiff(p, z, scale=(res, res), tie=(2.0, 45.0 + 10 * res), model_type=2)
    dem = load_geotiff_dem(p)
    mx, my = degrees_to_metres(45.0)
    assert dem.dx_m == pytest.approx(res * mx, rel=1e-4)
    assert dem.dy_m == pytest.approx(res * my, rel=1e-4)


def test_load_geotiff_errors(tmp_path):
    with pytest.raises(ValueError, match="^path: file not found"):
        load_geotiff_dem(tmp_path / "nope.tif")
    bad = tmp_path / "bad.tif"
    bad.write_bytes(b"this is not a tiff")
    with pytest.raises(ValueError, match="^path: cannot read"):
        load_geotiff_dem(bad)
    import tifffile
    plain = tmp_path / "plain.tif"
    tifffile.imwrite(plain, np.zeros((4, 4), np.float32))
    with pytest.raises(ValueError, match="ModelPixelScaleTag"):
        load_geotiff_dem(plain)
    assert load_geotiff_dem(plain, pixel_size_m=2.0).dx_m == 2.0


def test_resample():
    dem = plane_dem(0.1, 0.05, 3.0, dx=10.0, dy=10.0, nx=31, ny=21)
    fine = resample(dem, 2.5)
    assert fine.dx_m == fine.dy_m == 2.5
    (xa, xb), (ya, yb) = fine.x_range, fine.y_range
    assert dem.x_range[0] <= xa and xb <= dem.x_range[1]
    assert dem.y_range[0] <= ya and yb <= dem.y_range[1]
    X, Y = np.meshgrid(fine.x, fine.y)
    np.testing.assert_allclose(fine.z, 3.0 + 0.1 * X + 0.05 * Y, atol=1e-9)   # bilinear is exact on planes
    coarse = resample(dem, 25.0)
    X, Y = np.meshgrid(coarse.x, coarse.y)
    np.testing.assert_allclose(coarse.z, 3.0 + 0.1 * X + 0.05 * Y, atol=1e-6)  # the prefilter keeps planes
    with pytest.raises(ValueError, match="^resolution_m:"):
        resample(dem, -1.0)


# -----------------------------------------------------------------------------
# Illumination
# -----------------------------------------------------------------------------
@pytest.mark.parametrize("elev, azim", [(30.0, 0.0), (55.0, 135.0), (70.0, -100.0)])
def test_irradiance_is_analytic_cosine_on_tilted_plane(elev, azim):
    a, b = 0.25, -0.15
    dem = plane_dem(a, b, 50.0, dx=10.0, dy=10.0, nx=30, ny=30)
    n = np.array([-a, -b, 1.0]) / math.sqrt(1 + a * a + b * b)
    s = sun_direction(elev, azim)
    expected = 0.15 + 0.85 * max(0.0, float(n @ s))
    irr = sun_irradiance(dem, elevation_deg=elev, azimuth_deg=azim, ambient=0.15)
    assert irr.shape == dem.shape
    np.testing.assert_allclose(irr, expected, atol=1e-12)


def test_sun_direction_convention():
    np.testing.assert_allclose(sun_direction(90.0, 17.0), [0, 0, 1], atol=1e-15)
    np.testing.assert_allclose(sun_direction(0.0, 90.0), [0, 1, 0], atol=1e-15)   # azimuth from +x toward +y
    np.testing.assert_allclose(Sun(elevation_deg=30.0, azimuth_deg=0.0).direction, [math.sqrt(3) / 2, 0, 0.5])


def test_shadow_behind_ridge():
    dx = 2.0
    x = np.arange(-400.0, 400.0 + dx, dx)
    h = 100.0
    z = np.maximum(0.0, h - np.abs(x))                  # ridge along y at x = 0, 45° flanks
    dem = Dem(x[0], -50.0, dx, dx, np.tile(z, (51, 1)))
    # sun toward +x at 30°: the -x flank and the ground up to h / tan(30°) behind the crest are dark
    lit = cast_shadows(dem, elevation_deg=30.0, azimuth_deg=0.0)
    dark_x = x[~lit[25]]
    assert dark_x.min() == pytest.approx(-h / math.tan(math.radians(30.0)), abs=dx)
    assert dark_x.max() < 0.0
    assert lit[25][x > 0].all() and lit[25][x < -175.0].all()
    assert (lit == lit[25]).all()                      # uniform along the ridge
    # the same ridge lit from -x, and a higher sun shortens the shadow
    lit_w = cast_shadows(dem, elevation_deg=30.0, azimuth_deg=180.0)
    np.testing.assert_array_equal(lit_w[25], lit[25][::-1])
    lit_hi = cast_shadows(dem, elevation_deg=40.0, azimuth_deg=0.0)
    assert x[~lit_hi[25]].min() == pytest.approx(-h / math.tan(math.radians(40.0)), abs=dx)
    # a sun higher than the 45° flank: no shadow at all
    assert cast_shadows(dem, elevation_deg=50.0, azimuth_deg=0.0).all()
    irr = sun_irradiance(dem, elevation_deg=30.0, azimuth_deg=0.0, ambient=0.2)
    assert np.all(irr[25][~lit[25]] == pytest.approx(0.2))
    flat_lit = irr[25][(x > 120.0)]
    np.testing.assert_allclose(flat_lit, 0.2 + 0.8 * 0.5, atol=1e-12)
    assert sun_irradiance(dem, elevation_deg=30.0, azimuth_deg=0.0, shadows=False)[25, 50] > 0.2


def test_sample_grid_matches_dem_bilinear():
    dem = plane_dem(0.3, -0.2, 12.0, dx=5.0, dy=5.0)
    field = np.asarray(dem.z)
    g = sample_grid(dem, field, x0_m=-90.0, y0_m=50.0, texel_m=1.3, nx=60, ny=40)
    assert g.shape == (40, 60) and g.dtype == np.float32
    x, y = texel_centres(-90.0, 50.0, 1.3, 60, 40)
    np.testing.assert_allclose(g, dem.height(x[None, :], y[:, None]), rtol=1e-5)
    irr = sun_irradiance(dem, elevation_deg=40.0, azimuth_deg=20.0)
    g2 = sample_grid(dem, irr, x0_m=-90.0, y0_m=50.0, texel_m=1.3, nx=60, ny=40)
    np.testing.assert_allclose(g2, irr[0, 0], rtol=1e-6)
    with pytest.raises(ValueError, match="^values:"):
        sample_grid(dem, field[:3], x0_m=0.0, y0_m=0.0, texel_m=1.0, nx=2, ny=2)


# -----------------------------------------------------------------------------
# Procedural texture
# -----------------------------------------------------------------------------
@pytest.fixture(scope="module")
def tex():
    return ProceduralTexture(seed=3, water_fraction=0.15, cloud_fraction=0.1, urban_fraction=0.1,
                             forest_fraction=0.25)


@pytest.fixture(scope="module")
def scene(tex):
    """A 4 km × 4 km window at 2 m (chosen to hold every class) and its classes."""
    args = (0.0, -4000.0, 2.0, 2000, 2000)
    return tex.grid_and_land_cover(*args)


def test_grid_shape_range_and_determinism(tex):
    g = tex.grid(100.0, -300.0, 1.0, 300, 200)
    assert g.shape == (5, 200, 300) and g.dtype == np.float32
    assert g.min() >= 0.0 and g.max() <= 1.0
    again = ProceduralTexture(seed=3, water_fraction=0.15, cloud_fraction=0.1, urban_fraction=0.1,
                              forest_fraction=0.25, workers=1).grid(100.0, -300.0, 1.0, 300, 200)
    assert g.tobytes() == again.tobytes()
    other = ProceduralTexture(seed=4, water_fraction=0.15, cloud_fraction=0.1, urban_fraction=0.1,
                              forest_fraction=0.25).grid(100.0, -300.0, 1.0, 300, 200)
    assert np.mean(np.abs(other - g)) > 0.01


@pytest.mark.parametrize("texel", [1.0, 1.25, 0.7])
def test_tiles_reproduce_the_block_exactly(tex, texel):
    x0, y0, nx, ny = -1234.0, 567.0, 611, 433
    big = tex.grid(x0, y0, texel, nx, ny)
    mosaic = np.empty_like(big)
    for j0, j1 in [(0, 97), (97, 300), (300, ny)]:
        for i0, i1 in [(0, 1), (1, 258), (258, 500), (500, nx)]:
            mosaic[:, j0:j1, i0:i1] = tex.grid(x0 + i0 * texel, y0 + j0 * texel, texel, i1 - i0, j1 - j0)
    np.testing.assert_array_equal(mosaic, big)


def test_land_cover_matches_grid_and_points(tex):
    x0, y0, t, nx, ny = -700.0, -300.0, 1.5, 240, 180
    cls = tex.land_cover_grid(x0, y0, t, nx, ny)
    refl, cls2 = tex.grid_and_land_cover(x0, y0, t, nx, ny)
    np.testing.assert_array_equal(cls2, cls)
    np.testing.assert_array_equal(refl, tex.grid(x0, y0, t, nx, ny))
    x, y = texel_centres(x0, y0, t, nx, ny)
    X, Y = np.meshgrid(x, y)
    np.testing.assert_array_equal(tex.land_cover(X, Y), cls)
    # scattered points give the same class as when they are computed inside a grid
    rng = np.random.default_rng(1)
    k = rng.integers(0, X.size, 500)
    np.testing.assert_array_equal(tex.land_cover(X.ravel()[k], Y.ravel()[k]), cls.ravel()[k])
    assert tex.land_cover(0.0, 0.0).shape == ()


def test_band_selection_and_pan(tex):
    g = tex.grid(0.0, 0.0, 1.0, 120, 80)
    sub = ProceduralTexture(seed=3, water_fraction=0.15, cloud_fraction=0.1, urban_fraction=0.1,
                            forest_fraction=0.25, bands=("nir", "pan", "red")).grid(0.0, 0.0, 1.0, 120, 80)
    np.testing.assert_array_equal(sub[0], g[3])
    np.testing.assert_array_equal(sub[2], g[2])
    pan = sum(w * g[k] for k, w in enumerate(PAN_WEIGHTS))
    np.testing.assert_allclose(g[4], pan, atol=1e-6)
    with pytest.raises(ValueError, match="^bands:"):
        ProceduralTexture(bands=("red", "swir"))


def test_every_class_present_and_fractions(scene):
    _, cls = scene
    frac = np.bincount(cls.ravel(), minlength=8) / cls.size
    for c in (LandCover.WATER, LandCover.CROPLAND, LandCover.FOREST, LandCover.ROAD, LandCover.BUILDING,
              LandCover.URBAN_OPEN, LandCover.CLOUD):
        assert frac[c] > 0.002, LandCover(c).name


def test_area_fractions_over_a_large_area():
    t = ProceduralTexture(seed=11, water_fraction=0.2, cloud_fraction=0.15, urban_fraction=0.1,
                          forest_fraction=0.3)
    rng = np.random.default_rng(2)
    x, y = rng.uniform(-60e3, 60e3, (2, 40000))
    cls = t.land_cover(x, y)
    frac = np.bincount(cls, minlength=8) / cls.size
    assert frac[LandCover.CLOUD] == pytest.approx(0.15, abs=0.06)
    ground = cls != LandCover.CLOUD
    f = np.bincount(cls[ground], minlength=8) / ground.sum()
    assert f[LandCover.WATER] == pytest.approx(0.2, abs=0.08)
    assert f[LandCover.FOREST] == pytest.approx(0.3, abs=0.1)
    urban = f[LandCover.BUILDING] + f[LandCover.URBAN_OPEN]
    assert 0.04 < urban < 0.16
    none = ProceduralTexture(seed=11, water_fraction=0.0, cloud_fraction=0.0, urban_fraction=0.0,
                             forest_fraction=0.0).land_cover(x[:5000], y[:5000])
    assert not np.isin(none, [LandCover.WATER, LandCover.CLOUD, LandCover.BUILDING, LandCover.FOREST]).any()


def _local_texture(img):
    """Standard deviation of the detail (image minus its 5×5 mean)."""
    return img - ndimage.uniform_filter(img, 5, mode="nearest")


def _interior(mask, r=4):
    return ndimage.binary_erosion(mask, iterations=r)


def test_water_and_clouds_are_texture_poor_land_is_rich(scene):
    g, cls = scene
    detail = _local_texture(g[4])          # pan
    std = {c: detail[_interior(cls == c)].std() for c in (LandCover.WATER, LandCover.CLOUD, LandCover.CROPLAND,
                                                            LandCover.FOREST, LandCover.URBAN_OPEN)}
    assert std[LandCover.WATER] < 0.002
    assert std[LandCover.CLOUD] < 0.004
    for c in (LandCover.CROPLAND, LandCover.FOREST, LandCover.URBAN_OPEN):
        assert std[c] > 5 * std[LandCover.WATER], LandCover(c).name
        assert std[c] > 0.004, LandCover(c).name
    # built-up areas: sharp roof edges and shadows give the strongest texture
    urban = _interior((cls == LandCover.BUILDING) | (cls == LandCover.URBAN_OPEN), 1)
    assert detail[urban].std() > 0.02
    # water is dark in every band and nearly uniform
    water = _interior(cls == LandCover.WATER)
    assert g[:4, water].mean(axis=1).max() < 0.09 and g[3, water].mean() < 0.03


def test_nir_contrast_over_vegetation_and_water(scene):
    g, cls = scene
    red, nir = g[2], g[3]
    forest = _interior(cls == LandCover.FOREST, 2)
    assert nir[forest].mean() > 3 * red[forest].mean()
    crops = cls == LandCover.CROPLAND
    assert np.median(nir[crops] / np.maximum(red[crops], 1e-3)) > 1.8
    water = _interior(cls == LandCover.WATER)
    assert nir[water].mean() < 0.6 * red[water].mean()
    # visible bands resemble each other more than they resemble NIR
    land = ~np.isin(cls, [LandCover.WATER, LandCover.CLOUD])
    b, gr, r, n = (g[k][land] for k in range(4))
    assert np.corrcoef(gr, r)[0, 1] > np.corrcoef(r, n)[0, 1] + 0.3


def test_roads_are_bright_thin_lines(tex):
    # a window at 0.5 m: roads outside towns are a few metres wide
    cls = tex.land_cover_grid(-2000.0, -2000.0, 0.5, 4000, 400)
    road = cls == LandCover.ROAD
    assert road.mean() > 0.005
    dist = ndimage.distance_transform_edt(road) * 0.5
    assert np.percentile(dist[road], 99) < 7.0          # half-width of the widest roads (m)


def test_building_shadows_fall_on_the_anti_sun_side():
    # sun toward +x: roofs shade the ground on their -x side
    t = ProceduralTexture(seed=5, urban_fraction=0.6, water_fraction=0.0, forest_fraction=0.0,
                          sun_elevation_deg=35.0, sun_azimuth_deg=0.0, bands=("red",))
    refl, cls = t.grid_and_land_cover(-500.0, -500.0, 0.5, 1200, 1200)
    red = refl[0]
    roof = cls == LandCover.BUILDING
    ground = (cls == LandCover.URBAN_OPEN) | (cls == LandCover.ROAD)
    west = ground & np.roll(roof, -2, axis=1)            # a roof 1 m to the east (sun side) of the texel
    east = ground & np.roll(roof, 2, axis=1)             # a roof 1 m to the west
    assert west.sum() > 500 and east.sum() > 500
    assert red[west].mean() < 0.6 * red[east].mean()


def test_texture_pickles_to_the_same_texture(tex):
    import pickle
    clone = pickle.loads(pickle.dumps(tex))
    np.testing.assert_array_equal(clone.grid(-50.0, 20.0, 1.0, 64, 48), tex.grid(-50.0, 20.0, 1.0, 64, 48))


def test_procedural_validation():
    with pytest.raises(ValueError, match="^water_fraction:"):
        ProceduralTexture(water_fraction=1.5)
    with pytest.raises(ValueError, match="^forest_fraction:"):
        ProceduralTexture(water_fraction=0.5, urban_fraction=0.3, forest_fraction=0.4)
    with pytest.raises(ValueError, match="^seed:"):
        ProceduralTexture(seed=1.5)
    t = ProceduralTexture()
    with pytest.raises(ValueError, match="^texel_m:"):
        t.grid(0.0, 0.0, 0.0, 10, 10)
    with pytest.raises(ValueError, match="^nx:"):
        t.grid(0.0, 0.0, 1.0, 0, 10)


# -----------------------------------------------------------------------------
# Orthoimage texture
# -----------------------------------------------------------------------------
def test_ortho_texture_png(tmp_path):
    import cv2
    rgb = np.zeros((40, 60, 3), np.uint8)
    rgb[..., 0] = np.arange(60, dtype=np.uint8)[None, :] * 4          # red ramps with the column
    rgb[..., 1] = np.arange(40, dtype=np.uint8)[:, None] * 6          # green ramps down the rows
    rgb[..., 2] = 200
    p = tmp_path / "ortho.png"
    cv2.imwrite(str(p), rgb[..., ::-1])                                # OpenCV writes BGR
    t = OrthoTexture(p, texel_m=2.0, bands={"red": 0, "green": 1, "blue": 2}, output_bands=("red", "green",
                                                                                             "blue", "pan"))
    assert t.shape == (40, 60)
    # pixel centres are reproduced exactly; north up: image row 0 is at the +y edge
    g = t.grid(-60.0, -40.0, 2.0, 60, 40)
    np.testing.assert_allclose(g[0], rgb[::-1, :, 0] / 255.0, atol=1e-6)
    np.testing.assert_allclose(g[1], rgb[::-1, :, 1] / 255.0, atol=1e-6)
    np.testing.assert_allclose(g[2], 200 / 255.0, atol=1e-6)
    w = np.array(PAN_WEIGHTS[:3]) / sum(PAN_WEIGHTS[:3])
    np.testing.assert_allclose(g[3], w[0] * g[2] + w[1] * g[1] + w[2] * g[0], atol=1e-6)   # b, g, r weights
    # bilinear between pixel centres: half way along a linear ramp
    h = t.grid(-59.0, -40.0, 2.0, 10, 1)
    np.testing.assert_allclose(h[0, 0], (np.arange(10) * 4 + 2) / 255.0, atol=1e-6)
    assert (t.land_cover([0.0, 1.0], [0.0, 1.0]) == LandCover.UNKNOWN).all()
    with pytest.raises(ValueError, match="^path: file not found"):
        OrthoTexture(tmp_path / "none.png", texel_m=1.0, bands={"red": 0})
    with pytest.raises(ValueError, match=r"^bands\.red:"):
        OrthoTexture(p, texel_m=1.0, bands={"red": 5})


# -----------------------------------------------------------------------------
# Scenario sections
# -----------------------------------------------------------------------------
RANGES = dict(x_range_m=(-1000.0, 1000.0), y_range_m=(-600.0, 600.0))


def test_dem_from_config_fractal(tmp_path):
    sec = Section({"kind": "fractal", "resolution_m": 20.0, "relief_m": 80.0, "roughness": 0.5}, "scene.dem")
    dem = dem_from_config(sec, base_dir=tmp_path, seed=9, **RANGES)
    ref = fractal_dem(resolution_m=20.0, relief_m=80.0, roughness=0.5, seed=9, **RANGES)
    np.testing.assert_array_equal(dem.z, ref.z)
    default = dem_from_config(Section({}, "scene.dem"), base_dir=tmp_path, seed=9, **RANGES)
    assert default.covers(*RANGES.values())


@pytest.mark.parametrize("data, message", [
    ({"resolution_m": -3}, "scene.dem.resolution_m: must be >= 0.1, got -3"),
    ({"relief_m": "high"}, "scene.dem.relief_m: must be a number"),
    ({"roughness": 2.0}, "scene.dem.roughness: must be <= 1, got 2"),
    ({"kind": "lidar"}, "scene.dem.kind: must be one of"),
    ({"kind": "fractal", "path": "x.tif"}, "scene.dem.path: unknown key"),
    ({"kind": "geotiff"}, "scene.dem.path: missing (required)"),
])
def test_dem_config_errors_name_the_key(tmp_path, data, message):
    with pytest.raises(ScenarioError) as err:
        dem_from_config(Section(data, "scene.dem"), base_dir=tmp_path, seed=0, **RANGES)
    assert str(err.value).startswith(message)
    assert "\n" not in str(err.value)


def test_dem_config_geotiff_paths(tmp_path):
    (tmp_path / "data").mkdir()
    z = np.random.default_rng(0).uniform(0, 50, (60, 90))
    _write_geotiff(tmp_path / "data" / "dem.tif", z, scale=(30.0, 30.0), tie=(0.0, 0.0), model_type=1)
    sec = Section({"kind": "geotiff", "path": "data/dem.tif", "resolution_m": 15.0}, "scene.dem")
    dem = dem_from_config(sec, base_dir=tmp_path, seed=0, **RANGES)
    assert dem.dx_m == 15.0 and dem.covers(*RANGES.values())
    with pytest.raises(ScenarioError) as err:
        dem_from_config(Section({"kind": "geotiff", "path": "data/missing.tif"}, "scene.dem"),
                        base_dir=tmp_path, seed=0, **RANGES)
    assert str(err.value) == f"scene.dem.path: file not found: {tmp_path / 'data' / 'missing.tif'}"
    with pytest.raises(ScenarioError, match=r"^scene\.dem\.path: DEM covers"):
        dem_from_config(Section({"kind": "geotiff", "path": "data/dem.tif"}, "scene.dem"), base_dir=tmp_path,
                        seed=0, x_range_m=(-5000.0, 5000.0), y_range_m=(-100.0, 100.0))


def test_dem_config_matplotlib_sample(tmp_path):
    dem = dem_from_config(Section({"kind": "matplotlib_sample"}, "scene.dem"), base_dir=tmp_path, seed=0,
                          **RANGES)
    assert dem.covers(*RANGES.values()) and dem.z_min > 200.0
    with pytest.raises(ScenarioError, match=r"^scene\.dem\.relief_m: unknown key"):
        dem_from_config(Section({"kind": "matplotlib_sample", "relief_m": 3.0}, "scene.dem"),
                        base_dir=tmp_path, seed=0, **RANGES)


def test_knowledge_dem_from_config():
    truth = Dem(0.0, 0.0, 10.0, 10.0, np.zeros((50, 50)))
    assert knowledge_dem_from_config(Section({}, "scene.dem_knowledge"), truth=truth, seed=1) is truth
    k = knowledge_dem_from_config(Section({"noise_m": 1.5, "bias_m": 2.0, "correlation_m": 30.0},
                                          "scene.dem_knowledge"), truth=truth, seed=1)
    assert (k.z - truth.z).std() == pytest.approx(1.5)
    with pytest.raises(ScenarioError, match=r"^scene\.dem_knowledge\.noise_m: must be >= 0"):
        knowledge_dem_from_config(Section({"noise_m": -1}, "scene.dem_knowledge"), truth=truth, seed=1)
    with pytest.raises(ScenarioError, match=r"^scene\.dem_knowledge\.sigma: unknown key"):
        knowledge_dem_from_config(Section({"sigma": 1}, "scene.dem_knowledge"), truth=truth, seed=1)


def test_sun_from_config():
    sun = sun_from_config(Section({"elevation_deg": 35, "azimuth_deg": -20.0, "ambient": 0.1}, "scene.sun"))
    assert (sun.elevation_deg, sun.azimuth_deg, sun.ambient, sun.cast_shadows) == (35.0, -20.0, 0.1, True)
    assert sun_from_config(Section({}, "scene.sun")) == Sun()
    with pytest.raises(ScenarioError, match=r"^scene\.sun\.elevation_deg: must be >= 1, got 0"):
        sun_from_config(Section({"elevation_deg": 0}, "scene.sun"))
    with pytest.raises(ScenarioError, match=r"^scene\.sun\.ambient: must be <= 1"):
        sun_from_config(Section({"ambient": 1.5}, "scene.sun"))
    with pytest.raises(ScenarioError, match=r"^scene\.sun\.zenith_deg: unknown key"):
        sun_from_config(Section({"zenith_deg": 10}, "scene.sun"))


def test_texture_from_config(tmp_path):
    sun = Sun(elevation_deg=40.0, azimuth_deg=10.0)
    t = texture_from_config(Section({"water_fraction": 0.2, "cloud_fraction": 0.05, "texel_m": 1.25,
                                     "bands": ["red", "nir"]}, "scene.texture"), base_dir=tmp_path, seed=7,
                            sun=sun)
    assert isinstance(t, ProceduralTexture)
    assert t.bands == ("red", "nir") and t.texel_m == 1.25 and t.water_fraction == 0.2
    assert t.sun_azimuth_deg == 10.0 and t.seed == 7
    assert texture_from_config(Section({}, "scene.texture"), base_dir=tmp_path, seed=0).bands == BAND_NAMES
    for data, message in [
        ({"water_fraction": 1.5}, "scene.texture.water_fraction: must be <= 1, got 1.5"),
        ({"water_fraction": 0.6, "urban_fraction": 0.3, "forest_fraction": 0.3},
         "scene.texture.forest_fraction: water_fraction + urban_fraction + forest_fraction must be <= 1"),
        ({"bands": ["red", "swir"]}, "scene.texture.bands[1]: must be one of"),
        ({"texel_m": 0}, "scene.texture.texel_m: must be >= 0.01, got 0"),
        ({"kind": "orthoimage", "channels": {"red": 0}}, "scene.texture.path: missing (required)"),
        ({"kind": "orthoimage", "path": "o.png", "channels": {"red": 0}},
         f"scene.texture.path: file not found: {tmp_path / 'o.png'}"),
        ({"path": "o.png"}, "scene.texture.path: unknown key"),
    ]:
        with pytest.raises(ScenarioError) as err:
            texture_from_config(Section(data, "scene.texture"), base_dir=tmp_path, seed=0)
        assert str(err.value).startswith(message), (data, str(err.value))


def test_texture_from_config_orthoimage(tmp_path):
    import tifffile
    img = np.random.default_rng(0).integers(0, 10000, (30, 40, 4)).astype(np.uint16)
    tifffile.imwrite(tmp_path / "o.tif", img)
    sec = Section({"kind": "orthoimage", "path": "o.tif", "texel_m": 0.5, "scale": 1e-4,
                   "channels": {"blue": 0, "green": 1, "red": 2, "nir": 3}}, "scene.texture")
    t = texture_from_config(sec, base_dir=tmp_path, seed=0)
    assert isinstance(t, OrthoTexture) and t.bands == ("blue", "green", "red", "nir")
    g = t.grid(-10.0, -7.5, 0.5, 40, 30)
    np.testing.assert_allclose(g[3], img[::-1, :, 3] * 1e-4, rtol=1e-5, atol=1e-7)
    bad = Section({"kind": "orthoimage", "path": "o.tif", "channels": {"red": 7}}, "scene.texture")
    with pytest.raises(ScenarioError, match=r"^scene\.texture\.channels\.red: must be a channel index"):
        texture_from_config(bad, base_dir=tmp_path, seed=0)
    bad = Section({"kind": "orthoimage", "path": "o.tif", "channels": {"swir": 1}}, "scene.texture")
    with pytest.raises(ScenarioError, match=r"^scene\.texture\.channels\.swir: unknown band"):
        texture_from_config(bad, base_dir=tmp_path, seed=0)


def test_terrain_shading_lights_the_ground_not_the_clouds():
    tex = ProceduralTexture(seed=3, cloud_fraction=0.5, texel_m=2.0)
    nx, ny = 400, 300
    rng = np.random.default_rng(0)
    irr_a = rng.uniform(0.2, 1.0, (ny, nx))
    irr_b = rng.uniform(0.2, 1.0, (ny, nx))
    # a window across a cloud edge, found on a coarse land-cover map
    coarse = tex.land_cover_grid(-15000.0, -15000.0, 50.0, 600, 600) == LandCover.CLOUD
    frac = ndimage.uniform_filter(coarse.astype(float), size=(12, 16))
    j, i = np.unravel_index(np.argmin(np.abs(frac - 0.5)), frac.shape)
    x0, y0 = -15000.0 + i * 50.0 - nx, -15000.0 + j * 50.0 - ny
    plain = tex.grid(x0, y0, 2.0, nx, ny)
    a = tex.grid(x0, y0, 2.0, nx, ny, ground_irradiance=irr_a, cloud_irradiance=0.8)
    b = tex.grid(x0, y0, 2.0, nx, ny, ground_irradiance=irr_b, cloud_irradiance=0.8)
    cls = tex.land_cover_grid(x0, y0, 2.0, nx, ny)
    cloud = cls == LandCover.CLOUD
    assert 0.2 < cloud.mean() < 0.8
    # cloud interiors (full opacity): the same whatever the ground's shading
    inner = ndimage.binary_erosion(cloud, iterations=15)
    assert inner.sum() > 500
    same = np.isclose(a[:, inner], b[:, inner], rtol=1e-5, atol=1e-6).all(axis=0)
    assert same.mean() > 0.95
    # and lit by the cloud-top irradiance
    np.testing.assert_allclose(a[:, inner][:, same], 0.8 * plain[:, inner][:, same], rtol=1e-5, atol=1e-6)
    # clear ground far from clouds: reflectance × its own irradiance
    clear = ndimage.binary_erosion(~cloud, iterations=40)
    assert clear.sum() > 500
    np.testing.assert_allclose(a[:, clear], plain[:, clear] * irr_a[clear], rtol=1e-4, atol=1e-6)
    with pytest.raises(ValueError, match="ground_irradiance"):
        tex.grid(0.0, 0.0, 2.0, nx, ny, ground_irradiance=irr_a[:10])


@pytest.mark.parametrize("kind,fractions,code", [
    ("cloud", dict(cloud_fraction=0.35, water_fraction=0.0), "CLOUD"),
    ("water", dict(water_fraction=0.25), "WATER"),
])
def test_cover_fractions_are_realised_in_the_imaged_footprint(kind, fractions, code):
    """A requested 35 % cloud / 25 % water lands in the footprint (± 5 points), seed after seed."""
    from simsat.terrain.texture import LandCover, ProceduralTexture

    (x0, x1), (y0, y1) = extent = ((-5695.0, 5695.0), (-1119.0, 1119.0))   # phr_cmg's footprint
    want = fractions[f"{kind}_fraction"]
    for seed in range(5):
        tx = ProceduralTexture(seed=seed, calibration_extent_m=extent, workers=1, **fractions)
        cls = tx.land_cover_grid(x0, y0, 40.0, int((x1 - x0) / 40), int((y1 - y0) / 40))
        assert np.mean(cls == getattr(LandCover, code)) == pytest.approx(want, abs=0.05), seed
