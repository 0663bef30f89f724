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
