"""The aircraft - flight control - actuator loop (docs: aircraft): trim at a flight condition,
margins at the actuator-command break with an ideal actuator and with the linearised
EMA, the equivalent time delay the EMA adds (phase-matched over 0.1-10 rad/s,
MIL-STD-1797A style), and pitch responses with the nonlinear EMA (a theta_cmd step and
a vertical 1-cosine gust). Requirement: GM >= 6 dB, PM >= 45 deg.
Example: ema aircraft --airframe transport --condition all --plot-dir aircraft --json
"""

from __future__ import annotations

import math
import time

from .._util._files import atomic_dir
from . import UserError, add_progress, check_output_dir, load, stage
from ._flags import NoEffect, airframe_variant, fill_defaults, refuse_dt, rk4_step
from ._options import seconds

COMMAND = "aircraft"
ORDER = 11
HELP = "aircraft pitch loop around the EMA: trim, margins ideal/EMA, delay, step and gust responses"
AIRFRAMES = ("transport", "b747")
CONDITION_NAMES = ("cruise_sl", "cruise_30k", "landing")


def add_arguments(p):
    add_progress(p)
    p.add_argument("--airframe", choices=AIRFRAMES, default=None,
                   help="airframe (the same as --variant airframe=...); default transport")
    p.add_argument("--condition", choices=[*CONDITION_NAMES, "all"], default="all",
                   help="flight condition (500 ft/s sea level, 800 ft/s at 30 000 ft, 250 ft/s landing); default all")
    p.add_argument("--step-deg", type=float, default=None, help="theta_cmd step (deg); default 1")
    p.add_argument("--gust", type=float, default=None, help="1-cosine gust peak (m/s, up); default 5")
    p.add_argument("--gust-time", type=seconds, default=None, help="gust length (s); default 1")
    p.add_argument("--t-end", type=seconds, default=None, help="response length (s); default 20")
    p.add_argument("--dt", type=seconds, default=None,
                   help="RK4 step of the responses (s; RK4 runs with --zoh or hybrid friction, else --dt is "
                        "refused); default 1e-4")
    p.add_argument("--zoh", action="store_true", help="sampled flight-control computer (80 Hz) and ECU")
    p.add_argument("--no-responses", action="store_true", help="trim, margins and delay only")
    p.add_argument("--plot-dir", default=None, metavar="DIR", help="Bode (ideal/EMA) and responses per condition")


#: The response flags' defaults (None in the parser: given or not, for --no-responses).
RESPONSE_DEFAULTS = {"step_deg": 1.0, "gust": 5.0, "gust_time": 1.0, "t_end": 20.0, "dt": 1e-4}
_QUIET = NoEffect((), "with --no-responses (nothing is simulated)", lambda a: a.no_responses)
#: Each flag -> the combinations where it has no effect (refused; docs: cli).
NO_EFFECT = {
    "--airframe": (), "--condition": (), "--no-responses": (), "--plot-dir": (),
    **{flag: (NoEffect(("--no-responses", flag, *value), _QUIET.why, _QUIET.when),)
       for flag, value in (("--step-deg", ("2",)), ("--gust", ("3",)), ("--gust-time", ("2",)), ("--t-end", ("10",)),
                           ("--zoh", ()))},
    # RK4 steps the responses only with --zoh or hybrid friction: checked once the model is built
    "--dt": (NoEffect(("--no-responses", "--dt", "1e-4"), _QUIET.why, _QUIET.when),
             NoEffect(("--dt", "1e-9", "--t-end", "3600"), "(the RK4 step): the solver chosen is rosenbrock")),
}


def _check(args):
    fill_defaults(args, RESPONSE_DEFAULTS)
    for flag, val, ok in (("--step-deg", args.step_deg, 0 < abs(args.step_deg) <= 10),
                          ("--gust", args.gust, abs(args.gust) <= 30), ("--gust-time", args.gust_time,
                                                                         0 < args.gust_time <= 30),
                          ("--t-end", args.t_end, 0 < args.t_end <= 3600), ("--dt", args.dt, 0 < args.dt <= 1e-3)):
        if not (math.isfinite(val) and ok):
            raise UserError(f"{flag} {val:g} is out of range")
    if args.t_end <= 1.0 + args.gust_time:
        raise UserError(f"--t-end {args.t_end:g} s must exceed the step time 1 s + --gust-time")


def run(args) -> dict:
    from ..aircraft import aircraft_margins, aircraft_point, gust_response, pitch_step
    from ..simulation import choose_solver

    dt_given = args.dt
    _check(args)
    airframe_variant(args, "transport", AIRFRAMES)
    conds = CONDITION_NAMES if args.condition == "all" else (args.condition,)
    if args.airframe == "b747":
        conds = conds[:1]  # the 747 has one flight condition (Mach 0.8, 40 000 ft); the gains of cruise
    names = [f"aircraft_{c}_{k}.png" for c in conds for k in ("margins", "responses")]
    plot_dir = check_output_dir(args.plot_dir, names, "--plot-dir")
    t0 = time.perf_counter()
    params, model = load(args)
    solver = True if model.switched else choose_solver(model, "auto", args.zoh)[0]
    refuse_dt(dt_given, solver, "give --zoh (RK4 at the sampling instants) or drop --dt")
    if solver in (True, "rk4"):  # inside RK4's stability limit, dividing the sample periods
        args.dt = rk4_step(model, dt_given, args.dt, args.zoh or model.switched)
    if not args.no_responses:  # the responses' size and step, named by the flags, before any work
        import inspect

        from ..simulation import check_run

        spacing = inspect.signature(pitch_step).parameters["dt_out"].default
        check_run(model, args.t_end, dt=args.dt, dt_out=spacing, zoh=args.zoh, error=UserError,
                  labels={"t_end": "--t-end", "dt": "--dt", "dt_out": f"the responses' sample spacing {spacing:g} s"})
    out, plots = {}, {}
    for k, c in enumerate(conds):
        stage(args, "aircraft", k / len(conds), f"{c}: trim, margins" + ("" if args.no_responses else ", responses"))
        op = aircraft_point(model, c)
        am = aircraft_margins(model, c, op)
        r = am.as_dict()
        if not args.no_responses:
            st = pitch_step(model, op, c, math.radians(args.step_deg), t_end=args.t_end, dt=args.dt, zoh=args.zoh)
            gu = gust_response(model, op, c, args.gust, args.gust_time, t_end=args.t_end, dt=args.dt, zoh=args.zoh)
            r["step"] = {"step_deg": args.step_deg, **(st["metrics"] or {})}
            r["gust"] = {"peak_m_s": args.gust, "duration_s": args.gust_time, **gu["peaks"]}
            plots[c] = (am, st, gu)
        else:
            plots[c] = (am, None, None)
        out[c] = r
    stage(args, "aircraft", 1.0, "done")
    written = []
    if plot_dir is not None:
        from ..plots._aircraft import plot_condition

        with atomic_dir(plot_dir) as tmp:
            for c, (am, st, gu) in plots.items():
                figs = plot_condition(_loop_curves(model, c, am), c, am.delay["tau_s"], st, gu,
                                      model.variants["friction"], tmp)
                written += [str(plot_dir / w.name) for w in figs]
    return {"model": args.model, "variants": model.variants, "airframe": args.airframe,
            "requirement": {"gm_db": 6.0, "pm_deg": 45.0}, "conditions": out,
            "wall_time_s": time.perf_counter() - t0, "written": written}


def report(r: dict) -> None:
    print(f"aircraft loop ({r['airframe']}), broken at the actuator command; requirement GM >= 6 dB, PM >= 45 deg")
    print(f"  {'condition':11s} {'actuator':8s} {'GM dB':>7s} {'PM deg':>7s} {'f_c Hz':>7s}  ok   delay ms")
    for c, d in r["conditions"].items():
        for k in ("ideal", "ema"):
            m = d[k]
            delay = f"{d['delay']['tau_s'] * 1e3:8.2f}" if k == "ema" else ""
            print(f"  {c:11s} {k:8s} {m['gm_db']:7.2f} {m['pm_deg']:7.2f} {m['f_gc_hz'] or float('nan'):7.3f}  "
                  f"{'yes' if m['meets_requirement'] else 'NO ':3s} {delay}")
        if "step" in d:
            s, g = d["step"], d["gust"]
            print(f"  {'':11s} step {s['step_deg']:g} deg: overshoot {s.get('overshoot', float('nan')) * 100:.1f} %, "
                  f"{_settling(s.get('settling_time_s'))}; gust {g['peak_m_s']:g} m/s: "
                  f"|d n_z| {g['n_z_dev']:.3f} g, |d theta| {math.degrees(g['theta_dev_rad']):.2f} deg")
    for w in r["written"]:
        print(f"wrote {w}")


def _settling(t) -> str:
    """``settling 1.23 s``, or ``not settled`` for a response that never stays in its
    band within the run (an infinite or missing settling time), never ``inf s``."""
    if isinstance(t, (int, float)) and math.isfinite(t):
        return f"settling {t:.2f} s"
    return "not settled within --t-end"


def _loop_curves(model, condition, am) -> dict:
    """The aircraft loop's Bode with an ideal actuator and with the EMA, and their margins."""
    from ..aircraft import aircraft_point, ema_loop, ideal_loop
    from ..frequency import bode, frequency_grid

    f = frequency_grid(1e-3, 100.0, 100)
    op = aircraft_point(model, condition)
    return {"ideal": (bode(ideal_loop(model, op), f), am.ideal), "EMA": (bode(ema_loop(model, op), f), am.ema)}
