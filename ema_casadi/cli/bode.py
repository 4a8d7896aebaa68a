"""Bode data of the linearised actuator.

--kind closed: x_rod/x_cmd; --kind stiffness: dynamic stiffness -f_ext/x_rod (N/m,
magnitude in dB re 1 N/m); --kind open: the loop transfer at the --loop break (other
loops closed, or the outer ones opened with --outer open), margins marked on the plot.
Example: ema bode --kind closed --plot bode.png --json
"""

from __future__ import annotations

import argparse
import math

from ..linearisation import LOOPS, OUTER
from . import UserError, check_output_path, load
from ._flags import NoEffect
from .linearize import OPERATING_POINT, add_operating_point_arguments, op_summary, operating_point_from_args
from .margins import OUTERMOST, add_frequency_window, check_window, refuse_outer

COMMAND = "bode"
ORDER = 5
HELP = "Bode data: closed loop, dynamic stiffness or open loop at a break; --plot"
KINDS = ("closed", "stiffness", "open")


_OPEN = NoEffect((), "with --kind {kind}: it sets the loop break of --kind open", lambda a: a.kind != "open")
#: Each flag -> the combinations where it has no effect (refused; docs: cli).
NO_EFFECT = {**OPERATING_POINT, "--kind": (), "--fmin": (), "--fmax": (), "--points": (), "--plot": (),
             "--loop": (NoEffect(("--kind", "stiffness", "--loop", "velocity"), _OPEN.why, _OPEN.when),),
             "--outer": (NoEffect(("--outer", "open"), _OPEN.why, _OPEN.when),
                         NoEffect(("--kind", "open", *OUTERMOST.example), OUTERMOST.why))}

def add_arguments(p):
    p.add_argument("--kind", choices=KINDS, default="closed", help="closed (x_rod/x_cmd, default), stiffness, open")
    p.add_argument("--loop", choices=list(LOOPS), default="position",
                   help="loop break for --kind open; default position")
    p.add_argument("--outer", choices=OUTER, default="closed",
                   help="for --kind open: the other loops closed or the outer ones open")
    add_frequency_window(p, 0.1, 2e3)
    p.add_argument("--points", type=_count, default=400,
                   help="number of log-spaced frequencies (at most 100000); default 400")
    p.add_argument("--plot", default=None, metavar="FILE.png", help="Bode plot (margins marked for --kind open)")
    add_operating_point_arguments(p)


def _count(text: str) -> int:
    """A whole number, also written 2e7; argparse reports anything else as one line."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got '{text}'") from None
    if not (math.isfinite(v) and v == int(v)):
        raise argparse.ArgumentTypeError(f"expected a whole number, got '{text}'")
    return int(v)


def run(args) -> dict:
    import numpy as np

    from ..frequency import bandwidth, bode, check_points, closed_loop, dynamic_stiffness, margins, modes
    from ..linearisation import loop_model

    plot = check_output_path(args.plot, (".png",), "--plot")
    check_window(args)
    if args.points < 2:
        raise UserError(f"--points must be at least 2, got {args.points}")
    check_points(args.points, f"--points {args.points}", error=UserError)
    params, model = load(args)
    op = operating_point_from_args(args, params, model)
    f = np.logspace(np.log10(args.fmin), np.log10(args.fmax), args.points)
    extra, lm = {}, None
    if args.kind == "closed":
        T = closed_loop(model, op)
        b = bode(T, f)
        unit, label = "m/m", "x_rod/x_cmd"
        extra["bandwidth_3db_hz"] = bandwidth(T)
        extra["modes"] = modes(T)
    elif args.kind == "stiffness":
        b = dynamic_stiffness(model, op, f)
        unit, label = "N/m", "dynamic stiffness -f_ext/x_rod"
        extra["magnitude_n_per_m"] = b["magnitude"]
    else:
        refuse_outer(args, model, [args.loop])
        L = loop_model(model, args.loop, op, outer=args.outer)
        b = bode(L, f)
        unit, label = "1", f"L at the {args.loop} break"
        lm = margins(L, loop=args.loop)
        extra["margins"] = lm.as_dict()
    written = []
    if plot is not None:
        from ..plots._frequency import plot_bode

        stiff = args.kind == "stiffness"
        written.append(str(plot_bode(dict(b, label=label), plot, margins=lm, linear_magnitude=stiff,
                                     mag_label="|stiffness| (N/m)" if stiff else "magnitude (dB)",
                                     title=f"{args.model}: {label} (f_ext = {op.f_ext / 1e3:.3g} kN)")))
    return {
        "model": args.model, "variants": model.variants, "kind": args.kind,
        "loop": args.loop if args.kind == "open" else None,
        "operating_point": op_summary(op), "label": label, "unit": unit,
        "freq_hz": b["freq_hz"], "mag_db": b["mag_db"], "phase_deg": b["phase_deg"],
        **extra, "written": written,
    }


def report(r: dict) -> None:
    import numpy as np

    print(f"{r['label']} ({r['unit']}), {len(r['freq_hz'])} frequencies")
    f = np.asarray(r["freq_hz"])
    decades = np.unique(np.clip(np.searchsorted(f, 10.0 ** np.arange(-3, 6)), 0, len(f) - 1))
    for i in decades:
        mag = (f"{r['magnitude_n_per_m'][i]:11.4g} N/m" if "magnitude_n_per_m" in r
               else f"{r['mag_db'][i]:9.3f} dB")
        print(f"  {f[i]:10.4g} Hz  {mag}  {r['phase_deg'][i]:9.2f} deg")
    if "bandwidth_3db_hz" in r:
        print(f"  -3 dB bandwidth {r['bandwidth_3db_hz']:.3g} Hz")
    if "margins" in r:
        m = r["margins"]
        from ..frequency import margin_text

        print(f"  {margin_text(m, 2)}, disk margin {m['disk_margin']:.3f}")
    for w in r["written"]:
        print(f"wrote {w}")
