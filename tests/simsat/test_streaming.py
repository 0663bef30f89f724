"""Block-wise processing gives the whole-image results (memory bounded by the block)."""
from __future__ import annotations

import numpy as np
from scipy.ndimage import map_coordinates

from restore.correction import SPLINE_MARGIN_LINES, correct_band_block


def test_block_resampling_equals_whole_image_splines():
    rng = np.random.default_rng(5)
    img = rng.normal(500, 50, (700, 90)).astype(np.float32)
    L, C = np.meshgrid(np.arange(700.0), np.arange(90.0), indexing="ij")
    rl = L + 2.5 * np.sin(L / 37.0) + 0.3          # a jittered line coordinate, as a restored attitude makes
    rc = C - 1.7 * np.cos(L / 23.0)
    whole = map_coordinates(img.astype(np.float64), [rl, rc], order=3, mode="nearest", prefilter=True).astype(np.float32)
    inside = (rl >= 0) & (rl <= 699) & (rc >= 0) & (rc <= 89)
    whole[~inside] = np.nan
    blocks = np.vstack([correct_band_block(img, rl[a:a + 64], rc[a:a + 64]) for a in range(0, 700, 64)])
    assert SPLINE_MARGIN_LINES >= 12
    np.testing.assert_allclose(blocks, whole, rtol=0, atol=1e-3)  # float32 rounding of ~500 DN
    assert np.array_equal(np.isnan(blocks), np.isnan(whole))


def test_compiled_spline_sampling_equals_scipy_map_coordinates_edges_included():
    from restore._spline_kernel import cubic_spline_resample

    rng = np.random.default_rng(6)
    img = rng.normal(500, 50, (60, 45))
    L, C = np.meshgrid(np.linspace(-3.0, 62.5, 70), np.linspace(-2.2, 47.9, 51), indexing="ij")
    ref = map_coordinates(img, [L, C], order=3, mode="nearest", prefilter=True)
    np.testing.assert_allclose(cubic_spline_resample(img, L, C), ref, rtol=0, atol=1e-9)


def test_probe_window_gain_is_the_formula_averaged_over_the_hann_kernel():
    """A flat prior gives the point formula back; a line narrower than a bin is spread over the main lobe."""
    from reports.report_data import frozen_chain_gain, probe_window_gain

    te, n, taus = 4e-4, 4000, [7.4e-3]
    f = np.linspace(5.0, 120.0, 47)
    flat = {"freq": np.array([0.0, 1250.0]), "psd": np.array([1e-12, 1e-12]), "noise_std": np.array([1e-7])}
    np.testing.assert_allclose(probe_window_gain(f, taus, flat, te, n), frozen_chain_gain(f, taus, flat, te), atol=2e-3)
    line = {"freq": np.array([0.0, 59.9, 60.0, 60.1, 1250.0]), "psd": np.array([0, 0, 1e-9, 0, 0]),
            "noise_std": np.array([1e-7])}
    g = probe_window_gain(np.array([60.0, 61.0, 70.0]), taus, line, te, n)
    assert 0 < g[0] < 0.5 and g[1] > 0 and g[2] < 1e-6  # spread over ± one 2.4 Hz bin, nothing 10 Hz away


def test_product_does_not_depend_on_block_lines_and_lazy_blocks_equal_full_read(tmp_path):
    """Rendering by blocks of 128 or 50 lines writes the same images; a block read equals the full read's rows.

    The renderer's float32 arithmetic depends slightly on the batch of rays (Dr.Jit), so a radiance on
    a DN boundary may round the other way: at most 1 DN, on a handful of pixels (3 of 19 200 on tiny).
    """
    import xarray as xr

    from simsat.product import read_product
    from simsat.scenario import load_scenario
    from simsat.simulate import simulate

    runs = {}
    for bl in (128, 50):
        sc = load_scenario("tiny", overrides={"acquisition": {"lines": 150, "block_lines": bl}})
        simulate(sc, tmp_path / f"b{bl}", progress=False)
        runs[bl] = xr.load_dataset(tmp_path / f"b{bl}" / "product.nc")
    for name in ("B0", "B3"):
        a, b = runs[128][f"image_{name}"].values, runs[50][f"image_{name}"].values
        assert a.shape[0] == 150 and a.std() > 0
        diff = np.abs(a.astype(np.int64) - b.astype(np.int64))
        assert diff.max() <= 1 and np.count_nonzero(diff) <= 1e-3 * diff.size
    p = read_product(tmp_path / "b50")
    full = p.image("B1")
    block = p.image("B1", lines=slice(37, 91))
    assert block.shape == (54, full.shape[1]) and block.dtype == np.float32
    np.testing.assert_array_equal(block, full[37:91])


def test_inverse_location_of_a_nan_ground_point_is_nan_not_an_error(tmp_path):
    """A point direct location could not place (NaN) stays NaN; the others are located as alone."""
    from simsat.product import read_product
    from simsat.scenario import load_scenario
    from simsat.simulate import simulate

    simulate(load_scenario("tiny", overrides={"acquisition": {"lines": 150}}), tmp_path / "r", progress=False)
    sm = read_product(tmp_path / "r").sensor_model()
    g = sm.direct_location("B0", np.array([40.0, 75.0]), np.array([30.0, 60.0]))
    alone_l, alone_c = sm.inverse_location("B0", g)
    gg = np.vstack([g, np.full((1, 3), np.nan)])
    ll, cc = sm.inverse_location("B0", gg)
    np.testing.assert_allclose(alone_l, [40.0, 75.0], atol=1e-3)
    np.testing.assert_array_equal(ll[:2], alone_l)
    np.testing.assert_array_equal(cc[:2], alone_c)
    assert np.isnan(ll[2]) and np.isnan(cc[2])


def test_matching_in_blocks_equals_whole_image_matching():
    """Same matches from blocks of lines (each with the matcher's margin) as from the whole images."""
    from scipy import ndimage

    from restore.matching import match_points, match_points_in_blocks

    rng = np.random.default_rng(8)
    a = ndimage.gaussian_filter(rng.normal(0, 1, (900, 120)), 1.5).astype(np.float32) * 300 + 1000
    shift_l, shift_c = 0.37, -0.61            # B is A translated by a known sub-pixel shift
    b = ndimage.shift(a.astype(np.float64), (shift_l, shift_c), order=3, mode="nearest").astype(np.float32)
    la = rng.uniform(5, 895, 3000).round()
    ca = rng.uniform(20, 100, 3000).round()
    kw = dict(window=(3, 31), search=(3, 3), method="ncc", min_quality=0.5)
    whole = match_points(a, b, la, ca, la + 0.2, ca - 0.2, **kw)
    blocks = match_points_in_blocks(lambda s: a[s], lambda s: b[s], (900, 900), la, ca, la + 0.2, ca - 0.2,
                                    block_lines=128, **kw)
    np.testing.assert_array_equal(blocks.valid, whole.valid)
    np.testing.assert_array_equal(blocks.flags, whole.flags)
    np.testing.assert_allclose(blocks.line_b, whole.line_b, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(blocks.col_b, whole.col_b)
    ok = whole.valid
    assert ok.mean() > 0.8
    assert abs(np.median(whole.line_b[ok] - la[ok]) - shift_l) < 0.02  # the known shift is found
    assert abs(np.median(whole.col_b[ok] - ca[ok]) - shift_c) < 0.02


def test_node_grid_resampling_equals_full_grid_resampling():
    """Coordinates given at grid columns and interpolated inside the sampler = interpolated first, then sampled."""
    from restore.correction import _interpolate_columns, correct_band_block, correct_band_block_nodes

    rng = np.random.default_rng(7)
    img = rng.normal(500, 50, (300, 97)).astype(np.float32)
    cols = np.unique(np.r_[np.arange(0, 97, 16), 96]).astype(np.float64)
    L = np.arange(100, 164, dtype=np.float64)[:, None]
    rl = L + 1.7 * np.sin(cols / 30.0)[None, :] + 0.3 * rng.standard_normal((64, cols.size))
    rc = cols[None, :] + 0.8 * np.cos(L / 9.0) - 1.2  # some columns fall outside the band: NaN
    rl[5, 3] = np.nan
    full = correct_band_block(img, *_interpolate_columns(rl, rc, cols, 97))
    nodes = correct_band_block_nodes(lambda s: img[s], rl, rc, cols, pixels=97, n_lines=300)
    assert np.array_equal(np.isnan(full), np.isnan(nodes)) and np.isnan(nodes).any()
    np.testing.assert_allclose(nodes, full, rtol=0, atol=1e-3)  # float32 DN ~500: rounding only
