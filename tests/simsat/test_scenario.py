"""Scenario loading and validation: every error names the TOML key or the file."""
import subprocess
import sys
import tomllib

import pytest

from simsat.config import ScenarioError, Section
from simsat.scenario import builtin_scenarios, load_scenario

BUILTIN = builtin_scenarios()


def _raw(name="tiny"):
    with open(BUILTIN[name], "rb") as fh:
        return tomllib.load(fh)


def _err(raw) -> str:
    with pytest.raises(ScenarioError) as e:
        load_scenario(raw)
    msg = str(e.value)
    assert "\n" not in msg
    return msg


@pytest.mark.parametrize("name", sorted(BUILTIN))
def test_builtin_scenarios_validate(name):
    sc = load_scenario(name)
    assert sc.acquisition.lines > 0
    assert sc.x_range_m[0] < 0 < sc.x_range_m[1]


def test_phr_cmg_has_the_cnes_delays():
    sc = load_scenario("phr_cmg")
    assert sc.delay_s("B1", "B0") == pytest.approx(7.4e-3, rel=1e-6)
    assert sc.delay_s("B0", "B2") == pytest.approx(14.8e-3, rel=1e-6)
    assert sc.delay_s("B1", "B2") == pytest.approx(22.2e-3, rel=1e-6)
    assert sc.instrument.ifov_rad() == pytest.approx(4.03e-6, rel=1e-2)
    assert sc.line_period_s == pytest.approx(0.4e-3)


def test_wrong_type_names_the_key():
    raw = _raw()
    raw["instrument"]["focal_length_m"] = "long"
    assert "instrument.focal_length_m: must be a number" in _err(raw)


def test_unknown_key_is_named_with_the_allowed_ones():
    raw = _raw()
    raw["platform"]["altitude"] = 5
    msg = _err(raw)
    assert "platform.altitude: unknown key" in msg and "altitude_m" in msg


def test_negative_line_period():
    raw = _raw()
    raw["instrument"]["line_period_ms"] = -0.4
    assert "instrument.line_period_ms: must be >= 0.001, got -0.4" in _err(raw)


def test_detector_off_the_focal_plane():
    raw = _raw()
    raw["instrument"]["detectors"][1]["along_track_mm"] = 50.0
    msg = _err(raw)
    assert "instrument.detectors[1].along_track_mm" in msg and "off the focal plane" in msg


def test_negative_jitter_frequency_names_the_array_index():
    raw = _raw()
    raw["attitude"]["jitter"].append({"kind": "harmonic", "axis": "roll", "frequency_hz": -3, "amplitude_urad": 1.0})
    idx = len(raw["attitude"]["jitter"]) - 1
    assert f"attitude.jitter[{idx}].frequency_hz: must be > 0, got -3" in _err(raw)


def test_missing_dem_file(tmp_path):
    raw = _raw()
    raw["scene"]["dem"] = {"kind": "geotiff", "path": "no_such_dem.tif"}
    msg = _err(raw)
    assert "scene.dem.path" in msg and "no_such_dem.tif" in msg


def test_unknown_top_level_table():
    raw = _raw()
    raw["orbit"] = {}
    assert "orbit: unknown key" in _err(raw)


def test_toml_syntax_error_names_file_and_line(tmp_path):
    p = tmp_path / "bad.toml"
    p.write_text("[scenario]\nname = \"x\"\nseed = = 3\n")
    with pytest.raises(ScenarioError) as e:
        load_scenario(p)
    assert str(p) in str(e.value) and "line 3" in str(e.value)


def test_overrides_and_section_helpers():
    sc = load_scenario("tiny", overrides={"acquisition": {"lines": 100}})
    assert sc.acquisition.lines == 100
    s = Section({"a": 1, "b": [1, 2]}, "x")
    assert s.integer("a") == 1
    assert s.numbers("b") == [1.0, 2.0]
    with pytest.raises(ScenarioError, match=r"x\.c: missing"):
        s.number("c")


def test_cli_validate_reports_one_line_without_traceback(tmp_path):
    raw = _raw()
    raw["instrument"]["line_period_ms"] = -1
    bad = tmp_path / "bad.toml"
    # write TOML by hand (no TOML writer in the stdlib)
    text = BUILTIN["tiny"].read_text().replace("line_period_ms = 0.4", "line_period_ms = -1")
    bad.write_text(text)
    p = subprocess.run([sys.executable, "-m", "simsat_cli", "validate", str(bad)], capture_output=True, text=True)
    assert p.returncode == 2
    assert "Traceback" not in p.stderr
    assert p.stderr.count("\n") == 1
    assert "instrument.line_period_ms: must be >= 0.001" in p.stderr and str(bad) in p.stderr
    ok = subprocess.run([sys.executable, "-m", "simsat_cli", "validate", "tiny"], capture_output=True, text=True)
    assert ok.returncode == 0, ok.stderr
    assert "OK" in ok.stdout


def test_a_scenario_can_derive_from_a_base(tmp_path):
    """[scenario] base: the base's tables overlaid key by key; arrays and tables of another kind replace."""
    from simsat.scenario import load_scenario

    (tmp_path / "d.toml").write_text('[scenario]\nbase = "tiny"\nname = "derived"\n\n[scene.sun]\nirradiance_scale = 0.5\n'
                                     '\n[scene.dem]\nkind = "matplotlib_sample"\n\n[[attitude.jitter]]\nkind = "harmonic"\n'
                                     'axis = "roll"\nfrequency_hz = 3.0\namplitude_urad = 1.0\n')
    sc = load_scenario(tmp_path / "d.toml")
    base = load_scenario("tiny")
    assert sc.name == "derived" and sc.seed == base.seed
    assert sc.sun().irradiance_scale == 0.5 and sc.sun().elevation_deg == base.sun().elevation_deg
    assert sc.raw["scene"]["dem"] == {"kind": "matplotlib_sample"}            # another kind: replaced
    assert [j["kind"] for j in sc.raw["attitude"]["jitter"]] == ["harmonic"]  # arrays replace
    assert sc.requirement.get("max_rms_px") is None                           # a requirement is not inherited
    assert sc.instrument == base.instrument


def test_a_base_that_leads_back_to_itself_is_refused(tmp_path):
    from simsat.scenario import load_scenario

    (tmp_path / "a.toml").write_text('[scenario]\nbase = "b.toml"\n')
    (tmp_path / "b.toml").write_text('[scenario]\nbase = "a.toml"\n')
    with pytest.raises(ScenarioError, match="leads back to itself"):
        load_scenario(tmp_path / "a.toml")


def test_every_stress_scenario_validates():
    from reports.bench import stress_scenarios
    from simsat.scenario import load_scenario

    suite = stress_scenarios()
    assert len(suite) >= 8
    for name, path in suite.items():
        sc = load_scenario(path)
        assert sc.name == f"stress_{name}" and sc.requirement["max_rms_px"] == 0.05
