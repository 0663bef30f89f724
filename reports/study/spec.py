"""``STUDY.toml``: a base scenario, sweep axes over any scenario key, Monte Carlo seeds, a level.

.. code-block:: toml

    [study]
    name = "tau_amplitude"
    base = "phr_cmg"              # built-in name or a path (relative to the study file)
    level = "differential"        # or "rendered" (the full chain per point)
    seeds = 10                    # or an explicit list of scenario seeds
    lines = 4000                  # optional: acquisition.lines of every point

    [[study.sweep]]               # one axis: a key (KEY.SUB[INDEX] as for --set) and its values
    name = "tau_scale"            # optional column name (default: the key)
    key = "instrument.detectors[1].along_track_mm"
    values = [0.0, 0.0]
    # several keys moving together: keys = [...] and values = [[v_key1, v_key2, ...], ...]

    [study.noise]                 # differential level: matching noise per line and pair
    differential_noise_px = "calibrate"   # or a number [px]: see reports.study.evaluate

Designs are the Cartesian product of the axes; every design runs with every
seed; a point is (design, seed) and has a stable key, so a study that stops
half-way resumes where it stopped.
"""
from __future__ import annotations

import copy
import hashlib
import itertools
import json
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from simsat.config import ScenarioError, Section
from simsat.scenario import SCENARIO_DIR, load_scenario

__all__ = ["StudySpec", "SweepAxis", "StudyPoint", "load_study", "key_override", "merge_overrides", "LEVELS"]

LEVELS = ("differential", "rendered")


@dataclass(frozen=True)
class SweepAxis:
    """One sweep axis: a column name, the scenario keys it sets, and its values (one tuple per key set)."""

    name: str
    keys: tuple
    values: tuple
    labels: tuple | None = None

    def label(self, i: int):
        """What the table and the plots call value ``i``: its label, else the value (one key), else all of them."""
        if self.labels is not None:
            return self.labels[i]
        vals = self.values[i]
        return vals[0] if len(vals) == 1 else list(vals)


@dataclass(frozen=True)
class StudyPoint:
    """One (design, seed): the swept values by axis name, and the scenario overrides they make."""

    design: dict
    seed: int
    overrides: dict
    key: str


@dataclass
class StudySpec:
    """A parsed study."""

    name: str
    base: str
    level: str
    seeds: list
    lines: int | None
    axes: list
    noise_px: float | str = "calibrate"
    source: Path | None = None
    raw: dict = field(default_factory=dict)

    def designs(self) -> list[dict]:
        """Every design: ``{axis name: value}`` (the Cartesian product of the axes, in file order)."""
        if not self.axes:
            return [{}]
        return [dict(zip([a.name for a in self.axes], combo))
                for combo in itertools.product(*[range(len(a.values)) for a in self.axes])]

    def points(self) -> list[StudyPoint]:
        """Every (design, seed), with its overrides and stable key."""
        out = []
        for idx in self.designs():
            over: dict = {}
            design = {}
            for ax in self.axes:
                vals = ax.values[idx[ax.name]]
                for k, v in zip(ax.keys, vals):
                    merge_overrides(over, key_override(k, v))
                design[ax.name] = ax.label(idx[ax.name])
            if self.lines:
                merge_overrides(over, {"acquisition": {"lines": int(self.lines)}})
            for seed in self.seeds:
                o = copy.deepcopy(over)
                merge_overrides(o, {"scenario": {"seed": int(seed)}})
                key = hashlib.sha256(json.dumps([self.base, self.level, o], sort_keys=True).encode()).hexdigest()[:16]
                out.append(StudyPoint(design=design, seed=int(seed), overrides=o, key=key))
        return out


_PART = re.compile(r"([A-Za-z0-9_-]+)((?:\[\d+\])*)")


def key_override(key: str, value) -> dict:
    """``"attitude.jitter[0].amplitude_urad", 3.0`` → ``{"attitude": {"jitter": {0: {"amplitude_urad": 3.0}}}}``."""
    path: list = []
    for part in str(key).strip().split("."):
        m = _PART.fullmatch(part)
        if not m:
            raise ScenarioError(f"study.sweep key {key!r}: {part!r} is not a key name (KEY or KEY[INDEX], e.g. "
                                f"attitude.jitter[0].amplitude_urad)")
        path.append(m.group(1))
        path.extend(int(i) for i in re.findall(r"\[(\d+)\]", m.group(2)))
    out: dict = {}
    d = out
    for p in path[:-1]:
        d = d.setdefault(p, {})
    d[path[-1]] = value
    return out


def merge_overrides(into: dict, more: dict) -> dict:
    """Deep-merge ``more`` into ``into`` (in place; returns it)."""
    for k, v in more.items():
        if isinstance(v, dict) and isinstance(into.get(k), dict):
            merge_overrides(into[k], v)
        else:
            into[k] = v
    return into


def _axis(sec: Section, i: int) -> SweepAxis:
    where = f"study.sweep[{i}]"
    keys = sec.raw("keys", None)
    key = sec.raw("key", None)
    if (keys is None) == (key is None):
        raise ScenarioError(f"{where}: give either key = \"...\" or keys = [...]")
    keys = [key] if key is not None else keys
    if not isinstance(keys, list) or not keys or not all(isinstance(k, str) for k in keys):
        raise ScenarioError(f"{where}.keys: must be a non-empty array of scenario keys")
    values = sec.raw("values", None)
    if not isinstance(values, list) or not values:
        raise ScenarioError(f"{where}.values: must be a non-empty array")
    if key is not None:
        vals = tuple((v,) for v in values)
    else:
        if not all(isinstance(v, list) and len(v) == len(keys) for v in values):
            raise ScenarioError(f"{where}.values: with keys = [...] (length {len(keys)}) each value must be an array "
                                f"of {len(keys)} values, one per key")
        vals = tuple(tuple(v) for v in values)
    name = sec.raw("name", None)
    if name is not None and (not isinstance(name, str) or not name):
        raise ScenarioError(f"{where}.name: must be a non-empty string")
    labels = sec.raw("labels", None)
    if labels is not None:
        if not isinstance(labels, list) or len(labels) != len(vals) or \
                not all(isinstance(x, (str, int, float)) and not isinstance(x, bool) for x in labels):
            raise ScenarioError(f"{where}.labels: must be an array of {len(vals)} strings or numbers, one per value")
        if len({str(x) for x in labels}) != len(labels):
            raise ScenarioError(f"{where}.labels: two values have the same label")
        labels = tuple(labels)
    for k in keys:
        key_override(k, 0)  # checks the syntax
    sec.finish(extra_allowed=("name", "key", "keys", "values", "labels"))
    return SweepAxis(name=name or keys[0], keys=tuple(keys), values=vals, labels=labels)


def load_study(path: str | Path) -> StudySpec:
    """Parse and check ``STUDY.toml``; every design's scenario is validated before anything runs.

    Raises
    ------
    simsat.config.ScenarioError
        Naming the file and the key at fault.
    """
    p = Path(path)
    if not p.is_file():
        raise ScenarioError(f"{p}: no such study file")
    try:
        raw = tomllib.loads(p.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as e:
        raise ScenarioError(f"{p}: not valid TOML ({e})") from None
    try:
        return _parse(raw, p)
    except ScenarioError as e:
        raise ScenarioError(f"{p}: {e}") from None


def _parse(raw: dict, p: Path) -> StudySpec:
    top = Section(raw, "")
    sec = top.section("study", required=True)
    name = sec.string("name", p.stem)
    base = sec.string("base", "phr_cmg")
    base_path = (p.parent / base) if base.endswith(".toml") else None
    if base_path is not None:
        if not base_path.is_file():
            raise sec.error("base", f"no scenario file {base_path}")
        base = str(base_path.resolve())
    elif not (SCENARIO_DIR / f"{base}.toml").is_file():
        raise sec.error("base", f"no built-in scenario {base!r} (a path must end in .toml)")
    level = sec.string("level", "differential", choices=LEVELS)
    seeds = sec.raw("seeds", 10)
    if isinstance(seeds, int) and not isinstance(seeds, bool):
        if not 1 <= seeds <= 10000:
            raise sec.error("seeds", f"must be 1 to 10000 seeds, got {seeds}")
        seeds = list(range(seeds))
    elif not (isinstance(seeds, list) and seeds and all(isinstance(s, int) and not isinstance(s, bool) and s >= 0
                                                          for s in seeds)):
        raise sec.error("seeds", f"must be a count or an array of integer seeds >= 0, got {seeds!r}")
    if len(set(seeds)) != len(seeds):
        raise sec.error("seeds", "names a seed twice")
    lines = sec.integer("lines", None, ge=64, le=1_000_000) if sec.has("lines") else None
    axes = [_axis(s, i) for i, s in enumerate(sec.sections("sweep"))]
    names = [a.name for a in axes]
    if len(set(names)) != len(names):
        raise sec.error("sweep", f"two axes have the same name: {names}")
    noise = sec.section("noise")
    npx = noise.number_or("differential_noise_px", "calibrate", gt=0)
    noise.finish()
    sec.finish(extra_allowed=("sweep", "noise"))
    top.finish(extra_allowed=("study",))
    spec = StudySpec(name=name, base=base, level=level, seeds=list(seeds), lines=lines, axes=axes, noise_px=npx,
                     source=p, raw=raw)
    for design_point in {json.dumps(pt.overrides, sort_keys=True): pt for pt in spec.points()[::len(seeds)]}.values():
        try:
            load_scenario(base, overrides=design_point.overrides, check_models=True)
        except ScenarioError as e:
            raise ScenarioError(f"design {design_point.design}: {e}") from None
    return spec
