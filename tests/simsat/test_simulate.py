"""End-to-end rendering of the `tiny` scenario: files, determinism, jitter in the pixels."""
import json

import numpy as np
import pytest
import xarray as xr

from simsat.product import read_product, read_truth
from simsat.simulate import simulate
from simsat.attitude import AttitudeSeries
from simsat.product import clamped_attitude


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    d = tmp_path_factory.mktemp("runs") / "tiny"
    simulate("tiny", d, progress=False)
    return d


def test_run_directory_holds_product_truth_and_run_json(tiny_run):
    assert sorted(p.name for p in tiny_run.iterdir() if not p.name.startswith(".")) == ["product.nc", "run.json", "truth.nc"]
    assert not any(p.name.endswith(".part") for p in tiny_run.iterdir())
    ds = xr.load_dataset(tiny_run / "product.nc")
    for b in ("B0", "B1", "B2", "B3"):
        assert ds[f"image_{b}"].dims == ("line", "column")
        assert ds[f"image_{b}"].attrs["units"] == "DN"
    assert ds["time"].attrs["units"] == "s"
    assert "roll" not in ds and "truth" not in ds.attrs.get("title", "")
    tr = read_truth(tiny_run)
    dt = np.diff(tr["time"].values)
    assert dt.max() <= ds.attrs["line_period_s"] + 1e-12
    assert tr["time"].values[0] <= ds["time"].values[0] and tr["time"].values[-1] >= ds["time"].values[-1]
    run = json.loads((tiny_run / "run.json").read_text())
    assert run["seed"] == run["scenario"]["raw"]["scenario"]["seed"]
    assert "mitsuba" in run["versions"] and run["timings"]["render_s"] > 0


def test_product_records_what_the_aocs_knowledge_covers(tiny_run):
    """A ground segment knows its AOCS: the knowledge's cut-off, rate and noise are in product.nc."""
    from simsat.scenario import load_scenario

    attrs = xr.load_dataset(tiny_run / "product.nc").attrs
    spec = load_scenario("tiny").attitude_model().knowledge
    assert attrs["knowledge_cutoff_hz"] == spec.cutoff_hz
    assert attrs["knowledge_rate_hz"] == spec.rate_hz
    assert attrs["knowledge_noise_urad"] == spec.noise_urad


def test_product_records_the_sun_as_a_ground_segment_knows_it(tiny_run):
    """The sun's elevation and azimuth (from the track towards +y) are in product.nc: the scene's band offset
    lies along its azimuth (reports.summary.scene_offset_line)."""
    from simsat.scenario import load_scenario

    attrs = xr.load_dataset(tiny_run / "product.nc").attrs
    sun = load_scenario("tiny").sun()
    assert attrs["sun_elevation_deg"] == sun.elevation_deg
    assert attrs["sun_azimuth_deg"] == sun.azimuth_deg


def test_product_records_the_detector_radiometry(tiny_run):
    """A ground segment knows its detector's calibration (gain, read noise): restore's noise model reads it;
    an older product without it reads as unknown (None)."""
    from simsat.product import read_product
    from simsat.scenario import load_scenario

    r = load_scenario("tiny").instrument.radiometry
    p = read_product(tiny_run)
    assert p.radiometry is not None
    assert (p.radiometry.full_well_e, p.radiometry.read_noise_e, p.radiometry.bits, p.radiometry.enabled) == \
        (r.full_well_e, r.read_noise_e, r.bits, r.enabled)
    assert p.radiometry.gain_dn_per_e == pytest.approx(r.gain_dn_per_e)
    for key in ("full_well_e", "read_noise_e", "radiometric_noise"):
        del p.ds.attrs[key]
    assert p.radiometry is None


def test_same_scenario_and_seed_give_the_same_bytes(tiny_run, tmp_path):
    d2 = tmp_path / "again"
    simulate("tiny", d2, progress=False)
    for f in ("product.nc", "truth.nc"):
        assert (tiny_run / f).read_bytes() == (d2 / f).read_bytes(), f


def test_knowledge_is_truth_low_passed_not_truth(tiny_run):
    p = read_product(tiny_run)
    tr = read_truth(tiny_run)
    t = p.time
    kr, kp, _ = p.knowledge.at(t)
    true_r = np.interp(t, tr["time"].values, tr["roll"].values)
    err = true_r - kr
    ifov = p.pixel_ifov_rad
    # the jitter (~1 px at 50-80 Hz) is not in the knowledge, the slow drift is
    assert 0.2 < np.std(err) / ifov < 3.0
    assert abs(np.mean(err)) / ifov < 0.5


def test_jitter_is_in_the_pixels(tiny_run):
    """Plain normalised cross-correlation (OpenCV, parabola peak) between B1 and B0 follows θ(t+τ) − θ(t) from truth."""
    import cv2

    p = read_product(tiny_run)
    tr = read_truth(tiny_run)
    truth = AttitudeSeries(time=tr["time"].values, roll=tr["roll"].values, pitch=tr["pitch"].values,
                           yaw=tr["yaw"].values)
    sm_k = p.sensor_model()
    sm_t = p.sensor_model(attitude=clamped_attitude(truth))
    a, b = p.image("B1"), p.image("B0")
    meas, expect = [], []
    hl, hc, r = 1, 20, 4
    for line in range(20, 340, 7):
        c = 63.0
        g = sm_k.direct_location("B1", line, c)
        lb, cb = sm_k.inverse_location("B0", g[None])  # knowledge prediction
        lb, cb = float(lb[0]), float(cb[0])
        li, ci = int(round(lb)), int(round(cb))
        wa = a[line - hl:line + hl + 1, int(c) - hc:int(c) + hc + 1].astype(float)
        wb = b[li - hl - r:li + hl + r + 1, ci - hc - r:ci + hc + r + 1].astype(float)
        ncc = cv2.matchTemplate(wb.astype(np.float32), wa.astype(np.float32), cv2.TM_CCOEFF_NORMED)
        i, j = np.unravel_index(np.argmax(ncc), ncc.shape)
        i, j = min(max(i, 1), ncc.shape[0] - 2), min(max(j, 1), ncc.shape[1] - 2)
        def parab(m1, c0, p1):
            den = m1 - 2 * c0 + p1
            return 0.0 if den == 0 else 0.5 * (m1 - p1) / den
        shift = (i - r + parab(ncc[i - 1, j], ncc[i, j], ncc[i + 1, j]),
                 j - r + parab(ncc[i, j - 1], ncc[i, j], ncc[i, j + 1]))
        # where the window of A really is in B, minus the knowledge prediction
        meas.append((li + shift[0] - lb, ci + shift[1] - cb))
        gt = sm_t.direct_location("B1", line, c)
        lt, ct = sm_t.inverse_location("B0", gt[None])
        expect.append((float(lt[0]) - lb, float(ct[0]) - cb))
    meas, expect = np.array(meas), np.array(expect)
    # the differential signal is sizeable and the images follow it
    assert np.std(expect[:, 0]) > 0.2 and np.std(expect[:, 1]) > 0.2
    res = meas - expect
    for k in range(2):
        good = np.abs(res[:, k]) < 0.5
        # most points follow the truth differential (std > 0.5 px) to a fraction of a pixel (a
        # parabola fit on 3-line windows has pixel-locking bias; a few windows are texture-poor)
        assert np.median(np.abs(res[:, k])) < 0.3
        assert good.mean() > 0.6
        assert np.corrcoef(meas[good, k], expect[good, k])[0, 1] > 0.95


def test_streamed_images_equal_a_whole_image_render(tiny_run):
    """The product written block by block holds exactly the radiometry of a whole-image render."""
    from simsat.scenario import load_scenario
    from simsat.simulate import apply_radiometry, build_world, make_renderer

    sc = load_scenario("tiny")
    model, dem, known, texture, irr = build_world(sc)
    radiance = make_renderer(sc, model, dem, texture, irr).render(sc.line_times,
                                                                  block_lines=sc.acquisition.block_lines)
    ds = xr.load_dataset(tiny_run / "product.nc")
    for i, (name, img) in enumerate(radiance.items()):
        whole = apply_radiometry(img, sc.instrument.radiometry, seed=sc.seed, band_index=i)
        assert ds[f"image_{name}"].dtype == np.uint16
        np.testing.assert_array_equal(ds[f"image_{name}"].values, whole)
    assert "_FillValue" not in ds["image_B0"].encoding or ds["image_B0"].encoding["_FillValue"] is None


def test_radiometry_noise_does_not_depend_on_blocks():
    from simsat.scenario import load_scenario
    from simsat.simulate import apply_radiometry

    r = load_scenario("tiny").instrument.radiometry
    rad = np.random.default_rng(1).uniform(0.1, 0.9, (40, 16))
    whole = apply_radiometry(rad, r, seed=7, band_index=2)
    parts = np.vstack([apply_radiometry(rad[a:a + 13], r, seed=7, band_index=2, first_line=a) for a in range(0, 40, 13)])
    np.testing.assert_array_equal(whole, parts)


def test_scene_brightness_scales_the_signal(tiny_run, tmp_path):
    """scene.sun.irradiance_scale = 0.5 halves the mean signal of every band (no saturation in tiny)."""
    from simsat.scenario import load_scenario

    dim = tmp_path / "dim"
    simulate(load_scenario("tiny", overrides={"scene": {"sun": {"irradiance_scale": 0.5}}}), dim, progress=False)
    a, b = xr.load_dataset(tiny_run / "product.nc"), xr.load_dataset(dim / "product.nc")
    for band in ("B0", "B1", "B2", "B3"):
        ref = a[f"image_{band}"].values.astype(float)
        assert ref.max() < 4095
        assert b[f"image_{band}"].values.mean() / ref.mean() == pytest.approx(0.5, rel=0.01)


def test_product_records_the_star_trackers_noise_when_it_carries_its_samples():
    """The anchoring's uncertainty needs the star tracker's noise, as a ground segment knows its sensor."""
    from simsat.product import product_dataset
    from simsat.scenario import load_scenario

    for enabled in (True, False):
        sc = load_scenario("tiny", overrides={"attitude": {"star_tracker": {"enabled": enabled, "noise_urad": 1.5,
                                                                              "rate_hz": 4.0}}})
        model = sc.attitude_model()
        dem, known = sc.dems()
        ds = product_dataset(sc, None, sc.line_times, model.knowledge_series(), model.star_tracker_series(), known,
                             knowledge_spec=model.knowledge, star_tracker_spec=model.star_tracker)
        if enabled:
            assert ds.attrs["star_tracker_noise_urad"] == 1.5 and ds.attrs["star_tracker_rate_hz"] == 4.0
            assert "star_tracker_roll" in ds
        else:
            assert "star_tracker_noise_urad" not in ds.attrs and "star_tracker_roll" not in ds
