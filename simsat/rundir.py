"""Run directories: what simsat owns in them, locking, provenance.

A run directory holds the files simsat writes (:data:`SIMSAT_FILES`) and may
hold anything else the user put there; simsat never deletes a file it did not
write. Rules:

* ``simsat render --out DIR`` writes into a new or empty directory, or into a
  simsat run (replacing simsat's own files and removing the outputs derived
  from the previous product, which would no longer match it); a non-empty
  directory that is not a run is refused unless ``force`` is given, and even
  then only simsat's own file names are written.
* One writer at a time: every command that writes into a run directory holds
  :class:`RunLock` (an advisory ``flock`` on ``DIR/.simsat.lock``, released by
  the system when the process dies, so a killed run never leaves a stale lock).
* Provenance: ``product.nc`` and ``truth.nc`` carry a ``product_id`` (a hash of
  the resolved scenario, its seed and simsat's version: the same scenario gives
  the same bytes); ``restoration.nc`` carries that ``product_id`` and a
  ``restoration_id`` (hash of the product id and the restoration settings);
  ``corrected.nc`` carries both. :func:`check_consistency` refuses a set whose
  files come from different runs.
* Temporary files (``.NAME.XXXX.part``) left by a killed writer are removed by
  the next writer, which holds the lock.
"""
from __future__ import annotations

import errno
import hashlib
import json
import os
import re
import shutil
import time
from pathlib import Path

from .product import ProductError

__all__ = ["SIMSAT_FILES", "DERIVED_FILES", "RunDirError", "RunLock", "is_simsat_run", "prepare_output_dir",
           "clean_stale_parts", "install_files", "REPORT_MANIFEST", "content_id", "check_consistency", "read_ids"]

#: File names simsat writes in a run directory (the report is a directory).
SIMSAT_FILES = ("product.nc", "truth.nc", "run.json", "restoration.nc", "corrected.nc", "report", "navigation.nc")
#: Outputs derived from ``product.nc``: stale once the product is re-rendered.
DERIVED_FILES = ("restoration.nc", "corrected.nc", "report")
LOCK_NAME = ".simsat.lock"
_PART_RE = re.compile(r"^\.(?P<base>.+)\.[A-Za-z0-9_]{6,}\.part$")


class RunDirError(ProductError):
    """A run directory cannot be used as asked (message names the directory and the way out)."""


# --------------------------------------------------------------------------- identity
def content_id(*parts) -> str:
    """A short, stable hash of JSON-serialisable parts (16 hex digits).

    Used for ``product_id`` (resolved scenario + seed + version) and
    ``restoration_id`` (product id + settings). Deterministic: dict keys are
    sorted and floats written with ``repr``.
    """
    text = json.dumps(parts, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def is_simsat_run(path: str | Path) -> bool:
    """Whether ``path`` is a directory holding a run simsat wrote (a ``run.json`` of simsat's)."""
    p = Path(path)
    rj = p / "run.json"
    if not p.is_dir() or not rj.is_file():
        return False
    try:
        info = json.loads(rj.read_text())
    except (OSError, ValueError):
        return False
    return isinstance(info, dict) and "scenario" in info and isinstance(info.get("files"), dict)


def _entries(path: Path) -> list[str]:
    return sorted(e.name for e in os.scandir(path) if e.name != LOCK_NAME and not _PART_RE.match(e.name))


def prepare_output_dir(out_dir: str | Path, *, force: bool = False) -> Path:
    """Check that a render may write into ``out_dir`` and create it if needed.

    Raises
    ------
    RunDirError
        ``out_dir`` is a file; or a non-empty directory that is not a simsat
        run and ``force`` is false; or it cannot be created.
    """
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise RunDirError(f"{out}: exists and is not a directory; give --out a directory")
    if out.is_dir():
        foreign = [n for n in _entries(out) if n not in SIMSAT_FILES]
        if foreign and not is_simsat_run(out) and not force:
            shown = ", ".join(foreign[:5]) + (", ..." if len(foreign) > 5 else "")
            raise RunDirError(f"{out}: directory is not empty and is not a simsat run (holds {shown}); "
                              f"choose another --out, or add --force to write simsat's files beside them "
                              f"(nothing of yours is deleted)")
        return out
    try:
        out.mkdir(parents=True)
    except FileExistsError:
        pass
    except OSError as e:
        raise RunDirError(f"{out}: cannot create the run directory ({e.strerror})") from None
    return out


def clean_stale_parts(run_dir: str | Path) -> list[str]:
    """Remove temporary ``.NAME.XXXX.part`` files and directories of simsat's own files.

    Only names built on :data:`SIMSAT_FILES` (or the render's temporary
    directory) are touched; call it while holding :class:`RunLock`, when no
    other simsat process can be writing them.
    """
    removed = []
    d = Path(run_dir)
    if not d.is_dir():
        return removed
    for e in os.scandir(d):
        m = _PART_RE.match(e.name)
        if not m:
            continue
        base = m.group("base")
        if base not in SIMSAT_FILES and base not in ("render", "index.html"):
            continue
        try:
            if e.is_dir(follow_symlinks=False):
                shutil.rmtree(e.path)
            else:
                os.unlink(e.path)
            removed.append(e.name)
        except OSError:
            pass
    return removed


def install_files(tmp_dir: Path, out_dir: Path, names: list[str]) -> list[str]:
    """Move ``names`` from ``tmp_dir`` into ``out_dir`` (each by an atomic rename).

    ``run.json`` (the mark of a complete run) is removed first and installed
    last, and the outputs derived from a previous product (restoration,
    corrected images, report) are removed, since they no longer match it.

    Returns
    -------
    list of str
        The previous outputs that were replaced or removed, to be said.
    """
    replaced = []
    rj = out_dir / "run.json"
    if rj.exists():
        rj.unlink()
        replaced.append("run.json")
    for name in DERIVED_FILES:
        p = out_dir / name
        if p.is_dir() and not p.is_symlink():
            gone = _remove_report_dir(p)
            if gone is True:
                replaced.append(name + "/")
            elif gone is False:
                replaced.append(f"{name}/ (simsat's files; the others are kept)")
            else:
                replaced.append(f"nothing of {name}/ (no simsat manifest in it: kept, now stale)")
        elif p.exists() or p.is_symlink():
            p.unlink()
            replaced.append(name)
    order = [n for n in names if n != "run.json"] + [n for n in names if n == "run.json"]
    for name in order:
        if (out_dir / name).exists() and name != "run.json":
            replaced.append(name)
        os.replace(tmp_dir / name, out_dir / name)
    return replaced


REPORT_MANIFEST = ".simsat-manifest.json"


def _remove_report_dir(p: Path) -> bool | None:
    """Remove the files the report listed in its manifest; keep anything else.

    Returns True when the directory is gone, False when files simsat did not
    write are left in it, None when it has no manifest (nothing removed).
    """
    man = p / REPORT_MANIFEST
    try:
        files = json.loads(man.read_text()).get("files", [])
    except (OSError, ValueError, AttributeError):
        return None
    for name in files:
        f = p / str(name)
        if Path(name).name == str(name) and f.is_file() and not f.is_symlink():
            f.unlink()
    man.unlink()
    try:
        p.rmdir()
    except OSError:
        return False  # the user left something there: keep the directory
    return True


# --------------------------------------------------------------------------- locking
class RunLock:
    """Exclusive writer lock on a run directory (context manager).

    Parameters
    ----------
    run_dir : path
        The run directory (must exist).
    command : str
        What is writing, for the message a second writer gets.

    Raises
    ------
    RunDirError
        Another simsat process holds the lock (its command and pid named).
    """

    def __init__(self, run_dir: str | Path, command: str):
        self.run_dir = Path(run_dir)
        self.command = command
        self._fd = None

    def __enter__(self) -> "RunLock":
        import fcntl

        path = self.run_dir / LOCK_NAME
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
        except OSError as e:
            raise RunDirError(f"{self.run_dir}: cannot write in the run directory ({e.strerror})") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as e:
            holder = ""
            try:
                holder = os.pread(fd, 4096, 0).decode(errors="replace").strip()
            except OSError:
                pass
            os.close(fd)
            if e.errno in (errno.EAGAIN, errno.EACCES, errno.EWOULDBLOCK):
                raise RunDirError(f"{self.run_dir}: another simsat process is writing this run directory "
                                  f"({holder or 'unknown'}); wait for it to finish, or use another directory") from None
            raise RunDirError(f"{self.run_dir}: cannot lock the run directory ({e.strerror})") from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"simsat {self.command}, pid {os.getpid()}, since {time.strftime('%H:%M:%S')}\n".encode(), 0)
        self._fd = fd
        clean_stale_parts(self.run_dir)
        return self

    def __exit__(self, *exc) -> None:
        import fcntl

        if self._fd is not None:
            try:
                os.ftruncate(self._fd, 0)
                fcntl.flock(self._fd, fcntl.LOCK_UN)
            finally:
                os.close(self._fd)
                self._fd = None


# --------------------------------------------------------------------------- provenance
def read_ids(path: str | Path) -> dict:
    """``product_id`` / ``restoration_id`` global attributes of a NetCDF file ({} if unreadable)."""
    try:
        import netCDF4

        with netCDF4.Dataset(str(path), "r") as ds:
            return {k: str(ds.getncattr(k)) for k in ("product_id", "restoration_id") if k in ds.ncattrs()}
    except Exception:
        return {}


def check_consistency(run_dir: str | Path) -> None:
    """Refuse a run directory whose files come from different runs.

    ``truth.nc``, ``restoration.nc`` and ``corrected.nc`` must carry the
    ``product_id`` of ``product.nc``, and ``corrected.nc`` the
    ``restoration_id`` of ``restoration.nc``. Files written before ids
    existed (no attribute) are not judged.

    Raises
    ------
    RunDirError
        Naming the two files that disagree and how to make them agree.
    """
    d = Path(run_dir)
    prod = read_ids(d / "product.nc").get("product_id")
    rest_ids = read_ids(d / "restoration.nc") if (d / "restoration.nc").exists() else {}
    if prod:
        for name, fix in (("truth.nc", "render the run again"),
                          ("restoration.nc", "run `simsat restore` again"),
                          ("corrected.nc", "run `simsat restore` again")):
            if not (d / name).exists():
                continue
            other = read_ids(d / name).get("product_id")
            if other and other != prod:
                raise RunDirError(f"{d / name}: comes from another product (product_id {other}, product.nc has "
                                  f"{prod}); the run directory holds files of two runs: {fix}")
    rid = rest_ids.get("restoration_id")
    if rid and (d / "corrected.nc").exists():
        other = read_ids(d / "corrected.nc").get("restoration_id")
        if other and other != rid:
            raise RunDirError(f"{d / 'corrected.nc'}: made by another restoration (restoration_id {other}, "
                              f"restoration.nc has {rid}); run `simsat restore` again")
