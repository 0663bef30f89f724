"""Typed, path-aware access to scenario sections.

Every scenario error names the TOML key it is about, e.g.::

    attitude.jitter[2].frequency_hz: must be > 0, got -3

Modules read their own part of a scenario through a :class:`Section`, which
records which keys were read so that :meth:`Section.finish` can reject unknown
keys (naming them and listing the allowed ones).
"""
from __future__ import annotations

import math
from typing import Any, Iterable, Sequence

__all__ = ["ScenarioError", "Section", "REQUIRED", "record_keys"]


class ScenarioError(ValueError):
    """A scenario value is missing, of the wrong type or out of range.

    The message is a single line that starts with the dotted key path
    (or the file name) it is about.
    """


class _Required:
    def __repr__(self) -> str:  # pragma: no cover - cosmetic
        return "REQUIRED"


REQUIRED: Any = _Required()

#: when a list, every typed read of a key appends ``(dotted key, type, default, constraints)``
#: (used to generate the scenario-key reference from the validators themselves)
_RECORDER: list | None = None


def record_keys(on: bool = True) -> list | None:
    """Start (or stop) recording the keys the validators read; returns the record."""
    global _RECORDER
    _RECORDER = [] if on else None
    return _RECORDER


def _record(sec: "Section", name: str, kind: str, default: Any, **constraints) -> None:
    if _RECORDER is not None:
        c = {k: v for k, v in constraints.items() if v is not None and v != ()}
        _RECORDER.append((sec.key(name), kind, None if default is REQUIRED else default, default is REQUIRED, c))


def _type_name(value: Any) -> str:
    if isinstance(value, bool):
        return "boolean"
    if isinstance(value, int):
        return "integer"
    if isinstance(value, float):
        return "number"
    if isinstance(value, str):
        return "string"
    if isinstance(value, dict):
        return "table"
    if isinstance(value, list):
        return "array"
    return type(value).__name__


class Section:
    """A table of a scenario with the dotted path it came from.

    Parameters
    ----------
    data : dict
        The TOML table (may be empty).
    path : str
        Dotted key path of the table (``""`` for the root).
    """

    def __init__(self, data: dict | None, path: str = ""):
        if data is None:
            data = {}
        if not isinstance(data, dict):
            raise ScenarioError(f"{path or 'scenario'}: must be a table, got {_type_name(data)}")
        self.data = data
        self.path = path
        self._read: set[str] = set()

    # -- helpers -----------------------------------------------------------
    def key(self, name: str) -> str:
        return f"{self.path}.{name}" if self.path else name

    def error(self, name: str, message: str) -> ScenarioError:
        return ScenarioError(f"{self.key(name)}: {message}")

    def has(self, name: str) -> bool:
        return name in self.data

    def _raw(self, name: str, default: Any) -> Any:
        self._read.add(name)
        if name not in self.data:
            if default is REQUIRED:
                near = _near(name, [k for k in self.data if k not in self._read])
                hint = f"; found unknown key {self.key(near)!r}: a misspelling?" if near else ""
                raise self.error(name, f"missing (required){hint}")
            return default
        return self.data[name]

    # -- typed getters -----------------------------------------------------
    def number(self, name: str, default: Any = REQUIRED, *, gt: float | None = None,
               ge: float | None = None, lt: float | None = None, le: float | None = None) -> float:
        """A real number (integers accepted), with optional bounds."""
        _record(self, name, "number", default, gt=gt, ge=ge, lt=lt, le=le)
        value = self._raw(name, default)
        if value is default and name not in self.data:
            return value
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.error(name, f"must be a number, got {_type_name(value)} {value!r}")
        value = float(value)
        if not math.isfinite(value):
            raise self.error(name, f"must be finite, got {value}")
        _check_bounds(self, name, value, gt, ge, lt, le)
        return value

    def number_or(self, name: str, word: str, *, gt: float | None = None, ge: float | None = None,
                  lt: float | None = None, le: float | None = None) -> float | str:
        """A real number with optional bounds, or the word ``word`` (also the default, e.g. "auto")."""
        value = self.data.get(name, word)
        if value == word:
            _record(self, name, f"number or \"{word}\"", word, gt=gt, ge=ge, lt=lt, le=le)
            self._read.add(name)
            return word
        if isinstance(value, str):
            self._read.add(name)
            raise self.error(name, f"must be a number or \"{word}\", got string {value!r}")
        return self.number(name, word, gt=gt, ge=ge, lt=lt, le=le)

    def integer(self, name: str, default: Any = REQUIRED, *, gt: int | None = None,
                ge: int | None = None, lt: int | None = None, le: int | None = None) -> int:
        """An integer, with optional bounds."""
        _record(self, name, "integer", default, gt=gt, ge=ge, lt=lt, le=le)
        value = self._raw(name, default)
        if value is default and name not in self.data:
            return value
        if isinstance(value, bool) or not isinstance(value, int):
            if isinstance(value, float) and value.is_integer():
                value = int(value)
            else:
                raise self.error(name, f"must be an integer, got {_type_name(value)} {value!r}")
        _check_bounds(self, name, value, gt, ge, lt, le)
        return int(value)

    def boolean(self, name: str, default: Any = REQUIRED) -> bool:
        _record(self, name, "boolean", default)
        value = self._raw(name, default)
        if value is default and name not in self.data:
            return value
        if not isinstance(value, bool):
            raise self.error(name, f"must be true or false, got {_type_name(value)} {value!r}")
        return value

    def string(self, name: str, default: Any = REQUIRED, *, choices: Sequence[str] | None = None) -> str:
        _record(self, name, "string", default, choices=tuple(choices) if choices else None)
        value = self._raw(name, default)
        if value is default and name not in self.data:
            return value
        if not isinstance(value, str):
            raise self.error(name, f"must be a string, got {_type_name(value)} {value!r}")
        if choices is not None and value not in choices:
            raise self.error(name, f"must be one of {', '.join(map(repr, choices))}; got {value!r}")
        return value

    def numbers(self, name: str, default: Any = REQUIRED, *, length: int | None = None,
                min_length: int = 0, gt: float | None = None, ge: float | None = None) -> list[float]:
        """An array of numbers."""
        _record(self, name, "array of numbers", default, length=length, min_length=min_length or None, gt=gt, ge=ge)
        value = self._raw(name, default)
        if value is default and name not in self.data:
            return value
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            value = [value]
        if not isinstance(value, list):
            raise self.error(name, f"must be an array of numbers, got {_type_name(value)}")
        out = []
        for i, v in enumerate(value):
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise self.error(f"{name}[{i}]", f"must be a finite number, got {_type_name(v)} {v!r}")
            _check_bounds(self, f"{name}[{i}]", float(v), gt, ge, None, None)
            out.append(float(v))
        if length is not None and len(out) != length:
            raise self.error(name, f"must have {length} values, got {len(out)}")
        if len(out) < min_length:
            raise self.error(name, f"must have at least {min_length} values, got {len(out)}")
        return out

    def strings(self, name: str, default: Any = REQUIRED, *, choices: Sequence[str] | None = None) -> list[str]:
        """A string or an array of strings."""
        _record(self, name, "string or array of strings", default, choices=tuple(choices) if choices else None)
        value = self._raw(name, default)
        if value is default and name not in self.data:
            return value
        if isinstance(value, str):
            value = [value]
        if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
            raise self.error(name, "must be a string or an array of strings")
        if choices is not None:
            for i, v in enumerate(value):
                if v not in choices:
                    raise self.error(f"{name}[{i}]" if len(value) > 1 else name,
                                     f"must be one of {', '.join(map(repr, choices))}; got {v!r}")
        return list(value)

    def section(self, name: str, *, required: bool = False) -> "Section":
        """A sub-table (empty if absent and not required)."""
        value = self._raw(name, REQUIRED if required else None)
        if value is None:
            value = {}
        if not isinstance(value, dict):
            raise self.error(name, f"must be a table, got {_type_name(value)}")
        return Section(value, self.key(name))

    def sections(self, name: str) -> list["Section"]:
        """An array of tables (``[[name]]``); empty if absent."""
        value = self._raw(name, [])
        if isinstance(value, dict):
            value = [value]
        if not isinstance(value, list):
            raise self.error(name, f"must be an array of tables, got {_type_name(value)}")
        out = []
        for i, v in enumerate(value):
            if not isinstance(v, dict):
                raise self.error(f"{name}[{i}]", f"must be a table, got {_type_name(v)}")
            out.append(Section(v, f"{self.key(name)}[{i}]"))
        return out

    def raw(self, name: str, default: Any = None) -> Any:
        """The untyped value (marks the key as known)."""
        _record(self, name, "any", default)
        return self._raw(name, default)

    def finish(self, extra_allowed: Iterable[str] = ()) -> None:
        """Raise :class:`ScenarioError` if the table has keys nobody read."""
        allowed = self._read | set(extra_allowed)
        unknown = [k for k in self.data if k not in allowed]
        if unknown:
            k = unknown[0]
            near = _near(k, sorted(allowed))
            hint = f" (did you mean {near!r}?)" if near else ""
            raise self.error(k, f"unknown key{hint}; allowed here: " + (", ".join(sorted(allowed)) or "(none)"))


def _near(name: str, candidates: Sequence[str]) -> str | None:
    """The candidate closest to ``name`` when it looks like a misspelling of it."""
    import difflib

    m = difflib.get_close_matches(str(name), [str(c) for c in candidates], n=1, cutoff=0.75)
    return m[0] if m else None


def _check_bounds(sec: Section, name: str, value: float, gt, ge, lt, le) -> None:
    if gt is not None and not value > gt:
        raise sec.error(name, f"must be > {gt:g}, got {value:g}")
    if ge is not None and not value >= ge:
        raise sec.error(name, f"must be >= {ge:g}, got {value:g}")
    if lt is not None and not value < lt:
        raise sec.error(name, f"must be < {lt:g}, got {value:g}")
    if le is not None and not value <= le:
        raise sec.error(name, f"must be <= {le:g}, got {value:g}")
