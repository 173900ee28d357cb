"""The shape of the code (docs/conventions.md §4), read from the source with :mod:`ast`, never
by importing it, across all of ``src/coloradar``:

* no function over 120 lines or 10 parameters (a compiled kernel of ``dsp/_kernels/`` may take
  more parameters, its arrays and sizes, not more lines), no class over 500 lines, no module
  of 1,000 lines or more;
* no import circles among coloradar's modules: an import made only for type checking
  (``if TYPE_CHECKING:``) or inside a function counts like any other, because a reader
  following the code walks it all the same.

:data:`ALLOWED_OVERSIZE` (empty) is where an exception would have to be named; there is none.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"
PKG = SRC / "coloradar"

MAX_LINES = 120
MAX_PARAMS = 10
MAX_CLASS_LINES = 500
MAX_MODULE_LINES = 999
# Compiled kernels (numba-decorated functions) here may take more parameters, not more lines.
COMPILED_KERNELS = "dsp/_kernels"
# Functions allowed to break the limits: none. Never add to it; a long function is split, a long
# parameter list becomes a settings object.
ALLOWED_OVERSIZE: frozenset[str] = frozenset()


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


def _is_compiled(node: ast.FunctionDef | ast.AsyncFunctionDef) -> bool:
    """Whether a function is decorated as a numba kernel (``numba.njit(...)``, ``_jit(...)``)."""
    for dec in node.decorator_list:
        f = dec.func if isinstance(dec, ast.Call) else dec
        name = f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", "")
        if name in ("njit", "jit", "_jit"):
            return True
    return False


def definitions(source: str, compiled_ok: bool = False) -> list[str]:
    """Every function and class of ``source`` (text of one module) over the limits, as
    ``"qualified.name (line L): what"``; ``compiled_ok``: numba kernels may take more
    parameters."""
    out: list[str] = []

    def visit(node: ast.AST, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
                name = f"{prefix}{child.name}"
                n = (child.end_lineno or child.lineno) - child.lineno + 1
                if isinstance(child, ast.ClassDef):
                    if n > MAX_CLASS_LINES:
                        out.append(f"{name} (line {child.lineno}): class of {n} lines")
                else:
                    a = child.args
                    params = [p for p in (*a.posonlyargs, *a.args, *a.kwonlyargs)
                              if p.arg not in ("self", "cls")]
                    k = len(params) + (a.vararg is not None) + (a.kwarg is not None)
                    if n > MAX_LINES:
                        out.append(f"{name} (line {child.lineno}): {n} lines")
                    if k > MAX_PARAMS and not (compiled_ok and _is_compiled(child)):
                        out.append(f"{name} (line {child.lineno}): {k} parameters")
                visit(child, name + ".")
            else:
                visit(child, prefix)

    visit(ast.parse(source), "")
    return out


def _rel(path: Path) -> str:
    return path.relative_to(PKG).as_posix()


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


def test_size_checker_finds_planted_offenders():
    body = "\n".join(["    x = 1"] * 119)
    src = (f"def ok(a, b, c, d, e, f, g, h, i, j):\n{body}\n"                 # 120 lines, 10
           f"def long():\n{body}\n    x = 2\n"                                # 121 lines
           "def wide(a, b, c, d, e, f, g, h, i, *j, k):\n    pass\n"            # 11 parameters
           "@_jit(nogil=True)\ndef kernel(a, b, c, d, e, f, g, h, i, j, k):\n    pass\n"
           "class Big:\n    def method(self, a, b, c, d, e, f, g, h, i, j, k):\n        pass\n"
           + "\n".join(["    y = 1"] * 498) + "\n")
    found = definitions(src)
    assert [f.split(" (")[0] for f in found] == ["long", "wide", "kernel", "Big",
                                                "Big.method"]
    # a numba kernel may take more parameters where compiled kernels live, not more lines
    assert [f.split(" (")[0] for f in definitions(src, compiled_ok=True)] == [
        "long", "wide", "Big", "Big.method"]


def test_allowed_oversize_names_real_functions_outside_dsp():
    for entry in ALLOWED_OVERSIZE:
        rel, _, name = entry.partition(":")
        assert not rel.startswith("dsp/"), entry
        tree = ast.parse((PKG / rel).read_text())
        names = {n.name for n in ast.walk(tree)
                 if isinstance(n, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef)}
        assert name.split(".")[-1] in names, entry


@pytest.mark.parametrize("path", sorted(PKG.rglob("*.py")), ids=_rel)
def test_functions_classes_and_modules_are_short(path):
    rel = _rel(path)
    text = path.read_text()
    problems = [f for f in definitions(text, compiled_ok=rel.startswith(COMPILED_KERNELS + "/"))
                if f"{rel}:{f.split(' (')[0]}" not in ALLOWED_OVERSIZE]
    n = len(text.splitlines())
    if n > MAX_MODULE_LINES:
        problems.append(f"module of {n} lines")
    assert not problems, "; ".join(problems)
