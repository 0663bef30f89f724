"""A 2-D matrix detector taking overlapping frames (fig. 1): geometry, rendering, restoration.

The frame geometry is exact (one time per frame): direct and inverse location
invert each other over relief, the renderer puts spots where inverse location
says, a ground point moves v T / GSD rows from one frame to the next, and the
least-squares attitude from frame differences recovers a known attitude.
"""
from dataclasses import replace

import numpy as np
import pytest

from simsat.config import ScenarioError
from simsat.frames import (frame_direct_location, frame_inverse_location, frame_sensitivities, row_along_m,
                           rows_per_frame)
from simsat.sensor_model import SensorModel, constant_attitude

from support.geometry import F, SpotTexture, centred_platform, flat_dem, small_instrument, spot_centroid

ROWS, T_FRAME, N_FRAMES = 64, 16 * 4e-4, 5


def _matrix():
    inst = small_instrument()
    det = replace(inst.detector("B0"), rows=ROWS, name="M", band="pan")
    return replace(inst, detectors=(det,)), det


def _hill(step=5.0, half=900.0):
    from simsat.terrain.dem import Dem

    x = np.arange(-half, half + 0.1, step)
    xx, yy = np.meshgrid(x, x)
    z = 35.0 * np.exp(-(xx ** 2 + yy ** 2) / (2 * 220.0 ** 2)) - 0.02 * yy
    return Dem(x0_m=x[0], y0_m=x[0], dx_m=step, dy_m=step, z=z)


def _model(dem, attitude=None):
    inst, det = _matrix()
    plat = centred_platform(inst, int(N_FRAMES * T_FRAME / inst.line_period_s))
    return SensorModel(platform=plat, instrument=inst, dem=dem, attitude=attitude or constant_attitude()), det


def test_rows_are_ordered_forward_first_around_the_centre():
    _, det = _matrix()
    a = row_along_m(det, np.array([0, (ROWS - 1) / 2, ROWS - 1]))
    assert a[0] > a[1] > a[2]
    assert a[1] == pytest.approx(det.along_m)
    assert a[0] - a[2] == pytest.approx((ROWS - 1) * det.pitch_m)


def test_frame_inverse_location_inverts_direct_location_over_relief():
    sm, det = _model(_hill(), constant_attitude(2e-5, -1e-5, 3e-3))
    rr, cc = np.meshgrid(np.linspace(0, ROWS - 1, 7), np.linspace(0, det.pixels - 1, 9), indexing="ij")
    g = frame_direct_location(sm, det, 0.01, rr, cc)
    r2, c2 = frame_inverse_location(sm, det, 0.01, g)
    np.testing.assert_allclose(r2, rr, atol=1e-6)
    np.testing.assert_allclose(c2, cc, atol=1e-6)


def test_a_ground_point_moves_v_t_over_gsd_rows_between_frames():
    sm, det = _model(flat_dem())
    g = frame_direct_location(sm, det, 0.0, np.array([5.0]), np.array([40.0]))
    r1, c1 = frame_inverse_location(sm, det, T_FRAME, g)
    s = rows_per_frame(sm.platform, det, F, T_FRAME)
    assert s == pytest.approx(16.0, rel=1e-9)  # V T / GSD with V = GSD / Te
    assert r1[0] - 5.0 == pytest.approx(s, rel=1e-6)
    assert c1[0] == pytest.approx(40.0, abs=1e-6)
    # a positive pitch turns the lines of sight back (−x): a fixed point is seen one row further forward per
    # IFOV; a positive roll turns them to +y: the point is seen one column lower per IFOV
    j = frame_sensitivities(sm, det, T_FRAME, g)[0]
    ifov = det.pitch_m / F
    assert j[0, 1] * ifov == pytest.approx(-1.0, rel=1e-6)
    assert j[1, 0] * ifov == pytest.approx(-1.0, rel=1e-6)
    assert abs(j[0, 0] * ifov) < 1e-6 and abs(j[1, 1] * ifov) < 1e-6


def test_renderer_puts_matrix_spots_where_frame_inverse_location_says_over_relief():
    from simsat.frames import render_frames
    from simsat.render.pushbroom import PushbroomRenderer

    dem = _hill()
    ifov = 52e-6 / F
    att = constant_attitude(0.3 * ifov, -0.2 * ifov, 1e-4)
    sm, det = _model(dem, att)
    rng = np.random.default_rng(7)
    xs = np.linspace(-60, 60, 4) + rng.uniform(-2, 2, 4)
    ys = np.linspace(-90, 90, 4) + rng.uniform(-2, 2, 4)
    centres = np.array([(x, y) for x in xs for y in ys])
    r = PushbroomRenderer(platform=sm.platform, instrument=sm.instrument, dem=dem, texture=SpotTexture(centres),
                          attitude=att)
    times = np.array([0.0, T_FRAME]) + 0.5 * (N_FRAMES - 1) * T_FRAME
    frames = render_frames(r, det, times)
    g = np.c_[centres, dem.height(centres[:, 0], centres[:, 1])]
    errs = []
    for k, t in enumerate(times):
        rows, cols = frame_inverse_location(sm, det, t, g)
        for r0, c0 in zip(rows, cols):
            if 8 < r0 < ROWS - 8 and 8 < c0 < det.pixels - 8:
                rm, cm = spot_centroid(frames[k], r0, c0, half=6)
                errs.append((rm - r0, cm - c0))
    errs = np.array(errs)
    assert len(errs) >= 8
    # the exposure (one line period) smears the image by one row as the ground moves: the centroid is that of
    # the mean position, the centre of the exposure
    assert np.max(np.abs(errs)) <= 0.01, errs


def test_least_squares_recovers_a_known_attitude_from_frame_differences():
    from restore.frames import solve_frame_attitudes

    rng = np.random.default_rng(3)
    n, npts = 40, 120
    truth = rng.normal(0, 1e-6, (n, 2))
    truth -= truth.mean(axis=0)
    pairs = []
    for k in range(n - 1):
        j1 = np.zeros((npts, 2, 3))
        j1[:, 0, 1] = 2.5e5
        j1[:, 1, 0] = -2.5e5
        j1[:, 1, 2] = rng.uniform(-3e2, 3e2, npts)
        j0 = j1.copy()
        res = np.einsum("nca,a->nc", j1[:, :, :2], truth[k + 1]) - np.einsum("nca,a->nc", j0[:, :, :2], truth[k])
        res += rng.normal(0, 0.02, res.shape)
        res[:5] += 3.0  # outliers
        pairs.append((res, j1, j0, np.ones(npts, bool)))
    x, res_rms, kept, sigma = solve_frame_attitudes(pairs, n, [0, 1])
    # noise 0.02 px per point, 115 points per difference: the differences to ~0.002 px, the walk to ~0.006 px
    actual = np.sqrt(np.mean((x - truth) ** 2))
    assert actual * 2.5e5 < 0.01
    # the predicted 1-σ says so: the actual RMS within a factor 1.5 of the predicted RMS
    predicted = np.sqrt(np.mean(sigma ** 2))
    assert predicted / 1.5 < actual < predicted * 1.5
    # a random walk: the ends of the record are less certain than its middle
    assert sigma[0, 0] > 1.5 * sigma[n // 2, 0]
    assert np.all(kept <= npts - 5)
    assert np.nanmax(res_rms) < 0.03


def test_matrix_frames_render_restore_and_beat_the_knowledge(tmp_path):
    import xarray as xr

    from restore.pipeline import restore_run
    from reports.frames_report import frames_headline, frames_summary, make_frames_report
    from simsat.scenario import load_scenario
    from simsat.simulate import simulate

    sc = load_scenario("matrix_frames", overrides={"acquisition": {"lines": 30},
                                                   "instrument": {"detectors": {0: {"pixels": 128, "rows": 128}},
                                                                  "pixels": 128}})
    simulate(sc, tmp_path / "r", progress=False)
    res = restore_run(tmp_path / "r", progress=False)
    assert "29 overlapping pairs" in res.summary()
    rest = xr.load_dataset(tmp_path / "r" / "restoration.nc")
    truth = xr.load_dataset(tmp_path / "r" / "truth.nc")
    hd = frames_headline(rest, truth, {"scenario": sc.to_dict()})
    for a in ("roll", "pitch"):
        e = hd["errors"][a]
        assert e["rms_px"] < 0.06 and e["knowledge_rms_px"] > 5 * e["rms_px"]
        predicted = float(np.sqrt(np.mean(rest[f"sigma_{a}"].values ** 2))) / float(rest.attrs["pixel_ifov_rad"])
        assert 0 < predicted < 0.06
    assert "requirement" in frames_summary(tmp_path / "r")
    # read back through the restoration reader: the same attitude, σ, matches and summary
    from restore.frames import FrameRestoration
    from restore.restoration_io import read_restoration

    back = read_restoration(tmp_path / "r" / "restoration.nc", product_time=rest["time"].values)
    assert isinstance(back, FrameRestoration) and back.axes == res.axes
    for a in ("roll", "pitch", "yaw"):
        np.testing.assert_array_equal(back.restored[a], res.restored[a])
    for a in res.sigma:
        np.testing.assert_array_equal(back.sigma[a], res.sigma[a])
    np.testing.assert_array_equal(back.n_valid, res.n_valid)
    assert back.summary().splitlines()[:4] == res.summary().splitlines()[:4]
    index = make_frames_report(tmp_path / "r")
    assert index.is_file() and (index.parent / "attitude_roll.png").is_file()


@pytest.mark.parametrize("change,match", [
    ({"acquisition": {"frame_period_ms": 0.0}}, "acquisition.frame_period_ms.*is a matrix"),
    ({"acquisition": {"frame_period_ms": 200.0}}, "acquisition.frame_period_ms.*must overlap"),
    ({"acquisition": {"frame_period_ms": 0.1}}, "acquisition.frame_period_ms.*shorter than the exposure"),
])
def test_frame_settings_are_checked(change, match):
    from simsat.scenario import load_scenario

    with pytest.raises(ScenarioError, match=match):
        load_scenario("matrix_frames", overrides=change)


def test_frames_need_one_matrix_detector():
    from simsat.scenario import load_scenario

    with pytest.raises(ScenarioError, match="acquisition.frame_period_ms.*one matrix detector"):
        load_scenario("phr_cmg", overrides={"acquisition": {"frame_period_ms": 10.0}})


def test_a_pair_without_matches_splits_the_record_and_each_run_keeps_its_own_mean():
    from restore.frames import frame_segments, pair_ties, solve_frame_attitudes

    rng = np.random.default_rng(4)
    n, npts, cut = 30, 80, 14
    truth = rng.normal(0, 1e-6, (n, 2))
    pairs = []
    for k in range(n - 1):
        j = np.zeros((npts, 2, 3))
        j[:, 0, 1] = 2.5e5
        j[:, 1, 0] = -2.5e5
        res = np.einsum("nca,a->nc", j[:, :, :2], truth[k + 1] - truth[k]) + rng.normal(0, 0.01, (npts, 2))
        valid = np.ones(npts, bool) if k != cut else np.zeros(npts, bool)  # clouds over frames 14-15
        pairs.append((res, j, j.copy(), valid))
    segs = frame_segments(pair_ties([int(p[3].sum()) for p in pairs]), n)
    assert [list(s[[0, -1]]) for s in segs] == [[0, cut], [cut + 1, n - 1]]
    x, _, kept, sigma = solve_frame_attitudes(pairs, n, [0, 1])
    for seg in segs:  # each run: the truth up to its own mean (the offset between runs is unobservable)
        want = truth[seg] - truth[seg].mean(axis=0)
        np.testing.assert_allclose(x[seg], want, atol=0.01 / 2.5e5)
        np.testing.assert_allclose(x[seg].mean(axis=0), 0.0, atol=1e-12)
    assert kept[cut] == 0 and np.all(np.isfinite(sigma))


def test_a_truncated_frames_restoration_is_refused_with_its_name(tmp_path):
    import xarray as xr

    from restore.restoration_io import read_restoration
    from simsat.product import ProductError

    n = 5
    data = {v: ("time", np.zeros(n)) for a in ("roll", "pitch", "yaw") for v in (a, f"knowledge_{a}", f"correction_{a}")}
    data.update(pair_valid_matches=("pair", np.ones(n - 1, np.int32)), pair_points=("pair", np.ones(n - 1, np.int32)),
                pair_residual_px=("pair", np.zeros(n - 1)))
    attrs = {"acquisition": "frames", "axes": "roll,pitch", "pixel_ifov_rad": 4e-6, "highpass_hz": 0.0}
    ds = xr.Dataset(data, coords={"time": ("time", np.arange(n) * 0.02)}, attrs=attrs)
    ds.to_netcdf(tmp_path / "ok.nc")
    back = read_restoration(tmp_path / "ok.nc")
    assert back.axes == ("roll", "pitch") and back.time.size == n and back.sigma == {}
    with pytest.raises(ProductError, match="frame times"):
        read_restoration(tmp_path / "ok.nc", product_time=np.zeros(n + 1))
    ds.drop_vars("pair_points").to_netcdf(tmp_path / "cut.nc")
    with pytest.raises(ProductError, match=r"cut\.nc.*'pair_points'"):
        read_restoration(tmp_path / "cut.nc")
    ds.assign_attrs(axes="roll,tilt").to_netcdf(tmp_path / "axes.nc")
    with pytest.raises(ProductError, match="'tilt'"):
        read_restoration(tmp_path / "axes.nc")
