"""Limit cycles by describing function at a loop break (docs: aircraft), then the confirming
long simulation. The nonlinear open loop (loop opened with its break flag) is driven at
the break by a sine of each amplitude and frequency; L_N(A, f) is its first-harmonic
response; a limit cycle is a root of L_N = -1 (stable when the loop gain falls through
1 as A grows), refined by Newton, then balanced with the higher harmonics of the
break signal (--harmonics; the stick-slip cycle is far from a sine), and checked by a
closed-loop run (position: a 1 mm step held; aircraft: a 0.5 deg attitude pulse, back to
the trim) measured over its second half.
With --method shooting the periodic orbit itself is found by shooting (Newton on the
state and the period, the monodromy matrix from the integrator's sensitivities): its
period, amplitudes, Floquet multipliers and stability beside the describing function's
prediction; --continue NAME=LO:HI follows the orbit over a parameter (folds, period
doubling, birth) and --plot draws the bifurcation diagram.
Example: ema limit-cycle --variant controller=PI --variant friction=hybrid --k-i-x 3000 --plot lc.png
Example: ema limit-cycle --method shooting --variant controller=PI --k-i-x 3000 --csv orbit.csv
"""

from __future__ import annotations

import time

from ..simulation import check_run
from . import UserError, add_progress, check_output_path, load, stage
from ._flags import NoEffect, airframe_variant, no_effect, overrides, refuse_dt
from ._options import seconds

COMMAND = "limit-cycle"
ORDER = 12
HELP = ("limit cycles at a loop break: describing function and harmonic balance, or the exact periodic orbit "
        "by shooting (--method shooting) with its Floquet stability; confirmed by a simulation")
#: Most points of the describing-function grid (amplitudes x frequencies).
MAX_GRID = 400
DEFAULTS = {"position": ("1um-30um:7", "1.5-15:10", 6.0), "aircraft": ("3um-300um:7", "0.3-5:8", 300.0)}
#: ``--method shooting`` on the position loop of a controller without integral action
#: (the reference P) and no --variant controller nor --k-i-x: the P loop settles (no
#: orbit to shoot), so the shooting takes this hunting scenario (the integral action
#: against the friction: a 5.9 Hz cycle of 5.5 um on the reference set) and says so.
HUNTING_GAIN = "K_i_x"
HUNTING = {"controller": "PI", HUNTING_GAIN: 3000.0}

#: The largest RK4 step when --dt is not given (s): the default is the largest step at
#: most this inside RK4's stability limit on the model
#: (:func:`~ema_casadi.simulation.inside_limit`).
DEFAULT_DT = 1e-4


def _no_df(args) -> bool:
    return args.method == "shooting" and args.no_df


_SHOOTING = NoEffect((), "with --method {method}: it belongs to the shooting (give --method shooting)",
                     lambda a: a.method != "shooting")
_GRID = NoEffect((), "with --method shooting --no-df: no describing function is computed", _no_df)
_POSITION = NoEffect((), "with --loop position: it sets the aircraft loop (give --loop aircraft)",
                     lambda a: a.loop == "position")
#: Each flag -> the combinations where it has no effect (refused; docs: cli).
NO_EFFECT = {
    "--loop": (), "--backlash": (), "--t-end": (), "--plot": (), "--method": (),
    "--airframe": (NoEffect(("--airframe", "transport"), _POSITION.why, _POSITION.when),),
    "--condition": (NoEffect(("--condition", "landing"), _POSITION.why, _POSITION.when),),
    "--continue": (NoEffect(("--continue", "B=0:0.1"), _SHOOTING.why, _SHOOTING.when),),
    "--csv": (NoEffect(("--csv", "o.csv"), _SHOOTING.why, _SHOOTING.when),),
    "--no-df": (NoEffect(("--no-df",), _SHOOTING.why, _SHOOTING.when),),
    "--zoh": (NoEffect(("--zoh",), _SHOOTING.why, _SHOOTING.when),),
    **{flag: (NoEffect(("--method", "shooting", "--no-df", flag, *value), _GRID.why, _GRID.when),)
       for flag, value in (("--amplitudes", ("1um,5um",)), ("--freqs", ("2,4",)), ("--periods", ("8",)),
                           ("--no-refine", ()))},
    "--harmonics": (NoEffect(("--no-refine", "--harmonics", "3"), "with --no-refine (the harmonic balance refines "
                             "the grid's prediction)", lambda a: a.no_refine),
                    NoEffect(("--method", "shooting", "--no-df", "--harmonics", "3"), _GRID.why, _GRID.when)),
    # the model decides: RK4 steps only a hybrid or switched model; K_i_x acts only with controller=PI
    "--dt": (NoEffect(("--dt", "1e-9"), "(the RK4 step): the solver chosen is rosenbrock"),),
    "--k-i-x": (NoEffect(("--k-i-x", "3000"), "(the position loop's integral gain): the controller is P"),),
}


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
    p.add_argument("--dt", type=seconds, default=None,
                   help=f"RK4 step (s) where RK4 runs (hybrid friction, a switched model; refused where the "
                        f"variable-step solver runs); default the largest step at most {DEFAULT_DT:g} inside RK4's "
                        "stability limit on the model")
    p.add_argument("--periods", type=int, default=16, help="periods per point (half dropped); default 16")
    p.add_argument("--t-end", type=seconds, default=None, help="confirming run (s); default 6 / 300; 0 skips it")
    p.add_argument("--harmonics", default="3,5,7",
                   help="higher harmonics balanced after the describing function's root (orders 2..31, "
                        "comma-separated; 'none': first harmonic only); default 3,5,7")
    p.add_argument("--no-refine", action="store_true", help="grid prediction only (no Newton, no harmonic balance)")
    p.add_argument("--plot", default=None, metavar="FILE.png",
                   help="Nichols chart with amplitude contours (shooting: the orbit and its multipliers; "
                        "with --continue the bifurcation diagram)")
    p.add_argument("--method", choices=("df", "shooting"), default="df",
                   help="df: describing function (and harmonic balance); shooting: the periodic orbit by "
                        "shooting with its Floquet multipliers, the describing function beside it; default df")
    p.add_argument("--continue", dest="cont", default=None, metavar="NAME=LO:HI",
                   help="shooting: continue the orbit over a parameter or a held input from LO to HI (B in mm "
                        "unless a unit is given, e.g. B=0:100um; a gain such as K_i_x in SI; the load f_ext (or "
                        "'load') in N, e.g. f_ext=0:2kN), the value set to the range's nearest end inside it "
                        "when outside")
    p.add_argument("--csv", default=None, metavar="FILE.csv", help="shooting: the orbit over one period (CSV)")
    p.add_argument("--no-df", action="store_true", help="shooting: no describing function beside the orbit")
    p.add_argument("--zoh", action="store_true",
                   help="shooting: the ECU sampled at its rates (the finite-difference fallback on the RK4 rollout)")


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


def _continuation(args, params, model):
    """``--continue NAME=LO:HI`` as (name, lo, hi) in SI, checked before any work: a
    parameter (checked as a parameter file's value) or a driven input held constant (the
    load ``f_ext`` or ``load``, in N unless a unit is given; inside the model's envelope)."""
    from ..limitcycle import checked_inputs
    from ..model import checked
    from ..model.params import ParameterError
    from ..signals import KIND_OF_UNIT, SignalError, parse_quantity

    if args.cont is None:
        return None
    name, sep, rng = args.cont.partition("=")
    lo_txt, sep2, hi_txt = rng.partition(":")
    name = name.strip()
    if not sep or not sep2 or not name:
        raise UserError(f"--continue {args.cont!r}: expected NAME=LO:HI (e.g. B=0:100um)")
    name = model.input_with("load") if name == "load" else name
    info = model.input_info.get(name)
    driven = info is not None and not info.injection
    if name not in model.param_names and not driven:
        raise UserError(f"--continue: no parameter or driven input {name!r} in the model")
    try:
        if driven:
            lo, hi = (parse_quantity(v, info.kind, info.unit) for v in (lo_txt, hi_txt))
            for v in (lo, hi):
                checked_inputs(model, {name: v}, model.p())
        else:  # a parameter: a number in its SI unit, or a quantity of its kind (B: bare mm)
            unit = model.param_units().get(name, "")
            kind = "length" if name == "B" else KIND_OF_UNIT.get(unit)
            lo, hi = (_bound(v, name, kind, "mm" if name == "B" else unit, args.cont) for v in (lo_txt, hi_txt))
        for v in (lo, hi) if not driven else ():
            checked(name, v, f"--continue {name}={v:g}")
    except (SignalError, ValueError, ParameterError) as exc:
        msg = str(exc).split(", got ")[0]
        raise UserError(f"--continue: {msg.removeprefix('inputs: ')}" if driven else msg) from None
    if not lo < hi:
        raise UserError(f"--continue {args.cont}: need LO < HI")
    return name, lo, hi


def _bound(text: str, name: str, kind: str | None, unit: str, given: str) -> float:
    """One end of --continue's parameter range: a number (SI) or a quantity of ``kind``."""
    from ..signals import SignalError, parse_quantity

    try:
        return parse_quantity(text, kind, unit) if kind else float(text)
    except (SignalError, ValueError):
        what = f"a {kind} (a number in {unit}, or with a unit)" if kind else f"a number in {unit or '1'} (SI)"
        raise UserError(f"--continue {given}: {text.strip()!r} is not {what}") from None


def _shooting(args, model, s, over, cycles, t_end, t0, plot, csv, cont):
    import numpy as np

    from ..limitcycle import OrbitNotFound, confirm_cycle, continue_orbit, input_value, periodic_orbit

    pred = next((c for c in cycles if c.get("stable")), cycles[0] if cycles else None)
    p = s["p"] if args.loop == "position" else model.p(**over)
    held = {}
    if cont is not None and cont[0] in model.param_names:
        k = list(model.param_names).index(cont[0])
        p = np.array(p, float).copy()
        p[k] = min(max(p[k], cont[1]), cont[2])
    elif cont is not None:  # a held input: its value moved into the range the same way
        held = {cont[0]: min(max(input_value(model, cont[0], p), cont[1]), cont[2])}
    out = {"model": args.model, "variants": model.variants, "loop": args.loop, "overrides": over,
           "method": "shooting", "predicted": cycles, "written": []}
    stage(args, "limit-cycle", 0.3, "periodic orbit by shooting")
    try:
        orb = periodic_orbit(model, args.loop, p=p, condition=args.condition, prediction=pred, inputs=held,
                             zoh=args.zoh)
        out["orbit"] = orb.as_dict()
        if cont is not None:
            stage(args, "limit-cycle", 0.5, f"continuation over {cont[0]}")
            c = continue_orbit(model, cont[0], cont[1], cont[2], args.loop, p=p, condition=args.condition, orbit=orb,
                               progress=lambda f, note: stage(args, "limit-cycle", 0.5 + 0.4 * f, note))
            out["continuation"] = c.as_dict()
    except OrbitNotFound as exc:
        out["failure"] = str(exc)
        return out
    stage(args, "limit-cycle", 0.9, f"confirming by a {t_end:g} s simulation" if t_end > 0 else "")
    out["simulation"] = confirm_cycle(s, t_end, args.dt) if t_end > 0 else None
    out["t_end_s"] = t_end
    if csv is not None:
        out["written"].append(str(orb.to_csv(csv)))
    if plot is not None:
        out["written"].append(str(c.plot(plot) if cont is not None else orb.plot(plot)))
    stage(args, "limit-cycle", 1.0, "done")
    out["wall_time_s"] = time.perf_counter() - t0
    return out


def run(args) -> dict:
    from ..limitcycle import confirm_cycle, describing_function, harmonic_balance, plot_nichols, refine, setup

    plot = check_output_path(args.plot, (".png",), "--plot")
    shooting = args.method == "shooting"
    dt_given = args.dt
    args.dt = DEFAULT_DT if args.dt is None else args.dt
    csv = check_output_path(args.csv, (".csv",), "--csv")
    amps, freqs, t_end = _axes(args)
    orders = _orders(args.harmonics)
    for flag, value, ok, span in (("--dt", args.dt, 0 < args.dt <= 1e-3, "(0, 1e-3] s"),
                                  ("--periods", args.periods, 4 <= args.periods <= 200, "4..200"),
                                  ("--t-end", t_end, 0 <= t_end <= 7200, "0..7200 s")):
        if not ok:
            raise UserError(f"{flag} {value:g}: outside {span}")
    t0 = time.perf_counter()
    if args.loop == "aircraft":
        airframe_variant(args, "b747", ("b747", "transport"))
    args.condition = args.condition or "cruise_sl"
    params, model = load(args)
    hunting = _hunting(args, model)
    if hunting is not None:
        params, model = load(args)
    from ..simulation import choose_solver

    refuse_dt(dt_given, True if model.switched else choose_solver(model, "auto")[0],
              "give --variant friction=hybrid (RK4 with the stick/slip logic) or drop --dt")
    if dt_given is None and (model.switched or choose_solver(model, "auto")[0] == "rk4"):
        from ..simulation import inside_limit

        args.dt = inside_limit(model, {}, None, False, DEFAULT_DT)
    if "K_i_x" not in {g.name for g in model.gains}:
        no_effect(args, "--k-i-x", f"(the position loop's integral gain): the controller is "
                  f"{model.variants.get('controller')} (give --variant controller=PI)")
    if t_end > 0:  # the confirming run's size and step, named by the flags
        spacing = max(args.dt, 1e-4 if args.loop == "position" else 1e-3)  # what confirm_cycle keeps
        check_run(model, t_end, dt=args.dt, dt_out=spacing,
                  labels={"t_end": "--t-end", "dt": "--dt", "dt_out": "its sample spacing"}, error=UserError)
    over = overrides(params, {"--k-i-x": ("K_i_x", args.k_i_x, 1.0), "--backlash": ("B", args.backlash, 1e-3)})
    cont = _continuation(args, params, model) if shooting else None
    if shooting:
        from ..limitcycle import unsupported

        if (why := unsupported(model)) is not None:
            raise UserError(f"--method shooting: {why}")
    s = setup(model, args.loop, model.p(**over), args.condition)
    if shooting and args.no_df:
        return {**_shooting(args, model, s, over, [], t_end, t0, plot, csv, cont), "scenario": hunting}
    kw = dict(p=s["p"], x0=s["x0"], inputs=s["inputs"], meas0=s["meas0"], dt=args.dt, periods=args.periods,
              settle=args.periods // 2)
    stage(args, "limit-cycle", 0.0, "describing function")
    df = describing_function(model, args.loop, amps, freqs, **kw)
    stage(args, "limit-cycle", 0.4, "refining the predicted cycles")
    cycles = df.cycles if args.no_refine else [refine(model, args.loop, c, **kw) for c in df.cycles]
    if orders and not args.no_refine:
        cycles = [harmonic_balance(model, args.loop, c, harmonics=orders, **kw) for c in cycles]
    df.cycles = cycles
    if shooting:
        return {**_shooting(args, model, s, over, cycles, t_end, t0, plot, csv, cont), "scenario": hunting}
    stage(args, "limit-cycle", 0.6, f"confirming by a {t_end:g} s simulation" if t_end > 0 else "")
    sim = confirm_cycle(s, t_end, args.dt) if t_end > 0 else None
    stage(args, "limit-cycle", 1.0, "done")
    written = [str(plot_nichols(df, plot))] if plot is not None else []
    return {"model": args.model, "variants": model.variants, "loop": args.loop, "overrides": over,
            "describing_function": df.as_dict(), "harmonics": list(orders), "predicted": cycles, "simulation": sim,
            "t_end_s": t_end, "wall_time_s": time.perf_counter() - t0, "written": written}


def _hunting(args, model) -> str | None:
    """``--method shooting`` on the position loop of a controller without integral action
    (the reference set's P), nothing given that
    sets the loop (--variant controller, --k-i-x, --continue): the :data:`HUNTING`
    scenario put into ``args`` (the model to load again); the line that says so, else None."""
    given = {k for k, _ in args.variant}
    integral = HUNTING_GAIN in {g.name for g in model.gains}  # the loop's integral action (a PI controller)
    if (args.method != "shooting" or args.loop != "position" or integral
            or "controller" in given or args.k_i_x is not None or args.cont is not None):
        return None
    args.variant = [*args.variant, ("controller", HUNTING["controller"])]
    args.k_i_x = HUNTING[HUNTING_GAIN]
    return (f"scenario: the P loop settles (no orbit to shoot), so the hunting one: --variant controller="
            f"{HUNTING['controller']} --k-i-x {HUNTING[HUNTING_GAIN]:g} (give --variant controller=P to shoot the "
            "P loop)")


def _report_shooting(r: dict) -> None:
    from ..signals import format_quantity as q

    if "orbit" not in r:
        print("  no periodic orbit found")
        return
    o = r["orbit"]
    kind = "stable" if o["stable"] else "unstable"
    mu = o["multiplier_moduli"]
    tm = complex(*o["trivial_multiplier"])
    print(f"periodic orbit of the {r['loop']} loop by shooting ({o['info']['method']}, "
          f"{o['info']['iterations']} Newton steps): {kind}")
    print(f"  period {q(o['period_s'], 's', 6)}, frequency {o['freq_hz']:.6g} Hz, periodicity residual "
          f"{o['periodicity_residual']:.2g} (of full scale)")
    print(f"  Floquet multipliers: trivial {abs(tm):.9f} (check: 1), largest other |mu| {max(mu[1:]):.4g}")
    for n, v in o["signals"].items():
        u = v["unit"]
        print(f"  {n}: first harmonic {q(v['amplitude'], u)}, peak-to-peak {q(v['peak_to_peak'], u)}")
    pr = o.get("prediction")
    if pr:
        ae = "-" if pr["amplitude_error"] is None else f"{pr['amplitude_error'] * 100:+.1f} %"
        u = o["signals"].get(pr.get("signal"), {}).get("unit", "m")
        print(f"  describing-function prediction: first harmonic {q(pr['amplitude'], u)} of "
              f"{pr.get('signal', 'x_rod')} at {pr['freq_hz']:.4g} Hz "
              f"(frequency error {pr['freq_error'] * 100:+.1f} %, amplitude error {ae})")
    c = r.get("continuation")
    if c:
        print(f"  continuation over {c['parameter']}: {len(c['values'])} orbits, {q(min(c['values']), c['unit'])} .. "
              f"{q(max(c['values']), c['unit'])} (end: {c['info']['end']})")
        for b in c["bifurcations"]:
            print(f"    {b['kind']} at {c['parameter']} = {q(b['value'], c['unit'])}")


def report(r: dict) -> None:
    from ..signals import format_quantity as q

    if r.get("method") == "shooting":
        if r.get("scenario"):
            print(r["scenario"])
        _report_shooting(r)
        s = r.get("simulation")
        if s is not None:
            f = "-" if s["freq_hz"] is None else f"{s['freq_hz']:.4g} Hz"
            print(f"  simulation ({r['t_end_s']:g} s, second half): amplitude {q(s['amplitude'], 'm')}, frequency {f}")
        for w in r["written"]:
            print(f"wrote {w}")
        return
    print(f"describing function at the {r['loop']} loop break")
    if not r["predicted"]:
        print("  no limit cycle predicted (no root of L_N = -1 on the grid)")
    for c in r["predicted"]:
        kind = "stable" if c["stable"] else "unstable"
        if "harmonic_balance" in c:
            h = c["harmonic_balance"]
            bad = "" if h["converged"] else f" - NOT converged (residual {h['residual']:.2g}): not a cycle"
            print(f"  describing function: {kind} cycle, amplitude {q(c['df_amplitude'], 'm', 3)} at "
                  f"{c['df_freq_hz']:.4g} Hz")
            print(f"  harmonic balance (1, {', '.join(map(str, r['harmonics']))}): amplitude "
                  f"{q(h['amplitude'], 'm', 3)} at {h['freq_hz']:.4g} Hz{bad}")
            print(f"  prediction ({c['method']}): amplitude {q(c['amplitude'], 'm', 3)} at {c['freq_hz']:.4g} Hz")
        else:
            print(f"  predicted {kind} cycle: amplitude {q(c['amplitude'], 'm', 3)} at {c['freq_hz']:.4g} Hz")
    s = r["simulation"]
    if s is not None:
        f = "-" if s["freq_hz"] is None else f"{s['freq_hz']:.4g} Hz"
        print(f"  simulation ({r['t_end_s']:g} s, second half): amplitude {q(s['amplitude'], 'm', 3)} "
              f"(half peak-to-peak {q(s['half_pp'], 'm', 3)}), frequency {f}")
    for w in r["written"]:
        print(f"wrote {w}")
