"""Export of the linearised and the nonlinear model (docs: exports).

Linear model (:func:`save_linear` / :func:`load_linear`), with the signal names, their
units and the operating point:

``.mat``
    MATLAB/Octave: ``A, B, C, D``, cell arrays ``state_names``, ``input_names``,
    ``output_names`` (and ``*_units``), a struct ``op`` (operating point: ``x``, ``u``,
    ``y``, ``x_cmd``, ``f_ext``, ``v_rod``, parameter names and values, policy) and
    ``info``. In MATLAB::

        d = load('ema_lin.mat');
        sys = ss(d.A, d.B, d.C, d.D, 'StateName', d.state_names, ...
                 'InputName', d.input_names, 'OutputName', d.output_names);

``.npz``
    The same arrays (names as unicode arrays, loadable without pickle) plus ``meta``,
    a JSON string with the operating point and policy.
``.json``
    One object: ``format``, names, units, ``A B C D`` as nested lists, ``operating_point``.

Nonlinear model (:func:`export_function`): ``casadi`` writes the serialised CasADi
Function ``f(x, u, p) -> (xdot, y)`` (``casadi.Function.load`` reads it back); ``c``
writes generated C code (``.c`` and ``.h``, CasADi's calling convention). Both write a
sidecar ``<file>.json`` naming the entries of x, u, p and y, with the parameter
values of the set, because a Function carries only its input/output names.

FMUs, the self-contained C folder and the CasADi folder with the fixed-step
simulator (:func:`export_model`, formats :data:`MODEL_FORMATS`) are in
:mod:`ema_casadi.export.fmu`.

Every file is written to a temporary name in the target folder and then renamed, so
a failure leaves no half-written file.
"""

from __future__ import annotations

import json
import os
import re
import shutil
from pathlib import Path

import casadi as ca
import numpy as np

from .._util._checks import describe, instance
from .._util._files import scratch_dir, transaction, write_with
from ..linearisation import REQUEST_KEYS, LinearModel, OperatingPoint
from ..model.assembly import Model
from ._errors import ExportError

__all__ = ["LINEAR_FORMATS", "FUNCTION_FORMATS", "MODEL_FORMATS", "ExportError", "save_linear", "load_linear",
           "export_function", "export_model", "model_signature"]

LINEAR_FORMATS = ("mat", "npz", "json")
FUNCTION_FORMATS = ("casadi", "c")
#: Formats of :func:`export_model` (:mod:`ema_casadi.export.fmu`).
MODEL_FORMATS = ("fmu-me", "fmu-cs", "c", "casadi")
FORMAT_ID = "ema_casadi.linear/1"


def _path(path) -> Path:
    if not isinstance(path, (str, Path)):
        raise ExportError(f"path: expected a file path (str or Path), got {describe(path)}")
    return Path(path)


def _format_of(path: Path, fmt: str | None, allowed) -> str:
    if fmt is not None and not isinstance(fmt, str):
        raise ExportError(f"fmt: expected one of {', '.join(allowed)}, got {describe(fmt)}")
    fmt = (fmt or path.suffix.lstrip(".")).lower()
    if fmt not in allowed:
        raise ExportError(f"{path}: format '{fmt}' unknown; choose one of {', '.join(allowed)}")
    return fmt


def _units(lin: LinearModel, units: dict) -> dict:
    return {
        "states": [units.get(n, "") for n in lin.states],
        "inputs": [units.get(n, "") for n in lin.inputs],
        "outputs": [units.get(n.lstrip("-"), "") for n in lin.outputs],
    }


def _op_dict(op: OperatingPoint | None) -> dict:
    if op is None:
        return {}
    return {
        "x": op.x.tolist(), "u": op.u.tolist(), "y": op.y.tolist(),
        **op.request(),
        "state_names": list(op.states), "input_names": list(op.inputs), "output_names": list(op.outputs),
        "param_names": list(op.param_names), "param_values": op.p.tolist(),
        "policy": op.policy, "variants": dict(op.variants), "residual": op.residual,
    }


def save_linear(lin: LinearModel, path: str | Path, fmt: str | None = None, units: dict | None = None) -> Path:
    """Write a linear model with its names and operating point.

    Parameters
    ----------
    lin : LinearModel
        From :func:`~ema_casadi.linearisation.linear_model` (carries the operating point).
    path : str or Path
        Target file; its folder must exist.
    fmt : {"mat", "npz", "json"}, optional
        Default: from the suffix.
    units : dict, optional
        Signal name -> SI unit, the model's one unit table (``model.units``).
    """
    instance(lin, LinearModel, "lin", ExportError, " (from linear_model)")
    path = _path(path)
    if units is not None and not isinstance(units, dict):
        raise ExportError(f"units: expected a dict signal name -> unit (model.units), got {describe(units)}")
    fmt = _format_of(path, fmt, LINEAR_FORMATS)
    if not path.parent.exists():
        raise ExportError(f"{path}: folder {path.parent} does not exist")
    units = _units(lin, units or {})
    op = _op_dict(lin.op)
    doc = {
        "format": FORMAT_ID, "name": lin.name, "open_loops": list(lin.open_loops),
        "state_names": list(lin.states), "input_names": list(lin.inputs), "output_names": list(lin.outputs),
        "state_units": units["states"], "input_units": units["inputs"], "output_units": units["outputs"],
    }
    if fmt == "json":
        doc.update(A=lin.A.tolist(), B=lin.B.tolist(), C=lin.C.tolist(), D=lin.D.tolist(), operating_point=op)
        text = json.dumps(doc, indent=1, allow_nan=False)
        return write_with(path, lambda t: t.write_text(text))
    if fmt == "npz":
        arrays = {k: np.array(v) for k, v in doc.items() if isinstance(v, list)}
        arrays.update(A=lin.A, B=lin.B, C=lin.C, D=lin.D, format=np.array(FORMAT_ID), name=np.array(lin.name),
                      meta=np.array(json.dumps({"operating_point": op})))

        def write(t):
            with open(t, "wb") as fh:
                np.savez(fh, **arrays)

        return write_with(path, write)
    import scipy.io

    def cell(names):
        return np.array(list(names), dtype=object).reshape(-1, 1)

    mat = {k: cell(v) for k, v in doc.items() if isinstance(v, list)}
    mat.update(A=lin.A, B=lin.B, C=lin.C, D=lin.D, format=FORMAT_ID, name=lin.name)
    if op:
        mat["op"] = {
            "x": np.array(op["x"]).reshape(-1, 1), "u": np.array(op["u"]).reshape(-1, 1),
            "y": np.array(op["y"]).reshape(-1, 1), **{k: op[k] for k in REQUEST_KEYS},
            "state_names": cell(op["state_names"]), "input_names": cell(op["input_names"]),
            "output_names": cell(op["output_names"]), "param_names": cell(op["param_names"]),
            "param_values": np.array(op["param_values"]).reshape(-1, 1),
            "policy": json.dumps(op["policy"]), "variants": json.dumps(op["variants"]),
        }

    def write(t):
        with open(t, "wb") as fh:
            scipy.io.savemat(fh, mat, oned_as="column", long_field_names=True)

    return write_with(path, write)


def load_linear(path: str | Path) -> tuple[LinearModel, dict]:
    """Read a file written by :func:`save_linear`.

    Parameters
    ----------
    path : str or Path
        A ``.json``, ``.npz`` or ``.mat`` file (the format from the suffix).

    Returns
    -------
    lin : LinearModel
        The model, without an operating-point object.
    op : dict
        The operating point as saved: ``x``, ``u``, ``y`` (SI), ``x_cmd`` (m),
        ``f_ext`` (N), ``v_rod`` (m/s), names, parameters, policy, variants.
    """
    path = _path(path)
    fmt = _format_of(path, None, LINEAR_FORMATS)
    if not path.exists():
        raise ExportError(f"{path}: no such file")
    try:
        if fmt == "json":
            d = json.loads(path.read_text())
            op = d.get("operating_point", {})
        elif fmt == "npz":
            with np.load(path, allow_pickle=False) as z:
                d = {k: z[k] for k in z.files}
            d = {k: (v.tolist() if v.dtype.kind == "U" else v) for k, v in d.items()}
            op = json.loads(d["meta"])["operating_point"]
        else:
            import scipy.io

            d = scipy.io.loadmat(path, simplify_cells=True)
            op = d.get("op", {})
            if op:
                op = dict(op)
                op["policy"] = json.loads(op["policy"])
                op["variants"] = json.loads(op["variants"])
                for k in ("x", "u", "y", "param_values"):
                    op[k] = np.atleast_1d(op[k]).tolist()
                for k in ("state_names", "input_names", "output_names", "param_names"):
                    op[k] = list(np.atleast_1d(op[k]))
    except (OSError, ValueError, KeyError) as exc:
        raise ExportError(f"{path}: not a linear model file ({exc})") from None
    if str(d.get("format")) != FORMAT_ID:
        raise ExportError(f"{path}: not an {FORMAT_ID} file")

    def names(key):
        return tuple(str(s) for s in np.atleast_1d(d[key]))

    def mat(key, rows, cols):
        return np.array(d[key], dtype=float).reshape(rows, cols)

    st, ins, outs = names("state_names"), names("input_names"), names("output_names")
    lin = LinearModel(
        A=mat("A", len(st), len(st)), B=mat("B", len(st), len(ins)), C=mat("C", len(outs), len(st)),
        D=mat("D", len(outs), len(ins)), states=st, inputs=ins, outputs=outs, op=None,
        name=str(d.get("name", "ema")),
        open_loops=tuple(str(s) for s in np.atleast_1d(d.get("open_loops", [])) if str(s)),
    )
    return lin, op


def model_signature(model: Model) -> dict:
    """Names and units of x, u, p and y, the variants and the parameter values.

    Parameters
    ----------
    model : Model
        The assembled model.
    """
    instance(model, Model, "model", ExportError, " (from build_model)")
    return {
        "function": "f(x, u, p) -> (xdot, y)",
        "variants": dict(model.variants),
        "states": list(model.states), "state_units": [model.units[n] for n in model.states],
        "inputs": list(model.inputs), "input_units": [model.units[n] for n in model.inputs],
        "outputs": list(model.outputs), "output_units": [model.units[n] for n in model.outputs],
        "param_names": list(model.param_names), "param_values": model.p().tolist(),
    }


def export_function(model: Model, path: str | Path, fmt: str | None = None) -> list[Path]:
    """Write the nonlinear model ``f(x, u, p) -> (xdot, y)``.

    Parameters
    ----------
    model : Model
    path : str or Path
        ``casadi``: the serialised Function (any name, e.g. ``ema_f.casadi``).
        ``c``: the C file; its stem is the C function's name (an identifier) and a
        header with the same stem is written beside it.
    fmt : {"casadi", "c"}, optional
        Default: from the suffix (``.casadi`` or ``.c``).

    Returns
    -------
    list of Path
        The paths written (the file(s) and the ``.json`` sidecar).
    """
    instance(model, Model, "model", ExportError, " (from build_model)")
    path = _path(path)
    fmt = _format_of(path, fmt, FUNCTION_FORMATS)
    if not path.parent.exists():
        raise ExportError(f"{path}: folder {path.parent} does not exist")
    sidecar = json.dumps(model_signature(model), indent=1)
    written = []
    # the files of one export appear together or not at all
    with transaction():
        if fmt == "casadi":
            written.append(write_with(path, lambda t: model.f.save(str(t))))
        else:
            name = path.stem
            if path.suffix != ".c" or not re.fullmatch(r"[A-Za-z_]\w*", name):
                raise ExportError(f"{path}: C export needs a file NAME.c with NAME a C identifier")
            x, u, p = (ca.SX.sym(n, k) for n, k in (("x", model.nx), ("u", model.nu), ("p", len(model.param_names))))
            fn = ca.Function(name, [x, u, p], list(model.f(x, u, p)), ["x", "u", "p"], ["xdot", "y"])
            with scratch_dir() as tmp:
                gen = ca.CodeGenerator(f"{name}.c", {"with_header": True})
                gen.add(fn)
                gen.generate(str(tmp) + os.sep)
                for suffix in (".c", ".h"):
                    written.append(write_with(path.with_suffix(suffix),
                                              lambda t, s=suffix: shutil.copyfile(tmp / f"{name}{s}", t)))
        written.append(write_with(sidecar_path(path), lambda t: t.write_text(sidecar)))
    return written


def sidecar_path(path: str | Path) -> Path:
    """The JSON file naming the entries of x, u, p and y beside a nonlinear export.

    Parameters
    ----------
    path : str or Path
        The exported ``.casadi`` or ``.c`` file.
    """
    path = Path(path)
    return path.with_name(path.name + ".json")


def export_model(model: Model, path: str | Path, fmt: str, *, dt: float | None = None,
                 fmi_version: str | None = None, platforms=("linux64", "win64")) -> dict:
    """Export the nonlinear model as an FMU, a C folder or a CasADi folder.

    Dispatches to :func:`ema_casadi.export.fmu.export` (see there).

    Parameters
    ----------
    model : Model
    path : str or Path
        The ``.fmu`` file (``fmu-me``, ``fmu-cs``) or the folder (``c``, ``casadi``).
    fmt : {"fmu-me", "fmu-cs", "c", "casadi"}
    dt : float, optional
        Internal step of ``fmu-cs``, default step of ``c`` and ``casadi`` (s; 2e-6, with
        hybrid friction 1e-5).
    fmi_version : {"2.0", "3.0"}, optional
        FMI version of ``fmu-cs`` (default 2.0; ``fmu-me`` is FMI 3.0).
    platforms : sequence of str
        FMU binaries: ``linux64``, ``win64`` (built where MinGW-w64 is installed).
    """
    from . import fmu

    return fmu.export(model, path, fmt, dt=dt, fmi_version=fmi_version, platforms=platforms)
