"""Exports of the nonlinear model for other tools: FMUs, C, CasADi (docs: exports).

``fmu-me`` (:func:`export_fmu_me`)
    FMI 3.0 model exchange of the continuous (smooth-friction) model through CasADi's
    DaeBuilder, with the fixes it needs (flat naming, states visible with settable
    start values, event indicators, units); the importer's own solver integrates it.
    Hybrid friction is refused: its stick-slip map is not an ODE.
``fmu-cs`` (:func:`export_fmu_cs`)
    FMI 2.0 (or 3.0) co-simulation containing generated C of the toolkit's own
    fixed-step RK4 step (hybrid stick-slip projection and switch counting inside),
    sub-stepped with the internal step ``dt_internal`` (default :func:`default_dt`: 2e-6 s
    with a continuous friction law, 1e-5 s with hybrid friction); no Python on
    the importing side.
``c`` (:func:`export_c`)
    A self-contained C folder: model functions, fixed-step simulator, layout header,
    example ``main.c`` (the reference scenario) and a Makefile.
``casadi`` (:func:`export_casadi`)
    The serialised Functions (right-hand side, init, step, outputs, rollout) with
    their layout as JSON.

:func:`inputs_at_every_call` runs a model-exchange FMU in FMPy with a time-varying
input the way Simulink or Dymola do (FMPy's own driver sets continuous inputs only at
its output points).

FMU binaries: linux64 always (needs a C compiler); win64 when Debian's MinGW-w64
cross-compiler ``x86_64-w64-mingw32-gcc`` is installed. Every export is whole or
absent: files are written to temporary names and renamed, folders assembled beside
the target and moved into place. Errors are :class:`~ema_casadi.export.ExportError`
with a one-line message.
"""

from __future__ import annotations

from pathlib import Path

from ...model.assembly import Model
from .._errors import ExportError
from ._cbuild import MINGW, pe_exports, targets
from ._cs import export_fmu_cs
from ._csource import DT_DEFAULT, DT_SMOOTH, default_dt
from ._events import Switches, switches
from ._fmpy import inputs_at_every_call
from ._folders import export_c, export_casadi
from ._functions import SIM_STEPS, augmented_names, fixed_step_functions
from ._layout import Layout, Var, layout
from ._me import export_fmu_me
from ._pack import check_target

__all__ = [
    "FORMATS", "DEFAULTS", "ExportError", "export", "check_output", "export_fmu_me", "export_fmu_cs", "export_c",
    "export_casadi",
    "fixed_step_functions", "augmented_names", "layout", "Layout", "Var", "pe_exports", "targets", "MINGW",
    "DT_DEFAULT", "DT_SMOOTH", "default_dt", "SIM_STEPS", "inputs_at_every_call", "switches", "Switches",
]

#: Export formats of this package and whether each writes a file or a folder.
FORMATS = {"fmu-me": "file", "fmu-cs": "file", "c": "folder", "casadi": "folder"}
#: Default output of each format.
DEFAULTS = {"fmu-me": "ema_me.fmu", "fmu-cs": "ema_cs.fmu", "c": "ema_c", "casadi": "ema_functions"}


def check_output(path, fmt: str) -> Path:
    """Check an output before any work: the format, the suffix, a writable folder.

    Parameters
    ----------
    path : str or Path
        Target (``.fmu`` for the FMU formats, a folder otherwise).
    fmt : str
        One of :data:`FORMATS`.
    """
    if fmt not in FORMATS:
        raise ExportError(f"format '{fmt}' unknown; choose one of {', '.join(FORMATS)}")
    path = Path(path)
    if FORMATS[fmt] == "file" and path.suffix.lower() != ".fmu":
        raise ExportError(f"{path}: an FMU file must end in .fmu")
    return check_target(path, FORMATS[fmt])


def export(model: Model, path, fmt: str, *, dt: float | None = None, fmi_version: str | None = None,
           platforms=("linux64", "win64")) -> dict:
    """Export ``model`` in one of :data:`FORMATS`.

    Parameters
    ----------
    model : Model
        The assembled model.
    path : str or Path
        The ``.fmu`` file or the folder to write.
    fmt : {"fmu-me", "fmu-cs", "c", "casadi"}
    dt : float, optional
        Internal step of ``fmu-cs`` / default step of ``c`` and ``casadi`` (s);
        default :func:`default_dt` (2e-6 s, hybrid friction 1e-5 s). ``fmu-me`` has none
        (the importer's solver chooses): an error.
    fmi_version : {"2.0", "3.0"}, optional
        FMI version of ``fmu-cs`` (default 2.0); ``fmu-me`` is FMI 3.0 only.
    platforms : sequence of str
        FMU binaries to build: ``linux64``, ``win64`` (skipped without MinGW-w64).

    Returns
    -------
    dict
        What was written (``path``) and how long it took (``build_time``, s).
    """
    path = check_output(path, fmt)
    if fmt == "fmu-me" and dt is not None:
        raise ExportError("dt: a model-exchange FMU has no step (the importing tool's solver chooses); "
                          "the fixed-step FMU is fmu-cs")
    if fmi_version is not None and fmt != "fmu-cs" and not (fmt == "fmu-me" and fmi_version == "3.0"):
        raise ExportError(f"fmi_version {fmi_version}: only fmu-cs has a choice (2.0 or 3.0); "
                          "fmu-me is FMI 3.0")
    step = default_dt(model) if dt is None else dt
    if not (isinstance(step, (int, float)) and 0 < step < 1):
        raise ExportError(f"dt must be a step in seconds between 0 and 1, got {dt!r}")
    if fmt == "fmu-me":
        return export_fmu_me(model, path, platforms=platforms)
    if fmt == "fmu-cs":
        return export_fmu_cs(model, path, dt_internal=step, fmi_version=fmi_version or "2.0", platforms=platforms)
    if fmt == "c":
        return export_c(model, path, dt=step)
    return export_casadi(model, path, dt=step)
