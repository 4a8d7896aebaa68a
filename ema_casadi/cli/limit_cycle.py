"""Limit cycles by describing function at a loop break (docs: aircraft), then the confirming
long simulation. The nonlinear open loop (loop opened with its break flag) is driven at
the break by a sine of each amplitude and frequency; L_N(A, f) is its first-harmonic
response; a limit cycle is a root of L_N = -1 (stable when the loop gain falls through
1 as A grows), refined by Newton, then balanced with the higher harmonics of the
break signal (--harmonics; the stick-slip cycle is far from a sine), and checked by a
closed-loop run (position: a 1 mm step held; aircraft: a 0.5 deg attitude pulse, back to
the trim) measured over its second half.
Example: ema limit-cycle --variant controller=PI --variant friction=hybrid --k-i-x 3000 --plot lc.png
"""

from __future__ import annotations

import time

from ..simulation import check_run
from . import UserError, add_progress, check_output_path, load, stage
from ._flags import airframe_variant, overrides, refuse_unused

COMMAND = "limit-cycle"
ORDER = 12
HELP = "limit cycles at a loop break by describing function, confirmed by a long simulation"
#: Most points of the describing-function grid (amplitudes x frequencies).
MAX_GRID = 400
DEFAULTS = {"position": ("1um-30um:7", "1.5-15:10", 6.0), "aircraft": ("3um-300um:7", "0.3-5:8", 300.0)}


def add_arguments(p):
    add_progress(p)
    p.add_argument("--loop", choices=("position", "aircraft"), default="position", help="loop break; default position")
    p.add_argument("--airframe", choices=("b747", "transport"), default=None,
                   help="airframe of the aircraft loop (the same as --variant airframe=...); default b747")
    p.add_argument("--condition", default=None, help="flight condition of the aircraft loop; default cruise_sl")
    p.add_argument("--amplitudes", default=None,
                   help="amplitudes at the break: A0-A1:N (log-spaced) or a list (bare numbers mm); "
                        "default 1um-30um:7 (position), 3um-300um:7 (aircraft)")
    p.add_argument("--freqs", default=None, help="frequencies F0-F1:N or a list (Hz); default 1.5-15:10 (position), "
                                                 "0.3-5:8 (aircraft)")
    p.add_argument("--k-i-x", type=float, default=None, help="position-loop integral gain (1/s^2), PI controller")
    p.add_argument("--backlash", type=float, default=None, help="backlash B (mm)")
    p.add_argument("--dt", type=float, default=1e-4, help="RK4 step (s); default 1e-4")
    p.add_argument("--periods", type=int, default=16, help="periods per point (half dropped); default 16")
    p.add_argument("--t-end", type=float, default=None, help="confirming run (s); default 6 / 300; 0 skips it")
    p.add_argument("--harmonics", default="3,5,7",
                   help="higher harmonics balanced after the describing function's root (orders 2..31, "
                        "comma-separated; 'none': first harmonic only); default 3,5,7")
    p.add_argument("--no-refine", action="store_true", help="grid prediction only (no Newton, no harmonic balance)")
    p.add_argument("--plot", default=None, metavar="FILE.png", help="Nichols chart with amplitude contours")


def _axes(args):
    import numpy as np

    from ..signals import SignalError, log_grid
    from ..sinestream import parse_amplitudes, parse_freqs

    a_txt, f_txt, t_end = DEFAULTS[args.loop]
    try:  # each axis refused before it is allocated, the grid before any run
        amps = log_grid(args.amplitudes or a_txt, "length", "mm", "--amplitudes", UserError, MAX_GRID)
        amps = parse_amplitudes(args.amplitudes, 0.075) if amps is None else amps
        freqs = log_grid(args.freqs or f_txt, "frequency", "Hz", "--freqs", UserError, MAX_GRID)
        freqs = parse_freqs(args.freqs) if freqs is None else freqs
    except (SignalError, ValueError) as exc:
        raise UserError(str(exc)) from None
    if len(amps) < 2 or len(freqs) < 2 or np.any(amps <= 0) or len(amps) * len(freqs) > MAX_GRID:
        raise UserError(f"--amplitudes/--freqs: {len(amps)} x {len(freqs)} points; need 2 to {MAX_GRID} grid "
                        "points in all (MAX_GRID), at least 2 per axis, positive amplitudes")
    return amps, freqs, (t_end if args.t_end is None else args.t_end)


def _orders(text: str) -> tuple:
    from ..limitcycle import harmonic_orders
    from ..signals import SignalError, parse_list

    if text.strip().lower() == "none":
        return ()
    try:
        return harmonic_orders(parse_list(text, "dimensionless", "1"))
    except (SignalError, ValueError) as exc:
        raise UserError(f"--harmonics: {str(exc).removeprefix('harmonics: ')} (or 'none')") from None


def run(args) -> dict:
    from ..limitcycle import confirm_cycle, describing_function, harmonic_balance, plot_nichols, refine, setup

    plot = check_output_path(args.plot, (".png",), "--plot")
    amps, freqs, t_end = _axes(args)
    orders = _orders(args.harmonics)
    if not (0 < args.dt <= 1e-3 and 4 <= args.periods <= 200 and 0 <= t_end <= 7200):
        raise UserError("--dt in (0, 1e-3] s, --periods 4..200, --t-end 0..7200 s")
    t0 = time.perf_counter()
    if args.loop == "aircraft":
        airframe_variant(args, "b747", ("b747", "transport"))
    else:
        refuse_unused(args, {"--airframe": "airframe", "--condition": "condition"}, "to the position loop "
                      "(give --loop aircraft)")
    args.condition = args.condition or "cruise_sl"
    params, model = load(args)
    if t_end > 0:  # the confirming run's size and step, named by the flags
        spacing = max(args.dt, 1e-4 if args.loop == "position" else 1e-3)  # what confirm_cycle keeps
        check_run(model, t_end, dt=args.dt, dt_out=spacing,
                  labels={"t_end": "--t-end", "dt": "--dt", "dt_out": "its sample spacing"}, error=UserError)
    over = overrides(params, {"--k-i-x": ("K_i_x", args.k_i_x, 1.0), "--backlash": ("B", args.backlash, 1e-3)})
    s = setup(model, args.loop, model.p(**over), args.condition)
    kw = dict(p=s["p"], x0=s["x0"], inputs=s["inputs"], meas0=s["meas0"], dt=args.dt, periods=args.periods,
              settle=args.periods // 2)
    stage(args, "limit-cycle", 0.0, "describing function")
    df = describing_function(model, args.loop, amps, freqs, **kw)
    stage(args, "limit-cycle", 0.4, "refining the predicted cycles")
    cycles = df.cycles if args.no_refine else [refine(model, args.loop, c, **kw) for c in df.cycles]
    if orders and not args.no_refine:
        cycles = [harmonic_balance(model, args.loop, c, harmonics=orders, **kw) for c in cycles]
    df.cycles = cycles
    stage(args, "limit-cycle", 0.6, f"confirming by a {t_end:g} s simulation" if t_end > 0 else "")
    sim = confirm_cycle(s, t_end, args.dt) if t_end > 0 else None
    stage(args, "limit-cycle", 1.0, "done")
    written = [str(plot_nichols(df, plot))] if plot is not None else []
    return {"model": args.model, "variants": model.variants, "loop": args.loop, "overrides": over,
            "describing_function": df.as_dict(), "harmonics": list(orders), "predicted": cycles, "simulation": sim,
            "t_end_s": t_end, "wall_time_s": time.perf_counter() - t0, "written": written}


def report(r: dict) -> None:
    print(f"describing function at the {r['loop']} loop break")
    if not r["predicted"]:
        print("  no limit cycle predicted (no root of L_N = -1 on the grid)")
    for c in r["predicted"]:
        kind = "stable" if c["stable"] else "unstable"
        if "harmonic_balance" in c:
            h = c["harmonic_balance"]
            bad = "" if h["converged"] else f" - NOT converged (residual {h['residual']:.2g}): not a cycle"
            print(f"  describing function: {kind} cycle, amplitude {c['df_amplitude'] * 1e6:.3g} um at "
                  f"{c['df_freq_hz']:.4g} Hz")
            print(f"  harmonic balance (1, {', '.join(map(str, r['harmonics']))}): amplitude {h['amplitude'] * 1e6:.3g}"
                  f" um at {h['freq_hz']:.4g} Hz{bad}")
            print(f"  prediction ({c['method']}): amplitude {c['amplitude'] * 1e6:.3g} um at {c['freq_hz']:.4g} Hz")
        else:
            print(f"  predicted {kind} cycle: amplitude {c['amplitude'] * 1e6:.3g} um at {c['freq_hz']:.4g} Hz")
    s = r["simulation"]
    if s is not None:
        f = "-" if s["freq_hz"] is None else f"{s['freq_hz']:.4g} Hz"
        print(f"  simulation ({r['t_end_s']:g} s, second half): amplitude {s['amplitude'] * 1e6:.3g} um "
              f"(half peak-to-peak {s['half_pp'] * 1e6:.3g} um), frequency {f}")
    for w in r["written"]:
        print(f"wrote {w}")
