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
