"""Restoration end to end on the `tiny` scenario, robustness and error messages."""
import json
import shutil
import subprocess
import sys

import numpy as np
import pytest
import xarray as xr

from restore.pipeline import RestorationError, restore_run, restoration_settings
from reports.metrics import attitude_errors
from simsat.config import ScenarioError
from simsat.product import read_truth
from simsat.scenario import load_scenario
from simsat.simulate import simulate


@pytest.fixture(scope="module")
def tiny_restored(tmp_path_factory):
    d = tmp_path_factory.mktemp("restore") / "tiny"
    simulate("tiny", d, progress=False)
    # restoration must work without truth: hide it while restoring
    hidden = d.parent / "truth_hidden.nc"
    shutil.move(d / "truth.nc", hidden)
    res = restore_run(d, progress=False)
    shutil.move(hidden, d / "truth.nc")
    return d, res


def test_restoration_file_has_the_documented_content(tiny_restored):
    d, res = tiny_restored
    ds = xr.load_dataset(d / "restoration.nc")
    for a in ("roll", "pitch", "yaw"):
        assert ds[a].attrs["units"] == "rad"
    assert ds["time"].attrs["units"] == "s"
    assert ds.attrs["pixel_ifov_rad"] == pytest.approx(52e-6 / 12.905)
    assert set(ds["pair"].values) == {"B1/B0", "B0/B2", "B1/B2"}
    assert ds["diff_roll"].dims == ("pair", "time")
    assert ds.sizes["match"] > 1000
    corr = ds["match_corr_line_col"].values[ds["match_valid"].values.astype(bool)]
    assert np.all(np.abs(corr) <= 1.0) and np.std(corr) > 0.05       # the matcher's line / column correlation
    from restore.restoration_io import read_restoration
    back = read_restoration(d / "restoration.nc").pairs[0]
    assert back.corr_line_col is not None and back.corr_line_col.shape == back.line_a.shape
    assert 0.8 < ds.attrs["coverage_roll"] <= 1.0
    assert (d / "corrected.nc").exists()
    # the knowledge fusion's weights per restored axis, read back (tiny's band holds: nothing taken)
    fused = read_restoration(d / "restoration.nc").knowledge_fusion
    assert {"roll", "pitch"} <= set(fused)
    for a, fu in fused.items():
        w = ds[f"knowledge_fusion_weight_{a}"].values
        assert np.all((w >= 0) & (w < 1)) and fu.weight.shape == w.shape
        assert np.all(fu.knowledge_band_rad2[np.isfinite(ds[a].values)] > 0)


def test_restoration_beats_the_knowledge_on_roll_and_pitch(tiny_restored):
    d, res = tiny_restored
    errs = attitude_errors(xr.load_dataset(d / "restoration.nc"), read_truth(d))
    for a in ("roll", "pitch"):
        assert errs[a]["rms_px"] < 0.4 * errs[a]["knowledge_rms_px"], errs[a]


def test_no_nan_leaks_into_estimated_lines(tiny_restored):
    d, _ = tiny_restored
    ds = xr.load_dataset(d / "restoration.nc")
    for a in ("roll", "pitch"):
        v = ds[a].values
        m = np.isfinite(v)
        # estimated lines form one block (no isolated NaN inside)
        idx = np.flatnonzero(m)
        assert idx[-1] - idx[0] + 1 == idx.size


def test_misregistration_drops_after_correction(tiny_restored):
    _, res = tiny_restored
    pairs = {k: v for k, v in res.misregistration.items() if not v.get("weakly_correlated")}
    assert len(pairs) == 3  # the weakly correlated band has its own test
    for name, v in pairs.items():
        assert v["after_px"] < 0.5 * v["before_px"], (name, v)


def test_true_attitude_correction_is_the_floor_the_restoration_reaches(tiny_restored):
    # the control of the benchmark: bands corrected with the true attitude, measured the same way
    from reports.metrics import misregistration_floor
    from simsat.product import read_product

    d, res = tiny_restored
    floor = misregistration_floor(read_product(d), read_truth(d), res.pairs, res.settings)
    assert set(floor) == set(res.misregistration)
    for name, v in res.misregistration.items():
        f = floor[name]
        # a perfect attitude removes most of the jitter misregistration ... as far as images can show it: on a
        # weak pair (a band only matched against its neighbour, here B2/B3, red against NIR, 43 % of its
        # windows valid) the image-measured floor is its cross-band matching error, ~1 px, half its "before"
        # (0.497 / 0.503 of it with two matchers whose results differ by < 1 % on it): there the control asks
        # that the true attitude takes off at least a quarter of it
        weak = "valid_fraction" in f
        assert f["after_px"] < (0.75 if weak else 0.5) * v["before_px"], (name, f, v)
        # ... and the restored one leaves about as little (same points, same measurement)
        assert v["after_px"] < 1.3 * f["after_px"], (name, f, v)
    # the report repeats the control from the run directory alone (restoration.nc's matches)
    from reports.report_data import load_run, misregistration_rows

    rows = {r["pair"]: r for r in misregistration_rows(load_run(d))}
    for name, f in floor.items():
        assert rows[name]["true_attitude_px"] == pytest.approx(f["after_px"], rel=0.02)


def test_flat_product_ends_with_a_clear_message(tiny_restored, tmp_path):
    d, _ = tiny_restored
    ds = xr.load_dataset(d / "product.nc")
    rng = np.random.default_rng(0)
    for k in [v for v in ds.data_vars if v.startswith("image_")]:
        ds[k].values[:] = (500 + rng.normal(0, 3, ds[k].shape)).astype(np.uint16)
    flat = tmp_path / "flat"
    flat.mkdir()
    ds.to_netcdf(flat / "product.nc")
    with pytest.raises(RestorationError, match="no usable texture"):
        restore_run(flat, progress=False)
    p = subprocess.run([sys.executable, "-m", "simsat_cli", "restore", str(flat), "--quiet"], capture_output=True,
                       text=True)
    assert p.returncode == 2
    assert "Traceback" not in p.stderr and "no usable texture" in p.stderr
    assert not (flat / "restoration.nc").exists()


def test_noise_without_signal_ends_with_a_clear_message(tmp_path):
    # bands drowned in read noise: matching finds nothing, the restoration says so
    d = tmp_path / "noisy"
    simulate(load_scenario("tiny", overrides={"instrument": {"noise": {"read_noise_e": 3000.0,
                                                                       "signal_fraction": 0.1}}}), d, progress=False)
    p = subprocess.run([sys.executable, "-m", "simsat_cli", "restore", str(d), "--quiet"], capture_output=True,
                       text=True)
    assert p.returncode == 2 and "Traceback" not in p.stderr
    assert "no usable texture" in p.stderr and "restoration.texture_max_std_px" in p.stderr
    assert not (d / "restoration.nc").exists()


def test_missing_product_and_bad_settings_are_named(tmp_path):
    p = subprocess.run([sys.executable, "-m", "simsat_cli", "restore", str(tmp_path), "--quiet"], capture_output=True,
                       text=True)
    assert p.returncode == 2 and "product.nc" in p.stderr and "Traceback" not in p.stderr
    with pytest.raises(ScenarioError, match="restoration.window_lines: must be odd"):
        restoration_settings({"window_lines": 4})
    with pytest.raises(ScenarioError, match="restoration.methd: unknown key"):
        restoration_settings({"methd": "wiener"})
    with pytest.raises(ScenarioError, match="restoration.texture_max_std_px"):
        restoration_settings({"texture_max_std_px": 0.0})
    assert restoration_settings({"texture_max_std_px": 0.25}).texture_max_std_px == 0.25


@pytest.mark.slow
def test_half_the_scene_under_clouds_still_restores_with_gaps_flagged(tmp_path):
    sc = load_scenario("tiny", overrides={"scene": {"texture": {"cloud_fraction": 0.5}},
                                          "acquisition": {"lines": 768}})
    d = tmp_path / "cloudy"
    simulate(sc, d, progress=False)
    res = restore_run(d, progress=False)
    ds = xr.load_dataset(d / "restoration.nc")
    v = ds["roll"].values
    # clouds are texture-poor: lines under them are flagged (NaN), the rest restored
    assert 0.2 < res.coverage["roll"] < 1.0
    errs = attitude_errors(ds, read_truth(d))
    assert errs["roll"]["rms_px"] < errs["roll"]["knowledge_rms_px"]
    # short gaps are filled: every interior run of NaN is longer than the fill limit
    m = np.isfinite(v).astype(np.int8)
    edges = np.diff(np.r_[1, m, 1])
    starts, stops = np.flatnonzero(edges == -1), np.flatnonzero(edges == 1)
    for a, b in zip(starts, stops):
        if a > 0 and b < v.size:
            assert b - a > 8, (a, b)


def test_pilot_shift_recentres_searches_beyond_the_search_range():
    """Band B shifted by up to 6 px per line (twice the search range): the pilot finds the shift."""
    from scipy.ndimage import gaussian_filter, map_coordinates

    from restore.matching import match_points
    from restore.pipeline import RestorationSettings, pilot_shift

    rng = np.random.default_rng(5)
    n_lines, n_cols = 400, 300
    a = gaussian_filter(rng.standard_normal((n_lines + 40, n_cols + 40)), 1.2)
    lines = np.arange(n_lines, dtype=float)
    sl = 6.0 * np.sin(2 * np.pi * lines / 200.0)      # along-track shift, px
    sc = 5.0 * np.cos(2 * np.pi * lines / 260.0)      # across-track shift, px
    L, C = np.meshgrid(lines, np.arange(n_cols, dtype=float), indexing="ij")
    img_a = a[20:20 + n_lines, 20:20 + n_cols]
    # line l of B shows A's ground shifted by (sl(l), sc(l)): B(l, c) = A(l - sl(l), c - sc(l))
    img_b = map_coordinates(a, [L + 20 - sl[:, None], C + 20 - sc[:, None]], order=5, mode="nearest")
    la, ca = np.meshgrid(np.arange(20, n_lines - 20, dtype=float), np.linspace(30, n_cols - 31, 12), indexing="ij")
    la, ca = la.ravel(), ca.ravel()
    s = RestorationSettings()
    sh_l, sh_c = pilot_shift(img_a, img_b, la, ca, la.copy(), ca.copy(), n_lines, s)
    # A's line l is seen in B at line l_b with l_b - sl(l_b) = l: shifts sl(l_b), sc(l_b)
    inner = slice(30, n_lines - 30)
    lb = np.interp(lines, lines - sl, lines)
    exp_l = np.interp(lb, lines, sl)
    exp_c = np.interp(lb, lines, sc)
    assert np.max(np.abs(sh_l[inner] - exp_l[inner])) < 0.5
    assert np.max(np.abs(sh_c[inner] - exp_c[inner])) < 0.5
    # the full matching centred on it succeeds where the knowledge-centred one fails
    li = np.rint(la).astype(int)
    plain = match_points(img_a, img_b, la, ca, la, ca, window=s.window, search=s.search)
    piloted = match_points(img_a, img_b, la, ca, la + sh_l[li], ca + sh_c[li], window=s.window, search=s.search)
    big = np.abs(exp_l[li]) > 4.0
    assert plain.valid[big].mean() < 0.3
    assert piloted.valid[big].mean() > 0.9
    # on the right peak (the shift varies by 0.2 px/line here, so the 3-line window is stretched:
    # sub-pixel accuracy is tested in test_matching)
    ok = piloted.valid
    np.testing.assert_allclose((piloted.line_b - la)[ok], exp_l[li][ok], atol=0.15)
    np.testing.assert_allclose((piloted.col_b - ca)[ok], exp_c[li][ok], atol=0.15)


def test_pilot_is_off_when_not_wider_than_the_search():
    from restore.pipeline import RestorationSettings, pilot_shift

    s = RestorationSettings()
    s.pilot_search = (2, 2)
    z = np.zeros((50, 50))
    sh_l, sh_c = pilot_shift(z, z, np.array([10.0]), np.array([10.0]), np.array([10.0]), np.array([10.0]), 50, s)
    assert not sh_l.any() and not sh_c.any()
    assert restoration_settings({"pilot_search_lines": 0, "pilot_search_columns": 0}).pilot_search == (0, 0)


def test_best_first_pair_order_folds_pairs_in_and_beats_the_knowledge(tiny_restored, tmp_path):
    d, fused = tiny_restored
    run = tmp_path / "bf"
    run.mkdir()
    for name in ("product.nc", "truth.nc", "run.json"):
        shutil.copy(d / name, run / name)
    res = restore_run(run, overrides={"pair_order": "best_first", "correct_images": False}, progress=False)
    ds = xr.load_dataset(run / "restoration.nc")
    errs = attitude_errors(ds, read_truth(run))
    for a in ("roll", "pitch"):
        assert errs[a]["rms_px"] < 0.5 * errs[a]["knowledge_rms_px"], errs[a]
        assert res.coverage[a] == pytest.approx(fused.coverage[a], abs=0.05)
    assert json.loads(ds.attrs["settings"])["pair_order"] == "best_first"
    with pytest.raises(ScenarioError, match="pair_order"):
        restoration_settings({"pair_order": "worst_first"})


def test_resampling_grid_interpolated_between_exact_columns(tiny_restored):
    # the grid is exact every `column_step` columns and linear in between: with the
    # restored attitude (a rotation away from the knowledge) it must stay within
    # a thousandth of a pixel of the grid computed exactly at every column
    from restore.correction import resampling_grid
    from simsat.attitude import AttitudeSeries
    from simsat.product import read_product

    d, _ = tiny_restored
    product = read_product(d)
    rest = xr.load_dataset(d / "restoration.nc")
    t = np.asarray(rest["time"].values, dtype=np.float64)
    series = AttitudeSeries(time=t, **{a: np.nan_to_num(np.asarray(rest[a].values, dtype=np.float64))
                                       if a in rest else np.zeros(t.size) for a in ("roll", "pitch", "yaw")})
    exact = resampling_grid(product, "B0", series, column_step=1)
    coarse = resampling_grid(product, "B0", series, column_step=64)
    for e, c in zip(exact, coarse):
        assert np.nanmax(np.abs(e - c)) < 1e-3
    # and it really moves the pixels (the restored attitude is not the knowledge)
    cols = np.arange(exact[1].shape[1])
    assert np.nanmax(np.abs(exact[1] - cols[None, :])) > 0.1


@pytest.mark.parametrize("boost_px", [0.0, 4.0])
def test_linearised_resampling_grid_equals_the_sensor_model(tiny_restored, boost_px):
    """The first-order grid (default) against the exact sensor-model grid: the restored attitude, and the
    same plus a 4 px, 80 Hz line on roll and pitch and 20 µrad of yaw (the Newton solve of the implicit time).

    The line of sight must not move along track faster than the scan (a pixel per line): beyond, the band
    folds over itself, a ground point is seen on several lines and the two grids may pick different ones."""
    from restore.correction import resampling_grid
    from simsat.attitude import AttitudeSeries
    from simsat.product import read_product

    d, _ = tiny_restored
    product = read_product(d)
    rest = xr.load_dataset(d / "restoration.nc")
    t = np.asarray(rest["time"].values, dtype=np.float64)
    ifov = product.pixel_ifov_rad
    extra = boost_px * ifov * np.sin(2 * np.pi * 80.0 * t)
    vals = {a: np.nan_to_num(np.asarray(rest[a].values, dtype=np.float64)) for a in ("roll", "pitch", "yaw")}
    vals["roll"] = vals["roll"] + extra
    vals["pitch"] = vals["pitch"] - 0.7 * extra
    vals["yaw"] = vals["yaw"] + (20e-6 if boost_px else 0.0) * np.cos(2 * np.pi * 30.0 * t)
    series = AttitudeSeries(time=t, **vals)
    lines = slice(40, 340)
    assert np.abs(np.diff(vals["pitch"][lines])).max() / ifov < 0.95  # no fold-over (see above)
    exact = resampling_grid(product, "B2", series, column_step=32, lines=lines, exact=True)
    fast = resampling_grid(product, "B2", series, column_step=32, lines=lines)
    moved = np.nanmax(np.abs(exact[0] - np.arange(40, 340)[:, None]))
    assert moved > (2.0 if boost_px else 0.1)  # the mapping really moves the pixels
    for e, f in zip(exact, fast):
        assert np.array_equal(np.isnan(e), np.isnan(f))
        assert np.nanmax(np.abs(e - f)) < (2e-3 if boost_px else 5e-4)


# ----------------------------------------------------------------------------- what restoration.nc records
def _rms(x):
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    return float(np.sqrt(np.mean(x ** 2)))


def test_restoration_round_trips_through_its_file(tiny_restored):
    from restore.restoration_io import read_restoration

    d, res = tiny_restored
    back = read_restoration(d / "restoration.nc")
    np.testing.assert_array_equal(back.time, res.time)
    for a in ("roll", "pitch", "yaw"):
        for k in ("restored", "knowledge", "correction"):
            np.testing.assert_array_equal(getattr(back, k)[a], getattr(res, k)[a])
        assert back.coverage[a] == res.coverage[a]
    assert back.settings == res.settings and back.method == res.method and back.anchored == res.anchored
    assert back.pixel_ifov_rad == res.pixel_ifov_rad
    # the knowledge's latency as the images measured it (tiny's knowledge has none: measured, at most shrunk to a
    # small advance)
    assert back.knowledge_latency == res.knowledge_latency and "delay_s" in res.knowledge_latency
    lat = res.knowledge_latency
    assert abs(lat["applied_s"]) <= abs(lat["delay_s"]) and (lat["taken"] or not res.knowledge_dephasing)
    assert [p.name for p in back.pairs] == [p.name for p in res.pairs]
    for p, q in zip(back.pairs, res.pairs):
        assert (p.ahead, p.behind, p.tau_s, p.nominal_tau_s) == (q.ahead, q.behind, q.tau_s, q.nominal_tau_s)
        for k in ("line_a", "col_a", "meas_line_b", "meas_col_b", "pred_line_b", "pred_col_b", "quality", "std_line",
                  "std_col", "valid", "inlier"):
            np.testing.assert_array_equal(getattr(p, k), getattr(q, k), err_msg=f"{p.name}.{k}")
        assert p.residual_rms_px == q.residual_rms_px
    assert set(back.integration) == set(res.settings.axes) == set(res.integration)
    for a, rec in res.integration.items():
        got = back.integration[a]
        for k in ("diffs", "sigmas", "taus", "lags_s", "weights", "increment", "previous"):
            np.testing.assert_array_equal(getattr(got, k), getattr(rec, k), err_msg=f"{a}.{k}")
        assert (got.pairs, got.method, got.options, got.highpass_hz, got.line_period_s) == \
            (rec.pairs, rec.method, rec.options, rec.highpass_hz, rec.line_period_s)
        assert (got.unobservable_rms_rad, got.floor_rms_rad) == (rec.unobservable_rms_rad, rec.floor_rms_rad)
        assert 0 <= rec.unobservable_rms_rad <= rec.floor_rms_rad + rec.unobservable_rms_rad and rec.floor_rms_rad > 0
        for k in ("freq", "psd", "noise_std"):  # the prior wiener estimated from the data
            np.testing.assert_array_equal(getattr(got.spectrum, k), getattr(rec.spectrum, k))
        if rec.spectrum.noise_colour is None:
            assert got.spectrum.noise_colour is None
        else:  # weighed by the noise colour the knowledge proves (on by default): kept with the prior
            for x, y in zip(got.spectrum.noise_colour, rec.spectrum.noise_colour):
                np.testing.assert_array_equal(x, y)
    assert set(back.sigma) == set(res.sigma) == set(res.settings.axes)
    for a in res.sigma:
        np.testing.assert_array_equal(back.sigma[a], res.sigma[a])
        np.testing.assert_array_equal(back.flagged[a], res.flagged[a])
        assert back.noise_scale[a] == res.noise_scale[a]
        assert back.band_shares[a] == pytest.approx(res.band_shares[a])
        assert back.detrended_rms[a] == res.detrended_rms[a] and 0 < res.detrended_rms[a] < np.inf


def test_a_blind_frequency_tone_round_trips_through_the_file(tiny_restored, tmp_path):
    """The tone found through the lags (frequency, prior sd) is part of the frozen filter: it is written with
    the prior and read back, so that the report's reruns integrate as the restoration did."""
    import copy

    from restore.restoration_io import restoration_dataset, result_from_dataset

    _, res = tiny_restored
    res = copy.deepcopy(res)
    rec = res.integration["pitch"]
    assert rec.spectrum.tones is None
    rec.spectrum.tones = ([135.1351], 3.0e-6, 2)
    path = tmp_path / "restoration.nc"
    restoration_dataset(res).to_netcdf(path)
    back = result_from_dataset(xr.load_dataset(path), path)
    assert back.integration["pitch"].spectrum.tones == ([135.1351], 3.0e-6, 2)
    assert back.integration["roll"].spectrum.tones is None
    assert back.integration["pitch"].frozen_options()["tones"] == ([135.1351], 3.0e-6, 2)
    # a swept tone keeps its rate
    rec.spectrum.tones = ([135.1351], 3.0e-6, 4, [0.78])
    restoration_dataset(res).to_netcdf(path)
    back = result_from_dataset(xr.load_dataset(path), path)
    assert back.integration["pitch"].spectrum.tones == ([135.1351], 3.0e-6, 4, [0.78])


def test_the_knowledge_band_a_colour_was_read_in_round_trips_through_the_file(tiny_restored, tmp_path):
    """``knowledge_band_hz`` (where the MAP's noise colour was read from the differentials, which σ's draws take)
    is written with the integration and read back; the tiny run reads none (its differentials show no excess
    in its knowledge's band), and the stage says so with None."""
    import copy
    from dataclasses import replace

    from restore import stages
    from restore.restoration_io import restoration_dataset, result_from_dataset
    from simsat.product import read_product

    d, res = tiny_restored
    assert all(rec.knowledge_band_hz is None for rec in res.integration.values())
    assert all(stages.knowledge_band_weighted(rec, read_product(d), res.settings) is None
               for rec in res.integration.values())
    res = copy.deepcopy(res)
    res.integration["pitch"] = replace(res.integration["pitch"], knowledge_band_hz=(2.0, 9.0))
    path = tmp_path / "restoration.nc"
    restoration_dataset(res).to_netcdf(path)
    back = result_from_dataset(xr.load_dataset(path), path)
    assert back.integration["pitch"].knowledge_band_hz == (2.0, 9.0)
    assert back.integration["roll"].knowledge_band_hz is None


def test_every_restored_line_has_a_predicted_sigma_and_flagged_lines_are_not_restored(tiny_restored):
    d, res = tiny_restored
    ds = xr.load_dataset(d / "restoration.nc")
    for a in res.settings.axes:
        sg = ds[f"sigma_{a}"].values
        restored = np.isfinite(ds[a].values)
        assert np.all(np.isfinite(sg[restored]) & (sg[restored] > 0))
        flagged = ds[f"flagged_{a}"].values.astype(bool)
        assert not np.any(restored & flagged)
        assert np.all(sg[flagged] > ds[f"sigma_{a}"].attrs["flag_limit_rad"])
        # "auto": 3 × the median σ — of the model's σ where a raise the same on every line (the local error, the
        # knowledge check, the knowledge's filter and latency) set the level above it, which is then the lower
        limit = ds[f"sigma_{a}"].attrs["flag_limit_rad"]
        if ds[f"sigma_{a}"].attrs["flag_judged_on"] == "reported":
            assert limit == pytest.approx(3 * np.nanmedian(sg))
        else:
            assert 0 < limit <= 3 * np.nanmedian(sg) * (1 + 1e-12)


def test_a_sigma_limit_below_every_line_flags_them_all_and_says_so(tiny_restored, tmp_path):
    d, _ = tiny_restored
    run = tmp_path / "tiny"
    shutil.copytree(d, run)
    with pytest.raises(RestorationError, match="flagged for a predicted σ above restoration.max_sigma_px"):
        restore_run(run, progress=False, overrides={"max_sigma_px": 1e-6})


@pytest.mark.slow  # a full restore of its own (or two): 15–30 s on 2 cores
def test_noise_colour_weighting_integrates_again_and_the_file_keeps_the_colour(tiny_restored, tmp_path):
    """restoration.noise_colour_weighting (on by default): the same differentials and prior as without it,
    integrated again with the residual weighed by the colour the knowledge proves noise (≥ 1); the colour is
    written with the prior and the file's frozen filter reproduces the increment. Off: no colour, and a product
    that does not record its knowledge's filter is not weighed either (nothing bounds the signal)."""
    from restore.restoration_io import read_restoration

    d, on = tiny_restored
    run = tmp_path / "tiny"
    shutil.copytree(d, run)
    # the integration conditioned on the knowledge afterwards (on by default) takes its mean off the
    # differentials: compared here without it, where the weighting's own record is the last
    plain = {"knowledge_conditioning": False, "correct_images": False}
    weighed = restore_run(run, progress=False, overrides=plain)
    off = restore_run(run, progress=False, overrides={**plain, "noise_colour_weighting": False})
    assert not any(k.startswith("prior_noise_colour") for k in xr.load_dataset(run / "restoration.nc").data_vars)
    assert "colour_weighting_s" in on.timings and "colour_weighting_s" not in off.timings
    weighted = [a for a, rec in on.integration.items() if rec.spectrum.noise_colour is not None]
    assert weighted, "the tiny scene's low-frequency matching noise exceeds what its knowledge allows as signal"
    back = read_restoration(d / "restoration.nc")
    for a in weighted:
        rec = on.integration[a]
        assert off.integration[a].spectrum.noise_colour is None
        assert np.all(rec.spectrum.noise_colour[1] >= 1.0) and np.any(rec.spectrum.noise_colour[1] > 1.0)
        w = weighed.integration[a]
        np.testing.assert_array_equal(w.diffs, off.integration[a].diffs)
        np.testing.assert_array_equal(w.spectrum.psd, off.integration[a].spectrum.psd)
        assert not np.array_equal(w.increment, off.integration[a].increment)
        got = back.integration[a]
        for x, y in zip(got.spectrum.noise_colour, rec.spectrum.noise_colour):
            np.testing.assert_array_equal(x, y)
        np.testing.assert_array_equal(got.rerun(), rec.increment)
    # without the knowledge's filter in the product nothing bounds the signal: no axis is weighed
    ds = xr.load_dataset(run / "product.nc")
    ds.attrs.pop("knowledge_cutoff_hz")
    ds.to_netcdf(run / "product.nc")
    bare = restore_run(run, progress=False, overrides={"correct_images": False})
    assert all(rec.spectrum.noise_colour is None for rec in bare.integration.values())


@pytest.mark.slow  # a full restore of its own (or two): 15–30 s on 2 cores
def test_the_local_matching_error_raises_the_predicted_sigma_where_larger(tiny_restored, tmp_path):
    """restoration.sigma_local_error (on by default): σ per line is the larger of the residual-calibrated
    prediction (the same with it off: same seeds) and the one with the local matching error measured from
    the pipeline's own pairs (two interleaved halves of the swath), computed here again."""
    from restore import stages
    from restore.posterior import local_error_sigma
    from simsat.product import read_product

    d, on = tiny_restored
    run = tmp_path / "tiny"
    shutil.copytree(d, run)
    off = restore_run(run, progress=False, overrides={"sigma_local_error": False, "correct_images": False})
    product = read_product(run)
    noise, rate = product.knowledge_noise or (0.0, None)
    smoothing = stages.knowledge_smoothings(product, on.settings, on.settings.axes)
    local = stages.local_errors(on.pairs, on.settings, on.time.size)
    assert set(local) == {p.name for p in on.pairs}
    order = sorted(set(on.settings.axes) | set(on.integration))
    for a, s_on in on.sigma.items():
        rec = on.integration[a]
        k = ["roll", "pitch", "yaw"].index(a)
        ps = local_error_sigma(rec, np.array([local[p][:, k] for p in rec.pairs]),
                               samples=on.settings.posterior_samples, seed=order.index(a),
                               knowledge_noise_rad=noise, knowledge_rate_hz=rate,
                               knowledge_smoothing=smoothing.get(a))
        assert np.isfinite(ps.sigma).sum() > 0.9 * np.isfinite(s_on).sum()
        both = np.isfinite(s_on) & np.isfinite(off.sigma[a]) & np.isfinite(ps.sigma)
        assert both.sum() > 0.9 * np.isfinite(s_on).sum()
        np.testing.assert_allclose(s_on[both], np.maximum(off.sigma[a], ps.sigma)[both], rtol=1e-12)
        # "auto" flags judge the model's σ (= σ with the local error off): 3 × its median, recorded as such
        attrs = xr.load_dataset(d / "restoration.nc")[f"sigma_{a}"].attrs
        assert attrs["flag_judged_on"] == "model"
        assert attrs["flag_limit_rad"] == pytest.approx(3.0 * np.nanmedian(off.sigma[a]), rel=1e-12)
        np.testing.assert_array_equal(on.flagged[a], off.flagged[a])
    with pytest.raises(ScenarioError, match="sigma_local_error"):
        restoration_settings({"sigma_local_error": "yes"})


def test_posterior_samples_zero_writes_no_sigma_and_one_is_refused(tiny_restored, tmp_path):
    with pytest.raises(ScenarioError, match="posterior_samples"):
        restoration_settings({"posterior_samples": 1})
    s = {"posterior_samples": 0, "correct_images": False}
    d, _ = tiny_restored
    run = tmp_path / "tiny"
    shutil.copytree(d, run)
    res = restore_run(run, progress=False, overrides=s)
    assert res.sigma == {} and "sigma_roll" not in xr.load_dataset(run / "restoration.nc")


def test_recorded_lags_are_the_inliers_line_offsets_less_the_delay_and_were_integrated_with(tiny_restored):
    """Time synchronisation: the lag of each line is the mean matched line offset of its inliers less the pair's
    delay τ′ (computed here from the recorded matches; not the residual about the knowledge's prediction, which
    moves with the knowledge's own noise), and the correction is the integration *with* those lags (its exposure undone,
    the knowledge's smoothed low band added): integrating the same differentials without them gives a clearly
    different correction."""
    from restore import stages
    from restore.restoration_io import read_restoration
    from simsat.product import read_product

    d, _ = tiny_restored
    res = read_restoration(d / "restoration.nc")
    product = read_product(d)
    te = res.integration["roll"].line_period_s
    n = res.time.size
    for j, p in enumerate(res.pairs):
        lag_lines = res.integration["pitch"].lags_s[j] / te
        li = np.rint(p.line_a).astype(int)
        r = p.meas_line_b - p.line_a - p.tau_s / te
        checked = 0
        for line in range(0, n, 7):
            m = p.inlier & (li == line) & np.isfinite(r)
            if m.any():
                assert lag_lines[line] == pytest.approx(r[m].mean(), abs=1e-9)
                checked += 1
        assert checked > n // 14
        assert np.abs(lag_lines).max() > 0.05  # pitch jitter moves the actual delay by a sizeable fraction of a line
    for a, rec in res.integration.items():
        ref = np.nan_to_num(rec.increment)
        same = rec.rerun()
        assert _rms(same - rec.increment) < 1e-3 * _rms(ref)
        without = replace_lags(rec, 0.0).rerun()
        assert _rms(without - rec.increment) > 20 * _rms(same - rec.increment) + 1e-3 * _rms(ref), a
        # the correction: that integration, its exposure undone, plus the knowledge's smoothed low band
        est = stages.undo_exposure({a: rec.previous + rec.increment}, product, res.settings)[a]
        c = np.where(np.isfinite(res.correction[a]), est + res.knowledge_smoothing.get(a, 0.0), np.nan)
        c = c - np.nanmean(c)
        np.testing.assert_allclose(c, res.correction[a], atol=1e-12 * np.nanmax(np.abs(c)) + 1e-18)


def replace_lags(rec, value):
    from dataclasses import replace

    return replace(rec, lags_s=np.full_like(rec.lags_s, value))


def test_actual_delay_tau_prime_is_recorded_and_integrated_with(tiny_restored):
    """τ′: the median over a pair's valid matches of the predicted line offset × line period (computed here
    from the recorded matches), not the nominal delay; the integration used τ′."""
    from restore.restoration_io import read_restoration

    d, _ = tiny_restored
    res = read_restoration(d / "restoration.nc")
    te = res.integration["roll"].line_period_s
    for j, p in enumerate(res.pairs):
        v = p.valid & np.isfinite(p.pred_line_b)
        tau = float(np.median((p.pred_line_b[v] - p.line_a[v]) * te))
        assert p.tau_s == pytest.approx(tau, rel=1e-12)
        assert p.tau_s != p.nominal_tau_s  # relief and attitude: τ′ is not the nominal delay
        for rec in res.integration.values():
            assert rec.taus[j] == p.tau_s


@pytest.mark.slow
def test_star_tracker_anchoring_removes_a_knowledge_bias(tmp_path):
    """An AOCS knowledge with a bias (and a drift, a delay, a causal filter): the image restoration removes
    the mean it cannot see, so the absolute (not mean-removed) error keeps the bias unless the restored
    attitude is anchored on the star tracker."""
    sc = load_scenario("tiny", overrides={"attitude": {
        "knowledge": {"bias_urad": 25.0, "drift_urad_per_s": 2.0, "delay_ms": 20.0, "filter": "causal"},
        "star_tracker": {"enabled": True, "rate_hz": 8.0, "noise_urad": 1.0}}})
    d = tmp_path / "biased"
    simulate(sc, d, progress=False)
    assert xr.open_dataset(d / "product.nc").attrs["knowledge_filter"] == "butterworth_causal"
    truth = read_truth(d)
    absolute = {}
    for anchor in (False, True):
        res = restore_run(d, progress=False, overrides={"anchor_star_tracker": anchor, "correct_images": False})
        assert res.anchored == anchor
        ds = xr.load_dataset(d / "restoration.nc")
        t = ds["time"].values
        absolute[anchor] = {}
        for a in ("roll", "pitch"):
            true = np.interp(t, truth["time"].values, truth[a].values)
            e = ds[a].values - true
            absolute[anchor][a] = float(np.sqrt(np.nanmean(e ** 2)))
    ifov = float(xr.open_dataset(d / "product.nc").attrs["pixel_ifov_rad"])
    for a in ("roll", "pitch"):
        # unanchored: the knowledge's mean error stays (tens of µrad); anchored: a few µrad at most
        assert absolute[False][a] > 3 * absolute[True][a], (a, absolute)
        assert absolute[True][a] < 1.5 * ifov


@pytest.mark.slow  # a full restore of its own (or two): 15–30 s on 2 cores
def test_small_dedicated_detector_restores_from_the_shared_columns_only(tmp_path):
    """Claim 20: a main strip and a small detector behind it, sharing a few of its columns. Points are
    selected in those columns only (before: '0 candidates' / 'no line could be synthesised')."""
    from restore.stages import shared_columns

    sc = load_scenario("tiny", overrides={"instrument": {"detectors": [
        {"name": "B0", "band": "pan", "along_track_mm": 0.0, "pixels": 256},
        {"name": "S", "band": "pan", "along_track_mm": -2.886, "across_track_mm": 1.0, "pixels": 80}]},
        "acquisition": {"lines": 768}})
    d = tmp_path / "small"
    simulate(sc, d, progress=False)
    res = restore_run(d, progress=False, overrides={"correct_images": False})
    from simsat.product import read_product

    sm = read_product(d).sensor_model()
    c0, c1 = shared_columns(sm, "B0", "S", (768, 256), (768, 80), lines=[100, 400, 700], margin_cols=0)
    # 80 pixels of the small detector cover about 80 of the strip's 256, offset by 1.0 mm ≈ 19 px
    assert 70 <= c1 - c0 + 1 <= 82 and 140 < 0.5 * (c0 + c1) < 155
    pair = res.pairs[0]
    assert pair.col_a.min() >= c0 and pair.col_a.max() <= c1
    assert res.coverage["roll"] > 0.9 and res.coverage["pitch"] > 0.9
    errs = attitude_errors(xr.load_dataset(d / "restoration.nc"), read_truth(d))
    for a in ("roll", "pitch"):
        assert errs[a]["rms_px"] < 0.5 * errs[a]["knowledge_rms_px"]


@pytest.mark.parametrize("compression", ["lz4", "none"])
def test_corrected_images_compression_changes_the_file_not_the_pixels(tiny_restored, tmp_path, compression):
    """corrected.nc written with Blosc LZ4 or uncompressed holds the same pixels as the default (zlib) one."""
    import netCDF4

    from restore.correction import correct_bands
    from simsat.attitude import AttitudeSeries
    from simsat.product import read_product

    d, _ = tiny_restored
    product = read_product(d)
    rest = xr.load_dataset(d / "restoration.nc")
    t = np.asarray(rest["time"].values, dtype=np.float64)
    series = AttitudeSeries(time=t, **{a: np.nan_to_num(np.asarray(rest[a].values, dtype=np.float64))
                                       for a in ("roll", "pitch", "yaw")})
    ref = correct_bands(product, restored=series, bands=["B1"], path=tmp_path / "zlib.nc")
    other = correct_bands(product, restored=series, bands=["B1"], path=tmp_path / f"{compression}.nc",
                          compression=compression)
    a, b = ref["image_B1"].values, other["image_B1"].values
    assert np.array_equal(a, b, equal_nan=True) and np.isfinite(a).mean() > 0.9
    ref.close(), other.close()
    with netCDF4.Dataset(tmp_path / f"{compression}.nc") as nc:
        filters = nc["image_B1"].filters()
    assert (filters.get("blosc") or {}).get("compressor") == "blosc_lz4" if compression == "lz4" else \
        not filters.get("zlib")
    with pytest.raises(ValueError, match="compression"):
        correct_bands(product, restored=series, bands=["B1"], path=tmp_path / "x.nc", compression="gzip")


def test_weakly_correlated_band_is_measured_before_and_after(tiny_restored):
    """Claims 9–11: the near-infrared band (in no pair) is corrected from the visible pairs and its
    misregistration against the nearest pair band (red, 7.4 ms) measured before / after."""
    d, res = tiny_restored
    mis = res.misregistration
    assert {"B1/B0", "B0/B2", "B1/B2"} <= set(mis)
    row = mis["B2/B3"]
    assert row["weakly_correlated"] and row["reference_band"] == "B2"
    # τ by hand: 0.962 mm of the 52 µm pixel pitch per 0.4 ms line → 18.5 lines = 7.4 ms
    assert row["tau_s"] == pytest.approx(0.962e-3 / 52e-6 * 0.4e-3, rel=1e-3)
    # tiny is too short (a few hundred lines) for a precise cross-band measurement (its floor, the same
    # measurement after correcting with the true attitude, is ~1 px): only the direction is checked here
    assert row["after_px"] < row["before_px"] and row["valid_fraction"] > 0.2 and row["lines"] > 20
    assert not any(v.get("weakly_correlated") for k, v in mis.items() if k != "B2/B3")
    # recorded in restoration.nc, read back with the rest
    from restore.restoration_io import read_restoration

    assert read_restoration(d / "restoration.nc").misregistration["B2/B3"]["reference_band"] == "B2"


def test_gradient_reader_equals_the_whole_band_gradient():
    from scipy import ndimage

    from restore.correction import _gradient_reader

    img = np.random.default_rng(3).normal(100, 10, (50, 20)).astype(np.float32)
    whole = np.hypot(ndimage.sobel(img, axis=0, mode="nearest"), ndimage.sobel(img, axis=1, mode="nearest"))
    read = _gradient_reader(lambda s: img[s], 50)
    for s in (slice(0, 7), slice(10, 30), slice(44, 50)):
        np.testing.assert_array_equal(read(s), whole[s])


def _claim_knowledge_noise(run, ds, noise_urad: float) -> None:
    """Rewrite ``run``'s product.nc from ``ds`` with the AOCS knowledge's noise it records set to ``noise_urad``."""
    ds.attrs["knowledge_noise_urad"] = noise_urad
    ds.to_netcdf(run / "product_noisy.nc")
    shutil.move(run / "product_noisy.nc", run / "product.nc")


@pytest.mark.slow
def test_a_noisy_aocs_knowledge_lowers_the_auto_highpass(tiny_restored, tmp_path):
    """The product says its knowledge is noisy: the images take over below the default high-pass."""
    d, res0 = tiny_restored
    run = tmp_path / "tiny"
    shutil.copytree(d, run)
    ds = xr.load_dataset(run / "product.nc")
    _claim_knowledge_noise(run, ds, 30.0)  # 100× what tiny's AOCS claims
    res = restore_run(run, progress=False, overrides={"correct_images": False})
    assert res.settings.highpass_hz < 0.25 * res0.settings.highpass_hz
    assert res.timings["highpass_lowered_hz"] == res.settings.highpass_hz
    # the crossover scales as 1 / σ_k: a knowledge noisy enough to put it at 0.35 × the default (within the
    # margin the images' optimistic low-frequency error model needs) leaves the default alone
    _claim_knowledge_noise(run, ds, 30.0 * res.settings.highpass_hz / (0.35 * res0.settings.highpass_hz))
    kept = restore_run(run, progress=False, overrides={"correct_images": False})
    assert kept.settings.highpass_hz == res0.settings.highpass_hz and "highpass_lowered_hz" not in kept.timings
    _claim_knowledge_noise(run, ds, 30.0)
    assert all(rec.highpass_hz == res.settings.highpass_hz for rec in res.integration.values())
    # a given high-pass is kept as given; so is the default without the measured noise colour
    assert restore_run(run, progress=False, overrides={"correct_images": False, "highpass_hz": 2.0}
                       ).settings.highpass_hz == 2.0
    assert restore_run(run, progress=False, overrides={"correct_images": False, "posterior_samples": 0}
                       ).settings.highpass_hz == res0.settings.highpass_hz


@pytest.mark.slow
def test_per_axis_highpass_lowers_only_the_axes_the_knowledge_does_not_prove_wrong(tiny_restored, tmp_path):
    """highpass_per_axis (off by default): an axis whose differentials the knowledge does not prove wrong below
    the default takes its own crossover, the others keep the default; the settings' high-pass stays the default."""
    from restore import stages

    d, res0 = tiny_restored
    run = tmp_path / "tiny"
    shutil.copytree(d, run)
    ds = xr.load_dataset(run / "product.nc")
    _claim_knowledge_noise(run, ds, 30.0)
    res = restore_run(run, progress=False, overrides={"correct_images": False})
    # a knowledge noisy enough to put the common crossover at 0.35 × the default leaves the default alone
    _claim_knowledge_noise(run, ds, 30.0 * res.settings.highpass_hz / (0.35 * res0.settings.highpass_hz))
    kept = restore_run(run, progress=False, overrides={"correct_images": False})
    assert kept.settings.highpass_hz == res0.settings.highpass_hz
    # axis by axis: an axis whose differentials the knowledge does not prove wrong below the default takes
    # its own crossover, the others keep the default; the settings' high-pass stays the default
    each = restore_run(run, progress=False, overrides={"correct_images": False, "highpass_per_axis": True,
                                                       "knowledge_noise_floor": True})
    assert each.settings.highpass_hz == res0.settings.highpass_hz
    lowered = each.timings.get("highpass_lowered_hz", {})
    assert isinstance(lowered, dict)
    for a, rec in each.integration.items():
        if a in lowered:
            assert rec.highpass_hz == lowered[a] < res0.settings.highpass_hz
            assert not stages.knowledge_proves_excess(kept.integration[a], lowered[a], res0.settings.highpass_hz)
        else:
            assert rec.highpass_hz == res0.settings.highpass_hz


def test_a_trend_in_the_truth_is_named_as_unobservable_and_leaves_the_rest_unchanged(tiny_restored, tmp_path):
    """An attitude a + b t gives constant differentials: adding one to the truth moves the total error, but not
    what the summary and the bench call the error outside the unobservable parts."""
    from reports import report_data as D
    from reports.metrics import restoration_unobservable_split
    from reports.summary import unobservable_line
    from restore.restoration_io import read_restoration

    d, _ = tiny_restored
    run = tmp_path / "run"
    shutil.copytree(d, run)
    res = read_restoration(run / "restoration.nc")
    before = restoration_unobservable_split(res, read_truth(run), "pitch")
    tr = xr.load_dataset(run / "truth.nc")
    t = tr["time"].values
    slope = 0.5 * res.pixel_ifov_rad * (t - t.mean()) / (t.max() - t.min()) * 2   # ±0.5 px over the record
    tr["pitch"] = tr["pitch"] + slope
    tr.to_netcdf(run / "truth.nc")
    after = restoration_unobservable_split(res, read_truth(run), "pitch")
    px = res.pixel_ifov_rad
    assert after["trend_rms"] / px > 0.25 and abs(after["outside_rms"] - before["outside_rms"]) / px < 1e-4
    line = unobservable_line(D.load_run(run), ["roll", "pitch"])
    assert "without what no pair sees" in line and f"pitch {after['outside_rms'] / px:.3f} px" in line


def test_the_knowledge_below_the_highpass_is_smoothed_and_recorded(tiny_restored, tmp_path):
    """The correction is the integration's estimate (its exposure undone) plus the smoothing of the knowledge's
    low band, recorded in
    restoration.nc and recomputed from the product alone; off, no smoothing is recorded."""
    from restore import stages
    from simsat.product import read_product

    d, res = tiny_restored
    ds = xr.load_dataset(d / "restoration.nc")
    product = read_product(d)
    smooth = stages.knowledge_smoothing_correction(
        product, stages.knowledge_smoothings(product, res.settings, res.settings.axes), res.integration)
    for a in res.settings.axes:
        sm = np.asarray(ds[f"knowledge_smoothing_{a}"].values)
        np.testing.assert_allclose(sm, smooth[a], rtol=0, atol=1e-15)
        assert 0 < np.std(sm) < np.std(ds[f"knowledge_{a}"].values)
        rec = res.integration[a]
        est = stages.undo_exposure({a: rec.previous + rec.increment}, product, res.settings)[a]
        ok = np.isfinite(ds[f"correction_{a}"].values)
        x = ds[f"correction_{a}"].values[ok] - sm[ok] - est[ok]
        np.testing.assert_allclose(x - x.mean(), 0.0, atol=1e-12)
    run = tmp_path / "tiny"
    shutil.copytree(d, run)
    off = restore_run(run, progress=False, overrides={"knowledge_smoothing": False, "posterior_samples": 0,
                                                      "correct_images": False})
    assert off.knowledge_smoothing == {}
    assert not any(v.startswith("knowledge_smoothing") for v in xr.load_dataset(run / "restoration.nc").variables)


def test_the_knowledge_check_raises_sigma_by_what_it_books_and_leaves_the_flags(tiny_restored, monkeypatch):
    """stages.raise_by_knowledge_check on the tiny run's own product and records (a 0.15 s record has no
    periodogram bin to check between its high-pass and the knowledge's cut-off: nothing is checked or raised),
    then with the check's core made to find an excess: recorded with restoration.sigma_knowledge_check off, σ
    untouched; with it on (the default), σ rises in quadrature on every line by the images' share of it, the σ
    "auto" flags judge stays the one before, and an axis with no excess is left as it was."""
    from dataclasses import replace
    from restore import stages
    from restore.knowledge_check import KnowledgeCheck
    from restore.posterior import PosteriorSigma
    from simsat.product import read_product

    d, res = tiny_restored
    product = read_product(d)
    s = res.settings
    smoothings = stages.knowledge_smoothings(product, s, s.axes)
    assert set(smoothings) >= {"roll", "pitch"}
    assert res.knowledge_checks == {}
    assert json.loads(xr.load_dataset(d / "restoration.nc")["sigma_roll"].attrs["knowledge_check"]) == {}
    n = res.time.size
    sig = np.full(n, 1e-8)
    fake = {a: PosteriorSigma(sigma=sig, noise_scale=1.0, samples=2, detrended_rms=1e-8, detrended_sigma=sig,
                              error_power=np.zeros(n // 2 + 1)) for a in ("roll", "pitch")}
    out, checks = stages.raise_by_knowledge_check(fake, res.integration, product, s, res.restored, smoothings)
    assert checks == {} and out == fake
    with pytest.raises(ScenarioError, match="sigma_knowledge_check"):
        restoration_settings({"sigma_knowledge_check": "yes"})
    seen = {}

    def booked(restored, ks, k, power, sm, **kw):
        seen[len(seen)] = (restored, ks, k, power, kw)
        excess = 9e-16 if len(seen) == 1 else 0.0
        return KnowledgeCheck((2.5, 7.0), 1e-15 + excess, 5e-16, 5e-16, 8, excess)

    monkeypatch.setattr(stages, "knowledge_check", booked)
    # off: the checks are recorded, σ is left as it is
    assert s.sigma_knowledge_check        # the default
    off = replace(s, sigma_knowledge_check=False)
    out, checks = stages.raise_by_knowledge_check(fake, res.integration, product, off, res.restored, smoothings)
    assert set(checks) == {"roll", "pitch"} and checks["pitch"].excess_rad2 == 9e-16 and out == fake
    seen.clear()
    out, checks = stages.raise_by_knowledge_check(fake, res.integration, product, s, res.restored, smoothings)
    assert set(checks) == {"roll", "pitch"}
    # images and knowledge predicted alike (5e-16 each): σ takes half the excess; sorted, pitch comes first
    assert checks["pitch"].booked_rad2 == pytest.approx(4.5e-16, rel=1e-12)
    np.testing.assert_allclose(out["pitch"].sigma, np.sqrt(sig ** 2 + 4.5e-16), rtol=1e-12)
    np.testing.assert_array_equal(out["pitch"].model_sigma, sig)
    assert out["pitch"].detrended_rms == pytest.approx(np.sqrt(1e-16 + 4.5e-16))
    assert out["roll"] is fake["roll"]
    restored, ks, k, power, kw = seen[0]
    np.testing.assert_array_equal(restored, res.restored["pitch"])
    assert kw["highpass_hz"] == res.integration["pitch"].highpass_hz and power is fake["pitch"].error_power


def test_knowledge_conditioning_integrates_again_with_the_conditional_prior_and_round_trips(tiny_restored):
    """The tiny run's axes are integrated again with the prior given the AOCS knowledge
    (stages.knowledge_conditioned): the record says so, holds the conditional mean as its earlier estimate and
    the differentials with that mean's taken off, restoration.nc gives all of it back and the recorded integration reproduces the estimate;
    the stage declines with the setting off, and on a record already holding an earlier estimate."""
    from dataclasses import replace
    from restore import stages
    from restore.posterior import PosteriorSigma
    from restore.restoration_io import read_restoration
    from simsat.product import read_product

    d, res = tiny_restored
    product = read_product(d)
    s = res.settings
    assert s.knowledge_conditioning          # the default
    for a in ("roll", "pitch"):
        rec = res.integration[a]
        assert rec.knowledge_conditioned
        assert np.any(rec.previous != 0) and np.all(np.isfinite(rec.previous))
        np.testing.assert_allclose(rec.rerun(), rec.increment, rtol=0, atol=1e-12)
        assert "given the AOCS knowledge" in xr.load_dataset(d / "restoration.nc")[f"prior_psd_{a}"].attrs["long_name"]
    back = read_restoration(d / "restoration.nc")
    assert back.integration["pitch"].knowledge_conditioned
    np.testing.assert_allclose(back.integration["pitch"].previous, res.integration["pitch"].previous)
    rec = res.integration["pitch"]
    off = replace(s, knowledge_conditioning=False)
    assert stages.knowledge_conditioned(rec, object(), product, res.knowledge["pitch"], rec.increment, off) is None
    assert stages.knowledge_conditioned(rec, None, product, res.knowledge["pitch"], rec.increment, s) is None
    n = res.time.size
    ps = PosteriorSigma(sigma=np.full(n, 1e-8), noise_scale=1.0, samples=2, error_power=np.full(n // 2 + 1, 1e-18))
    again = stages.knowledge_conditioned(replace(rec, previous=np.zeros(n), knowledge_conditioned=False), ps, product,
                                         res.knowledge["pitch"], rec.increment, s)
    assert again is not None and again.knowledge_conditioned
    # an earlier estimate (iterations) is not what the conditional mean is taken from: declined
    assert stages.knowledge_conditioned(rec, ps, product, res.knowledge["pitch"], rec.increment, s) is None
    with pytest.raises(ScenarioError, match="knowledge_conditioning"):
        restoration_settings({"knowledge_conditioning": "yes"})


def test_lines_that_took_the_knowledge_s_band_are_counted_and_said_in_the_report(tiny_restored, tmp_path):
    """restoration.nc's knowledge_fusion_weight_<axis> is what the report counts and says (the tiny run fuses
    nothing; a copy with 40 roll lines weighted stands for one that did)."""
    from reports import report_data as D
    from reports.run_report import _Page, _uncertainty_section

    d, _ = tiny_restored
    run = tmp_path / "fused"
    run.mkdir()
    for name in ("product.nc", "truth.nc", "run.json"):
        shutil.copy(d / name, run / name)
    ds = xr.load_dataset(d / "restoration.nc")
    assert int((ds["knowledge_fusion_weight_roll"].values > 0).sum()) == 0
    w = ds["knowledge_fusion_weight_roll"].values.copy()
    w[100:140] = 0.9
    ds["knowledge_fusion_weight_roll"].values[:] = w
    ds.to_netcdf(run / "restoration.nc")
    unc = D.uncertainty(D.load_run(run))
    assert unc["roll"]["fused_lines"] == 40 and unc["pitch"]["fused_lines"] == 0
    pg = _Page(tmp_path / "page")
    (tmp_path / "page").mkdir()
    _uncertainty_section(pg, D.load_run(run), {"ifov_rad": float(ds.attrs["pixel_ifov_rad"])})
    text = "\n".join(pg.parts)
    assert "Knowledge fusion: roll 40 lines" in text and "pitch 0 lines" not in text


def test_off_nadir_the_uncertainty_figure_compares_sigma_with_the_error_less_the_yaw_seen(tiny_restored, tmp_path):
    """reports.report_data.uncertainty: with a material yaw coupling (restoration.nc's yaw_roll_coupling) the
    actual error set against σ is the error less the yaw the axis books as its own, which no pair tells apart and σ
    does not hold (the tiny run with a 40 Hz yaw added to truth and 0.3 × the yaw its knowledge misses added to the
    restored roll gives back the tiny run's own error); the report's caption says so."""
    from reports import report_data as D
    from reports.metrics import truth_at
    from reports.run_report import _Page, _uncertainty_section

    d, _ = tiny_restored
    before = D.uncertainty(D.load_run(d))["roll"]
    run = tmp_path / "tilted"
    run.mkdir()
    for name in ("product.nc", "run.json"):
        shutil.copy(d / name, run / name)
    truth = xr.load_dataset(d / "truth.nc")
    amp, c = 3e-6, 0.3
    truth["yaw"].values[:] = truth["yaw"].values + amp * np.sin(2 * np.pi * 40.0 * truth["time"].values)
    truth.to_netcdf(run / "truth.nc")
    ds = xr.load_dataset(d / "restoration.nc")
    # what a tilted restoration books as roll: c × the yaw its knowledge misses (reports.metrics.yaw_seen)
    missed = truth_at(truth, "yaw", ds["time"].values) - ds["knowledge_yaw"].values
    ds["roll"].values[:] = ds["roll"].values + c * missed
    ds.attrs["yaw_roll_coupling"] = c
    ds.to_netcdf(run / "restoration.nc")
    after = D.uncertainty(D.load_run(run))["roll"]
    assert after["yaw_seen_removed"] == pytest.approx(c) and "yaw_seen_removed" not in before
    ok = np.isfinite(before["error"])
    assert np.nanmax(np.abs(after["error"][ok] - before["error"][ok])) < 0.02 * c * amp
    pg = _Page(tmp_path / "page")
    (tmp_path / "page").mkdir()
    _uncertainty_section(pg, D.load_run(run), {"ifov_rad": float(ds.attrs["pixel_ifov_rad"])})
    assert "less the yaw seen as roll" in "\n".join(pg.parts)


def test_an_estimate_over_its_conditioned_prior_is_shrunk_and_its_error_booked(tiny_restored):
    """stages.shrunk_excesses on a conditioned record (the tiny run's pitch record given a 3.2 s estimate, a flat
    prior and a 4 Hz knowledge; the tiny record itself is too short for the band): a sine 30 × the estimate's RMS
    at 2 Hz is shrunk to under a fifth, the Restorer puts the shrunk increment in the record and the estimate,
    and σ takes the booked error in quadrature (stages.raise_by_excess_shrink); with excess_shrink off, the excess is
    only reported."""
    from dataclasses import replace
    from types import SimpleNamespace
    from restore import stages
    from restore.posterior import PosteriorSigma
    from restore.restorer import Restorer

    _, res = tiny_restored
    assert res.settings.excess_shrink
    dt, n = 4e-4, 8000
    f = np.fft.rfftfreq(n, dt)
    rng = np.random.default_rng(0)
    base = np.cumsum(rng.standard_normal(n)) * 1e-9
    t = np.arange(n) * dt
    sine = 30 * np.std(base) * np.sin(2 * np.pi * 2.0 * t)
    rec = res.integration["pitch"]
    loud = replace(rec, increment=base + sine, previous=np.zeros(n), line_period_s=dt, highpass_hz=0.4,
                   taus=np.array([0.0074, 0.0148, 0.0222]), knowledge_conditioned=True, conditioned_attitude_psd=None,
                   spectrum=replace(rec.spectrum, freq=f, psd=np.full(f.size, 1e-15),
                                    noise_std=np.array([3e-7, 3e-7, 3e-7])))
    product = SimpleNamespace(ds=SimpleNamespace(attrs={"knowledge_cutoff_hz": 4.0}))
    sh = stages.shrunk_excesses({"pitch": loud}, product, res.settings)["pitch"]
    assert sh.shrunk and any(abs(h - 2.0) < 0.7 for h in sh.excess.excess_hz) and sh.excess.shrink_error_rad > 0
    # the same offset extrapolated above the band (3.6 Hz) up to the scene offset band's top (6.8 Hz)
    assert sh.excess.above_error_rad > 0
    assert sh.excess.booked_rad == pytest.approx(np.hypot(sh.excess.shrink_error_rad, sh.excess.above_error_rad))
    assert abs(np.dot(sh.increment - base, sine)) < 0.2 * np.dot(sine, sine)
    records, estimate, excesses = Restorer(res.settings).shrink_excess(product, {"pitch": loud},
                                                                       {"pitch": loud.increment}, _NoBar())
    np.testing.assert_allclose(records["pitch"].increment, sh.increment)
    np.testing.assert_allclose(estimate["pitch"], sh.increment)
    ps = PosteriorSigma(sigma=np.full(n, 3e-8), noise_scale=1.0, samples=2, detrended_rms=3e-8,
                        detrended_sigma=np.full(n, 3e-8))
    up = stages.raise_by_excess_shrink({"pitch": ps}, excesses)["pitch"]
    np.testing.assert_allclose(up.sigma, np.hypot(3e-8, sh.excess.booked_rad))
    assert up.detrended_rms == pytest.approx(np.hypot(3e-8, sh.excess.booked_rad))
    off = Restorer(replace(res.settings, excess_shrink=False))
    records, _, excesses = off.shrink_excess(product, {"pitch": loud}, {"pitch": loud.increment}, _NoBar())
    assert records["pitch"] is loud and excesses["pitch"].excess_hz and excesses["pitch"].shrink_error_rad is None
    with pytest.raises(ScenarioError, match="excess_shrink"):
        restoration_settings({"excess_shrink": 1})


def test_the_offset_one_axis_shrinks_reaches_the_other_by_the_suns_split():
    """stages.offset_shared_excesses: pitch's offset booked above the band (1.2e-7 rad) reaches roll, whose own test
    found nothing, as √(¼ / ¾) of it under a sun 150° from a track along +x, and raise_by_excess_shrink books it on
    roll's σ; with the track along +y (the sun 60° from it, roll's share the larger) nothing is shared, nor without
    the sun's azimuth in the product."""
    from types import SimpleNamespace
    from restore import stages
    from restore.conditioned_excess import ConditionedExcess
    from restore.posterior import PosteriorSigma

    excesses = {"pitch": ConditionedExcess(band_hz=(0.625, 1.75), excess_hz=[0.625], max_ratio=8.2,
                                           excess_rms_rad=2e-7, shrink_error_rad=4e-8, above_error_rad=1.2e-7),
                "roll": ConditionedExcess(band_hz=(0.625, 1.75), excess_hz=[], max_ratio=1.8, excess_rms_rad=0.0,
                                          shrink_error_rad=0.0, above_error_rad=0.0)}

    def product(sun=None, track_y=False):
        attrs = {"knowledge_cutoff_hz": 2.0} | ({} if sun is None else {"sun_azimuth_deg": sun})
        eph = np.array([[0.0, 0.0, 7e5], [0.0, 1e4, 7e5]] if track_y else [[0.0, 0.0, 7e5], [1e4, 0.0, 7e5]])
        return SimpleNamespace(ds=xr.Dataset({"ephemeris": (("line", "xyz"), eph)}, attrs=attrs))

    got = stages.offset_shared_excesses(excesses, product(150.0))
    assert got["roll"].shared_above_rad == pytest.approx(1.2e-7 / np.sqrt(3.0))
    assert got["pitch"].shared_above_rad is None and got["pitch"] == excesses["pitch"]
    n = 50
    ps = PosteriorSigma(sigma=np.full(n, 3e-8), noise_scale=1.0, samples=2, detrended_rms=3e-8,
                        detrended_sigma=np.full(n, 3e-8))
    up = stages.raise_by_excess_shrink({"roll": ps, "pitch": ps}, got)
    np.testing.assert_allclose(up["roll"].sigma, np.hypot(3e-8, 1.2e-7 / np.sqrt(3.0)))
    np.testing.assert_allclose(up["pitch"].sigma, np.hypot(3e-8, np.hypot(4e-8, 1.2e-7)))
    assert stages.offset_shared_excesses(excesses, product(150.0, track_y=True)) == excesses
    assert stages.offset_shared_excesses(excesses, product()) == excesses


class _NoBar:
    def note(self, *_):
        pass
