"""``--format c`` and ``--format casadi``: self-contained export folders.

``c``
    ``ema_model.c/.h`` (CasADi-generated ``ema_f``, ``ema_init``, ``ema_step``,
    ``ema_out``), ``ema_sim.c/.h`` (the fixed-step driver), ``ema_layout.h`` (the
    state/input/parameter/output layout with units and defaults), ``main.c`` (the
    reference scenario: 1 mm step at 0.01 s, prints ``t x_rod``), a ``Makefile``;
    builds with plain ``gcc -O2 -o ema_example main.c ema_sim.c ema_model.c -lm``.
``casadi``
    ``ema_f``, ``ema_init``, ``ema_step``, ``ema_out`` and the rollout ``ema_sim``
    serialised (``casadi.Function.load``), see :mod:`._functions`.

Both hold ``ema_layout.json``: the variants and every vector's names, units,
meanings and defaults, and the Functions' signatures.
"""

from __future__ import annotations

import shutil
import time

from ..._util._files import write_with
from ...model.assembly import Model
from .._errors import ExportError
from ._csource import C_DIR, layout_doc, write_c_sources
from ._functions import SIM_STEPS, fixed_step_functions
from ._pack import check_target, export_folder

__all__ = ["export_c", "export_casadi"]

_SIGNATURES = {
    "ema_f": "f(x[nx], u[nu], p[np]) -> (xdot[nx], y[ny])",
    "ema_init": "init(x0[nx], u[nu], p[np]) -> xa[nxa]",
    "ema_step": "step(xa[nxa], U3[nu x 3], p[np], h) -> xa_next[nxa]  (U3: inputs at t, t+h/2, t+h)",
    "ema_out": "out(xa[nxa], u[nu], p[np]) -> y[ny]",
    "ema_sim": "sim(xa0[nxa], U[nu x 3n], p[np], h) -> (XA[nxa x n], Y[ny x n])",
}


def export_c(model: Model, folder, *, dt: float | None = None) -> dict:
    """Write the self-contained C folder (see the module docstring).

    Parameters
    ----------
    model : Model
        The assembled model (any variant; hybrid friction runs its projection inside
        ``ema_step``).
    folder : str or Path
        The folder to create (an earlier export folder there is replaced).
    dt : float, optional
        Default step (s) of ``main.c`` (``EMA_DT_DEFAULT``); without it
        :func:`~ema_casadi.export.fmu.default_dt`.

    Returns
    -------
    dict
        ``path``, ``files`` and ``build_time`` (s).
    """
    t0 = time.perf_counter()
    folder = check_target(folder, "folder")
    doc = layout_doc(model, dt)
    with export_folder(folder, "c", _with_functions(doc, ["ema_f", "ema_init", "ema_step", "ema_out"])) as tmp:
        write_c_sources(model, tmp, doc)
        for name in ("main.c", "Makefile"):
            write_with(tmp / name, lambda t, n=name: shutil.copyfile(C_DIR / n, t))
        files = sorted(p.name for p in tmp.iterdir())
    return {"path": folder, "files": files + ["ema_layout.json"], "build_time": time.perf_counter() - t0}


def export_casadi(model: Model, folder, *, n_sim: int = SIM_STEPS, dt: float | None = None) -> dict:
    """Write the serialised Functions and their layout (see the module docstring).

    Parameters
    ----------
    model : Model
        The assembled model.
    folder : str or Path
        The folder to create (an earlier export folder there is replaced).
    n_sim : int
        Steps per call of ``ema_sim``.
    dt : float, optional
        Default step (s) recorded in the layout; without it
        :func:`~ema_casadi.export.fmu.default_dt`.

    Returns
    -------
    dict
        ``path``, ``files`` and ``build_time`` (s).
    """
    t0 = time.perf_counter()
    if not (isinstance(n_sim, int) and not isinstance(n_sim, bool) and n_sim >= 1):
        raise ExportError(f"n_sim must be a positive number of steps, got {n_sim!r}")
    folder = check_target(folder, "folder")
    fns = fixed_step_functions(model, n_sim=n_sim)
    doc = layout_doc(model, dt)
    doc["sim_steps"] = n_sim
    with export_folder(folder, "casadi", _with_functions(doc, [f.name() for f in fns.values()])) as tmp:
        for fn in fns.values():
            write_with(tmp / f"{fn.name()}.casadi", lambda t, f=fn: f.save(str(t)))
        files = sorted(p.name for p in tmp.iterdir())
    return {"path": folder, "files": files + ["ema_layout.json"], "build_time": time.perf_counter() - t0}


def _with_functions(doc: dict, names) -> dict:
    return {**doc, "functions": {n: _SIGNATURES[n] for n in names}}

