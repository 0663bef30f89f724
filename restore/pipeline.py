"""Restoration of a run directory: product → restored line-of-sight attitude (patent claims 9–11).

``simsat restore RUN_DIR`` reads ``product.nc`` and the ``[restoration]`` table
recorded in ``run.json``, runs the :class:`~restore.restorer.Restorer` (select
→ match → synthesise → integrate → anchor → correct, :mod:`restore.stages`)
and writes ``restoration.nc`` (:mod:`restore.restoration_io`) and
``corrected.nc``, with the provenance the report checks. Never reads
``truth.nc``.
"""
from __future__ import annotations

import json
import os
from pathlib import Path

from simsat.config import Section
from simsat.product import (
    Product,
    ProductError,
    atomic_write_dataset,
    read_product,
    temporary_path,
)
from simsat.rundir import RunLock, content_id

from .errors import RestorationError
from .restoration_io import restoration_dataset
from .restorer import Restorer
from .result import PairData, RestorationResult
from .settings import RestorationSettings, restoration_settings, settings_dict
from .stages import match_pair, pilot_shift

__all__ = ["RestorationSettings", "restoration_settings", "restore_product", "restore_run", "RestorationResult",
           "RestorationError", "PairData", "match_pair", "pilot_shift", "restoration_dataset"]


def restore_product(product: Product, settings: RestorationSettings | None = None, *, progress: bool = False,
                    run_dir: Path | None = None, corrected_path: Path | None = None,
                    corrected_attrs: dict | None = None) -> RestorationResult:
    """Restore the line-of-sight attitude of a product: ``Restorer(settings).run(product)``."""
    return Restorer(settings, progress=progress).run(product, run_dir=run_dir, corrected_path=corrected_path,
                                                     corrected_attrs=corrected_attrs)


def _restoration_table(run_json: Path) -> dict:
    """The ``[restoration]`` table of the scenario recorded in ``run.json``."""
    try:
        info = json.loads(run_json.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ProductError(f"{run_json}: not a readable JSON file ({e}); render the run again or remove it") from None
    if not isinstance(info, dict):
        raise ProductError(f"{run_json}: must hold a JSON object (simsat's run record), got {type(info).__name__}")
    table = info.get("scenario", {})
    for k in ("raw", "restoration"):
        table = table.get(k, {}) if isinstance(table, dict) else None
    if table is None or not isinstance(table, dict):
        raise ProductError(f"{run_json}: scenario.raw.restoration must be a table, got {type(table).__name__}")
    return table


def restore_run(run_dir: str | Path, *, overrides: dict | None = None, progress: bool = True) -> RestorationResult:
    """``simsat restore RUN_DIR``: read the product, restore, write restoration.nc (+ corrected.nc)."""
    run_dir = Path(run_dir)
    if run_dir.exists() and not run_dir.is_dir():
        raise ProductError(f"{run_dir}: is a file; expected a run directory (the one holding product.nc)")
    product = read_product(run_dir)
    table = {}
    run_json = run_dir / "run.json"
    if run_json.exists():
        table = _restoration_table(run_json)
    if overrides:
        ov = overrides.get("restoration", overrides)
        table = {**table, **ov}
    settings = restoration_settings(Section(table, "restoration"))
    # provenance: which product and settings the outputs come from (checked by the report)
    pid = str(product.ds.attrs.get("product_id", "")) or content_id(str(product.path))
    rid = content_id(pid, settings_dict(settings))
    if product.is_frames:
        return _restore_frames_run(run_dir, product, settings, pid, rid, progress=progress)
    with RunLock(run_dir, "restore"):
        part = temporary_path(run_dir / "corrected.nc")  # written block by block, renamed when complete
        try:
            res = restore_product(product, settings, progress=progress, run_dir=run_dir, corrected_path=part,
                                  corrected_attrs={"product_id": pid, "restoration_id": rid})
            ds = restoration_dataset(res)
            ds.attrs.update(product_id=pid, restoration_id=rid)
            # corrected.nc first: a restore killed between the two writes leaves a corrected.nc whose
            # restoration_id no longer matches restoration.nc, which the report refuses
            corrected = res.corrected
            if corrected is not None:
                corrected.close()
                os.replace(part, run_dir / "corrected.nc")
                res.corrected = None
            elif (run_dir / "corrected.nc").is_file():
                (run_dir / "corrected.nc").unlink()  # simsat's own output of an earlier restoration: stale now
        finally:
            part.unlink(missing_ok=True)
        res.path = atomic_write_dataset(ds, run_dir / "restoration.nc")
    return res


def _restore_frames_run(run_dir: Path, product, settings, pid: str, rid: str, *, progress: bool):
    """A matrix detector's frames: :func:`restore.frames.restore_frames`, written as restoration.nc."""
    from .frames import frames_restoration_dataset, restore_frames

    with RunLock(run_dir, "restore"):
        res = restore_frames(product, settings, progress=progress)
        ds = frames_restoration_dataset(res)
        ds.attrs.update(product_id=pid, restoration_id=rid)
        if (run_dir / "corrected.nc").is_file():
            (run_dir / "corrected.nc").unlink()  # simsat's own output of an earlier restoration: stale now
        res.path = atomic_write_dataset(ds, run_dir / "restoration.nc")
    return res
