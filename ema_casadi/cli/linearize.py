"""Operating point (trim) and exact linear model (CasADi AD Jacobians).

The operating point is the state at rest for --x-cmd and --f-ext (or moving at a
constant --v-rod). Small-signal policy: backlash off (B = 0) and Coulomb-type friction
off (seal/bearing friction, screw-nut efficiency switch frozen) unless --friction
smooth / --backlash keep. Saturations must be inactive at the point: a load the
current limit cannot hold is an error.
Example: ema linearize --f-ext 20kN --out lin.mat --json
"""

from __future__ import annotations

import math
import sys
import warnings

from ..linearisation import BACKLASH_POLICIES, FRICTION_POLICIES, LOOPS
from ..signals import SignalError, parse_quantity
from . import UserError, check_output_path, load

COMMAND = "linearize"
ORDER = 3
HELP = "operating point + linear model (A B C D with names); --out .mat/.npz/.json"


#: The operating-point flags of linearize, margins, bode (each acts on the trim).
OPERATING_POINT = {"--x-cmd": (), "--f-ext": (), "--v-rod": (), "--friction": (), "--backlash": ()}
#: Each flag -> the combinations where it has no effect (refused; docs: cli).
NO_EFFECT = {**OPERATING_POINT, "--open": (), "--out": ()}

def add_operating_point_arguments(p) -> None:
    """The trim and small-signal-policy flags shared by linearize, margins, bode, export."""
    p.add_argument("--x-cmd", default="0", metavar="LENGTH",
                   help="commanded rod position: 1mm, 0.5%% (of the stroke), a bare number is mm; default 0")
    p.add_argument("--f-ext", default="0", metavar="FORCE",
                   help="external rod force, positive pushes the rod in: 10kN, 500N, a bare number is N; default 0")
    p.add_argument("--v-rod", default="0", metavar="RATE",
                   help="constant rod velocity of a moving operating point: 20mm/s, a bare number is mm/s; default 0")
    p.add_argument("--friction", choices=FRICTION_POLICIES, default="off",
                   help="Coulomb friction and efficiency switch: off (default, left out of the small-signal "
                        "model) or smooth (linearised; depends on v_s)")
    p.add_argument("--backlash", choices=BACKLASH_POLICIES, default="off",
                   help="backlash: off (default, B = 0) or keep")


def operating_point_from_args(args, params, model):
    """Parse the operating-point flags and trim; user mistakes and a missing operating
    point become one-line :class:`UserError`; warnings go to stderr as one line each."""
    from ..linearisation import operating_point

    values = {}
    for flag, attr, kind, bare in (("--x-cmd", "x_cmd", "length", "mm"), ("--f-ext", "f_ext", "force", "N"),
                                   ("--v-rod", "v_rod", "rate", "mm/s")):
        text = str(getattr(args, attr))
        try:
            values[attr] = parse_quantity(text, kind, bare, stroke=params.actuator.stroke)
        except SignalError as exc:
            raise UserError(f"{flag} {exc}") from None
        if not math.isfinite(values[attr]):
            raise UserError(f"{flag} '{text}': not a finite number")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        op = operating_point(model, **values, friction=args.friction, backlash=args.backlash)
    for w in caught:
        sys.stderr.write(f"ema {args.command}: warning: {w.message}\n")
    return op


def op_summary(op) -> dict:
    """Compact operating point for --json results."""
    keys = ("x_rod", "x_in", "v_rod", "omega", "i_q", "i_cmd", "v_q", "F_in")
    return {"x_cmd": op.x_cmd, "f_ext": op.f_ext, "v_rod": op.v_rod,
            "outputs": {k: op.output(k) for k in keys if k in op.outputs}, "policy": op.policy}


def add_arguments(p):
    add_operating_point_arguments(p)
    p.add_argument("--open", action="append", choices=list(LOOPS), default=[], metavar="LOOP",
                   help="open a loop at its break (position, velocity, current); repeatable")
    p.add_argument("--out", default=None, metavar="FILE",
                   help="write the linear model: .mat (MATLAB/Octave), .npz or .json, with names and operating point")


def run(args) -> dict:
    import numpy as np

    from ..export import ExportError, save_linear
    from ..frequency import modes
    from ..linearisation import linear_model

    out = check_output_path(args.out, (".mat", ".npz", ".json"), "--out")
    params, model = load(args)
    op = operating_point_from_args(args, params, model)
    lin = linear_model(model, op, open_loops=args.open)
    written = []
    if out is not None:
        try:
            written.append(str(save_linear(lin, out, units=model.units)))
        except ExportError as exc:
            raise UserError(f"--out {exc}") from None
        except OSError as exc:
            raise UserError(f"--out {out}: cannot write ({exc.strerror or exc})") from None
    lam = np.linalg.eigvals(lin.A)
    return {
        "model": args.model,
        "variants": model.variants,
        "operating_point": op.as_dict(),
        "open_loops": list(lin.open_loops),
        "states": list(lin.states), "inputs": list(lin.inputs), "outputs": list(lin.outputs),
        "state_units": [model.units[n] for n in lin.states],
        "A": lin.A, "B": lin.B, "C": lin.C, "D": lin.D,
        "eigenvalues": {"real": lam.real, "imag": lam.imag},
        "modes": modes(lin),
        "written": written,
    }


def report(r: dict) -> None:
    op = r["operating_point"]
    o = op["outputs"]
    print(f"operating point: x_cmd = {op['x_cmd'] * 1e3:.4g} mm, f_ext = {op['f_ext'] / 1e3:.4g} kN, "
          f"v_rod = {op['v_rod'] * 1e3:.4g} mm/s (friction {op['policy']['friction']}, "
          f"backlash {op['policy']['backlash']})")
    print(f"  x_rod = {o['x_rod'] * 1e3:.6g} mm, x_in = {o['x_in'] * 1e3:.6g} mm, i_q = {o['i_q']:.4g} A, "
          f"F_in = {o['F_in'] / 1e3:.4g} kN")
    print(f"linear model: {len(r['states'])} states ({', '.join(r['states'])}), "
          f"{len(r['inputs'])} inputs, {len(r['outputs'])} outputs"
          + (f"; open loops: {', '.join(r['open_loops'])}" if r["open_loops"] else ""))
    for m in r["modes"]:
        print(f"  mode {m['f_n_hz']:9.2f} Hz, damping {m['zeta']:.3f}")
    for w in r["written"]:
        print(f"wrote {w}")
