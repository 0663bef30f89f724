"""Accuracy history: records appended atomically, compare flags a regression beyond the run-to-run noise."""
import json

import pytest

from reports.bench import bench_end_to_end
from reports.history import (
    HistoryError,
    append_record,
    compare,
    figures_of,
    format_comparison,
    make_record,
    read_history,
)


def _record(figures, settings=None, benchmark="regression"):
    return {"date": "2026-11-24T00:00:00", "commit": "abc", "machine": {}, "benchmark": benchmark,
            "settings": settings or {"scenario": None}, "figures": figures}


def test_append_and_read_back(tmp_path):
    h = tmp_path / "history.jsonl"
    append_record(_record({"tiny.roll.rms_px": 0.1}), h)
    append_record(_record({"tiny.roll.rms_px": 0.2}), h)
    recs = read_history(h)
    assert [r["figures"]["tiny.roll.rms_px"] for r in recs] == [0.1, 0.2]
    assert h.read_text().count("\n") == 2


def test_a_corrupt_line_is_named(tmp_path):
    h = tmp_path / "history.jsonl"
    append_record(_record({"a.roll.rms_px": 0.1}), h)
    with h.open("a") as f:
        f.write("{not json\n")
    with pytest.raises(HistoryError, match="line 2"):
        read_history(h)


def test_direction_and_default_tolerance():
    recs = [_record({"s.roll.rms_px": 0.100, "s.roll.coverage": 0.99, "s.restore_s": 10.0}),
            _record({"s.roll.rms_px": 0.104, "s.roll.coverage": 0.90, "s.restore_s": 5.0})]
    _, _, ch = compare(recs)
    by = {c.name: c for c in ch}
    assert not by["s.roll.rms_px"].regression          # +4 %: within the 5 % default
    assert by["s.roll.coverage"].regression             # coverage down 9 %: worse
    assert by["s.restore_s"].improvement and not by["s.restore_s"].regression


def test_noise_measured_from_the_history_widens_the_tolerance():
    vals = [0.100, 0.120, 0.090, 0.110, 0.125]
    recs = [_record({"s.roll.rms_px": v}) for v in vals]
    _, _, ch = compare(recs)
    assert ch[0].noise_from_history and not ch[0].regression
    _, _, ch = compare(recs[:-1] + [_record({"s.roll.rms_px": 0.25})])
    assert ch[0].regression


def test_only_the_same_settings_are_compared():
    recs = [_record({"s.roll.rms_px": 0.1}, {"lines": 100}), _record({"s.roll.rms_px": 0.5}, {"lines": 200})]
    prev, latest, ch = compare(recs)
    assert prev is None and ch == [] and "no earlier record" in format_comparison(prev, latest, ch)


@pytest.mark.slow
def test_a_deliberately_degraded_setting_is_flagged_as_a_regression(tmp_path):
    """The real bench on `tiny`, twice the same (no regression: same seed, same bytes), then with a degraded
    restoration (8 points per line, an 11-column window): flagged."""
    h = tmp_path / "history.jsonl"
    settings = {"scenario": "tiny", "lines": None, "seed": 0}
    for k, over in enumerate([None, None, {"restoration": {"points_per_line": 8, "window_columns": 11}}]):
        e = bench_end_to_end(scenario="tiny", run_dir=str(tmp_path / f"run{k}"), overrides=over)
        rec = make_record("regression", {"runs": [e]}, settings=settings)
        append_record(rec, h)
        prev, latest, ch = compare(read_history(h))
        if k == 1:
            assert prev is not None and ch and not any(c.regression for c in ch if not c.name.endswith("_s"))
            assert all(c.previous == c.latest for c in ch if c.name.endswith("rms_px"))
    regressions = [c.name for c in ch if c.regression]
    assert any(n.startswith("tiny.") and n.endswith("rms_px") for n in regressions), format_comparison(prev, latest, ch)
    assert json.loads(h.read_text().splitlines()[-1])["figures"] == figures_of("regression", {"runs": [e]})


def test_cli_compare_exits_1_on_a_regression_and_names_it(tmp_path, capsys):
    from simsat_cli import main

    h = tmp_path / "history.jsonl"
    append_record(_record({"s.roll.rms_px": 0.02}), h)
    append_record(_record({"s.roll.rms_px": 0.02}), h)
    assert main(["bench", "compare", "--history", str(h)]) == 0
    append_record(_record({"s.roll.rms_px": 0.03}), h)
    assert main(["bench", "compare", "--history", str(h)]) == 1
    assert "REGRESSION" in capsys.readouterr().out
    h.write_text("garbage\n")
    assert main(["bench", "compare", "--history", str(h)]) == 2
    assert "line 1" in capsys.readouterr().err


def test_robustness_rows_record_the_matching_lock_higher_is_better():
    row = {"scenario": "large_amplitude", "errors": {"roll": {"rms_px": 0.02}},
           "matching": {"pair": "B1/B2", "lock": 0.998, "valid_restored": 0.789, "valid_true": 0.791}}
    figs = figures_of("robustness", {"rows": [row]})
    assert figs["large_amplitude.matching.lock"] == 0.998
    assert figs["large_amplitude.matching.valid_restored"] == 0.789
    assert "large_amplitude.matching.valid_true" not in figs      # the images' own limit, not the algorithm's
    assert figures_of("robustness", {"rows": [{**row, "matching": {"error": "ValueError: x"}}]}).keys() == \
        {"large_amplitude.roll.rms_px"}
    _, _, ch = compare([_record({"s.matching.lock": 0.99}), _record({"s.matching.lock": 0.90})])
    assert ch[0].regression
