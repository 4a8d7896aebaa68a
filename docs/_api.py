"""Write the API reference page (``api/index.md``) from the package itself.

Every public module (no leading underscore) that declares ``__all__`` gets a section
listing its names; each object is documented once, where it is first met: the names
of ``ema_casadi`` itself first, then each subpackage in turn. So the page follows the
code as it grows or moves, and nothing in it is written by hand.
"""

from __future__ import annotations

import importlib
import inspect
import pkgutil
from pathlib import Path

_SKIP = ("ema_casadi.cli",)  # the command line has its own page (cli.md)


def _modules(package: str) -> list[str]:
    pkg = importlib.import_module(package)
    names = []
    for info in pkgutil.walk_packages(pkg.__path__, prefix=f"{package}."):
        parts = info.name.split(".")
        if any(p.startswith("_") for p in parts) or info.name.startswith(_SKIP):
            continue
        names.append(info.name)
    return sorted(names)


def _summary(obj) -> str:
    doc = inspect.getdoc(obj) or ""
    return doc.strip().split("\n\n")[0].replace("\n", " ") if doc else ""


def _documentable(obj) -> bool:
    return inspect.isclass(obj) or inspect.isfunction(obj) or inspect.isbuiltin(obj) or callable(obj)


def write(out: Path, package: str = "ema_casadi") -> Path:
    """Write the page; returns its path."""
    seen: set[int] = set()
    lines = ["# API reference", "",
             "Every public name of the package, from its docstrings. The names of the top level",
             "(`import ema_casadi as ema`; `ema.simulate`, `ema.build_model`, ...) come first; each",
             "subpackage follows with what it adds. Physical quantities are SI unless a docstring says",
             "otherwise.", ""]
    for modname in [package, *_modules(package)]:
        mod = importlib.import_module(modname)
        names = [n for n in getattr(mod, "__all__", ()) if not n.startswith("_")]
        entries = []
        for n in names:
            obj = getattr(mod, n, None)
            if obj is None or inspect.ismodule(obj) or not _documentable(obj) or id(obj) in seen:
                continue
            seen.add(id(obj))
            entries.append(f"   {modname}.{n}")
        if not entries:
            continue
        title = f"`{modname}`"
        lines += [f"## {title}", ""]
        summary = _summary(mod)
        if summary:
            lines += [summary, ""]
        lines += ["```{eval-rst}", ".. autosummary::", "   :toctree: generated", "   :nosignatures:", "",
                  *entries, "```", ""]
    out.parent.mkdir(parents=True, exist_ok=True)
    text = "\n".join(lines)
    if not out.exists() or out.read_text() != text:  # unchanged: Sphinx keeps its cache
        out.write_text(text)
    return out
