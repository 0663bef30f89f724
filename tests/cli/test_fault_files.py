"""Fault injection on run files: corrupt, truncated, inconsistent or misplaced inputs.

Every fault gets exit code 2 and one line naming the file and the variable
(or key) at fault; nothing is drawn from an invalid restoration; no user file
is deleted.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

import simsat_cli as cli


@pytest.fixture(scope="module")
def restored(tmp_path_factory):
    d = tmp_path_factory.mktemp("faults") / "run"
    assert cli.main(["render", "tiny", "--out", str(d), "--set", "acquisition.lines=96", "--quiet"]) == 0
    assert cli.main(["restore", str(d), "--quiet"]) == 0
    return d


def _copy(src: Path, dst: Path) -> Path:
    dst.mkdir(parents=True)
    for f in src.iterdir():
        if f.is_file() and not f.name.startswith("."):
            (dst / f.name).write_bytes(f.read_bytes())
    return dst


def _run(capsys, *argv):
    rc = cli.main(list(argv))
    out, err = capsys.readouterr()
    assert "Traceback" not in err and "internal error" not in err, err
    return rc, err


def _edit(path: Path, fn) -> None:
    ds = xr.load_dataset(path)
    ds = fn(ds) or ds
    path.unlink()
    ds.to_netcdf(path)


def _nan_times(ds):
    t = ds["time"].values.copy()
    t[10] = np.nan
    ds["time"] = ("line", t, ds["time"].attrs)


def _reversed_times(ds):
    t = ds["time"].values.copy()
    t[20], t[21] = t[21], t[20]
    ds["time"] = ("line", t, ds["time"].attrs)


def _nan_image(ds):
    img = ds["image_B0"].values.astype(np.float32)
    img[5, 7] = np.nan
    ds["image_B0"] = (ds["image_B0"].dims, img)


def _zero_band(ds):
    ds["image_B2"] = (ds["image_B2"].dims, np.zeros_like(ds["image_B2"].values))


PRODUCT_FAULTS = [
    ("nan_times", _nan_times, "product.nc", "'time'"),
    ("times_not_increasing", _reversed_times, "product.nc", "'time'"),
    ("missing_knowledge", lambda ds: ds.drop_vars("knowledge_roll"), "product.nc", "knowledge_roll"),
    ("missing_attr", lambda ds: ds.attrs.pop("line_period_s") and None, "product.nc", "line_period_s"),
    ("nan_image", _nan_image, "product.nc", "image_B0"),
    ("zero_band", _zero_band, "product.nc", "image_B2"),
    ("missing_band", lambda ds: ds.drop_vars("image_B3"), "product.nc", "image_B3"),
]


@pytest.mark.parametrize("name,fault,file,var", PRODUCT_FAULTS, ids=[f[0] for f in PRODUCT_FAULTS])
def test_corrupt_product_is_refused_by_restore(capsys, tmp_path, restored, name, fault, file, var):
    d = _copy(restored, tmp_path / "run")
    _edit(d / file, fault)
    rc, err = _run(capsys, "restore", str(d), "--quiet")
    assert rc == 2 and file in err and var in err, err
    assert err.count("\n") == 1


@pytest.mark.parametrize("name,fault,file,var", [f for f in PRODUCT_FAULTS if f[0] not in ("nan_image", "zero_band")],
                         ids=[f[0] for f in PRODUCT_FAULTS if f[0] not in ("nan_image", "zero_band")])
def test_corrupt_product_is_refused_by_report(capsys, tmp_path, restored, name, fault, file, var):
    d = _copy(restored, tmp_path / "run")
    _edit(d / file, fault)
    rc, err = _run(capsys, "report", str(d), "--quiet")
    assert rc == 2 and file in err and var in err, err
    assert not (d / "report" / "index.html").exists()


def _truncate(path: Path) -> None:
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])


def _all_nan(ds):
    for a in ("roll", "pitch"):
        ds[a] = ("time", np.full(ds.sizes["time"], np.nan), ds[a].attrs)


def _shorter(ds):
    return ds.isel(time=slice(0, ds.sizes["time"] - 5))


RESTORATION_FAULTS = [
    ("truncated", "truncate", "restoration.nc", "cannot read"),
    ("not_netcdf", "garbage", "restoration.nc", "cannot read"),
    ("missing_variable", lambda ds: ds.drop_vars("correction_pitch"), "restoration.nc", "correction_pitch"),
    ("other_length", _shorter, "restoration.nc", "'time'"),
    ("all_nan", _all_nan, "restoration.nc", "NaN on every line"),
    ("truth_missing_axis", lambda ds: ds.drop_vars("yaw"), "truth.nc", "'yaw'"),
    ("truth_nan", lambda ds: ds.assign(roll=ds["roll"] * np.nan), "truth.nc", "'roll'"),
]


@pytest.mark.parametrize("name,fault,file,expect", RESTORATION_FAULTS, ids=[f[0] for f in RESTORATION_FAULTS])
def test_inconsistent_run_files_are_refused_not_drawn(capsys, tmp_path, restored, name, fault, file, expect):
    d = _copy(restored, tmp_path / "run")
    if fault == "truncate":
        _truncate(d / file)
    elif fault == "garbage":
        (d / file).write_bytes(b"this is not a NetCDF file\n" * 10)
    else:
        _edit(d / file, fault)
    rc, err = _run(capsys, "report", str(d), "--quiet")
    assert rc == 2 and file in err and expect in err, err
    assert err.count("\n") == 1
    assert not (d / "report" / "index.html").exists()


@pytest.mark.parametrize("content", ["[1, 2, 3]", "{not json", '{"scenario": 3}'])
def test_malformed_run_json_is_named(capsys, tmp_path, restored, content):
    d = _copy(restored, tmp_path / "run")
    (d / "run.json").write_text(content)
    rc, err = _run(capsys, "restore", str(d), "--quiet")
    assert rc == 2 and "run.json" in err, err


def test_product_file_given_for_a_run_directory(capsys, restored):
    rc, err = _run(capsys, "restore", str(restored / "product.nc"), "--quiet")
    assert rc == 2 and "is a file" in err and "run directory" in err
    rc, err = _run(capsys, "report", str(restored / "product.nc"))
    assert rc == 2 and "is a file" in err


def test_report_directory_that_is_a_file(capsys, tmp_path, restored):
    d = _copy(restored, tmp_path / "run")
    (d / "report").write_text("my notes")
    rc, err = _run(capsys, "report", str(d), "--quiet")
    assert rc == 2 and "report" in err
    assert (d / "report").read_text() == "my notes"


@pytest.mark.skipif(hasattr(os, "geteuid") and os.geteuid() == 0, reason="root ignores permissions")
def test_read_only_run_directory(capsys, tmp_path, restored):  # pragma: no cover - not as root
    d = _copy(restored, tmp_path / "run")
    os.chmod(d, 0o555)
    try:
        rc, err = _run(capsys, "restore", str(d), "--quiet")
        assert rc == 2 and str(d) in err
    finally:
        os.chmod(d, 0o755)


def test_unwritable_run_directory_is_one_line(capsys, tmp_path, restored, monkeypatch):
    """As root permissions are not enforced, so the refusal is injected where simsat first writes."""
    import errno

    import simsat.rundir as rundir

    d = _copy(restored, tmp_path / "run")
    real_open = os.open

    def refuse(path, *a, **k):
        if str(path).startswith(str(d)):
            raise PermissionError(errno.EACCES, "Permission denied", str(path))
        return real_open(path, *a, **k)

    monkeypatch.setattr(rundir.os, "open", refuse)
    for argv in (["restore", str(d), "--quiet"], ["render", "tiny", "--out", str(d), "--quiet"],
                 ["report", str(d), "--quiet"]):
        rc, err = _run(capsys, *argv)
        assert rc == 2 and str(d) in err and "Permission denied" in err, (argv, err)
        assert err.count("\n") == 1
    assert sorted(p.name for p in d.iterdir()) == sorted(p.name for p in restored.iterdir() if not p.name.startswith("."))
