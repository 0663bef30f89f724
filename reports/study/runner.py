"""Run a study on Dask: one task per (design, seed), resumable, a failed point recorded in its row.

Every finished point is written at once as its own small JSON file
(``rows/<key>.json``, atomically): a study killed half-way and started again
computes only the keys that have no file, and no key is ever written twice.
The tidy table, the dataset and the plots are rebuilt from those files at the
end (:mod:`.outputs`).

Default cluster: a :class:`distributed.LocalCluster` with one single-threaded
worker process per core. ``scheduler="tcp://HOST:PORT"`` runs the same tasks
on an existing cluster (``dask scheduler`` / ``dask worker``); its workers
need simsat importable.
"""
from __future__ import annotations

import json
import sys
from dataclasses import asdict
from pathlib import Path

from tqdm import tqdm

from simsat.cluster import dask_client

from simsat.product import atomic_write_bytes, atomic_write_json

from .evaluate import calibrate_noise, evaluate_point
from .outputs import write_outputs
from .spec import StudySpec

__all__ = ["RowStore", "run_study", "study_client"]


class RowStore:
    """One JSON file per finished point under ``rows/`` (written atomically, never twice)."""

    def __init__(self, out_dir: Path):
        self.dir = Path(out_dir) / "rows"
        self.dir.mkdir(parents=True, exist_ok=True)

    def has(self, key: str) -> bool:
        return (self.dir / f"{key}.json").exists()

    def write(self, row: dict) -> bool:
        """Write ``row``; False (and nothing written) if its key already has a row."""
        path = self.dir / f"{row['key']}.json"
        if path.exists():
            return False
        atomic_write_bytes(json.dumps(row, sort_keys=True, default=float).encode("utf-8"), path)
        return True

    def rows(self, keys: list[str] | None = None) -> list[dict]:
        """The rows of ``keys`` (in that order; all rows if None)."""
        paths = [self.dir / f"{k}.json" for k in keys] if keys is not None else sorted(self.dir.glob("*.json"))
        return [json.loads(p.read_text(encoding="utf-8")) for p in paths if p.exists()]


study_client = dask_client


def _per_axis(cal: dict):
    """The calibrated noise per axis (the median over axes where one is missing)."""
    per = cal.get("per_axis") or {}
    if per and all(v is not None for v in per.values()):
        return {a: float(v) for a, v in per.items()}
    return float(cal["noise_px"])


def _noise(spec: StudySpec, out_dir: Path, client):
    if spec.level != "differential":
        return None
    if spec.noise_px != "calibrate":
        return float(spec.noise_px)
    path = out_dir / "calibration.json"
    if path.exists():
        return _per_axis(json.loads(path.read_text()))
    over = {"acquisition": {"lines": spec.lines}} if spec.lines else {}
    print(f"study: calibrating the matching noise on a rendered run of {spec.base} ...", file=sys.stderr, flush=True)
    cal = client.submit(calibrate_noise, spec.base, over, out_dir / "calibration_run", pure=False).result()
    atomic_write_json(cal, path)
    print(f"study:   {', '.join(f'{a} {v:.4f}' for a, v in cal['per_axis'].items())} px per line and pair",
          file=sys.stderr, flush=True)
    return _per_axis(cal)


def run_study(spec: StudySpec, out_dir: str | Path, *, scheduler: str | None = None, workers: int | None = None,
              progress: bool = True, max_points: int | None = None) -> dict:
    """Run every missing point of ``spec`` and write the outputs; returns ``{"rows", "computed", "paths"}``.

    ``max_points`` stops after that many new points (a partial run, as if killed; the outputs are still written).
    """
    from distributed import as_completed

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_json({"study": spec.name, "base": spec.base, "level": spec.level, "seeds": spec.seeds,
                       "lines": spec.lines, "axes": [asdict(a) for a in spec.axes], "noise_px": spec.noise_px},
                      out / "study.json")
    store = RowStore(out)
    points = spec.points()
    todo = [p for p in points if not store.has(p.key)]
    done_before = len(points) - len(todo)
    if max_points is not None:
        todo = todo[:max_points]
    computed = 0
    with study_client(scheduler, workers) as client:
        noise = _noise(spec, out, client)
        futures = [client.submit(evaluate_point, spec.level, spec.base,
                                 {"key": p.key, "seed": p.seed, "design": p.design, "overrides": p.overrides},
                                 noise_px=noise, work_dir=str(out), key=f"simsat-study-{p.key}", pure=False)
                   for p in todo]
        bar = tqdm(total=len(points), initial=done_before,
                   desc=f"study {spec.name}", unit="point", file=sys.stderr, disable=not progress,
                   dynamic_ncols=True)
        try:
            for fut in as_completed(futures):
                row = fut.result()
                computed += int(store.write(row))
                bar.update(1)
                if row.get("error"):
                    bar.write(f"study: point {row['key']} failed: {row['error'][:200]}")
        finally:
            bar.close()
    rows = store.rows([p.key for p in points])
    paths = write_outputs(spec, rows, out)
    return {"rows": rows, "computed": computed, "paths": paths, "total": len(points)}
