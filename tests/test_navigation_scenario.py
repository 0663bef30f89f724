"""Navigation scenarios: built-ins load, bad input names the key or the file."""
import pytest

from navigation.scenario import builtin_navigation_scenarios, load_navigation_scenario
from simsat.config import ScenarioError


def test_builtins_load():
    names = builtin_navigation_scenarios()
    assert {"nav_default", "nav_tiny", "nav_degraded"} <= set(names)
    for n in names:
        sc = load_navigation_scenario(n)
        assert sc.name == n
    d = load_navigation_scenario("nav_degraded")
    assert [x.kind for x in d.degraded] == ["desert", "fog"]
    assert d.world.deserts == ((20000.0, 32000.0),)
    assert d.fog_at(45000.0) == 350.0 and d.fog_at(10000.0) is None


@pytest.mark.parametrize("overrides, message", [
    ({"camera.hfov_deg": 200}, "camera.hfov_deg"),
    ({"route.agl_max_m": 100}, "route.agl_max_m: must be >= route.agl_min_m"),
    ({"route.lenght_km": 3}, "did you mean 'length_km'"),
    ({"camera.frame_rate_hz": 7}, "camera.frame_rate_hz: must divide imu.rate_hz"),
    ({"aiding.min_views": 50}, "aiding.min_views: must be <= aiding.frames"),
    ({"imu.accel_bias_mg": -1}, "imu.accel_bias_mg"),
    ({"camera.band": "uv"}, "camera.band"),
])
def test_bad_values_name_the_key(overrides, message):
    with pytest.raises(ScenarioError, match=message.replace("(", r"\(")):
        load_navigation_scenario("nav_tiny", overrides=overrides)


def test_degraded_stretch_beyond_the_route(tmp_path):
    p = tmp_path / "s.toml"
    p.write_text('kind = "navigation"\n[navigation]\nname = "x"\n[route]\nlength_km = 10\n'
                 '[[degraded]]\nfrom_km = 5\nto_km = 12\nkind = "fog"\n')
    with pytest.raises(ScenarioError, match=r"s.toml: degraded\[0\].to_km: beyond the route's end"):
        load_navigation_scenario(p)


def test_missing_file_and_syntax_error(tmp_path):
    with pytest.raises(ScenarioError, match="navigation scenario not found"):
        load_navigation_scenario(tmp_path / "nope.toml")
    p = tmp_path / "bad.toml"
    p.write_text("[navigation\nname = 1\n")
    with pytest.raises(ScenarioError, match="bad.toml: TOML syntax error"):
        load_navigation_scenario(p)
    q = tmp_path / "noname.toml"
    q.write_text('[navigation]\nseed = 1\n')
    with pytest.raises(ScenarioError, match="navigation.name: missing"):
        load_navigation_scenario(q)


def test_key_reference_is_up_to_date_and_every_key_has_a_meaning():
    from pathlib import Path

    from reports.keyref import navigation_key_reference

    text = navigation_key_reference()
    rows = [line for line in text.splitlines() if line.startswith("| `")]
    assert len(rows) > 50
    assert not [r for r in rows if r.rstrip().endswith("|  |")], "a key without a meaning in NAV_MEANING"
    doc = Path(__file__).resolve().parents[1] / "docs" / "navigation-keys.md"
    assert doc.read_text() == text, "run: python -m reports.keyref --navigation > docs/navigation-keys.md"


def test_bench_navigation_figures_enter_the_history_with_their_direction():
    from reports.history import _lower_is_better, figures_of

    r = {"summary": {"final_horizontal_m": {"p95": 3.0, "median": 2.0}, "improvement_median": 900.0,
                     "nees_inside_fraction": 0.93}, "detection_tracking": {"total_ms": 12.0}}
    f = figures_of("navigation", r)
    assert f["navigation.final_horizontal_p95_m"] == 3.0 and f["navigation.detection_tracking_s"] == 0.012
    assert _lower_is_better("navigation.final_horizontal_p95_m") is True
    assert _lower_is_better("navigation.detection_tracking_s") is True
    assert _lower_is_better("navigation.improvement_median") is False
    assert _lower_is_better("navigation.nees_inside_fraction") is False


def test_degraded_flags_and_wrong_fixes_on_a_synthetic_dataset():
    import numpy as np
    import xarray as xr

    from reports.bench_navigation import degraded_flags, wrong_fixes

    sc = load_navigation_scenario("nav_degraded")
    d = np.array([10e3, 21e3, 23e3, 30e3, 44e3, 55e3])
    status = np.array([["ok", "no", "no", "ok", "no", "ok"]])
    err = np.zeros((1, 6, 3))
    err[0, 5, 0] = 10.0                          # a fix 10 m off with σ 1 m: wrong
    sig = np.ones((1, 6, 3))
    sig[0, 1:3, :] = [[2, 2, 2], [3, 3, 3]]
    ds = xr.Dataset({"update_distance_m": (("update",), d), "update_status": (("seed", "update"), status),
                     "update_error": (("seed", "update", "axis"), err),
                     "update_sigma": (("seed", "update", "axis"), sig)})
    fl = degraded_flags(ds, sc)
    # desert 20–32 km seen only up to 32 − 7 km; fog 42–50 km
    assert fl["updates_inside"] == 3 and fl["fixes_inside"] == 0 and fl["flagged_no_aiding_fraction"] == 1.0
    w = wrong_fixes(ds)
    assert (w["fixes"], w["wrong"]) == (3, 1)


def test_a_route_too_short_for_any_aiding_sequence_is_named():
    from navigation.run import NavigationRun

    run = NavigationRun(load_navigation_scenario("nav_tiny", overrides={"route.length_km": 1.5}), progress=False)
    with pytest.raises(ScenarioError, match="aiding.first_s: no aiding sequence fits"):
        run.render_sequences()
