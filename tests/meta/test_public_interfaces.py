"""Packages meet through public names: no module of ``ema_casadi`` imports another
package's private module (``simulation._api``) or private name (``from ..signals import
_x``), except the shared helpers ``_util`` and the figures ``plots``. What a package
offers the others is in its ``__init__`` and ``__all__`` (documented, see test_api).

The imports are read from the source with :mod:`ast` (nothing is imported): every
``import``/``from`` statement, at module level, inside a function or under
``if TYPE_CHECKING:``, relative ones resolved. A package is a top-level package of
``ema_casadi`` (``model.components`` belongs to ``model``).
"""

from __future__ import annotations

import ast
from pathlib import Path

import ema_casadi

ROOT = Path(ema_casadi.__file__).parent
#: Packages whose private modules every package may use.
SHARED = {"_util", "plots"}
#: Reviewed exceptions, file -> the private module it may name, each with its reason. A file
#: that no longer exists drops out; one that no longer needs its exception fails the test.
EXCEPTIONS: dict[str, str] = {}


def _package(dotted: str) -> str | None:
    """The top-level package of a dotted ``ema_casadi`` name (None: the root)."""
    parts = dotted.split(".")
    return parts[1] if len(parts) > 1 else None


def _reach_ins(source: str, rel: str) -> list[tuple[int, str]]:
    """``(line, what)`` of every import of another package's private module or name in
    the module ``source`` at ``rel`` (its path under the package, ``mission/_run.py``)."""
    parts = ("ema_casadi", *Path(rel).with_suffix("").parts)
    is_pkg = parts[-1] == "__init__"
    name = ".".join(parts[:-1] if is_pkg else parts)
    here = name if is_pkg else name.rpartition(".")[0]
    mine = _package(name)
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = here.split(".")[: len(here.split(".")) - node.level + 1]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            targets = [(module, a.name) for a in node.names]
        elif isinstance(node, ast.Import):
            targets = [(a.name, None) for a in node.names]
        else:
            continue
        for module, item in targets:
            if module != "ema_casadi" and not module.startswith("ema_casadi."):
                continue
            other = _package(module)
            if other is None:  # from ema_casadi import X: X is a package or a root name
                other, module, item = (item, f"ema_casadi.{item}", None) if item else (None, module, None)
                if other is None or not other.startswith("_") or other in SHARED or other == "__version__":
                    continue
            if other == mine or other in SHARED:
                continue
            private = [s for s in module.split(".")[2:] if s.startswith("_")]
            if private or (item and item.startswith("_")):
                found.append((node.lineno, f"{module}" + (f" import {item}" if item else "")))
    return found


def _all_reach_ins() -> dict[str, list[tuple[int, str]]]:
    out = {}
    for path in sorted(ROOT.rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        hits = _reach_ins(path.read_text(encoding="utf-8"), rel)
        if hits:
            out[rel] = hits
    return out


def test_no_package_imports_another_packages_private_names():
    found = _all_reach_ins()
    bad = [f"{f}:{line}: {what}" for f, hits in found.items() for line, what in hits
           if not (f in EXCEPTIONS and what.startswith(EXCEPTIONS[f]))]
    assert not bad, "import through the package's __init__ (export the name there):\n" + "\n".join(bad)


def test_every_exception_is_still_needed():
    found = _all_reach_ins()
    stale = [f for f, module in EXCEPTIONS.items() if (ROOT / f).exists()
             and not any(what.startswith(module) for _, what in found.get(f, []))]
    assert not stale, f"exceptions no longer needed (remove them): {stale}"


def test_the_scan_sees_a_reach_in():
    """The scan is not blind: planted private imports are found, public and own ones are not."""
    source = ("from ..simulation._api import check_run\nfrom ..simulation import simulate\n"
              "from .._util._files import atomic_dir\nfrom ..signals import _x\nfrom ._result import _y\n"
              "import ema_casadi.model._flat\nfrom .. import _util\nfrom ..plots._mission import f\n")
    hits = _reach_ins(source, "mission/_probe.py")
    assert [w for _, w in hits] == ["ema_casadi.simulation._api import check_run", "ema_casadi.signals import _x",
                                    "ema_casadi.model._flat"]
