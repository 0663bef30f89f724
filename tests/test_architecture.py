"""The structure docs/design.md promises, checked statically on the source tree.

* packages depend downwards only: simsat ← restore ← reports ← simsat_cli;
* no import cycle between the project's modules (top-level imports);
* no branching on a method's name outside the registries (callers ask a
  method's spec what it can do);
* no function over 80 lines of code unless its docstring says why ("Long: ...").
"""
import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LAYERS = {"simsat": 0, "restore": 1, "navigation": 1, "reports": 2, "simsat_cli": 3}


def _modules() -> dict:
    out = {}
    for pkg in LAYERS:
        for p in (ROOT / pkg).rglob("*.py"):
            name = ".".join(p.relative_to(ROOT).with_suffix("").parts)
            out[name[:-len(".__init__")] if name.endswith(".__init__") else name] = p
    return out


def _imports(name: str, path: Path, modules: dict) -> set:
    """Project modules imported at the top level of ``name`` (its own ancestor packages excluded)."""
    deps = set()
    for node in ast.parse(path.read_text()).body:
        nodes = node.body if isinstance(node, ast.Try) else [node]
        for n in nodes:
            if isinstance(n, ast.Import):
                deps.update(a.name for a in n.names)
            elif isinstance(n, ast.ImportFrom):
                base = n.module or ""
                if n.level:
                    pkg = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
                    pkg = pkg[:len(pkg) - (n.level - 1)]
                    base = ".".join(pkg + ([base] if base else []))
                deps.add(base)
                deps.update(f"{base}.{a.name}" for a in n.names)
    return {d for d in deps if d in modules and d != name and not name.startswith(d + ".")}


@pytest.fixture(scope="module")
def graph():
    mods = _modules()
    return {m: _imports(m, p, mods) for m, p in mods.items()}


def _upward(graph: dict) -> list:
    return [f"{m} -> {d}" for m, ds in graph.items() for d in ds
            if LAYERS[d.split(".")[0]] > LAYERS[m.split(".")[0]]]


def _cycles(graph: dict) -> list:
    state: dict = {}
    cycles = []

    def visit(m, stack):
        state[m] = 1
        for d in sorted(graph.get(m, ())):
            if state.get(d) == 1:
                cycles.append(stack[stack.index(d):] + [d])
            elif d not in state:
                visit(d, stack + [d])
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m, [m])
    return cycles


def test_packages_depend_downwards_only(graph):
    assert not _upward(graph), _upward(graph)


def test_no_import_cycle(graph):
    assert not _cycles(graph), _cycles(graph)


def test_the_checks_see_a_cycle_and_an_upward_import(tmp_path):
    """The checks above are not vacuous: a planted cycle and a planted upward import are found."""
    a = tmp_path / "a.py"
    a.write_text("from restore import stages\nfrom . import b\n")
    mods = {"simsat.a": a, "simsat.b": a, "restore.stages": a, "restore": a}
    deps = _imports("simsat.a", a, mods)
    assert deps == {"restore", "restore.stages", "simsat.b"}
    assert sorted(_upward({"simsat.a": deps})) == ["simsat.a -> restore", "simsat.a -> restore.stages"]
    assert _cycles({"simsat.a": {"simsat.b"}, "simsat.b": {"simsat.a"}}) == [["simsat.a", "simsat.b", "simsat.a"]]
def test_no_branching_on_method_names():
    pattern = re.compile(r"method\s*==|method in \(")
    found = [f"{p.relative_to(ROOT)}:{i}" for pkg in ("restore", "reports") for p in (ROOT / pkg).rglob("*.py")
             for i, line in enumerate(p.read_text().splitlines(), 1) if pattern.search(line)]
    assert not found, found


def _code_lines(path: Path, fn: ast.FunctionDef) -> int:
    """Lines of code of a function: its body without the docstring, blank lines and comments."""
    body = fn.body
    first = body[0]
    has_doc = isinstance(first, ast.Expr) and isinstance(getattr(first, "value", None), ast.Constant) and \
        isinstance(first.value.value, str)
    start = (first.end_lineno + 1) if has_doc and len(body) > 1 else body[0].lineno
    lines = path.read_text().splitlines()[start - 1:fn.end_lineno]
    return sum(1 for ln in lines if ln.strip() and not ln.strip().startswith("#"))


def test_no_function_over_80_lines_without_a_reason():
    long = []
    for pkg in LAYERS:
        for p in (ROOT / pkg).rglob("*.py"):
            for node in ast.walk(ast.parse(p.read_text())):
                if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    n = _code_lines(p, node)
                    if n > 80 and "Long:" not in (ast.get_docstring(node) or ""):
                        long.append(f"{p.relative_to(ROOT)}:{node.lineno} {node.name} ({n} lines)")
    assert not long, long


def test_the_length_check_counts_code_not_docstrings(tmp_path):
    p = tmp_path / "m.py"
    p.write_text('def f():\n    """Doc.\n\n    More doc.\n    """\n    # a comment\n    x = 1\n\n    return x\n')
    fn = ast.parse(p.read_text()).body[0]
    assert _code_lines(p, fn) == 2
