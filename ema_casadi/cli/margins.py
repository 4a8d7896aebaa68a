"""Stability margins at the position, velocity and current loop breaks.

Each loop is broken at its feedback (the paper's "Gain = 1" block) with the other loops
closed (loop-at-a-time; --outer open opens the loops outside it too). Reported per
loop: gain margin gm_db (negative = the gain may only fall that much) at f_pc_hz,
phase margin pm_deg at f_gc_hz, delay margin, and the balanced disk margin
(alpha, with its gain and phase equivalents). Requirement template: |GM| >= 6 dB,
PM >= 45 deg.
Example: ema margins --loop all --f-ext 20kN --plot margins.png --json
"""

from __future__ import annotations

import math
import time

from ..linearisation import LOOPS, OUTER
from . import UserError, check_output_path, load
from ._flags import NoEffect, no_effect
from .linearize import OPERATING_POINT, add_operating_point_arguments, op_summary, operating_point_from_args

COMMAND = "margins"
ORDER = 4
HELP = "gain, phase and disk margins of the position/velocity/current loops"


#: --outer with the outermost loop: nothing lies outside it (checked on the model's loops).
OUTERMOST = NoEffect(("--loop", "position", "--outer", "open"), "with --loop position: no loop of this model lies "
                     "outside it (--outer opens the loops outside the break)")
#: Each flag -> the combinations where it has no effect (refused; docs: cli).
NO_EFFECT = {**OPERATING_POINT, "--loop": (), "--outer": (OUTERMOST,), "--fmin": (), "--fmax": (), "--plot": ()}


def refuse_outer(args, model, loops) -> None:
    """--outer given where every loop broken is the model's outermost one: refused."""
    order = list(model.loops)
    if all(order.index(k) == 0 for k in loops if k in order):
        no_effect(args, "--outer", f"with --loop {args.loop}: no loop of this model lies outside it (--outer opens "
                  "the loops outside the break)")

def add_frequency_window(p, f_min: float, f_max: float) -> None:
    p.add_argument("--fmin", type=float, default=f_min, help=f"lowest frequency (Hz); default {f_min:g}")
    p.add_argument("--fmax", type=float, default=f_max, help=f"highest frequency (Hz); default {f_max:g}")


def check_window(args, per_decade: int | None = None) -> None:
    """--fmin/--fmax: 0 < fmin < fmax, and with ``per_decade`` a grid of that density
    within the limit."""
    from ..frequency import MAX_FREQ_POINTS

    if not (math.isfinite(args.fmin) and math.isfinite(args.fmax) and 0 < args.fmin < args.fmax):
        raise UserError(f"--fmin/--fmax must satisfy 0 < fmin < fmax (Hz), got {args.fmin:g}, {args.fmax:g}")
    decades = math.log10(args.fmax) - math.log10(args.fmin)
    n = (per_decade or 0) * decades
    if n > MAX_FREQ_POINTS:
        raise UserError(f"--fmin/--fmax {args.fmin:g}-{args.fmax:g} Hz: {decades:.3g} "
                        f"decades at {per_decade} frequencies per decade = {n:.3g}, above the limit of "
                        f"{MAX_FREQ_POINTS} (MAX_FREQ_POINTS)")


def add_arguments(p):
    p.add_argument("--loop", choices=[*LOOPS, "all"], default="all", help="loop to break; default all")
    p.add_argument("--outer", choices=OUTER, default="closed",
                   help="the other loops: closed (loop-at-a-time, default) or open the outer ones")
    add_frequency_window(p, 1e-2, 1e5)
    p.add_argument("--plot", default=None, metavar="FILE.png", help="open-loop Bode of each loop with margins marked")
    add_operating_point_arguments(p)


def run(args) -> dict:
    from ..frequency import REQUIREMENT, loop_margins

    plot = check_output_path(args.plot, (".png",), "--plot")
    check_window(args, per_decade=200)
    t0 = time.perf_counter()
    params, model = load(args)
    refuse_outer(args, model, list(LOOPS) if args.loop == "all" else [args.loop])
    op = operating_point_from_args(args, params, model)
    res = loop_margins(model, op, args.loop, outer=args.outer, f_min=args.fmin, f_max=args.fmax)
    written = []
    if plot is not None:
        from ..frequency import bode, frequency_grid
        from ..linearisation import loop_model
        from ..plots._frequency import plot_loop_margins

        f = frequency_grid(args.fmin, args.fmax, 100)
        curves = {k: (bode(loop_model(model, k, op, outer=args.outer), f), m) for k, m in res.items()}
        written.append(str(plot_loop_margins(curves, plot, title=f"{args.model}: loop margins "
                                             f"(f_ext = {op.f_ext / 1e3:.3g} kN, others {args.outer})")))
    return {
        "model": args.model,
        "variants": model.variants,
        "operating_point": op_summary(op),
        "outer": args.outer,
        "requirement": REQUIREMENT,
        "loops": {k: m.as_dict() for k, m in res.items()},
        "all_meet_requirement": all(m.meets() for m in res.values()),
        "wall_time_s": time.perf_counter() - t0,
        "written": written,
    }


def _f(v, fmt):
    return "-" if v is None else format(v, fmt)


def report(r: dict) -> None:
    req = r["requirement"]
    print(f"loop margins ({r['outer']} other loops; requirement GM and gain-reduction margin >= {req['gm_db']:g} dB "
          f"at every phase crossover, PM >= {req['pm_deg']:g} deg at every gain crossover)")
    print(f"  {'loop':9s} {'GM dB':>7s} {'at Hz':>8s} {'GRM dB':>7s} {'at Hz':>8s} {'PM deg':>7s} {'at Hz':>8s} "
          f"{'disk a':>7s} {'dGM dB':>7s} {'dPM deg':>7s}  ok")
    for k, m in r["loops"].items():
        print(f"  {k:9s} {m['gm_db']:7.2f} {_f(m['f_pc_hz'], '8.3g')} {m['gm_down_db']:7.2f} "
              f"{_f(m['f_down_hz'], '8.3g')} {m['pm_deg']:7.2f} {_f(m['f_gc_hz'], '8.3g')} "
              f"{m['disk_margin']:7.3f} {m['disk_gm_db']:7.2f} {m['disk_pm_deg']:7.2f}  "
              f"{'yes' if m['meets_requirement'] else 'NO'}{'' if m['stable'] else ' (closed loop unstable)'}")
    print("  GM: the gain may rise by that much; GRM (gain-reduction margin): it may fall by that much - only a "
          "conditionally stable loop (a phase crossover where |L| > 1) has one, inf otherwise")
    for k, m in r["loops"].items():
        gcs = ", ".join(f"{c['f_hz']:.3g} Hz PM {c['pm_deg']:.1f} deg" for c in m["gain_crossovers"]) or "none"
        pcs = ", ".join(f"{c['f_hz']:.3g} Hz " + (f"GM {-c['gain_db']:.1f} dB" if c["gain_db"] < 0 else
                                                 f"gain-reduction margin {c['gain_db']:.1f} dB")
                        for c in m["phase_crossovers"]) or "none"
        print(f"  {k}: gain crossovers {gcs}; phase crossovers {pcs}")
    for w in r["written"]:
        print(f"wrote {w}")
