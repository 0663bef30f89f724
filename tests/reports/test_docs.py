"""The project's own documentation: complete, current, self-contained."""
from __future__ import annotations

import re
import subprocess
from pathlib import Path

from reports.keyref import MEANING, _norm, recorded_keys, scenario_key_reference
from simsat.scenario import _read_toml, builtin_scenarios

ROOT = Path(__file__).resolve().parents[2]


def _leaf_keys(node, path=""):
    if isinstance(node, dict):
        if not node and path:
            yield path
        for k, v in node.items():
            yield from _leaf_keys(v, f"{path}.{k}" if path else k)
    elif isinstance(node, list) and node and all(isinstance(x, dict) for x in node):
        for v in node:
            yield from _leaf_keys(v, f"{path}[]")
    else:
        yield path


def test_scenario_key_reference_is_up_to_date():
    text = (ROOT / "docs" / "scenario-keys.md").read_text()
    assert text == scenario_key_reference(), "run: python -m reports.keyref > docs/scenario-keys.md"


def test_every_validated_key_has_a_meaning():
    missing = [k for entries in recorded_keys().values() for k, *_ in entries if k not in MEANING]
    assert not missing, f"add to reports.keyref.MEANING: {missing}"


def test_every_key_of_the_builtin_scenarios_is_documented():
    documented = {k for entries in recorded_keys().values() for k, *_ in entries}
    tables = set(recorded_keys())
    for name, path in builtin_scenarios().items():
        for key in _leaf_keys(_read_toml(path)):
            key = _norm(key)
            # `[scenario] base` has its own section of the reference (a scenario derived from another)
            assert key in documented or key in ("restoration", "report", "scenario.base") or key in tables, \
                (name, key)
    assert "`[scenario] base`" in (ROOT / "docs" / "scenario-keys.md").read_text()


def test_design_notes_exist_and_nothing_points_outside_the_repository():
    assert (ROOT / "docs" / "design.md").read_text().startswith("# simsat")
    files = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True).stdout.split()
    files += [str(p.relative_to(ROOT)) for p in (ROOT / "docs").glob("*.md")]
    offenders = []
    for f in files:
        p = ROOT / f
        if p.suffix in (".py", ".md", ".toml", ".txt", ".html", ".cfg") and p.is_file():
            text = p.read_text(errors="replace")
            if re.search(r"\.\./shared|shared/DESIGN\.md", text) and p.name != "test_docs.py":
                offenders.append(f)
    assert not offenders, offenders
