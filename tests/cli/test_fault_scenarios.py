"""Fault injection on scenarios: every mutation of a built-in gets a clean verdict.

Each leaf key of the built-in scenarios is mutated (NaN, ±inf, ±1e300, a huge
integer, zero, a negative, a string, an empty array, deleted, misspelt) and
an unknown key is added to every table; each mutant goes through
``simsat validate`` (the CLI, with ``--set``; deletions and misspellings
in-process). Required of every mutant:

* the CLI answers 0 (valid) or 2 (a one-line message) — never 1 (internal
  error), never a traceback;
* a rejection names the mutated key, or the table it is in, or the key whose
  value it made impossible (e.g. the detector that left the focal plane);
* mutants that are invalid by construction (non-finite numbers, ±1e300,
  strings where numbers go, unknown keys) are rejected — zero silently
  accepted invalid inputs;
* each verdict comes quickly (validation estimates resources, it does not
  allocate them).

The default run takes a deterministic sample; ``-m slow`` runs them all.
"""
from __future__ import annotations

import time

import pytest

import simsat_cli as cli
from simsat.config import ScenarioError
from simsat.scenario import builtin_scenarios, load_scenario, _read_toml

import restore  # noqa: F401  (registers [restoration] in load_scenario's validation pass)

#: mutations that are invalid whatever the key (value as TOML text for --set)
ALWAYS_INVALID = {"nan": "nan", "inf": "inf", "-inf": "-inf", "1e300": "1e300", "-1e300": "-1e300"}
#: mutations that may be valid for some keys (a verdict is required, not a rejection)
MAYBE = {"zero": "0", "negative": "-1", "huge_int": "123456789012345678901234567890", "string": '"x"',
         "empty_array": "[]"}


def _leaves(node, path=""):
    """(dotted key with [i] indices, value) of every leaf of a raw scenario."""
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _leaves(v, f"{path}.{k}" if path else k)
    elif isinstance(node, list) and node and all(isinstance(x, dict) for x in node):
        for i, v in enumerate(node):
            yield from _leaves(v, f"{path}[{i}]")
    else:
        yield path, node


def _tables(node, path=""):
    if isinstance(node, dict):
        yield path
        for k, v in node.items():
            yield from _tables(v, f"{path}.{k}" if path else k)
    elif isinstance(node, list) and node and all(isinstance(x, dict) for x in node):
        for i, v in enumerate(node):
            yield from _tables(v, f"{path}[{i}]")


def _mutants(name: str):
    raw = _read_toml(builtin_scenarios()[name])
    out = []
    for key, value in _leaves(raw):
        for label, text in ALWAYS_INVALID.items():
            out.append((name, key, label, text, True))
        for label, text in MAYBE.items():
            out.append((name, key, label, text, isinstance(value, (int, float)) and label == "string"))
        out.append((name, key, "delete", None, False))
        out.append((name, key, "misspell", None, True))
    for t in _tables(raw):
        if t:
            out.append((name, f"{t}.unknown_key_x", "unknown", "1", True))
    return out


ALL = _mutants("tiny") + _mutants("phr_cmg")


def _set_path(raw, key):
    """Parent container and final key of a dotted key with [i] indices."""
    import re

    parts = []
    for part in key.split("."):
        m = re.fullmatch(r"([^\[]+)((?:\[\d+\])*)", part)
        parts.append(m.group(1))
        parts.extend(int(i) for i in re.findall(r"\[(\d+)\]", m.group(2)))
    node = raw
    for p in parts[:-1]:
        node = node[p]
    return node, parts[-1]


def _names_key(message: str, key: str, text: str | None) -> bool:
    """Whether a message blames the mutated key, a table above it, or names the new value
    (a key it made impossible, e.g. a reference to a detector renamed to 'x')."""
    leaf = key.rsplit(".", 1)[-1].split("[")[0]
    table = key.rsplit(".", 1)[0] if "." in key else key
    value = (text or "").strip('"')
    return leaf in message or table.split("[")[0] in message or (len(value) > 0 and repr(value) in message)


def _verdict(capsys, name, key, label, text):
    """Validate the mutant; returns (rc, one-line stderr)."""
    t0 = time.perf_counter()
    if text is not None:
        rc = cli.main(["validate", name, "--set", f"{key}={text}"])
        out, err = capsys.readouterr()
    else:
        raw = _read_toml(builtin_scenarios()[name])
        parent, last = _set_path(raw, key)
        value = parent.pop(last) if isinstance(parent, dict) else None
        if label == "misspell":
            parent[last + "x"] = value
        rc, err = 0, ""
        try:
            load_scenario(raw)  # the single validation pass: every table of every stage
        except (ScenarioError, ValueError) as e:
            rc, err = 2, f"simsat: error: {e}\n"
    elapsed = time.perf_counter() - t0
    assert elapsed < 20, f"{key} {label}: validate took {elapsed:.1f} s"
    return rc, err


def _check(capsys, case):
    name, key, label, text, must_reject = case
    rc, err = _verdict(capsys, name, key, label, text)
    where = f"{name}: {key} = {label}"
    assert rc in (0, 2), f"{where}: exit code {rc}: {err}"
    assert "Traceback" not in err and "internal error" not in err, f"{where}: {err}"
    if rc == 2:
        assert err.count("\n") == 1, f"{where}: not one line: {err!r}"
        assert _names_key(err, key, text), f"{where}: message does not name the key: {err}"
    if must_reject:
        assert rc == 2, f"{where}: an invalid value was accepted"


@pytest.mark.parametrize("case", ALL, ids=[f"{c[0]}:{c[1]}:{c[2]}" for c in ALL])
def test_every_mutated_scenario_gets_a_clean_verdict(capsys, case):
    _check(capsys, case)


# the scenarios that validated and then exhausted the machine, each blamed on the key that drives it
EXHAUSTING = [
    ("attitude.jitter[0]={kind=\"psd\", axis=\"roll\", rms_urad=1.0, corner_hz=10.0, n_components=1000000000}",
     "n_components"),
    ("scene.dem.resolution_m=0.3", "scene.dem.resolution_m"),
    ("attitude.jitter[0].amplitude_urad=1e300", "attitude.jitter[0].amplitude_urad"),
    ("attitude.star_tracker.rate_hz=1e9", "attitude.star_tracker.rate_hz"),
    ("scene.sun.elevation_deg=1e-9", "scene.sun.elevation_deg"),
    ("scene.texture.texel_m=1e-6", "scene.texture.texel_m"),
    ("scene.dem.relief_m=1e300", "scene.dem.relief_m"),
    ("acquisition.lines=5000000", "acquisition.lines"),
    ("platform.altitude_m=1e12", "platform.altitude_m"),
]


@pytest.mark.parametrize("override,key", EXHAUSTING, ids=[k for _, k in EXHAUSTING])
def test_exhausting_values_are_refused_fast_naming_their_key(capsys, override, key):
    t0 = time.perf_counter()
    rc = cli.main(["validate", "phr_cmg", "--set", override])
    out, err = capsys.readouterr()
    assert time.perf_counter() - t0 < 20
    assert rc == 2 and "internal error" not in err
    assert key in err, err


def test_large_but_sane_designs_validate(capsys):
    assert cli.main(["validate", "phr_full"]) == 0
    assert cli.main(["validate", "phr_cmg", "--set", "acquisition.lines=50000"]) == 0


def test_mutation_set_is_large_and_covers_every_table():
    assert len(ALL) > 500
    keys = {c[1] for c in ALL}
    for table in ("platform", "instrument.noise", "attitude.jitter[0]", "scene.dem", "scene.texture",
                  "acquisition", "restoration", "report"):
        assert any(k.startswith(table) for k in keys), table


@pytest.mark.parametrize("override,key,hint", [
    ("restoration.integration.noise_sd=1e-6", "restoration.integration.noise_sd", "noise_std"),
    ("restoration.method=\"wienr\"", "restoration.method", "wiener"),
    ("restoration.windw_lines=3", "restoration.windw_lines", "window_lines"),
    ("report.foo=1", "report.foo", ""),
])
def test_bad_keys_of_later_stages_fail_at_validate(capsys, override, key, hint):
    """The issue's examples: options of the integration method, [report] keys, misspellings of [restoration]."""
    rc = cli.main(["validate", "tiny", "--set", override])
    err = capsys.readouterr().err
    assert rc == 2 and "internal error" not in err and err.count("\n") == 1
    assert key in err and hint in err, err


def test_load_scenario_alone_validates_restoration_once_restore_is_imported():
    raw = _read_toml(builtin_scenarios()["tiny"])
    raw.setdefault("restoration", {})["window_lines"] = 4
    with pytest.raises(ScenarioError, match="restoration.window_lines"):
        load_scenario(raw)
