"""One optimisation layer: no module outside ``ema_casadi/optimisation`` creates an IPOPT
(or any CasADi NLP/QP) solver or writes its own Levenberg-Marquardt loop; the analyses
that optimise import the layer; the Newton iterations take their step from it.

Read from the source with :mod:`ast`: a call of ``nlpsol``, ``qpsol``, ``conic`` or an
``Opti`` object's ``.solver(...)`` (any ``X.solver(...)`` call), and a function whose name
speaks of Levenberg-Marquardt or Gauss-Newton, or a call of SciPy's ``least_squares``.
"""

from __future__ import annotations

import ast
from pathlib import Path

import ema_casadi

ROOT = Path(ema_casadi.__file__).parent
LAYER = "optimisation"
SOLVER_CALLS = ("nlpsol", "qpsol", "conic", "solver")
LSQ_WORDS = ("levenberg", "marquardt", "gauss_newton", "least_squares")
#: The analyses that optimise: each imports the layer.
CALLERS = ("tuning", "optimal", "design", "identification", "linearisation", "limitcycle")


def _sources():
    for path in sorted(ROOT.rglob("*.py")):
        rel = path.relative_to(ROOT)
        if rel.parts[0] != LAYER:
            yield rel.as_posix(), ast.parse(path.read_text(encoding="utf-8"))


def _called(node: ast.Call) -> str:
    f = node.func
    return f.attr if isinstance(f, ast.Attribute) else f.id if isinstance(f, ast.Name) else ""


def test_the_layer_is_found():
    # a check that cannot pass on nothing: the layer holds the solver and the LM loop
    text = (ROOT / LAYER / "_ipopt.py").read_text(encoding="utf-8")
    assert ".solver(" in text
    assert "def levenberg_marquardt" in (ROOT / LAYER / "_lsq.py").read_text(encoding="utf-8")


def test_one_ipopt_wrapper():
    found = [f"{rel}:{node.lineno} {_called(node)}(" for rel, tree in _sources() for node in ast.walk(tree)
             if isinstance(node, ast.Call) and _called(node) in SOLVER_CALLS]
    assert not found, f"solvers created outside ema_casadi/{LAYER} (use solve_ipopt): {found}"


def test_one_least_squares_loop():
    found = []
    for rel, tree in _sources():
        for node in ast.walk(tree):
            name = node.name if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) else \
                _called(node) if isinstance(node, ast.Call) else ""
            if any(w in name.lower() for w in LSQ_WORDS) and not isinstance(node, ast.Call):
                found.append(f"{rel}:{node.lineno} def {name}")
            elif isinstance(node, ast.Call) and name == "least_squares":
                found.append(f"{rel}:{node.lineno} {name}(")
    assert not found, f"least-squares loops outside ema_casadi/{LAYER} (use levenberg_marquardt): {found}"


def test_the_callers_use_the_layer():
    for caller in CALLERS:
        text = "".join(p.read_text(encoding="utf-8") for p in (ROOT / caller).rglob("*.py"))
        assert "..optimisation import" in text, f"{caller} does not use ema_casadi.{LAYER}"


def test_one_newton_step():
    # the Newton iterations (trim, flight trim, periodic orbit, harmonic balance) keep their
    # residuals and globalisation; the step itself is the layer's newton_step
    found = []
    for rel, tree in _sources():
        for fn in ast.walk(tree):
            if isinstance(fn, ast.FunctionDef) and "newton" in fn.name.lower():
                found += [f"{rel}:{n.lineno} {_called(n)}(" for n in ast.walk(fn)
                          if isinstance(n, ast.Call) and _called(n) in ("solve", "lstsq", "pinv")]
    assert not found, f"Newton steps solved outside ema_casadi/{LAYER} (use newton_step): {found}"
