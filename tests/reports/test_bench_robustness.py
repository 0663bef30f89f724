"""The robustness bench's table: one row per stress scenario, a failing scenario recorded, not fatal."""
from reports.bench import _format_robustness


def test_robustness_table_rows_and_verdicts():
    ok = {"scenario": "low_snr", "errors": {a: {"rms_px": r, "p997_px": 3 * r, "knowledge_rms_px": 0.7}
                                            for a, r in (("roll", 0.03), ("pitch", 0.06))},
          "coverage": {"roll": 0.99, "pitch": 0.99}, "passed": False, "requirement_rms_px": 0.05,
          "unobservable_rms_px": {"roll": 0.001, "pitch": 0.002}, "floor_rms_px": {"roll": 0.01, "pitch": 0.02}}
    bad = {"scenario": "off_nadir", "error": "ScenarioError: scene.dem: too small"}
    text = "\n".join(_format_robustness({"rows": [ok, bad], "lines": None}))
    assert "low_snr" in text and "0.0300" in text and "0.0600" in text and "FAIL (> 0.05 px)" in text
    assert "0.001/0.002" in text and "0.010/0.020" in text
    assert "off_nadir" in text and "failed: ScenarioError: scene.dem: too small" in text


def test_robustness_table_gives_predicted_sigma_and_the_yaw_split():
    row = {"scenario": "off_nadir", "errors": {a: {"rms_px": r, "p997_px": 3 * r, "knowledge_rms_px": 0.7}
                                               for a, r in (("roll", 0.1), ("pitch", 0.45))},
           "coverage": {"roll": 0.99, "pitch": 0.99}, "passed": False, "requirement_rms_px": 0.05,
           "unobservable_rms_px": {"roll": 0.001, "pitch": 0.002}, "floor_rms_px": {"roll": 0.01, "pitch": 0.02},
           "predicted_detrended_rms_px": {"roll": 0.025, "pitch": 0.03}, "actual_over_predicted": {"roll": 4.0, "pitch": 15.0},
           "without_yaw_coupling_rms_px": {"pitch": 0.13}, "yaw_coupling": {"pitch": 0.364}}
    text = "\n".join(_format_robustness({"rows": [row], "lines": None}))
    assert "0.025/0.030" in text and "4.00/15.00" in text
    assert "pitch without the yaw seen as pitch (0.364 × missed yaw): 0.1300 px RMS" in text


def test_rows_say_which_other_criteria_they_miss():
    """Predicted σ within × 1.5 of the actual RMS (either way) and 95 % of the clear lines restored."""
    from reports.bench import unmet_criteria

    row = {"actual_over_predicted": {"roll": 1.44, "pitch": 1.86}, "coverage_of_clear_lines": {"roll": 0.996,
                                                                                               "pitch": 0.93}}
    assert unmet_criteria(row) == ["σ pitch × 1.86", "clear lines pitch 93.0 %"]
    assert unmet_criteria({"actual_over_predicted": {"roll": 0.25, "pitch": 0.9},
                           "coverage_of_clear_lines": {"roll": float("nan")}}) == ["σ roll × 0.25"]
    assert unmet_criteria({"actual_over_predicted": {"roll": 0.67, "pitch": 1.5}}) == []
    ok = {"scenario": "damped_chirp", "errors": {a: {"rms_px": 0.03, "p997_px": 0.1, "knowledge_rms_px": 1.2}
                                                 for a in ("roll", "pitch")},
          "coverage": {"roll": 0.99, "pitch": 0.99}, "passed": True, "requirement_rms_px": 0.05,
          "unobservable_rms_px": {"roll": 0.001, "pitch": 0.002}, "floor_rms_px": {"roll": 0.01, "pitch": 0.02},
          "unmet": ["σ pitch × 1.86"]}
    assert "PASS; not met: σ pitch × 1.86" in "\n".join(_format_robustness({"rows": [ok], "lines": None}))


def test_regression_table_counts_and_verdicts():
    from reports.bench import _format_regression

    runs = [{"scenario": "phr_cmg", "errors": {"roll": {"rms_px": 0.025}, "pitch": {"rms_px": 0.027}},
             "requirement_rms_px": 0.05, "passed": True},
            {"scenario": "stress_off_nadir", "errors": {"roll": {"rms_px": 0.1}, "pitch": {"rms_px": 0.46}},
             "requirement_rms_px": 0.05, "passed": False},
            {"scenario": "broken", "error": "ScenarioError: x", "passed": False}]
    text = "\n".join(_format_regression({"runs": runs, "lines": None, "passed": 1, "total": 3}))
    assert "1 of 3 scenarios meet their requirement" in text
    assert "phr_cmg" in text and "PASS" in text and "stress_off_nadir" in text and "FAIL" in text
    assert "broken" in text and "failed: ScenarioError: x" in text


def test_axis_verdict_follows_the_done_when():
    """Outright within the requirement; otherwise only once a non-negligible unobservable part is removed."""
    from reports.bench import axis_verdict

    assert axis_verdict(0.04, 0.04, 0.05) == "pass"
    assert axis_verdict(0.456, 0.043, 0.05) == "pass outside"         # off nadir: the yaw seen as pitch
    assert axis_verdict(0.0546, 0.054, 0.05) == "fail"                # outside the requirement too
    assert axis_verdict(0.0503, 0.0499, 0.05) == "fail"               # 0.006 px "unobservable": negligible
    assert axis_verdict(0.06, float("nan"), 0.05) == "fail"


def test_a_row_passing_only_outside_the_unobservable_part_says_so():
    row = {"scenario": "real_aocs", "errors": {a: {"rms_px": r, "p997_px": 3 * r, "knowledge_rms_px": 0.7}
                                               for a, r in (("roll", 0.028), ("pitch", 0.0996))},
           "coverage": {"roll": 0.99, "pitch": 0.99}, "passed": True, "passed_outright": False,
           "requirement_rms_px": 0.05, "unobservable_rms_px": {"roll": 0.001, "pitch": 0.002},
           "floor_rms_px": {"roll": 0.01, "pitch": 0.02},
           "unobservable_measured_px": {"roll": {"yaw_rms": 0.0, "trend_rms": 0.0138, "band_rms": 0.0009},
                                        "pitch": {"yaw_rms": 0.0, "trend_rms": 0.0958, "band_rms": 0.0019}}}
    text = "\n".join(_format_robustness({"rows": [row], "lines": None}))
    assert "PASS outside the unobservable part" in text
    assert "pitch: trend 0.096, band 0.002" in text


def test_suite_overrides_reach_every_run_and_are_recorded(monkeypatch, tmp_path):
    """``simsat bench robustness --set KEY=VALUE``: the override goes to every scenario's run (in its own
    scratch directory), into the result and the history, and the JSON defaults to bench/robustness_set.json."""
    import json

    from reports import bench

    calls = []

    def fake_end_to_end(**kw):
        calls.append(kw)
        raise RuntimeError("not rendered in this test")

    monkeypatch.setattr(bench, "bench_end_to_end", fake_end_to_end)
    monkeypatch.setattr(bench, "stress_scenarios", lambda: {"one": tmp_path / "one.toml"})
    monkeypatch.chdir(tmp_path)
    over = {"restoration": {"noise_colour_weighting": True}}
    result = bench.run_bench("robustness", overrides=over, history=tmp_path / "history.jsonl")
    assert calls and calls[0]["overrides"] == over and calls[0]["tag"] == "stress_set"
    assert result["result"]["rows"][0]["error"].startswith("RuntimeError")
    assert result["_path"] == "bench/robustness_set.json" and result["overrides"] == over
    assert json.loads((tmp_path / "bench" / "robustness_set.json").read_text())["overrides"] == over
    record = json.loads((tmp_path / "history.jsonl").read_text().splitlines()[-1])
    assert record["settings"]["overrides"] == over


def test_overrides_are_refused_where_a_benchmark_does_not_take_them(monkeypatch, capsys):
    import pytest

    from reports import bench
    import simsat_cli

    with pytest.raises(ValueError, match="only the robustness and regression"):
        bench.run_bench("render", overrides={"acquisition": {"lines": 64}}, history=None)
    rc = simsat_cli.main(["bench", "matching", "--set", "restoration.noise_colour_weighting=true"])
    assert rc != 0 and "--set: only `simsat bench robustness / regression`" in capsys.readouterr().err


def test_robustness_table_says_whether_matching_stays_locked():
    from reports.bench import matching_lock_line

    row = {"scenario": "large_amplitude", "errors": {a: {"rms_px": 0.02, "p997_px": 0.06, "knowledge_rms_px": 2.7}
                                                     for a in ("roll", "pitch")},
           "coverage": {"roll": 0.99, "pitch": 0.99}, "passed": True, "requirement_rms_px": 0.05,
           "unobservable_rms_px": {"roll": 0.001, "pitch": 0.002}, "floor_rms_px": {"roll": 0.01, "pitch": 0.02},
           "matching": {"pair": "B1/B2", "valid_restored": 0.7894, "valid_true": 0.7907, "lock": 0.9983,
                        "lost": 0.0083, "shift_rms_restored_px": 0.6514, "shift_rms_true_px": 0.6515}}
    text = "\n".join(_format_robustness({"rows": [row], "lines": None}))
    assert "matching (B1/B2, the worst pair): 78.9 % valid under the restored attitude, 79.1 % under the true " \
           "one (lock 99.8 %, 0.8 % lost)" in text
    failed = matching_lock_line({"error": "ProductError: truth.nc missing"})
    assert failed == "matching lock not measured: ProductError: truth.nc missing"
    assert matching_lock_line(None) is None and matching_lock_line({}) is None
