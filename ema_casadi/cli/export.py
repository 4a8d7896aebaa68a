"""Export the model.

Linear model at an operating point (same flags as ema linearize): --format mat
(MATLAB/Octave: A B C D, cell arrays of names and units, struct op), npz or json.
Nonlinear model f(x, u, p) -> (xdot, y): --format casadi (serialised CasADi Function,
read back with casadi.Function.load) or c (generated C code NAME.c + NAME.h) when
--out names a .casadi / .c file; they write a sidecar FILE.json naming the entries
of x, u, p and y.
Nonlinear model for other tools (ema_casadi.export.fmu): --format fmu-me (FMI 3.0 model
exchange, smooth friction; an event indicator per switch, the switches held between
events), fmu-cs (FMI 2.0, or 3.0 with --fmi-version 3.0,
co-simulation of the fixed-step RK4 with the hybrid friction inside; --dt sets its
internal step, default 2e-6 s, with hybrid friction 1e-5 s), c (a
folder: generated C, fixed-step simulator, layout header, main.c, Makefile) and
casadi (a folder: serialised Functions and their layout) when --out is a folder.
Examples::

    ema export --format mat --f-ext 10kN --out ema_lin.mat
    ema export --format fmu-cs --variant friction=hybrid --out ema_cs.fmu
"""

from __future__ import annotations

import re
from pathlib import Path

from ..export import FUNCTION_FORMATS, LINEAR_FORMATS, MODEL_FORMATS
from ..linearisation import LOOPS
from . import UserError, check_output_path, load
from ._flags import NoEffect
from ._options import seconds
from .linearize import add_operating_point_arguments, op_summary, operating_point_from_args

COMMAND = "export"
ORDER = 8
HELP = "export the linear model (mat/npz/json) or the nonlinear one (fmu-me/fmu-cs/c/casadi)"
SUFFIX = {"mat": ".mat", "npz": ".npz", "json": ".json", "casadi": ".casadi", "c": ".c"}


def add_arguments(p):
    formats = list(dict.fromkeys([*LINEAR_FORMATS, *FUNCTION_FORMATS, *MODEL_FORMATS]))
    p.add_argument("--format", choices=formats, required=True,
                   help="mat, npz, json (linear model); fmu-me, fmu-cs, c, casadi (nonlinear model)")
    p.add_argument("--out", default=None, metavar="PATH",
                   help="output; default ema_lin.<format> (linear), ema_me.fmu / ema_cs.fmu, the folders "
                        "ema_c / ema_functions (c, casadi; a NAME.c / FILE.casadi writes the single-file form)")
    p.add_argument("--dt", type=seconds, default=None, metavar="SECONDS",
                   help="fmu-cs: internal fixed step; c, casadi: default step of the simulator "
                        "(default 2e-6; with hybrid friction 1e-5)")
    p.add_argument("--fmi-version", choices=["2.0", "3.0"], default=None,
                   help="fmu-cs: FMI version of the co-simulation FMU (default 2.0; fmu-me is always 3.0)")
    p.add_argument("--open", action="append", choices=list(LOOPS), default=[], metavar="LOOP",
                   help="linear formats: open a loop at its break; repeatable")
    add_operating_point_arguments(p)


def _model_export(args) -> bool:
    """Formats of ema_casadi.export.fmu; c and casadi unless --out names the single file."""
    if args.format in MODEL_FORMATS and args.format not in FUNCTION_FORMATS:
        return True
    return args.format in FUNCTION_FORMATS and not (args.out and Path(args.out).suffix == SUFFIX[args.format])


def _run_model_export(args) -> dict:
    from ..export import ExportError, export_model, fmu

    out = fmu.DEFAULTS[args.format] if args.out is None else args.out
    try:
        fmu.check_output(out, args.format)
    except ExportError as exc:
        raise UserError(f"--out {exc}") from None
    params, model = load(args)
    try:
        r = export_model(model, out, args.format, dt=args.dt, fmi_version=args.fmi_version)
    except ExportError as exc:  # an argument of export_model is the flag that set it
        text = re.sub(r"^(dt|fmi_version)\b", lambda m: "--" + m.group(1).replace("_", "-"), str(exc))
        raise UserError(f"--format {args.format}: {text}") from None
    except OSError as exc:
        raise UserError(f"--out {out}: cannot write ({exc.strerror or exc})") from None
    return {"model": args.model, "variants": model.variants, "format": args.format, "written": [str(r["path"])],
            **{k: v for k, v in r.items() if k != "path"}}


def _applicable(args) -> None:
    if args.out is not None and not args.out.strip():
        raise UserError("--out: empty path; name the output")


def _nonlinear(args) -> bool:
    return args.format not in LINEAR_FORMATS


def _single_file(args) -> bool:
    """c / casadi written as the single file (the Function alone, no simulator)."""
    return args.format in FUNCTION_FORMATS and not _model_export(args)


_OP_WHY = ("on ema export --format {format}: the nonlinear model takes x_cmd and f_ext as inputs and keeps every "
           "nonlinearity (an operating point is for the linear formats mat, npz, json)")
#: Each flag -> the combinations where it has no effect (refused; docs: cli).
NO_EFFECT = {
    "--format": (), "--out": (),
    "--dt": (NoEffect(("--format", "mat", "--dt", "1e-3"), "with --format {format}: nothing of it steps (fmu-cs has "
                      "a fixed step; c and casadi folders a simulator's default step)",
                      lambda a: a.format in LINEAR_FORMATS),
             NoEffect(("--format", "fmu-me", "--dt", "1e-5"), "with --format {format}: nothing of it steps (a "
                      "model-exchange FMU's solver is the importing tool's; the fixed-step FMU is fmu-cs)",
                      lambda a: a.format == "fmu-me"),
             NoEffect(("--format", "c", "--out", "f.c", "--dt", "1e-5"), "with --format {format} written as the "
                      "single file {out} (the Function alone; a folder holds the simulator that steps)", _single_file)),
    "--fmi-version": (NoEffect(("--format", "fmu-me", "--fmi-version", "3.0"), "with --format {format}: only fmu-cs "
                               "has a choice (fmu-me is FMI 3.0; the other formats are not FMUs)",
                               lambda a: a.format != "fmu-cs"),),
    "--open": (NoEffect(("--format", "fmu-cs", "--open", "position"), "with --format {format}: loops are opened in "
                        "the linear formats mat, npz, json", _nonlinear),),
    **{flag: (NoEffect(("--format", "fmu-me", flag, value), _OP_WHY, _nonlinear),)
       for flag, value in (("--x-cmd", "5mm"), ("--f-ext", "10kN"), ("--v-rod", "20mm/s"), ("--friction", "smooth"),
                           ("--backlash", "keep"))},
}


def run(args) -> dict:
    from ..export import ExportError, export_function, save_linear

    _applicable(args)
    if _model_export(args):
        return _run_model_export(args)

    linear = args.format in LINEAR_FORMATS
    default = ("ema_lin" if linear else "ema_f") + SUFFIX[args.format]
    out = check_output_path(default if args.out is None else args.out, (SUFFIX[args.format],), "--out")
    if not linear:  # the header and the sidecar beside it must be writable too
        from ..export import sidecar_path

        for extra in [out.with_suffix(".h")] * (args.format == "c") + [sidecar_path(out)]:
            check_output_path(str(extra), (extra.suffix,), "--out")
    params, model = load(args)
    result = {"model": args.model, "variants": model.variants, "format": args.format}
    try:
        if linear:
            from ..linearisation import linear_model

            op = operating_point_from_args(args, params, model)
            lin = linear_model(model, op, open_loops=args.open)
            written = [save_linear(lin, out, args.format, units=model.units)]
            result["operating_point"] = op_summary(op)
        else:
            written = export_function(model, out, args.format)
    except ExportError as exc:
        raise UserError(f"--out {exc}") from None
    except OSError as exc:
        raise UserError(f"--out {out}: cannot write ({exc.strerror or exc})") from None
    result["written"] = [str(Path(w)) for w in written]
    return result


def report(r: dict) -> None:
    for w in r["written"]:
        print(f"wrote {w}")
