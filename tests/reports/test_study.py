"""Trade studies on Dask: the spec, the points, a local cluster, an external scheduler, resuming after a kill."""
import json
import socket
import subprocess
import sys
import time

import numpy as np
import pandas as pd
import pytest
import xarray as xr

from reports.study.evaluate import differential_point, evaluate_point
from reports.study.runner import RowStore, run_study
from reports.study.spec import key_override, load_study
from simsat.config import ScenarioError

STUDY = """
[study]
name = "small"
base = "phr_cmg"
level = "differential"
seeds = [0, 1]
lines = 800

[[study.sweep]]
name = "tau"
keys = ["instrument.detectors[0].along_track_mm", "instrument.detectors[2].along_track_mm"]
values = [[0.962, -1.924], [1.443, -2.886]]
labels = [1.0, 1.5]

[[study.sweep]]
key = "attitude.jitter[0].amplitude_urad"
values = [2.2]

[study.noise]
differential_noise_px = 0.1
"""


@pytest.fixture()
def study_file(tmp_path):
    p = tmp_path / "small.toml"
    p.write_text(STUDY)
    return p


def _table(path):
    df = pd.read_parquet(path)
    return df.drop(columns=[c for c in df.columns if c.endswith("_s")]).sort_values("key").reset_index(drop=True)


def test_points_are_the_product_of_the_axes_times_the_seeds(study_file):
    spec = load_study(study_file)
    pts = spec.points()
    assert len(pts) == 4 and len({p.key for p in pts}) == 4
    assert [p.design["tau"] for p in pts] == [1.0, 1.0, 1.5, 1.5]
    assert pts[2].overrides["instrument"]["detectors"][2]["along_track_mm"] == -2.886
    assert pts[3].overrides["scenario"]["seed"] == 1 and pts[3].overrides["acquisition"]["lines"] == 800
    assert [p.key for p in load_study(study_file).points()] == [p.key for p in pts]  # stable keys


@pytest.mark.parametrize("bad,match", [
    ('base = "nope"', "base"),
    ('seeds = 0', "seeds"),
    ('level = "fast"', "level"),
])
def test_bad_study_keys_are_named(tmp_path, bad, match):
    text = STUDY.replace('base = "phr_cmg"', bad) if "base" in bad else STUDY.replace('seeds = [0, 1]', bad) \
        if "seeds" in bad else STUDY.replace('level = "differential"', bad)
    p = tmp_path / "bad.toml"
    p.write_text(text)
    with pytest.raises(ScenarioError, match=match):
        load_study(p)


def test_a_sweep_over_a_key_the_scenario_refuses_is_named_with_its_design(tmp_path):
    p = tmp_path / "bad.toml"
    p.write_text(STUDY.replace("values = [2.2]", "values = [-5.0]"))
    with pytest.raises(ScenarioError, match="amplitude_urad"):
        load_study(p)
    with pytest.raises(ScenarioError, match="not a key name"):
        key_override("attitude.jitter[x].a", 1)


def test_differential_point_scores_the_restoration_and_a_failed_point_is_recorded():
    row = differential_point("phr_cmg", {"acquisition": {"lines": 800}}, noise_px=0.1, seed=0)
    assert 0 < row["roll_rms_px"] < row["roll_knowledge_rms_px"] / 5
    assert row["taus_ms"] == "7.400,22.200,14.800"
    bad = evaluate_point("differential", "phr_cmg", {"key": "k", "seed": 0, "design": {},
                                                      "overrides": {"acquisition": {"lines": -3}}},
                         noise_px=0.1, work_dir=".")
    assert bad["error"] and "lines" in bad["error"]


@pytest.mark.slow
def test_study_on_a_local_cluster_of_two_workers(study_file, tmp_path):
    spec = load_study(study_file)
    res = run_study(spec, tmp_path / "out", workers=2, progress=False)
    assert res["computed"] == 4 and len(res["rows"]) == 4 and not any(r["error"] for r in res["rows"])
    df = pd.read_parquet(res["paths"]["parquet"])
    assert list(df["design.tau"]) == [1.0, 1.0, 1.5, 1.5] and set(df["seed"]) == {0, 1}
    assert (df["roll_rms_px"] < 0.2).all()
    ds = xr.load_dataset(res["paths"]["netcdf"])
    assert ds["roll_rms_px"].dims == ("tau", "attitude.jitter[0].amplitude_urad", "seed")
    assert np.isfinite(ds["roll_rms_px"].values).all()
    # the same study again: nothing to compute, the same table
    again = run_study(spec, tmp_path / "out", workers=2, progress=False)
    assert again["computed"] == 0
    pd.testing.assert_frame_equal(_table(res["paths"]["parquet"]), _table(again["paths"]["parquet"]))


@pytest.mark.slow  # 45 s on 2 cores (a study killed mid-run and resumed); runs with -m slow
def test_killed_and_restarted_gives_the_uninterrupted_table(study_file, tmp_path):
    """A `simsat study` process killed once its first rows are written, then started again, ends with the
    table of an uninterrupted run; no row file is written twice."""
    out = tmp_path / "killed"
    cmd = [sys.executable, "-m", "simsat_cli", "study", str(study_file), "--out", str(out), "--workers", "1",
           "--quiet"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    rows = out / "rows"
    t0 = time.time()
    while time.time() - t0 < 120 and (not rows.exists() or len(list(rows.glob("*.json"))) < 1):
        time.sleep(0.2)
    proc.kill()
    proc.wait()
    first = {p.name: p.stat().st_mtime_ns for p in rows.glob("*.json")}
    assert 1 <= len(first) < 4, "the study should have been killed half-way"
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert f"{4 - len(first)} computed now" in done.stdout
    assert {p.name: p.stat().st_mtime_ns for p in rows.glob("*.json") if p.name in first} == first
    whole = run_study(load_study(study_file), tmp_path / "whole", workers=1, progress=False)
    pd.testing.assert_frame_equal(_table(out / "table.parquet"), _table(whole["paths"]["parquet"]))


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_study_on_a_separately_started_scheduler(study_file, tmp_path):
    port = _free_port()
    addr = f"tcp://127.0.0.1:{port}"
    sched = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                              "--port", str(port), "--no-dashboard"], stdout=subprocess.DEVNULL,
                             stderr=subprocess.DEVNULL)
    worker = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", addr, "--nworkers", "1",
                               "--nthreads", "1", "--no-dashboard"], stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL)
    try:
        res = run_study(load_study(study_file), tmp_path / "out", scheduler=addr, progress=False)
        assert res["computed"] == 4 and not any(r["error"] for r in res["rows"])
        assert json.loads((tmp_path / "out" / "study.json").read_text())["study"] == "small"
    finally:
        for p in (worker, sched):
            p.terminate()
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()


def test_row_store_never_writes_a_key_twice(tmp_path):
    st = RowStore(tmp_path)
    assert st.write({"key": "a", "v": 1}) and not st.write({"key": "a", "v": 2})
    assert st.rows(["a"]) == [{"key": "a", "v": 1}]


def test_the_noise_can_be_given_per_axis():
    row = differential_point("phr_cmg", {"acquisition": {"lines": 800}}, noise_px={"roll": 0.02, "pitch": 0.3},
                             seed=0)
    assert (row["roll_noise_px"], row["pitch_noise_px"]) == (0.02, 0.3)
    assert row["pitch_rms_px"] > 2 * row["roll_rms_px"]


def test_a_rendered_point_scores_the_full_chain_and_removes_its_run(tmp_path):
    row = evaluate_point("rendered", "tiny", {"key": "abc", "seed": 0, "design": {"x": 1.0}, "overrides": {}},
                         noise_px=None, work_dir=str(tmp_path))
    assert row["error"] == "" and row["design.x"] == 1.0
    assert 0 < row["roll_rms_px"] < row["roll_knowledge_rms_px"] and row["render_s"] > 0 and row["restore_s"] > 0
    assert not (tmp_path / "runs" / "abc").exists()


def test_simulated_gain_against_tau_over_the_fig14_curve(tmp_path):
    import pandas as pd

    from reports.study.outputs import _plot_gain, simulated_gain

    df = pd.DataFrame({"taus_ms": ["7.4,14.8,22.2", "7.4,14.8,22.2", "3.7,7.4,11.1", "3.7,7.4,11.1"],
                       "roll_rms_px": [0.02, 0.03, 0.05, 0.06], "roll_noise_px": [0.1, 0.1, 0.1, 0.1],
                       "pitch_rms_px": [0.02, 0.02, 0.04, 0.04], "pitch_noise_px": [0.2, 0.2, 0.2, 0.2]})
    g = simulated_gain(df)
    t, v = g["roll"]
    assert np.allclose(t, [7.4e-3, 7.4e-3, 3.7e-3, 3.7e-3]) and np.allclose(v, [0.2, 0.3, 0.5, 0.6])
    assert np.allclose(g["pitch"][1], [0.1, 0.1, 0.2, 0.2])

    class Spec:
        name, level, base = "t", "differential", "tiny"

    png = _plot_gain(Spec(), df, tmp_path / "gain.png")
    assert png is not None and png.stat().st_size > 10_000
    # one τ set only: nothing to plot against τ
    assert _plot_gain(Spec(), df.iloc[:2], tmp_path / "none.png") is None
