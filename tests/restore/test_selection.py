"""Characteristic-point selection: texture criterion and the patent's three methods."""
import numpy as np
import pytest

from reports.synthetic import textured_image
from restore.matching import support_margin
from restore.selection import (NoiseLevel, double_gradient_points, estimate_image_noise, expected_matching_std,
                               gradient_energy, grid_points, noise_level_function, select_points,
                               spread_quality_subset, texture_mask)

NOISE = 0.5
L, C = 160, 640
WATER = (slice(None), slice(250, 360))      # dark, flat
CLOUD = (slice(40, 110), slice(450, 560))   # bright, saturated


@pytest.fixture(scope="module")
def scene():
    """Textured ground (std 10 around 100) with a water band and a saturated cloud."""
    rng = np.random.default_rng(0)
    img = 100.0 + 10.0 * textured_image((L, C), rng=rng)
    img[WATER] = 20.0
    img[CLOUD] = 4095.0
    img += NOISE * rng.standard_normal(img.shape)
    img[CLOUD] = np.minimum(img[CLOUD], 4095.0)
    return img


def test_estimate_noise_on_white_noise():
    rng = np.random.default_rng(1)
    img = 3.0 * rng.standard_normal((400, 400)) + np.linspace(0, 50, 400)[None, :]  # a plane is ignored
    assert estimate_image_noise(img) == pytest.approx(3.0, rel=0.05)


def test_expected_std_matches_delon_rouge_on_a_sinusoid():
    # one full period per 31-column window: sum of cos^2 over it is exactly 31 / 2
    amp, w = 5.0, 31
    omega = 2 * np.pi / w
    img = amp * np.sin(omega * np.arange(200))[None, :] * np.ones((20, 1))
    gain = (8 * np.sin(omega) - np.sin(2 * omega)) / 6  # response of the 5-point gradient
    e_l, e_c = gradient_energy(img, window=(3, w))
    assert np.allclose(e_c[5:-5, 40:-40], 3 * (w / 2) * (amp * gain) ** 2, rtol=1e-9)
    assert np.allclose(e_l[5:-5], 0.0, atol=1e-12)
    std_l, std_c = expected_matching_std(img, window=(3, w), noise_std=0.1)
    e_noise = 3 * w * (130 / 144) * 0.1**2  # the noise part of the gradient energy
    assert np.allclose(std_c[5:-5, 40:-40], np.sqrt(2) * 0.1 / np.sqrt(3 * (w / 2) * (amp * gain) ** 2 - e_noise))
    assert np.all(np.isinf(std_l[5:-5, 40:-40]))  # no texture along the lines: unmatchable
    # pure noise: nothing left once the noise energy is removed, almost everywhere
    noise = 0.1 * np.random.default_rng(5).standard_normal((200, 300))
    std_l, std_c = expected_matching_std(noise, noise_std=0.1)
    assert np.mean(np.maximum(std_l, std_c) < 0.2) < 0.01


def test_texture_mask_rejects_water_cloud_and_no_data(scene):
    img = scene.copy()
    img[130:140, 20:60] = np.nan
    ok = texture_mask(img, window=(3, 31), noise_std=NOISE, max_std=0.05, saturation=4095.0)
    assert ok[10:30, 20:230].mean() > 0.95            # textured ground
    assert not ok[:, 266:344].any()                    # windows fully inside the water
    assert not ok[40 - 1:110 + 1, 450 - 15:560 + 15].any()  # windows touching the cloud
    assert not ok[130 - 1:140 + 1, 20 - 15:60 + 15].any()   # windows touching no data
    # bright and smooth without saturation: the relative contrast criterion
    ll, cc = np.mgrid[0:40, 0:100]
    smooth = 3000.0 + 5.0 * np.sin(0.7 * ll) * np.sin(0.5 * cc)
    smooth += 0.5 * np.random.default_rng(2).standard_normal((40, 100))
    assert texture_mask(smooth, noise_std=0.5, max_std=10.0).mean() > 0.5
    assert not texture_mask(smooth, noise_std=0.5, max_std=10.0, min_contrast=0.01).any()
    assert not texture_mask(smooth, noise_std=0.5, max_std=10.0, max_level=2000.0).any()


def test_texture_mask_bad_parameters(scene):
    with pytest.raises(ValueError, match="max_std"):
        texture_mask(scene, max_std=0.0)
    with pytest.raises(ValueError, match="window"):
        texture_mask(scene, window=(2, 31))
    with pytest.raises(ValueError, match="min_contrast"):
        texture_mask(scene, min_contrast=-1.0)


def test_double_gradient_keeps_spots_and_rejects_ridges():
    rng = np.random.default_rng(3)
    img = 0.2 * rng.standard_normal((60, 200))
    spots = [(10, 30), (25, 100), (40, 170)]
    for l, c in spots:
        img[l, c] += 20.0
    img[:, 60] += 20.0   # a straight ridge along the lines
    img[50, :] += 20.0   # and one along the columns
    li, ci, score = double_gradient_points(img, noise_std=0.2, n_sigma=5.0, min_distance=4)
    found = set(zip(li.astype(int), ci.astype(int)))
    assert set(spots) <= found
    # nothing on the straight ridges: every point is near a spot or the crossing
    near = np.zeros(li.size, dtype=bool)
    for l, c in spots + [(50, 60)]:
        near |= (np.abs(li - l) <= 6) & (np.abs(ci - c) <= 6)
    assert near.all()
    assert np.all(score > 0)
    # without smoothing, the threshold in noise units still holds
    li0, ci0, score0 = double_gradient_points(img, noise_std=0.2, n_sigma=5.0, sigma=0.0, min_distance=4)
    assert set(spots) <= set(zip(li0.astype(int), ci0.astype(int)))
    assert np.all(score0 >= 5.0 * np.sqrt(6) * 0.2)
    with pytest.raises(ValueError, match="min_distance"):
        double_gradient_points(img, min_distance=-1)


def test_grid_points():
    li, ci = grid_points((100, 200), step_lines=10, step_columns=50, margin=(5, 20))
    assert np.array_equal(np.unique(li), np.arange(5, 95, 10))
    assert np.array_equal(np.unique(ci), np.array([20, 70, 120, 170]))
    assert li.size == 9 * 4
    with pytest.raises(ValueError, match="step_columns"):
        grid_points((100, 200), step_columns=0)
    with pytest.raises(ValueError, match="margin"):
        grid_points((100, 200), margin=(-1, 0))


def test_spread_quality_subset_is_best_per_bin_and_line():
    rng = np.random.default_rng(4)
    n = 3000
    li = rng.integers(0, 30, n).astype(float)
    co = rng.uniform(0, 500, n)
    q = rng.uniform(0, 1, n)
    q[:50] = np.nan
    keep = spread_quality_subset(li, co, q, per_line=10, column_range=(0, 500))
    # brute force reference
    ref = set()
    for line in range(30):
        for b in range(10):
            sel = np.flatnonzero((li == line) & (co >= 50 * b) & (co < 50 * (b + 1)) & np.isfinite(q))
            if sel.size:
                ref.add(sel[np.argmax(q[sel])])
    assert set(keep.tolist()) == ref
    assert np.all(np.diff(li[keep]) >= 0)
    assert np.bincount(li[keep].astype(int)).max() <= 10
    with pytest.raises(ValueError, match="per_line"):
        spread_quality_subset(li, co, q, per_line=0)
    assert spread_quality_subset(li, co, q, per_line=5, min_quality=2.0).size == 0


@pytest.mark.parametrize("method", ["grid", "double_gradient", "spread"])
def test_select_points(scene, method):
    window, search = (3, 31), (2, 2)
    mask = np.zeros(scene.shape, dtype=bool)
    mask[120:130, 50:120] = True  # e.g. a cloud known beforehand
    li, ci = select_points(scene, method=method, per_line=20, window=window, search=search, mask=mask,
                           noise_std=NOISE, saturation=4095.0)
    assert li.dtype == float and li.shape == ci.shape
    assert np.array_equal(li, np.rint(li)) and np.array_equal(ci, np.rint(ci))
    assert np.all(np.diff(li) >= 0)
    ml, mc = support_margin(window=window, search=search)
    assert li.min() >= ml and li.max() <= L - 1 - ml
    assert ci.min() >= mc and ci.max() <= C - 1 - mc
    # no window touches the mask, the cloud or the inside of the water band
    hl, hc = window[0] // 2, window[1] // 2
    touches = lambda r0, r1, c0, c1: (li + hl >= r0) & (li - hl < r1) & (ci + hc >= c0) & (ci - hc < c1)
    assert not np.any(touches(120, 130, 50, 120))
    assert not np.any(touches(40, 110, 450, 560))
    assert not np.any((ci - hc >= 250) & (ci + hc < 360))
    # about 20 points per line where the texture allows (the water band and the
    # cloud take away 2 to 6 of the 20 column bins)
    clear = (li >= 10) & (li < 38)
    per_line = np.bincount(li[clear].astype(int))[10:38]
    assert np.median(per_line) >= 14
    assert per_line.max() <= 20


def test_select_points_line_mask_and_step(scene):
    line_mask = np.zeros(L, dtype=bool)
    line_mask[20:60] = True
    li, ci = select_points(scene, per_line=10, line_mask=line_mask, line_step=5, noise_std=NOISE,
                           saturation=4095.0, margin=(7, 21))
    assert set(np.unique(li).astype(int)) <= set(range(20, 60))
    assert np.all((li - 7) % 5 == 0)


@pytest.mark.parametrize("kw, name", [({"method": "random"}, "method"), ({"per_line": 0}, "per_line"),
                                      ({"line_step": 0}, "line_step"), ({"mask": np.zeros((3, 3), bool)}, "mask"),
                                      ({"line_mask": np.zeros(3, bool)}, "line_mask"),
                                      ({"margin": (-1, 0)}, "margin")])
def test_select_points_bad_parameters(scene, kw, name):
    with pytest.raises(ValueError, match=name):
        select_points(scene, **kw)


def test_noise_estimate_in_blocks_is_the_exact_median():
    from scipy import ndimage

    from restore.selection import _IMMERKAER, estimate_image_noise

    rng = np.random.default_rng(3)
    for shape in [(3, 3), (5, 4), (1300, 41)]:
        img = np.round(rng.normal(100, 5, shape) * (1 + rng.random(shape)))  # many ties
        resp = np.abs(ndimage.correlate(img.astype(float), _IMMERKAER, mode="nearest")[1:-1, 1:-1])
        assert estimate_image_noise(img) == float(np.median(resp) / (0.6745 * 6.0))


def test_noise_estimate_of_a_large_image_is_the_median_of_evenly_spaced_blocks():
    from scipy import ndimage

    from restore.selection import _IMMERKAER, estimate_image_noise

    rng = np.random.default_rng(5)
    img = rng.normal(100.0, 4.0, (5000, 60))  # 300 000 pixels, white noise σ = 4
    full = estimate_image_noise(img)
    sampled = estimate_image_noise(img, max_pixels=60_000)  # 2 blocks of 512 lines
    # exactly the median over the two blocks it reads (the first and the last)
    resp = []
    for a in (1, 1 + 512 * 9):
        b = min(4999, a + 512)
        resp.append(np.abs(ndimage.correlate(img[a - 1:b + 1], _IMMERKAER, mode="nearest")[1:-1, 1:-1]).ravel())
    assert sampled == float(np.median(np.concatenate(resp)) / (0.6745 * 6.0))
    assert sampled == pytest.approx(4.0, rel=0.02) and full == pytest.approx(4.0, rel=0.01)
    with pytest.raises(ValueError, match="max_pixels"):
        estimate_image_noise(img, max_pixels=0)


@pytest.mark.parametrize("method", ["grid", "double_gradient"])
def test_selection_in_blocks_equals_the_whole_image(method):
    from restore.selection import select_points, select_points_in_blocks

    rng = np.random.default_rng(4)
    from scipy import ndimage
    img = ndimage.gaussian_filter(rng.normal(0, 1, (1400, 200)), 2.0) * 200 + 1000 + rng.normal(0, 2, (1400, 200))
    img[600:700, 50:120] = 1000.0  # a flat patch (no texture) across a block edge
    lm = np.ones(1400, bool)
    lm[:20] = False
    kw = dict(method=method, per_line=12, window=(3, 31), search=(3, 3), line_mask=lm, max_std=0.4)
    a = select_points(img, **kw)
    b = select_points_in_blocks(img, block_lines=256, **kw)
    assert a[0].size > 1000
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])


# --------------------------------------------------------------------------- signal-dependent noise
def _poisson_gaussian_image(read_var, gain, *, shape=(600, 600), seed=3):
    """A smooth ramp of levels 5-800 (no texture Immerkaer sees) with noise of variance read_var + gain × level."""
    rng = np.random.default_rng(seed)
    level = np.linspace(5.0, 800.0, shape[1])[None, :] * np.ones((shape[0], 1))
    return level + np.sqrt(read_var + gain * level) * rng.standard_normal(shape), level


def test_noise_level_function_recovers_read_and_shot_noise():
    img, _ = _poisson_gaussian_image(7.5, 0.068)
    nl = noise_level_function(img)
    assert nl.read_var == pytest.approx(7.5, rel=0.1)
    assert nl.shot_gain == pytest.approx(0.068, rel=0.05)
    # a constant noise is found constant
    img = 50.0 + 3.0 * np.random.default_rng(4).standard_normal((400, 400)) + np.linspace(0, 50, 400)[None, :]
    nl = noise_level_function(img)
    assert nl.std(10.0) == pytest.approx(3.0, rel=0.05) and nl.std(100.0) == pytest.approx(3.0, rel=0.05)


def test_noise_level_of_the_detector_calibration_matches_the_rendered_noise():
    """σ²(DN) = (read · g)² + g · DN + 1/12 (g = DN per electron): the noise simsat's radiometry draws."""
    from simsat.instrument import Radiometry
    from simsat.simulate import apply_radiometry

    r = Radiometry(full_well_e=60000.0, signal_fraction=0.6, read_noise_e=40.0, bits=12)
    nl = NoiseLevel.from_radiometry(r)
    g = r.gain_dn_per_e
    assert nl.read_var == pytest.approx((40.0 * g) ** 2 + 1 / 12)
    assert nl.shot_gain == pytest.approx(g)
    for radiance in (0.005, 0.02, 0.3):   # (lower, the clip at 0 DN trims the noise)
        dn = apply_radiometry(np.full((200, 400), radiance), r, seed=1, band_index=0).astype(float)
        assert dn.std() == pytest.approx(float(nl.std(dn.mean())), rel=0.03)
    assert NoiseLevel.from_radiometry(Radiometry(enabled=False)).std(1000.0) == pytest.approx(np.sqrt(1 / 12))


def test_texture_criterion_takes_each_window_at_its_own_noise():
    """A dim textured patch (a cloud's shadow) beside bright ground: one σ for the band, read at the band's
    median level, overstates the shadow's noise and rejects its windows; the level function keeps them,
    and on bright ground it rejects what its real noise makes unmatchable."""
    rng = np.random.default_rng(6)
    nl = NoiseLevel(read_var=7.5, shot_gain=0.068)
    tex = textured_image((200, 600), rng=rng)
    level = np.where(np.arange(600)[None, :] < 300, 15.0, 400.0) * np.ones((200, 1))
    clean = level * (1.0 + 0.2 * tex)
    img = clean + nl.std(clean) * rng.standard_normal(clean.shape)
    constant = estimate_image_noise(img)
    assert nl.std(15.0) < constant < nl.std(400.0)
    dark, bright = (slice(20, 180), slice(40, 260)), (slice(20, 180), slice(340, 560))
    # expected σ with the level function is the constant-noise formula at the window's own σ (exactly where
    # the level is flat)
    flat = np.full((100, 200), 15.0) + 0.9 * np.sin(np.arange(200) * 2 * np.pi / 31)[None, :]
    _, sc = expected_matching_std(flat, window=(3, 31), noise_std=nl)
    _, sc0 = expected_matching_std(flat, window=(3, 31), noise_std=float(nl.std(15.0)))
    assert np.allclose(sc[5:-5, 40:-40], sc0[5:-5, 40:-40], rtol=1e-6)
    ok_level = texture_mask(img, window=(3, 31), noise_std=nl, max_std=0.4)
    ok_const = texture_mask(img, window=(3, 31), noise_std=constant, max_std=0.4)
    assert ok_level[dark].mean() > 0.5 and ok_const[dark].mean() < 0.05
    assert ok_level[bright].mean() <= ok_const[bright].mean()
    # and the point selection, given the level function, takes points in the dim half too
    pts = select_points(img, per_line=12, window=(3, 31), noise_std=nl, max_std=0.4)
    assert np.sum(pts[1] < 300) > 0.2 * pts[1].size


def test_noise_level_function_needs_an_image():
    with pytest.raises(ValueError, match="3 x 3"):
        noise_level_function(np.zeros((2, 10)))
    with pytest.raises(ValueError, match="bins"):
        noise_level_function(np.zeros((50, 50)), bins=1)
    flat = np.full((40, 40), 7.0)           # no spread of levels, too few pixels: the constant estimate
    assert noise_level_function(flat).shot_gain == 0.0
