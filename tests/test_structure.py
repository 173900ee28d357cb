"""The shape of the code: short functions with short parameter lists in ``batch/``, ``interop/``
and ``sim/run.py`` (at most 120 lines and 10 parameters), and no import circles among
coloradar's modules (docs/conventions.md §4).

Both are read from the source with :mod:`ast`, never by importing it: an import made only for
type checking (``if TYPE_CHECKING:``) or inside a function counts like any other, because a
reader following the code walks it all the same.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"
PKG = SRC / "coloradar"

MAX_LINES = 120
MAX_PARAMS = 10
# Where functions must stay short (folders or files, relative to src/coloradar).
SHORT_FUNCTIONS = ("batch", "interop", "sim/run.py")


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(SRC).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _modules() -> dict[str, Path]:
    return {_module_name(p): p for p in sorted(PKG.rglob("*.py"))}


def _is_package(mods: dict[str, Path], name: str) -> bool:
    return mods[name].name == "__init__.py"


def _absolute(mods: dict[str, Path], here: str, node: ast.ImportFrom) -> str:
    """The absolute module an ``ImportFrom`` names (``from ..x import y`` → ``coloradar.x``)."""
    if node.level == 0:
        return node.module or ""
    base = here.split(".") if _is_package(mods, here) else here.split(".")[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _reexports(mods: dict[str, Path], pkg: str) -> dict[str, str]:
    """Names a package's ``__init__`` takes from its own submodules: name → submodule."""
    out: dict[str, str] = {}
    for node in ast.walk(ast.parse(mods[pkg].read_text())):
        if isinstance(node, ast.ImportFrom) and node.level == 1 and node.module:
            sub = f"{pkg}.{node.module}"
            if sub in mods:
                out.update((a.asname or a.name, sub) for a in node.names)
    return out


def import_graph() -> dict[str, set[str]]:
    """Module → coloradar modules it imports (a name re-exported by a package counts as an
    import of the submodule that defines it, so that a package's ``__init__`` is no hub)."""
    mods = _modules()
    graph: dict[str, set[str]] = {m: set() for m in mods}
    for name, path in mods.items():
        for node in ast.walk(ast.parse(path.read_text())):
            targets: list[str] = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                mod = _absolute(mods, name, node)
                if mod in mods and _is_package(mods, mod):
                    again = _reexports(mods, mod)
                    for a in node.names:
                        if f"{mod}.{a.name}" in mods:
                            targets.append(f"{mod}.{a.name}")
                        else:
                            targets.append(again.get(a.name, mod))
                else:
                    targets = [mod]
            for t in targets:
                if t in mods and t != name and not name.startswith(t + "."):
                    graph[name].add(t)
    return graph


def import_cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    found: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def _functions(path: Path):
    tree = ast.parse(path.read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            a = node.args
            params = [*a.posonlyargs, *a.args, *a.kwonlyargs]
            params = [p for p in params if p.arg not in ("self", "cls")]
            n = len(params) + (a.vararg is not None) + (a.kwarg is not None)
            yield node.name, node.lineno, node.end_lineno - node.lineno + 1, n


def _short_function_files() -> list[Path]:
    return [p for d in SHORT_FUNCTIONS
            for p in ([PKG / d] if d.endswith(".py") else sorted((PKG / d).rglob("*.py")))]


def test_cycle_finder_finds_a_planted_circle():
    g = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": set()}
    assert import_cycles(g) == [["a", "b", "c"]]
    assert import_cycles({"a": {"b"}, "b": set()}) == []


def test_import_graph_sees_type_checking_and_function_imports():
    g = import_graph()
    # evaluation.py imports the metrics at module level; the CLI imports lazily inside functions.
    assert "coloradar.odometry.metrics" in g["coloradar.odometry.evaluation"]
    assert "coloradar.geometry.se3" in g["coloradar.geometry.trajectory"]
    assert any(t.startswith("coloradar.batch") for t in g["coloradar.cli.process"])


def test_no_import_cycles():
    assert import_cycles(import_graph()) == []


@pytest.mark.parametrize("path", _short_function_files(),
                         ids=lambda p: str(p.relative_to(PKG)))
def test_functions_are_short(path):
    long = [f"{name} (line {line}): {n} lines" for name, line, n, _ in _functions(path)
            if n > MAX_LINES]
    wide = [f"{name} (line {line}): {k} parameters" for name, line, _, k in _functions(path)
            if k > MAX_PARAMS]
    assert not long and not wide, "; ".join(long + wide)
