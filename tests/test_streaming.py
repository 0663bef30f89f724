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
