"""Architecture guards: the part contract, checked on the source.

1. Outside the model layer (:data:`MODEL_LAYER`) no code compares a variant value
   (``variants["friction"] == "hybrid"``) and none imports a ``components.<family>``
   module: everything else asks the model (signals by name and role, the parts'
   declarations merged by the assembly).
2. No analysis (:data:`ANALYSES`) names a parameter that a particular part declares
   (``F_seal``, ``I_max``, ``eta_inv``, ...): the list is collected from the parts'
   own ``params`` declarations, so a new part's parameters are guarded by themselves.

The checks read the source with :mod:`ast` (names, attributes, keywords and string
constants), so comments and docstrings may still speak of the physics.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import ema_casadi
from ema_casadi.model.components import PART_CLASSES, REGISTRY, VARIANTS

PACKAGE = Path(ema_casadi.__file__).resolve().parent

#: The model layer (paths relative to the package): the only code that may know
#: particular parts and variant values.
MODEL_LAYER = ["model"]

#: The analyses (paths relative to the package), which ask the model only.
ANALYSES = [
    "linearisation", "sinestream", "mission", "tuning", "sweeps", "simulation",
    "aircraft", "limitcycle", "export", "frequency", "faults", "optimal", "optimisation",  # export holds fmu/
]

#: Parameter groups that describe the whole actuator rather than one part: the stroke
#: is the actuator's rating, used to scale requests (amplitudes in % of the stroke).
MODEL_WIDE_GROUPS = ("actuator",)


def _files(roots, base=PACKAGE):
    for root in roots:
        path = base / root
        yield from sorted(path.rglob("*.py")) if path.is_dir() else ([path] if path.exists() else [])


def _in(path: Path, roots, base=PACKAGE) -> bool:
    rel = path.relative_to(base).as_posix()
    return any(rel == r or rel.startswith(r.rstrip("/") + "/") for r in roots)


def _outside_model(base=PACKAGE):
    return [f for f in _files(["."], base) if not _in(f, MODEL_LAYER, base)]


def _signal_names() -> set:
    """Every state, input, output and provided signal any part declares."""
    names = set()
    for cls in PART_CLASSES:  # the registry's, the parts they bring, their option forms
        names.update(s.name for s in cls.states)
        names.update(i.name for i in cls.inputs)
        names.update(o.name for o in cls.outputs)
        for key in cls().signals():
            names.update(key if isinstance(key, tuple) else (key,))
    return names


def part_parameters() -> set:
    """The parameter names the parts declare, less those that are also signal names
    (the ``eta`` input and parameter share a name) and the model-wide groups."""
    from ema_casadi.model.params import GROUPS

    wide = {f.name for g in MODEL_WIDE_GROUPS for f in GROUPS[g].__dataclass_fields__.values()}
    declared = {n for cls in PART_CLASSES for n in cls.params}
    return declared - _signal_names() - wide


# -- the checks (each returns "path:line: what" strings; base: the package root) ----
def variant_comparisons(base=PACKAGE) -> list[str]:
    """Comparisons of a variant dict entry (``x["friction"] == ...``, ``x.get("screw") in ...``)."""
    keys = set(VARIANTS)
    found = []

    def keyed(node) -> str | None:
        if isinstance(node, ast.Subscript) and isinstance(node.slice, ast.Constant) and node.slice.value in keys:
            return node.slice.value
        if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "get"
                and node.args and isinstance(node.args[0], ast.Constant) and node.args[0].value in keys):
            return node.args[0].value
        return None

    for path in _outside_model(base):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Compare):
                for side in (node.left, *node.comparators):
                    key = keyed(side)
                    if key:
                        found.append(f"{path.relative_to(base)}:{node.lineno}: compares the variant '{key}'")
    return found


def family_imports(base=PACKAGE) -> list[str]:
    """Imports of a ``components.<family>`` module outside the model layer."""
    families = {m.stem for m in (PACKAGE / "model" / "components").glob("*.py") if not m.stem.startswith("__")}
    found = []
    for path in _outside_model(base):
        for node in ast.walk(ast.parse(path.read_text())):
            mods = []
            if isinstance(node, ast.ImportFrom) and node.module:
                parts = node.module.split(".")
                if "components" in parts:
                    tail = parts[parts.index("components") + 1:]
                    mods = tail[:1] if tail else [a.name for a in node.names if a.name in families]
            elif isinstance(node, ast.Import):
                mods = [a.name.split(".")[2] for a in node.names if a.name.startswith("ema_casadi.model.components.")]
            for m in mods:
                if m in families:
                    found.append(f"{path.relative_to(base)}:{node.lineno}: imports components.{m}")
    return found


def _short(name: str) -> bool:
    """Names too generic to guard as identifiers (``p``, ``B``, ``C``: the lead, the
    backlash, the stiffness, but also a parameter vector and state-space matrices)."""
    return len(name) <= 2 and "_" not in name


def parameter_names_in_analyses(base=PACKAGE) -> list[str]:
    """Where an analysis names a part's parameter: as a string, an attribute, a keyword
    or (names of three or more characters) an identifier. The short names are checked
    where they can only be a parameter lookup: an ``index`` argument, ``getattr``."""
    names = part_parameters()
    found = []
    for path in _files(ANALYSES, base):
        tree = ast.parse(path.read_text())
        hits = set()
        for node in ast.walk(tree):
            if isinstance(node, ast.Constant) and isinstance(node.value, str) and node.value in names:
                if not _short(node.value):
                    hits.add((node.lineno, node.value))
            elif (isinstance(node, ast.Attribute) and node.attr in names and not _short(node.attr)
                  and not isinstance(node.value, ast.Call)):  # np.finfo(float).eps is no parameter
                hits.add((node.lineno, node.attr))
            elif isinstance(node, ast.Name) and node.id in names and not _short(node.id):
                hits.add((node.lineno, node.id))
            elif isinstance(node, ast.keyword) and node.arg in names and not _short(node.arg):
                hits.add((node.value.lineno, node.arg))
            elif isinstance(node, ast.Call):
                f = node.func
                lookup = (isinstance(f, ast.Attribute) and f.attr == "index") or (
                    isinstance(f, ast.Name) and f.id == "getattr")
                for a in node.args if lookup else ():
                    if isinstance(a, ast.Constant) and isinstance(a.value, str) and a.value in names:
                        hits.add((node.lineno, a.value))
        found += [f"{path.relative_to(base)}:{line}: names the parameter {name}" for line, name in sorted(hits)]
    return found


# -- the tests ----------------------------------------------------------------------
def test_the_guarded_sets_exist():
    for root in MODEL_LAYER + ANALYSES:
        assert (PACKAGE / root).exists(), root
    # the parameter list is not empty and holds what the parts declare
    names = part_parameters()
    assert {"F_seal", "C_bear", "I_max", "V_dc", "k_v", "eta_inv"} <= names


def test_no_variant_value_is_compared_outside_the_model_layer():
    assert variant_comparisons() == []


def _split(found: list[str]):
    """(path, name) of each 'path:line: ... name' entry."""
    return {(f.split(":")[0], f.split()[-1].split(".")[-1]) for f in found}


def test_no_family_module_is_imported_outside_the_model_layer():
    assert _split(family_imports()) == set()


def test_no_analysis_names_a_part_parameter():
    assert _split(parameter_names_in_analyses()) == set()



def test_the_registry_refuses_an_option_declared_twice_with_other_values():
    """Two parts may share one option declaration; a second, different one (or an option
    named like a variant key) is refused instead of silently merged."""
    from ema_casadi.model.components import OPTIONS, AssemblyError, Part
    from ema_casadi.model.components._registry import merge_options

    def part(family, value, options):
        return type(f"{family}{value}", (Part,), {"family": family, "value": value, "options": options})

    assert merge_options(REGISTRY) == OPTIONS
    same = {"a": {"x": part("a", "x", {"shape": ("clip", "smooth")})},
            "b": {"y": part("b", "y", {"shape": ("clip", "smooth")})}}
    assert merge_options(same) == {"shape": ("clip", "smooth")}
    other = {"a": {"x": part("a", "x", {"shape": ("clip", "smooth")})},
             "b": {"y": part("b", "y", {"shape": ("smooth", "clip")})}}
    with pytest.raises(AssemblyError, match="option 'shape' declared twice: a = x"):
        merge_options(other)
    with pytest.raises(AssemblyError, match="option 'b' of a = x has the name of a variant key"):
        merge_options({"a": {"x": part("a", "x", {"b": ("0", "1")})}, "b": {}})
