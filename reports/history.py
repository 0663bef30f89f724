"""Accuracy history: every ``simsat bench`` appends a record; ``simsat bench compare`` flags regressions.

A record is one JSON line of ``bench/history.jsonl``: date, commit, machine,
the benchmark and its settings, and its *figures* — a flat ``{name: number}``
of what the benchmark measured (per-axis RMS and 99.7 %, coverage, timings),
see :func:`figures_of`. :func:`compare` sets the latest record of a benchmark
against the previous one with the same settings and flags a figure that got
worse by more than the run-to-run noise: the spread of that figure over the
earlier records with those settings when there are enough of them, otherwise
a default tolerance (:data:`DEFAULT_TOLERANCE`).
"""
from __future__ import annotations

import json
import os
import platform
import subprocess
import time as _time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from simsat.product import atomic_write_bytes

__all__ = ["HISTORY_FILE", "DEFAULT_TOLERANCE", "figures_of", "make_record", "append_record", "read_history",
           "Change", "compare", "format_comparison", "HistoryError"]

#: default history file (beside the benches' JSON)
HISTORY_FILE = Path("bench") / "history.jsonl"

#: relative worsening tolerated when the history holds too few records to measure the run-to-run noise:
#: accuracy figures are deterministic for a seed (same scenario, same bytes), timings are not
DEFAULT_TOLERANCE = {"accuracy": 0.05, "timing": 0.30}

#: a figure's noise is measured from the history once it holds this many earlier records with the same settings
MIN_RECORDS_FOR_NOISE = 3

#: a change beyond this many run-to-run standard deviations is a regression
NOISE_SIGMAS = 3.0


class HistoryError(RuntimeError):
    """The history cannot be read or compared; the message says which file and line."""


def _lower_is_better(name: str) -> bool | None:
    """True for errors and durations, False for coverage and throughputs, None for neither."""
    leaf = name.rsplit(".", 1)[-1]
    if leaf.endswith(("rms_px", "p997_px", "rms_urad", "p997_urad", "_m")) or leaf in ("wall_s",) or \
            (leaf.endswith("_s") and not leaf.endswith("per_s")):
        return True
    if leaf in ("coverage", "valid_fraction", "improvement_median", "nees_inside_fraction", "lock",
                "valid_restored") or \
            leaf.endswith("per_s"):
        return False
    return None


def _kind(name: str) -> str:
    leaf = name.rsplit(".", 1)[-1]
    return "timing" if leaf.endswith("_s") or leaf.endswith("per_s") else "accuracy"


def _errors_figures(prefix: str, errors: dict) -> dict:
    out = {}
    for axis, e in (errors or {}).items():
        for k in ("rms_px", "p997_px", "coverage", "rms_px_without_yaw_coupling"):
            if k in e and e[k] is not None and np.isfinite(e[k]):
                out[f"{prefix}{axis}.{k}"] = float(e[k])
    return out


def _run_figures(prefix: str, e: dict) -> dict:
    """Per-axis errors, coverage and restore time of one scenario's run (a regression or robustness row)."""
    out = _errors_figures(prefix, e.get("errors"))
    for a, v in (e.get("coverage") or {}).items():
        out[f"{prefix}{a}.coverage"] = float(v)
    if "restore_s" in e:
        out[prefix + "restore_s"] = float(e["restore_s"])
    m = e.get("matching") or {}
    for k in ("lock", "valid_restored"):   # the worst pair's matching (reports.matching_lock), when measured
        if k in m and m[k] is not None and np.isfinite(m[k]):
            out[f"{prefix}matching.{k}"] = float(m[k])
    return out


def figures_of(what: str, result: dict) -> dict:
    """The flat figures of a benchmark result (``run_bench``'s ``result``): ``{name: number}``."""
    r = result
    out: dict = {}
    if what == "restore":
        for key in ("end_to_end", "clouds_30"):
            e = r.get(key)
            if e:
                out.update(_errors_figures(f"{key}.", e.get("errors")))
                if "restore_s" in e:
                    out[f"{key}.restore_s"] = float(e["restore_s"])
    elif what in ("regression", "robustness"):
        for e in r.get("runs" if what == "regression" else "rows", []):
            if "error" in e:
                continue
            out.update(_run_figures(f"{e['scenario']}.", e))
    elif what == "knowledge":
        for row in r.get("rows", []):
            key = f"{row['scenario']}.{row['cutoff_hz']:g}Hz"
            out[f"{key}.predicted_rms_px"] = float(row["predicted"]["rms_px"])
            out[f"{key}.predicted_end_rms_px"] = float(row["predicted"]["end_rms_px"])
    elif what == "navigation":
        sm = r.get("summary", {})
        out["navigation.final_horizontal_p95_m"] = float(sm["final_horizontal_m"]["p95"])
        out["navigation.final_horizontal_median_m"] = float(sm["final_horizontal_m"]["median"])
        out["navigation.improvement_median"] = float(sm["improvement_median"])
        out["navigation.nees_inside_fraction"] = float(sm["nees_inside_fraction"])
        out["navigation.detection_tracking_s"] = float(r["detection_tracking"]["total_ms"]) / 1e3
    elif what == "render":
        m = r.get("main", {})
        for k in ("rays_per_s", "ratio_to_ceiling", "render_wall_s"):
            if k in m:
                out[f"render.{k}"] = float(m[k])
            if k in m.get("baked", {}):
                out[f"render.baked_{k}"] = float(m["baked"][k])
    return out


def _git_commit(cwd: Path) -> str:
    try:
        head = subprocess.run(["git", "rev-parse", "--short=12", "HEAD"], cwd=cwd, capture_output=True, text=True,
                              timeout=10)
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=cwd,
                               capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    if head.returncode != 0:
        return "unknown"
    return head.stdout.strip() + ("+dirty" if dirty.stdout.strip() else "")


def make_record(what: str, result: dict, *, settings: dict) -> dict:
    """A history record of one benchmark run."""
    here = Path(__file__).resolve().parent.parent
    return {"date": _time.strftime("%Y-%m-%dT%H:%M:%S"), "commit": _git_commit(here),
            "machine": {"node": platform.node(), "cpus": os.cpu_count(), "python": platform.python_version(),
                        "system": platform.platform()},
            "benchmark": what, "settings": settings, "figures": figures_of(what, result)}


def read_history(path: str | Path = HISTORY_FILE) -> list[dict]:
    """The records of a history file (empty if it does not exist).

    Raises
    ------
    HistoryError
        A line that is not a JSON record, with its number.
    """
    p = Path(path)
    if not p.exists():
        return []
    out = []
    for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1):
        if not line.strip():
            continue
        try:
            rec = json.loads(line)
        except json.JSONDecodeError as e:
            raise HistoryError(f"{p}: line {i} is not JSON ({e.msg}); fix or remove that line") from None
        if not isinstance(rec, dict) or "benchmark" not in rec or not isinstance(rec.get("figures"), dict):
            raise HistoryError(f"{p}: line {i} is not a bench record (needs 'benchmark' and 'figures')")
        out.append(rec)
    return out


def append_record(record: dict, path: str | Path = HISTORY_FILE) -> Path:
    """Append ``record`` to the history (the whole file rewritten atomically: never half a line)."""
    p = Path(path)
    old = p.read_bytes() if p.exists() else b""
    if old and not old.endswith(b"\n"):
        old += b"\n"
    atomic_write_bytes(old + (json.dumps(record, sort_keys=True) + "\n").encode("utf-8"), p)
    return p


@dataclass
class Change:
    """One figure, previous → latest."""

    name: str
    previous: float
    latest: float
    tolerance: float
    noise_from_history: bool
    regression: bool
    improvement: bool

    @property
    def relative(self) -> float:
        return (self.latest - self.previous) / abs(self.previous) if self.previous else float("inf")


def _same(a: dict, b: dict) -> bool:
    return a.get("benchmark") == b.get("benchmark") and a.get("settings") == b.get("settings")


def compare(records: list[dict], *, benchmark: str | None = None) -> tuple[dict | None, dict | None, list[Change]]:
    """The latest record (of ``benchmark``, or of the last one run) against the previous one with the same settings.

    Returns ``(previous, latest, changes)``; ``previous`` is None when there is nothing to compare with.
    """
    pool = [r for r in records if benchmark is None or r["benchmark"] == benchmark]
    if not pool:
        return None, None, []
    latest = pool[-1]
    earlier = [r for r in pool[:-1] if _same(r, latest)]
    if not earlier:
        return None, latest, []
    previous = earlier[-1]
    changes = []
    for name, new in sorted(latest["figures"].items()):
        if name not in previous["figures"]:
            continue
        old = float(previous["figures"][name])
        new = float(new)
        direction = _lower_is_better(name)
        hist = [float(r["figures"][name]) for r in earlier if name in r["figures"]]
        from_history = len(hist) >= MIN_RECORDS_FOR_NOISE
        tol = NOISE_SIGMAS * float(np.std(hist, ddof=1)) if from_history else 0.0
        tol = max(tol, DEFAULT_TOLERANCE[_kind(name)] * abs(old), 1e-12)
        worse = (new - old) if direction else (old - new) if direction is False else 0.0
        changes.append(Change(name, old, new, tol, from_history, regression=worse > tol,
                              improvement=-worse > tol))
    return previous, latest, changes


def format_comparison(previous, latest, changes: list[Change]) -> str:
    """The comparison as lines for the terminal (regressions first)."""
    if latest is None:
        return "no bench record yet: run `simsat bench ...` first"
    head = f"{latest['benchmark']} at {latest['date']} ({latest['commit']})"
    if previous is None:
        return head + ": no earlier record with the same settings to compare with"
    lines = [f"{head} against {previous['date']} ({previous['commit']})"]
    reg = [c for c in changes if c.regression]
    lines.append(f"  {len(reg)} regression(s), {sum(c.improvement for c in changes)} improvement(s), "
                 f"{len(changes)} figures")
    for c in sorted(changes, key=lambda c: (not c.regression, not c.improvement, c.name)):
        tag = "REGRESSION" if c.regression else "better" if c.improvement else ""
        noise = "history" if c.noise_from_history else "default"
        lines.append(f"  {c.name:48s} {c.previous:12.5g} → {c.latest:12.5g} ({c.relative * 100:+6.1f} %; "
                     f"tolerance ±{c.tolerance:.3g} from {noise}) {tag}")
    return "\n".join(lines)
