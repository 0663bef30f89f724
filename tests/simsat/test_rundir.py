"""Run directories: no user file ever deleted, one writer at a time, provenance, scenario paths."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

import simsat_cli as cli
from simsat.config import ScenarioError
from simsat.rundir import (RunDirError, RunLock, check_consistency, clean_stale_parts, content_id,
                           is_simsat_run, prepare_output_dir, read_ids)
from simsat.scenario import SCENARIO_DIR, builtin_scenarios, find_scenario, load_scenario

SMALL = ["--set", "acquisition.lines=96", "--quiet"]


def _cli(capsys, *argv):
    rc = cli.main(list(argv))
    out, err = capsys.readouterr()
    assert "Traceback" not in err and "internal error" not in err, err
    return rc, out, err


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    """One small rendered run, copied by tests that modify it."""
    d = tmp_path_factory.mktemp("rendered") / "run"
    assert cli.main(["render", "tiny", "--out", str(d), *SMALL]) == 0
    return d


def _copy(src: Path, dst: Path) -> Path:
    dst.mkdir(parents=True, exist_ok=True)
    for f in src.iterdir():
        if f.is_file():
            (dst / f.name).write_bytes(f.read_bytes())
    return dst


# --------------------------------------------------------------------------- scenario paths
def test_builtin_scenarios_are_real_files_of_the_top_level_folder():
    repo_scenarios = Path(__file__).resolve().parents[2] / "scenarios"
    assert (repo_scenarios / "phr_cmg.toml").is_file() and not (repo_scenarios / "phr_cmg.toml").is_symlink()
    assert SCENARIO_DIR == repo_scenarios.resolve()
    assert {"phr_cmg", "tiny", "phr_full"} <= set(builtin_scenarios())


def test_missing_path_is_an_error_not_the_builtin_of_that_stem(tmp_path):
    with pytest.raises(ScenarioError, match="not found"):
        find_scenario(tmp_path / "nowhere" / "phr_cmg.toml")
    with pytest.raises(ScenarioError, match="no built-in scenario"):
        find_scenario("phr_cmgg")
    assert find_scenario("phr_cmg") == builtin_scenarios()["phr_cmg"]


def test_validate_cli_refuses_missing_path(capsys, tmp_path):
    rc, out, err = _cli(capsys, "validate", str(tmp_path / "phr_cmg.toml"))
    assert rc == 2 and "phr_cmg.toml: scenario file not found" in err


# --------------------------------------------------------------------------- --out safety
def test_render_refuses_a_foreign_non_empty_directory(capsys, tmp_path):
    d = tmp_path / "precious"
    d.mkdir()
    (d / "thesis.txt").write_text("x")
    rc, out, err = _cli(capsys, "render", "tiny", "--out", str(d), *SMALL)
    assert rc == 2 and "not a simsat run" in err and "--force" in err
    assert sorted(p.name for p in d.iterdir()) == ["thesis.txt"]


def test_render_dot_in_a_foreign_directory_is_refused(capsys, tmp_path, monkeypatch):
    (tmp_path / "notes.md").write_text("mine")
    monkeypatch.chdir(tmp_path)
    rc, out, err = _cli(capsys, "render", "tiny", "--out", ".", *SMALL)
    assert rc == 2 and "not a simsat run" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.md"]


def test_force_writes_beside_user_files_and_keeps_them(capsys, tmp_path):
    d = tmp_path / "mixed"
    d.mkdir()
    (d / "thesis.txt").write_text("x")
    rc, out, err = _cli(capsys, "render", "tiny", "--out", str(d), "--force", *SMALL)
    assert rc == 0
    assert (d / "thesis.txt").read_text() == "x"
    assert is_simsat_run(d) and (d / "product.nc").is_file()


def test_rerender_keeps_user_files_removes_stale_outputs_and_says_so(capsys, tmp_path, rendered):
    d = _copy(rendered, tmp_path / "run")
    (d / "restoration.nc").write_bytes(b"old restoration")
    (d / "my_notes.txt").write_text("keep me")
    (d / "report").mkdir()
    (d / "report" / "index.html").write_text("old")
    (d / "report" / ".simsat-manifest.json").write_text(json.dumps({"files": ["index.html"]}))
    (d / "report" / "my_plot.png").write_bytes(b"user")
    rc, out, err = _cli(capsys, "render", "tiny", "--out", str(d), *SMALL)
    assert rc == 0
    assert (d / "my_notes.txt").read_text() == "keep me"
    assert (d / "report" / "my_plot.png").read_bytes() == b"user"
    assert not (d / "report" / "index.html").exists()
    assert not (d / "restoration.nc").exists()
    assert "restoration.nc" in err and "replaced" in err


def test_output_path_that_is_a_file_is_refused(tmp_path):
    f = tmp_path / "afile"
    f.write_text("x")
    with pytest.raises(RunDirError, match="not a directory"):
        prepare_output_dir(f)


def test_crashed_render_leaves_no_product_and_no_part(tmp_path, monkeypatch):
    from simsat import simulate as sim

    def boom(*a, **k):
        raise RuntimeError("disk on fire")

    monkeypatch.setattr(sim, "atomic_write_json", boom)
    d = tmp_path / "crash"
    sc = load_scenario("tiny", overrides={"acquisition": {"lines": 64}})
    with pytest.raises(RuntimeError, match="disk on fire"):
        sim.simulate(sc, d, progress=False)
    assert not any(p.name.endswith(".nc") or p.name == "run.json" for p in d.iterdir())
    assert not any(p.name.endswith(".part") for p in d.iterdir())


# --------------------------------------------------------------------------- locking
def test_second_writer_is_refused_with_the_holder_named(tmp_path):
    d = tmp_path / "locked"
    d.mkdir()
    with RunLock(d, "restore"):
        with pytest.raises(RunDirError, match="another simsat process.*simsat restore, pid"):
            with RunLock(d, "render"):
                pass
    with RunLock(d, "render"):  # released
        pass


def test_cli_render_into_a_locked_run_is_refused(capsys, tmp_path, rendered):
    d = _copy(rendered, tmp_path / "run")
    with RunLock(d, "restore"):
        rc, out, err = _cli(capsys, "render", "tiny", "--out", str(d), *SMALL)
    assert rc == 2 and "another simsat process" in err


def test_stale_part_files_of_simsat_are_cleaned_others_kept(tmp_path):
    d = tmp_path / "r"
    d.mkdir()
    (d / ".product.nc.k3j2h1x9.part").write_bytes(b"half")
    (d / ".render.ab12cd34.part").mkdir()
    (d / ".render.ab12cd34.part" / "product.nc").write_bytes(b"half")
    (d / ".mydata.abcdef12.part").write_bytes(b"user's")
    removed = clean_stale_parts(d)
    assert sorted(removed) == [".product.nc.k3j2h1x9.part", ".render.ab12cd34.part"]
    assert (d / ".mydata.abcdef12.part").exists()


# --------------------------------------------------------------------------- provenance
def test_ids_are_deterministic_and_recorded(rendered, tmp_path):
    pid = read_ids(rendered / "product.nc")["product_id"]
    assert read_ids(rendered / "truth.nc")["product_id"] == pid
    assert json.loads((rendered / "run.json").read_text())["product_id"] == pid
    assert content_id({"a": 1, "b": [1.5]}) == content_id({"b": [1.5], "a": 1})
    assert content_id({"a": 1}) != content_id({"a": 2})


def test_files_of_two_runs_are_detected(tmp_path, rendered):
    import xarray as xr

    d = _copy(rendered, tmp_path / "run")
    check_consistency(d)  # a fresh render is consistent
    t = xr.load_dataset(d / "truth.nc")
    t.attrs["product_id"] = "0123456789abcdef"
    t.to_netcdf(d / "truth.nc")
    with pytest.raises(RunDirError, match="truth.nc: comes from another product"):
        check_consistency(d)


@pytest.fixture(scope="module")
def restored(tmp_path_factory, rendered):
    d = _copy(rendered, tmp_path_factory.mktemp("restored") / "run")
    assert cli.main(["restore", str(d), "--quiet"]) == 0
    return d


def test_restore_records_ids_and_report_refuses_a_mixed_set(capsys, tmp_path, restored):
    import xarray as xr

    pid = read_ids(restored / "product.nc")["product_id"]
    ids = read_ids(restored / "restoration.nc")
    assert ids["product_id"] == pid and len(ids["restoration_id"]) == 16
    assert read_ids(restored / "corrected.nc") == ids
    d = _copy(restored, tmp_path / "run")
    c = xr.load_dataset(d / "corrected.nc")
    c.attrs["restoration_id"] = "ffffffffffffffff"
    c.to_netcdf(d / "corrected.nc")
    rc, out, err = _cli(capsys, "report", str(d), "--quiet")
    assert rc == 2 and "corrected.nc: made by another restoration" in err
    assert not (d / "report" / "index.html").exists()


def test_restore_prints_the_restored_error_and_verdict(capsys, tmp_path, rendered):
    d = _copy(rendered, tmp_path / "run")
    rc, out, err = _cli(capsys, "restore", str(d), "--quiet")
    assert rc == 0
    assert "restored error" in out and "AOCS knowledge" in out
    for axis in ("roll", "pitch"):
        assert axis in out
    assert "requirement" in out and ("PASS" in out or "FAIL" in out)


def test_report_on_a_missing_run_creates_nothing(capsys, tmp_path):
    d = tmp_path / "nope"
    rc, out, err = _cli(capsys, "report", str(d))
    assert rc == 2 and "does not exist" in err
    assert not d.exists()


def test_restore_killed_between_its_writes_is_detected(capsys, tmp_path, restored, monkeypatch):
    """A restore with other settings that dies after corrected.nc: the report refuses the mixed pair."""
    import restore.pipeline as pl

    d = _copy(restored, tmp_path / "run")
    real = pl.atomic_write_dataset

    def write_then_die(ds, path, **kw):
        if Path(path).name == "restoration.nc":
            raise KeyboardInterrupt
        return real(ds, path, **kw)

    monkeypatch.setattr(pl, "atomic_write_dataset", write_then_die)
    with pytest.raises(KeyboardInterrupt):
        pl.restore_run(d, overrides={"min_quality": 0.55}, progress=False)
    monkeypatch.undo()
    assert not any(p.name.endswith(".part") for p in d.iterdir())
    rc, out, err = _cli(capsys, "report", str(d), "--quiet")
    assert rc == 2 and "made by another restoration" in err


def test_os_refusals_are_one_line_naming_the_path(capsys, tmp_path):
    f = tmp_path / "afile"
    f.write_text("x")
    rc, out, err = _cli(capsys, "figures", "--out", str(f), "--no-monte-carlo")
    assert rc == 2 and str(f) in err and "in the way" in err
    assert f.read_text() == "x"


def test_run_chains_the_stages_in_their_own_processes_and_ends_with_the_result(capfd, tmp_path):
    d = tmp_path / "whole"
    rc = cli.main(["run", "tiny", "--out", str(d), *SMALL])
    out, err = capfd.readouterr()
    assert rc == 0, err
    assert "Traceback" not in err and "internal error" not in err
    assert (d / "report" / "index.html").is_file() and (d / "restoration.nc").is_file()
    assert out.count("restored error") == 1 and "requirement" in out and str(d / "report" / "index.html") in out
    rc = cli.main(["run", "tiny", "--out", str(d), "--set", "acquisition.lines=-3", "--quiet"])
    out, err = capfd.readouterr()
    assert rc == 2 and "acquisition.lines" in err  # refused before any stage starts
