"""Sub-pixel matcher against analytic, exactly shifted band-limited windows."""
import numpy as np
import pytest

from reports.synthetic import synthetic_pairs
from restore.matching import (MatchFlag, exact_degree_for, lanczos_weights, match_points, resample_windows,
                              support_margin)
from support.textures import band_limited_texture


def _errors(res, data):
    return np.stack([res.line_b - data["lines"] - data["shift_lines"],
                     res.col_b - data["cols"] - data["shift_cols"]], axis=1)


def _locking(err, shift, n_bins=10):
    """Worst mean error over bins of the fractional shift (pixel locking), px."""
    frac = (shift + 0.5) % 1.0
    b = np.minimum((frac * n_bins).astype(int), n_bins - 1)
    return max(abs(err[b == k].mean()) for k in range(n_bins))


def _match(data, **kw):
    la, ca = data["lines"], data["cols"]
    return match_points(data["image_a"], data["image_b"], la, ca, la, ca, **kw)


@pytest.fixture(scope="module")
def same():
    # realistic texture (1/f spectrum, MTF 0.3 at Nyquist), noise 2 % of its std,
    # random shifts in [-1.5, 1.5] px on both axes, 3 x 31 windows
    return synthetic_pairs(seed=1, n=3000, case="same", noise=0.02, max_shift=1.5)


@pytest.fixture(scope="module")
def cross():
    return synthetic_pairs(seed=2, n=2000, case="cross", noise=0.02, max_shift=1.5)


@pytest.mark.parametrize("method, backend, rms_max, lock_max", [
    ("ncc", "compiled", 0.012, 0.006), ("ncc", "numpy", 0.012, 0.006), ("phase", "numpy", 0.04, 0.015)])
def test_same_band_known_shifts(same, method, backend, rms_max, lock_max):
    res = _match(same, window=(3, 31), search=(2, 2), method=method, backend=backend)
    assert res.valid.mean() > 0.98
    err = _errors(res, same)[res.valid]
    for ax, key in enumerate(("shift_lines", "shift_cols")):
        e = err[:, ax]
        assert abs(e.mean()) <= 0.01 / 4  # bias, 4x inside the 0.01 px goal
        assert _locking(e, same[key][res.valid]) <= lock_max
        assert np.sqrt(np.mean(e**2)) <= rms_max
    assert np.all(res.quality[res.valid] > 0.9)


def test_ncc_no_pixel_locking_without_noise():
    data = synthetic_pairs(seed=5, n=3000, case="same", noise=0.0)
    res = _match(data)
    err = _errors(res, data)
    assert res.valid.all()
    for ax, key in enumerate(("shift_lines", "shift_cols")):
        assert _locking(err[:, ax], data[key]) <= 0.004
        # the remaining error is the Lanczos-4 interpolation error on a
        # texture with MTF 0.3 at Nyquist
        assert np.sqrt(np.mean(err[:, ax] ** 2)) <= 0.008


def test_cross_band_unbiased(cross):
    res = _match(cross)
    assert res.valid.mean() > 0.9
    err = _errors(res, cross)[res.valid]
    assert np.all(np.abs(err.mean(axis=0)) <= 0.01)
    assert np.all(np.sqrt(np.mean(err**2, axis=0)) <= 0.25)


def test_std_estimate_tracks_the_error():
    data = synthetic_pairs(seed=4, n=2000, case="same", noise=0.05)
    res = _match(data)
    err = _errors(res, data)
    for ax, std in enumerate((res.std_line, res.std_col)):
        ratio = np.std(err[:, ax] / std)
        assert 0.6 < ratio < 1.4


def test_fractional_points_and_predictions(same):
    la, ca = same["lines"][:500] + 0.3, same["cols"][:500] - 0.2
    rng = np.random.default_rng(0)
    # predictions off by up to 1.4 px from the truth, fractional
    tl, tc = la + same["shift_lines"][:500], ca + same["shift_cols"][:500]
    pl, pc = tl + rng.uniform(-0.4, 0.4, 500), tc + rng.uniform(-0.4, 0.4, 500)
    res = match_points(same["image_a"], same["image_b"], la, ca, pl, pc, search=(2, 2))
    assert res.valid.mean() > 0.98
    # the match is reported for the fractional point itself (local translation)
    assert np.sqrt(np.mean((res.line_b - tl)[res.valid] ** 2)) < 0.015
    assert np.sqrt(np.mean((res.col_b - tc)[res.valid] ** 2)) < 0.015


@pytest.mark.parametrize("backend", ["compiled", "numpy"])
def test_flags(backend):
    data = synthetic_pairs(seed=3, n=200, case="same", noise=0.02, max_shift=0.0, search=(4, 4))
    a, b = data["image_a"].copy(), data["image_b"].copy()
    la, ca = data["lines"].copy(), data["cols"].copy()
    pl, pc = la.copy(), ca.copy()
    # 0: fine; 1: out of the image; 2: NaN in B's support; 3: flat A window;
    # 4: prediction 3.4 lines off with a +-2 search
    la[1] = 1.0
    b[int(la[2]) + 2, int(ca[2]) + 5] = np.nan
    a[int(la[3]) - 3:int(la[3]) + 4, :] = 7.0
    pl[4] += 3.4
    res = match_points(a, b, la, ca, pl, pc, search=(2, 2), backend=backend)
    assert res.flags[0] == 0 and res.valid[0]
    assert res.flags[1] & MatchFlag.OUT_OF_BOUNDS
    assert res.flags[2] & MatchFlag.NO_DATA
    assert res.flags[3] & MatchFlag.FLAT and np.isnan(res.quality[3])
    assert res.flags[4] & MatchFlag.SEARCH_BORDER
    assert not res.valid[1:5].any()
    assert np.array_equal(res.valid, res.flags == 0)
    # unrelated band: low correlation
    noise = np.random.default_rng(0).standard_normal(b.shape)
    res = match_points(a, noise, la[5:], ca[5:], pl[5:], pc[5:], backend=backend)
    assert np.all(res.flags & MatchFlag.LOW_CORRELATION)
    # a precision requirement nobody meets
    res = match_points(a, b, la[5:], ca[5:], pl[5:], pc[5:], max_std=1e-6, backend=backend)
    assert np.all(res.flags & MatchFlag.IMPRECISE)


def test_empty_and_single_point(same):
    res = match_points(same["image_a"], same["image_b"], [], [], [], [])
    assert len(res) == 0 and res.valid.dtype == bool
    la, ca = same["lines"][:1], same["cols"][:1]
    res = match_points(same["image_a"], same["image_b"], la, ca, la, ca)
    assert len(res) == 1 and res.valid[0]


@pytest.mark.parametrize("kw, name", [
    ({"method": "sad"}, "method"),
    ({"window": (4, 31)}, "window"),
    ({"window": (3,)}, "window"),
    ({"search": (-1, 2)}, "search"),
    ({"min_quality": 1.5}, "min_quality"),
    ({"max_std": 0.0}, "max_std"),
    ({"order": 0}, "order"),
    ({"max_iter": 0}, "max_iter"),
    ({"tol": -1.0}, "tol"),
    ({"backend": "gpu"}, "backend"),
    ({"backend": "compiled", "method": "phase"}, "backend"),
])
def test_bad_parameters(kw, name):
    img = np.zeros((50, 80))
    with pytest.raises(ValueError, match=name):
        match_points(img, img, [25.0], [40.0], [25.0], [40.0], **kw)


def test_bad_points_and_images():
    img = np.zeros((50, 80))
    with pytest.raises(ValueError, match="cols_a"):
        match_points(img, img, [25.0, 26.0], [40.0], [25.0, 26.0], [40.0, 40.0])
    with pytest.raises(ValueError, match="pred_lines_b"):
        match_points(img, img, [25.0], [40.0], [np.nan], [40.0])
    with pytest.raises(ValueError, match="image_b"):
        match_points(img, img[0], [25.0], [40.0], [25.0], [40.0])


def test_lanczos_weights():
    w = lanczos_weights([0.0, 0.25, -0.5, 0.9], order=4)
    assert w.shape == (4, 9)
    assert np.allclose(w.sum(axis=1), 1.0)
    assert np.array_equal(w[0], np.eye(9)[4])  # integer position: no smoothing
    # half pixel: symmetric about -0.5, the tap at +4 is outside the support
    assert np.allclose(w[2][:8], w[2][7::-1]) and w[2][8] == 0.0
    k = np.arange(-4, 5)
    x = k - 0.25
    ref = np.where(np.abs(x) < 4, np.sinc(x) * np.sinc(x / 4), 0.0)
    assert np.allclose(w[1], ref / ref.sum())
    with pytest.raises(ValueError, match="shift"):
        lanczos_weights([1.0])
    with pytest.raises(ValueError, match="order"):
        lanczos_weights([0.0], order=0)
    with pytest.raises(ValueError, match="exact_degree"):
        lanczos_weights([0.1], order=2, exact_degree=4)


def test_lanczos_weights_exact_for_cubics():
    """Corrected, the weights reproduce 1, d, d², d³ exactly (the plain kernel misses the ramp by 0.014 px at
    0.2 px), stay those of the identity at whole pixels and symmetric at half a pixel, and change the plain
    kernel's weights little."""
    shifts = np.array([0.0, 0.2, 0.25, -0.5, 0.9, -0.3])
    k = np.arange(-4, 5)
    plain = lanczos_weights(shifts, order=4)
    assert abs((plain[1] * k).sum() - 0.2) > 0.01
    w = lanczos_weights(shifts, order=4, exact_degree=3)
    for degree in range(4):
        np.testing.assert_allclose((w * k ** degree).sum(axis=1), shifts ** degree, atol=1e-12)
    assert not np.allclose((w * k ** 4).sum(axis=1), shifts ** 4)
    assert np.array_equal(w[0], np.eye(9)[4])
    assert np.allclose(w[3][:8], w[3][7::-1]) and w[3][8] == 0.0 and w[4][0] == 0.0
    assert np.abs(w - plain).max() < 0.01
    # two taps (order 1) fit a ramp at most: the matcher asks no more of them
    assert exact_degree_for(1) == 1 and exact_degree_for(4) == 3
    w1 = lanczos_weights([0.3, -0.6], order=1, exact_degree=exact_degree_for(1))
    np.testing.assert_allclose((w1 * np.arange(-1, 2)).sum(axis=1), [0.3, -0.6], atol=1e-12)


@pytest.mark.parametrize("backend", ["numpy", "compiled"])
def test_no_pixel_locking_on_smooth_texture(backend):
    """Known sub-pixel shifts of a smooth texture are measured without a pull towards whole pixels: the mean
    error at 0.1-0.4 px stays under 0.001 px (the plain Lanczos-4 resampling of B gave -0.005 to -0.008)."""
    n = 240
    lines, cols = np.meshgrid(np.arange(n, dtype=float), np.arange(n, dtype=float), indexing="ij")
    a = band_limited_texture(lines, cols, max_cycles=0.2)
    rng = np.random.default_rng(4)
    la, ca = rng.uniform(30, n - 30, 300).round(), rng.uniform(30, n - 30, 300).round()
    for shift in (0.1, 0.2, 0.3, 0.4):
        b = band_limited_texture(lines - shift, cols + 0.5 * shift, max_cycles=0.2)  # b(l + s, c - s/2) = a(l, c)
        m = match_points(a, b, la, ca, la, ca, window=(3, 31), search=(2, 2), backend=backend)
        v = m.valid
        assert v.mean() > 0.95
        assert abs(np.mean(m.line_b[v] - la[v] - shift)) < 1e-3
        assert abs(np.mean(m.col_b[v] - ca[v] + 0.5 * shift)) < 1e-3


def test_resample_windows_band_limited():
    rng = np.random.default_rng(0)
    n, order = 50, 4
    dl, dc = rng.uniform(-0.9, 0.9, n), rng.uniform(-0.9, 0.9, n)
    fl, fc = 0.08, 0.11  # cycles/px, well inside the band
    li = np.arange(3 + 2 * order) - order
    ci = np.arange(31 + 2 * order) - order
    patches = np.cos(2 * np.pi * (fl * li[None, :, None] + fc * ci[None, None, :])) * np.ones((n, 1, 1))
    out = resample_windows(patches, dl, dc, order=order)
    exact = np.cos(2 * np.pi * (fl * (np.arange(3)[None, :, None] + dl[:, None, None])
                                + fc * (np.arange(31)[None, None, :] + dc[:, None, None])))
    assert np.max(np.abs(out - exact)) < 1e-2  # the kernel's pass-band ripple
    # zero shift: the central window, untouched
    out0 = resample_windows(patches, np.zeros(n), np.zeros(n), order=order)
    assert np.array_equal(out0, patches[:, order:-order, order:-order])


def test_support_margin():
    assert support_margin(window=(3, 31), search=(2, 2), order=4) == (7, 21)
    assert support_margin(window=(1, 5), search=(0, 0), order=1) == (2, 4)
    with pytest.raises(ValueError, match="window"):
        support_margin(window=(2, 31))


@pytest.mark.parametrize("window, search, order, case", [
    ((3, 31), (2, 2), 4, "same"), ((3, 31), (3, 3), 4, "cross"), ((5, 21), (1, 3), 3, "cross"),
    ((1, 15), (0, 2), 2, "same"), ((3, 31), (0, 0), 4, "same")])
def test_compiled_kernel_agrees_with_numpy_reference(window, search, order, case):
    # two independent implementations of one algorithm (per-point compiled loop,
    # batched single-precision NumPy): same decisions, same positions
    data = synthetic_pairs(seed=7, n=600, case=case, noise=0.05, window=window, search=search,
                           max_shift=min(1.0, min(search)))
    rng = np.random.default_rng(1)
    la, ca = data["lines"] + rng.uniform(-0.5, 0.5, 600), data["cols"] + rng.uniform(-0.5, 0.5, 600)
    pl = la + data["shift_lines"] + rng.uniform(-0.3, 0.3, 600)
    pc = ca + data["shift_cols"] + rng.uniform(-0.3, 0.3, 600)
    kw = dict(window=window, search=search, order=order, min_quality=0.5)
    rc = match_points(data["image_a"], data["image_b"], la, ca, pl, pc, backend="compiled", **kw)
    rn = match_points(data["image_a"], data["image_b"], la, ca, pl, pc, backend="numpy", **kw)
    assert rc.valid.mean() > 0.8
    # decisions may differ only on the knife edge of a threshold
    assert np.mean(rc.flags == rn.flags) > 0.995
    both = rc.valid & rn.valid
    assert np.max(np.abs(rc.line_b - rn.line_b)[both]) < 1e-4
    assert np.max(np.abs(rc.col_b - rn.col_b)[both]) < 1e-4
    assert np.max(np.abs(rc.quality - rn.quality)[both]) < 1e-4
    assert np.allclose(rc.std_line[both], rn.std_line[both], rtol=1e-2)
    assert np.allclose(rc.std_col[both], rn.std_col[both], rtol=1e-2)
    assert np.max(np.abs(rc.corr_line_col - rn.corr_line_col)[both]) < 1e-2


def test_line_col_correlation_of_an_edge_follows_its_orientation():
    """An oriented edge: sliding along it moves line and column together. The normal matrix's 2 × 2 part is the
    window's structure tensor ``[[Σ gl², Σ gl gc], [Σ gl gc, Σ gc²]]``, so the errors' correlation is
    ``−Σ gl gc / √(Σ gl² Σ gc²)`` (the gain column projected out: a window whose mean gradient is ~0 barely
    changes it); an isotropic texture leaves it small."""
    from scipy import ndimage

    rng = np.random.default_rng(3)
    n = 160
    yy, xx = np.mgrid[0:n, 0:n].astype(float)
    weak = ndimage.gaussian_filter(rng.standard_normal((n, n)), 1.5)
    for phi in (0.3, 1.0, -0.6):
        img = 3 * np.tanh((xx * np.cos(phi) + yy * np.sin(phi) - 80 * (np.cos(phi) + np.sin(phi))) / 2.0) + 0.05 * weak
        b = ndimage.shift(img, (0.2, -0.3), order=5)
        # points on the edge line
        t = np.linspace(-25, 25, 11)
        lc, cc = 80 + t * np.cos(phi), 80 - t * np.sin(phi)
        la, ca = np.rint(lc), np.rint(cc)
        r = match_points(img, b, la, ca, la + 0.2, ca - 0.3, window=(7, 31), search=(1, 1), min_quality=0.5)
        gl = ndimage.correlate1d(img, np.array([1.0, -8.0, 0.0, 8.0, -1.0]) / 12.0, axis=0)
        gc = ndimage.correlate1d(img, np.array([1.0, -8.0, 0.0, 8.0, -1.0]) / 12.0, axis=1)
        box = lambda x: ndimage.uniform_filter(x, size=(7, 31))
        jll, jcc, jlc = box(gl * gl), box(gc * gc), box(gl * gc)
        li, ci = la.astype(int), ca.astype(int)
        expected = -jlc[li, ci] / np.sqrt(jll[li, ci] * jcc[li, ci])
        v = r.valid
        assert v.mean() >= 0.8
        np.testing.assert_allclose(r.corr_line_col[v], expected[v], atol=0.05)
        assert np.all(np.abs(r.corr_line_col[v]) > 0.9)
        assert np.all(np.sign(r.corr_line_col[v]) == -np.sign(np.sin(2 * phi)))
    iso = ndimage.gaussian_filter(rng.standard_normal((n, n)), 1.5)
    r = match_points(iso, ndimage.shift(iso, (0.2, -0.3), order=5), np.full(30, 80.0), np.linspace(40, 120, 30),
                     np.full(30, 80.2), np.linspace(40, 120, 30) - 0.3, window=(7, 31), search=(1, 1))
    assert np.median(np.abs(r.corr_line_col[r.valid])) < 0.3


def test_compiled_kernel_same_bytes_on_any_thread_count(cross):
    numba = pytest.importorskip("numba")
    la, ca = cross["lines"], cross["cols"]
    prev = numba.get_num_threads()
    out = []
    try:
        for n in sorted({1, prev}):
            numba.set_num_threads(n)
            out.append(match_points(cross["image_a"], cross["image_b"], la, ca, la + 0.2, ca - 0.3))
    finally:
        numba.set_num_threads(prev)
    for f in ("line_b", "col_b", "quality", "flags", "std_line", "std_col"):
        assert getattr(out[0], f).tobytes() == getattr(out[-1], f).tobytes()


@pytest.mark.parametrize("dtype", [np.float32, np.float64, np.uint16])
def test_compiled_kernel_image_types(same, dtype):
    # integer images (raw DN) are matched as float64; float32 stays float32
    a = (same["image_a"] * 100).astype(dtype)
    b = (same["image_b"] * 100).astype(dtype)
    la, ca = same["lines"][:300], same["cols"][:300]
    res = match_points(a, b, la, ca, la, ca, backend="compiled")
    err = np.hypot(res.line_b - la - same["shift_lines"][:300], res.col_b - ca - same["shift_cols"][:300])
    assert res.valid.mean() > 0.95
    tol = 0.05 if dtype == np.uint16 else 0.02  # 16-bit quantisation of the texture
    assert np.sqrt(np.mean(err[res.valid] ** 2)) < tol


def test_compiled_kernel_from_several_threads(same):
    # a threaded sweep calls the matcher concurrently: same results, no abort
    from concurrent.futures import ThreadPoolExecutor

    la, ca = same["lines"][:400], same["cols"][:400]
    ref = match_points(same["image_a"], same["image_b"], la, ca, la, ca)
    with ThreadPoolExecutor(4) as ex:
        outs = list(ex.map(lambda _: match_points(same["image_a"], same["image_b"], la, ca, la, ca), range(8)))
    for o in outs:
        assert o.line_b.tobytes() == ref.line_b.tobytes() and o.col_b.tobytes() == ref.col_b.tobytes()
