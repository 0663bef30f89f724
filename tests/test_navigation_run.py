"""A navigation run end to end on nav_tiny: rendered frames → aided INS, NetCDF product, report, degraded case."""
import hashlib

import numpy as np
import pytest

from navigation.io import read_navigation, summarise, write_navigation
from navigation.run import NavigationRun
from navigation.scenario import load_navigation_scenario


@pytest.fixture(scope="module")
def tiny_run():
    run = NavigationRun(load_navigation_scenario("nav_tiny"), progress=False)
    run.render_sequences()
    return run


def _horizontal(a, b):
    return np.hypot(*(a - b)[..., :2].T)


def test_aided_beats_unaided_and_stays_inside_its_covariance(tiny_run):
    res = tiny_run.run(seeds=[0, 1, 2], workers=1)
    truth = res.flight.p[::int(round(1 / res.flight.dt))]
    for r in res.runs:
        fixes = [u for u in r.updates if u["status"] == "ok"]
        assert len(fixes) >= 2, [u["status"] for u in r.updates]
        ea = _horizontal(r.aided[-1], truth[-1])
        eu = _horizontal(r.unaided[-1], truth[-1])
        assert ea < eu / 3, (ea, eu)
        # never a wrong fix: after every fix the horizontal error is within 3σ of the filter
        for u in fixes:
            e = np.hypot(*u["error_m"][:2])
            s = np.hypot(*u["sigma_m"][:2])
            assert e <= 3 * s, (e, s)
        # the filter's σ shrinks at a fix
        k = r.updates.index(fixes[0])
        assert r.updates[k]["sigma_m"][0] < r.sigma[int(r.updates[k]["t"]) - 1, 0]


def test_product_and_report(tiny_run, tmp_path):
    from reports.navigation_report import make_navigation_report

    res = tiny_run.run(seeds=[0, 1], workers=1)
    p = write_navigation(res, tmp_path / "a")
    ds = read_navigation(tmp_path / "a")
    assert ds.sizes["seed"] == 2 and ds.sizes["axis"] == 3
    for v in ("true_position", "unaided_position", "aided_position", "aided_sigma", "update_status", "found",
              "tracked", "reconstructed", "matched", "nees", "sample_frame", "reference_map", "terrain_height"):
        assert v in ds, v
    assert (ds.found.values >= ds.tracked.values).all() and (ds.tracked.values >= ds.reconstructed.values).all()
    s = summarise(ds)
    assert s["seeds"] == 2 and s["improvement_median"] > 3
    html = make_navigation_report(tmp_path / "a")
    for f in ("error_over_distance.png", "map_view.png", "consistency.png", "sample_frames.png"):
        assert (html.parent / f).stat().st_size > 10_000
    # same scenario, same seeds: the same bytes
    write_navigation(res, tmp_path / "b")
    digest = [hashlib.sha256((tmp_path / d / "navigation.nc").read_bytes()).hexdigest() for d in ("a", "b")]
    assert digest[0] == digest[1]
    assert p.name == "navigation.nc"


def test_monte_carlo_on_a_local_dask_cluster_matches_in_process(tiny_run):
    a = tiny_run.run(seeds=[5, 6], workers=1)
    b = tiny_run.run(seeds=[5, 6], workers=2)
    for ra, rb in zip(a.runs, b.runs):
        assert np.array_equal(ra.aided, rb.aided)


def test_desert_stretch_is_flagged_no_aiding_and_the_covariance_grows():
    sc = load_navigation_scenario("nav_tiny", overrides={
        "degraded": [{"from_km": 3.5, "to_km": 10.5, "kind": "desert"}]})
    run = NavigationRun(sc, progress=False)
    res = run.run(seeds=[0], workers=1)
    ups = res.runs[0].updates
    # the camera looks up to camera.max_range_m ahead: the updates that see only desert
    inside = [u for u in ups if 3500 <= u["distance_m"] <= 10500 - sc.sensor.max_range_m]
    assert inside and all(u["status"] != "ok" for u in inside), [u["status"] for u in inside]
    sig = [np.hypot(*u["sigma_m"][:2]) for u in inside]
    assert all(b > a for a, b in zip(sig, sig[1:]))
    # honest: the error stays inside 3σ while unaided
    for u in inside:
        assert np.hypot(*u["error_m"][:2]) <= 3 * np.hypot(*u["sigma_m"][:2])


def test_cli_navigate_writes_a_run_and_refuses_a_foreign_directory(tmp_path, capsys):
    from simsat_cli import main

    out = tmp_path / "run"
    assert main(["navigate", "nav_tiny", "--out", str(out), "--seeds", "2", "--workers", "1", "--quiet",
                 "--set", "route.length_km=6"]) == 0
    said = capsys.readouterr().out
    assert "final horizontal error median" in said
    assert (out / "navigation.nc").exists() and (out / "run.json").exists() and (out / "report" / "index.html").exists()
    foreign = tmp_path / "mine"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("keep me")
    assert main(["navigate", "nav_tiny", "--out", str(foreign), "--quiet"]) == 2
    assert "is not a simsat run" in capsys.readouterr().err
    assert (foreign / "notes.txt").read_text() == "keep me"
    assert main(["navigate", "nav_tiny", "--set", "camera.hfov_deg=500"]) == 2
    assert "camera.hfov_deg" in capsys.readouterr().err


def test_ir_band_frames_have_lines(tiny_run):
    from navigation.frames import FrameRenderer, SensorSettings
    from navigation.segments import SegmentExtractor

    sc, f = tiny_run.sc, tiny_run.flight
    idx = tiny_run.sequence_indices()[0]
    pose = sc.camera.pose(f.p[idx[0]], f.R[idx[0]])
    out = {}
    for band in ("visible", "ir"):
        r = FrameRenderer(tiny_run.world, tiny_run.dem, sc.camera, SensorSettings(band=band, supersample=1))
        r.prepare([pose])
        img = r.render(pose, rng=np.random.default_rng(0))
        assert img.shape == (sc.camera.height, sc.camera.width) and np.isfinite(img).all()
        out[band] = (img, SegmentExtractor()(img))
    assert len(out["ir"][1]) > 30
    # the IR-like band is not the visible one relabelled: its contrast is inverted on the ground
    lower = slice(sc.camera.height // 2, None)
    c = np.corrcoef(out["visible"][0][lower].ravel(), out["ir"][0][lower].ravel())[0, 1]
    assert c < 0
