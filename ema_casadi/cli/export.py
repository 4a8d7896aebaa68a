"""Export the model.

Linear model at an operating point (same flags as ema linearize): --format mat
(MATLAB/Octave: A B C D, cell arrays of names and units, struct op), npz or json.
Nonlinear model f(x, u, p) -> (xdot, y): --format casadi (serialised CasADi Function,
read back with casadi.Function.load) or c (generated C code NAME.c + NAME.h). The
nonlinear exports write a sidecar FILE.json naming the entries of x, u, p and y.
Example: ema export --format mat --f-ext 10kN --out ema_lin.mat
"""

from __future__ import annotations

from pathlib import Path

from ..export import FUNCTION_FORMATS, LINEAR_FORMATS
from ..linearisation import LOOPS
from . import UserError, check_output_path, load
from .linearize import add_operating_point_arguments, op_summary, operating_point_from_args

COMMAND = "export"
ORDER = 8
HELP = "export the linear model (mat/npz/json) or the nonlinear one (casadi/c)"
SUFFIX = {"mat": ".mat", "npz": ".npz", "json": ".json", "casadi": ".casadi", "c": ".c"}


def add_arguments(p):
    p.add_argument("--format", choices=[*LINEAR_FORMATS, *FUNCTION_FORMATS], required=True,
                   help="mat, npz, json (linear model); casadi, c (nonlinear model)")
    p.add_argument("--out", default=None, metavar="PATH",
                   help="output file; default ema_lin.<format> (linear) or ema_f.casadi / ema_f.c")
    p.add_argument("--open", action="append", choices=list(LOOPS), default=[], metavar="LOOP",
                   help="linear formats: open a loop at its break; repeatable")
    add_operating_point_arguments(p)


def run(args) -> dict:
    from ..export import ExportError, export_function, save_linear

    linear = args.format in LINEAR_FORMATS
    default = ("ema_lin" if linear else "ema_f") + SUFFIX[args.format]
    out = check_output_path(args.out or default, (SUFFIX[args.format],), "--out")
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
