"""Meta-tests of the package's layering: the import graph of ``ema_casadi`` has no
cycle, and the layers import only downward.

The graph is built from the source with :mod:`ast` (nothing is imported): every
``import``/``from`` statement counts, at module level or inside a function, relative
ones resolved; only annotations under ``if TYPE_CHECKING:`` are left out (they never
run). Importing ``a.b.c`` from outside ``a.b`` also runs ``a/__init__`` and
``a/b/__init__``, so such an import adds edges to those packages too: a package whose
``__init__`` re-exports a module that imports the package back is a cycle here, as it
is for Python when that module is imported first.

The layers, bottom to top (a module may import its own layer and the layers below):

================  ===========================================================================
``_util``         checks, files, interrupts, keywords, parallel map, compiled libraries
``signals``       the signal algebra, CSV tables, the text syntax
``model``         parameters, parts (``components/``), the assembly
``plots``         figures drawn from data (duck-typed results; no analysis imported)
``optimisation``  the IPOPT wrapper, least squares, transcriptions (model and helpers only)
analyses          ``simulation``, ``linearisation``, ``frequency``, ``export`` (with
                  ``fmu/``), ``sinestream``, ``limitcycle``, ``aircraft``, ``mission``,
                  ``tuning``, ``sweeps``, ``identification``, ``faults``: among themselves a DAG
                  (no package cycle)
``demo``          the demonstration run (uses everything below)
``cli``           the ``ema`` command
================  ===========================================================================

The package's root ``__init__`` loads its names on first use (no static import).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import ema_casadi

PKG = "ema_casadi"
ROOT = Path(ema_casadi.__file__).parent

ANALYSES = ("simulation", "linearisation", "frequency", "export", "sinestream", "limitcycle", "aircraft", "mission",
            "tuning", "sweeps", "identification", "faults", "design", "optimal")
#: Layer of each top-level module or package, bottom (0) to top.
LAYERS = [("_util",), ("signals",), ("model",), ("plots",), ("optimisation",), ANALYSES, ("demo",), ("cli",)]
RANK = {name: rank for rank, names in enumerate(LAYERS) for name in names}


def _modules(root: Path) -> dict[str, tuple[Path, bool]]:
    """``{dotted name: (file, is a package)}`` of every module under ``root``."""
    out = {}
    for path in root.rglob("*.py"):
        parts = (PKG, *path.relative_to(root).with_suffix("").parts)
        if parts[-1] == "__init__":
            out[".".join(parts[:-1])] = (path, True)
        else:
            out[".".join(parts)] = (path, False)
    return out


def _type_checking_lines(tree: ast.AST) -> set[int]:
    """Line numbers of statements under ``if TYPE_CHECKING:``."""
    lines = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            for stmt in node.body:
                lines.update(range(stmt.lineno, stmt.end_lineno + 1))
    return lines


def _imports(name: str, is_pkg: bool, tree: ast.AST, modules) -> set[str]:
    """The ``ema_casadi`` modules a module's import statements name."""
    skip = _type_checking_lines(tree)
    package = name if is_pkg else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(tree):
        if getattr(node, "lineno", None) in skip:
            continue
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module
            found.add(target)
            found.update(f"{target}.{a.name}" for a in node.names if f"{target}.{a.name}" in modules)
    return {t for t in found if t in modules}


def import_graph(root: Path = ROOT) -> dict[str, set[str]]:
    """``{module: modules its execution imports}`` (see the module docstring)."""
    modules = _modules(root)
    graph = {}
    for name, (path, is_pkg) in modules.items():
        edges = set()
        for target in _imports(name, is_pkg, ast.parse(path.read_text(encoding="utf-8")), modules):
            parts = target.split(".")
            for k in range(2, len(parts) + 1):  # the target and the packages above it
                head = ".".join(parts[:k])
                if head != name and not name.startswith(head + "."):
                    edges.add(head)
        graph[name] = edges
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph.get(v, ())):
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
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def _top(name: str) -> str:
    return name.split(".")[1] if name.count(".") else name


GRAPH = import_graph()


def test_graph_is_read():
    # the walk sees the layers and the edges (a test that cannot pass on an empty graph)
    assert {_top(m) for m in GRAPH} >= set(RANK)
    assert "ema_casadi.model.assembly" in GRAPH["ema_casadi.simulation._api"]
    assert "ema_casadi.export._errors" in GRAPH["ema_casadi.export.fmu._pack"]


def test_cycles_are_found():
    # the detector on a known graph: a -> b -> c -> a is one cycle, d hangs off it
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert cycles(graph) == [["a", "b", "c"]]


def test_no_import_cycle():
    found = cycles(GRAPH)
    assert not found, "import cycles: " + "; ".join(" <-> ".join(c) for c in found)


def test_no_package_cycle_among_analyses():
    packages = {}
    for mod, edges in GRAPH.items():
        packages.setdefault(_top(mod), set()).update(_top(t) for t in edges if _top(t) != _top(mod))
    found = cycles(packages)
    assert not found, "package cycles: " + "; ".join(" <-> ".join(c) for c in found)


def test_every_module_has_a_layer():
    unplaced = sorted({_top(m) for m in GRAPH} - set(RANK) - {PKG})
    assert not unplaced, f"top-level modules without a layer (add them to LAYERS): {unplaced}"


@pytest.mark.parametrize("module", sorted(m for m in GRAPH if m != PKG))
def test_layers_import_downward(module):
    rank = RANK[_top(module)]
    up = sorted(t for t in GRAPH[module] if t != PKG and RANK[_top(t)] > rank)
    assert not up, f"{module} (layer {_top(module)}) imports a higher layer: {up}"


# -- size guideline ----------------------------------------------------------------
# A guideline, not a cap to trim code to: a module over MAX_MODULE_LINES is split where it
# holds two ideas; where splitting would scatter one idea it is listed here, reviewed, with
# its reason and a ceiling of its own (an entry no longer needed fails, so the list stays true).
MAX_MODULE_LINES = 500
MAX_FUNCTION_LINES = 80
#: Reviewed long modules: path -> (ceiling in lines, why it stays one module).
LONG_MODULES = {
    "ema_casadi/model/params.py": (735, "the typed parameters: the groups (the optional sensor, fault, monitor "
                                        "and airframe tables with them, one field helper and one set of checks; "
                                        "a set of several actuators' tables delegated to the model's instances), "
                                        "their fields' rules, reading a file and checking one value by the same "
                                        "rules"),
    "ema_casadi/model/components/_part.py": (610, "the part contract: what every part declares (states, inputs, "
                                                  "outputs with their roles, loops, holds, bounds, ratings, the parts "
                                                  "it brings) and the Part and "
                                                  "Bus they meet through (which checks each read against the "
                                                  "reader's ports)"),
    "ema_casadi/linearisation/_trim.py": (540, "the operating point: the request (by name or role, checked "
                                               "against the envelope), the Newton trim and the point it returns"),
    "ema_casadi/sweeps/_spec.py": (540, "the sweep description, read from a file or built from objects and "
                                        "checked by the same rules: variants, parameter grids and draws, runs, "
                                        "scenario"),
    "ema_casadi/model/components/controller.py": (560, "the ECU: every loop's law (PI, limits, anti-windup, "
                                                       "FOC) and the parts that close the loops, the outer loops "
                                                       "and the current controllers the motor parts bring"),
    "ema_casadi/signals/_signal.py": (560, "the signal algebra and its quantities (the Signal class, the unit "
                                           "table and the parsers of a quantity are one vocabulary)"),
}


def _docstring_lines(node) -> int:
    first = node.body[0] if node.body else None
    if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant) and isinstance(first.value.value, str):
        return first.end_lineno - first.lineno + 1
    return 0


def test_the_long_module_list_is_needed():
    for rel, (ceiling, why) in LONG_MODULES.items():
        n = (ROOT.parent / rel).read_text(encoding="utf-8").count("\n")
        assert n > MAX_MODULE_LINES, f"{rel}: {n} lines, within the guideline: remove it from LONG_MODULES"
        assert ceiling > MAX_MODULE_LINES and why, rel


def test_module_and_function_sizes():
    long_modules, long_functions = [], []
    for path in sorted(ROOT.rglob("*.py")):
        text = path.read_text(encoding="utf-8")
        rel = path.relative_to(ROOT.parent)
        limit = LONG_MODULES.get(rel.as_posix(), (MAX_MODULE_LINES, ""))[0]
        if text.count("\n") > limit:
            long_modules.append(f"{rel}: {text.count(chr(10))} lines")
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = node.end_lineno - node.lineno + 1 - _docstring_lines(node)  # the code, not its documentation
                if n > MAX_FUNCTION_LINES:
                    long_functions.append(f"{rel}:{node.lineno} {node.name}: {n} lines")
    assert not long_modules, f"modules over {MAX_MODULE_LINES} lines (split, or review into LONG_MODULES): " \
                             f"{long_modules}"
    assert not long_functions, f"functions over {MAX_FUNCTION_LINES} lines: {long_functions}"
