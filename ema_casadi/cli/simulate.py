"""Time simulation of the actuator.

SIGNAL: step:AMP[@T0], ramp:RATE[@T0], sine:AMP@FREQ[@T0], chirp:AMP@F0-F1, a constant,
a CSV file (time and one signal column) or FILE.csv:COLUMN (one column of a table, e.g.
a run written by --out: run.csv:x_rod); join terms with '+'. Positions take 1mm, 250um,
0.01m or 0.5% (of the stroke); a bare number is mm. Forces take 10kN or 500N; a bare
number is N. A negative value may follow its flag: --f-ext -30kN.
CSV files are UTF-8 and SI: bare numbers in a file are m, N, s (the mm rule is for flag
values only) unless the header names a unit (x_cmd [mm], f_ext [kN], time [ms]) or a
'Unit:' row follows the header (the layout --out writes: time, then one column per
signal, then Unit: and each unit; MATLAB's Simulation Data Inspector reads it).
Solver: --solver auto (default) runs the compiled RODAS4 (rosenbrock) on a continuous
model and the compiled RK4 at --dt where the model switches or sticks (hybrid friction,
--zoh, inverter=pwm); the choice and its tolerance are reported (and in --json).
Samples: every --dt-out (default 1e-4 s) and at --t-end itself (the last interval
shorter when --dt-out does not divide --t-end); with rk4, --t-end and --dt-out must be
whole numbers of --dt. --from-trim starts at the operating point of the inputs' values
at t = 0 (a load present from the start does not knock the rod back).
Runs above 1e9 RK4 steps or a 1 GiB result are refused with the estimate.
With --variant inverter=pwm the model switches: rk4 steps to every switching instant
(--dt bounds its step inside a sub-interval), --t-end must be whole carrier periods
and --dt-out is rounded to whole periods (the report and --json say to what); the
power and loss columns then hold carrier-period averages (each row: the average over
the window ending there, so that the rows sum to the run's energies), and
--instantaneous adds their sampled values as <name>_inst columns.
--json reports the energy of every power and loss output, the stored-energy change and
the balance residual int P_dc - dE_stored - sum(int losses) - int P_load.
Example: ema simulate --x-cmd "step:1mm@0.01+sine:0.375mm@1@0.5" --t-end 1 --out run.csv
"""

from __future__ import annotations

import math
import time

from ..signals import SignalError, parse_signal
from ..simulation import (
    DT_DEFAULT,
    DT_MARGIN,
    DT_OUT,
    SOLVERS,
    SimulationError,
    check_inputs,
    check_run,
    check_switched,
    choose_solver,
    default_step,
    peak_load,
    rk4_step_limit,
    sampling_split,
    simulate,
)
from . import UserError, add_progress, check_output_path, load, progress_of
from ._common import key_values
from ._flags import NoEffect, no_effect, refuse_dt
from ._flags import given as flag_given
from ._options import seconds

#: The roles whose signals' final values a model of several actuators reports.
_FINAL_ROLES = ("rod_position", "rod_velocity", "attachment_force", "force_fight")

COMMAND = "simulate"
#: A rod command beyond this many strokes means nothing (the end stops hold the rod at
#: the stroke): refused.
COMMAND_STROKES = 3.0
#: The rod command when --x-cmd is not given (a model that takes x_cmd).
DEFAULT_X_CMD = "step:1mm@0.01"
ORDER = 2
HELP = "time simulation with named outputs (CSV/NPZ, plot)"


def add_arguments(p):
    p.add_argument("--x-cmd", default=None, metavar="SIGNAL",
                   help="commanded rod position (bare numbers in mm; in a CSV file m unless the header names a "
                        f"unit); default {DEFAULT_X_CMD} (a model with an airframe is commanded by "
                        "--input theta_cmd=...)")
    p.add_argument("--f-ext", default="0", metavar="SIGNAL",
                   help="external rod force, positive pushes the rod in (bare numbers in N, also in a CSV file); "
                        "default 0")
    p.add_argument("--input", action="append", default=[], metavar="NAME=SIGNAL",
                   help="drive any other model input by name, e.g. eta=0.85 or d_x=step:1um@0.01 "
                        "(lengths: bare numbers in mm; other inputs in their SI unit); repeatable")
    p.add_argument("--t-end", type=seconds, default=0.2, help="end time (s); default 0.2")
    p.add_argument("--dt", type=seconds, default=None,
                   help="RK4 step (s), where rk4 runs (refused where another solver runs, and above RK4's stability "
                        "limit on the model at the run's largest load; with --zoh it must divide every ECU sample "
                        f"period); default simulate()'s: {DT_DEFAULT:g} where that is under {DT_MARGIN:g} x the "
                        "limit, else the largest round step under it dividing the ECU's sample periods")
    p.add_argument("--dt-out", type=seconds, default=None,
                   help="spacing of the saved samples (s); default 1e-4 (rk4: the nearest whole number of steps); "
                        "the last sample is at --t-end")
    p.add_argument("--solver", choices=SOLVERS, default="auto",
                   help="auto (default: rosenbrock on a continuous model, rk4 where it switches or sticks), rk4 "
                        "(fixed step, compiled), cvodes (variable-step BDF) or rosenbrock (variable-step RODAS4, "
                        "compiled; smooth friction only)")
    p.add_argument("--from-trim", action="store_true",
                   help="start at the trimmed operating point of the first --x-cmd and --f-ext values (default: "
                        "at rest, all states zero)")
    p.add_argument("--zoh", action="store_true", help="sampled ECU at its rates (rk4 only)")
    p.add_argument("--out", default=None, metavar="FILE",
                   help="write the time series: .csv (column time, then one per signal, a Unit: row, SI, 17 "
                        "digits), .mat (struct ema_sim: time, one field per signal, units) or .npz")
    p.add_argument("--plot", default=None, metavar="FILE.png",
                   help="plot command, position, velocity, current, voltage (a switched inverter=pwm model: phase "
                        "currents, leg states, phase and line voltages over the last carrier periods, DC link)")
    p.add_argument("--event-tol", type=seconds, default=1e-7,
                   help="hybrid friction with cvodes: stick/slip switching instants located to this time (s); "
                        "default 1e-7")
    p.add_argument("--instantaneous", action="store_true",
                   help="switched model: also write the power and loss outputs sampled at the kept instants "
                        "(<name>_inst; the <name> columns hold carrier-period averages)")
    add_progress(p)


_DT_WHY = "where --solver {solver} runs (--dt is the RK4 step): give --solver rk4 or drop --dt"
#: Each flag -> the combinations where it has no effect (refused; docs: cli).
NO_EFFECT = {
    "--x-cmd": (), "--f-ext": (), "--input": (), "--t-end": (), "--dt-out": (), "--solver": (), "--from-trim": (),
    "--out": (), "--plot": (),
    # with --solver auto the solver is the model's (rosenbrock on a continuous one): checked once it is built
    "--dt": (NoEffect(("--solver", "cvodes", "--dt", "1e-5"), _DT_WHY, lambda a: a.solver in ("cvodes", "rosenbrock")),
             NoEffect(("--t-end", "0.1", "--dt", "0.5"), "(the RK4 step): the solver chosen is rosenbrock")),
    "--event-tol": (NoEffect(("--solver", "rk4", "--event-tol", "1e-6"), "with --solver {solver}: it locates the "
                             "stick/slip instants of --solver cvodes", lambda a: a.solver != "cvodes"),
                    NoEffect(("--solver", "cvodes", "--event-tol", "1e-6"), "(the stick/slip instants of hybrid "
                             "friction): this model has none")),
    "--zoh": (NoEffect(("--variant", "inverter=pwm", "--t-end", "1ms", "--zoh"), "(a sampled ECU): with a switched "
                       "model the ECU is always sampled"),),
    "--instantaneous": (NoEffect(("--instantaneous",), "without --out (it adds columns to the table written)",
                                 lambda a: a.out is None),
                        NoEffect(("--instantaneous", "--out", "run.csv"), "(the power and loss columns' sampled "
                                 "values): the model does not switch, its columns are instantaneous already")),
}

#: simulate()'s argument names as the flags that set them (messages name the flag).
FLAGS = {"t_end": "--t-end", "dt": "--dt", "dt_out": "--dt-out", "event_tol": "--event-tol",
         "solver": "--solver", "zoh": "--zoh", "from_trim": "--from-trim"}


def _named(exc, model) -> Exception:
    """simulate()'s error under the flag that set what it names: a signal checked against
    the chosen solver's sampling (``x_cmd ...`` -> ``--x-cmd ...``), an argument
    (``from_trim: ...`` -> ``--from-trim: ...``); any other error as it is."""
    if isinstance(exc, SignalError):
        name = str(exc).split(" ", 1)[0].rstrip(":")
        flag = _FLAG_OF.get(name, f"--input {name}" if name in model.inputs else name)
        return UserError(flag + str(exc)[len(name):])
    name = str(exc).split(":", 1)[0]
    return UserError(FLAGS[name] + str(exc)[len(name):]) if name in FLAGS else exc


def run(args) -> dict:
    out = check_output_path(args.out, (".csv", ".npz", ".mat"), "--out")
    plot = check_output_path(args.plot, (".png",), "--plot")
    for flag, val in (("--t-end", args.t_end), ("--dt", args.dt), ("--dt-out", args.dt_out),
                      ("--event-tol", args.event_tol)):
        if val is not None and not (math.isfinite(val) and val > 0):
            raise UserError(f"{flag} must be a positive number of seconds, got {val}")
    if flag_given(args, "--event-tol") and not args.event_tol < args.t_end:
        raise UserError(f"--event-tol {args.event_tol:g} s: not below --t-end {args.t_end:g} s (it locates the "
                        "switching instants inside the run)")
    dt_out = args.dt_out  # None: simulate()'s default (DT_OUT)
    params, model = load(args)
    _refuse_idle(args, model)
    user_dt, args.dt = args.dt, DT_DEFAULT if args.dt is None else args.dt
    if model.switched:  # the PWM bridge: carrier-synchronous, rk4 only, ECU always sampled
        if args.solver not in ("rk4", "auto"):
            raise UserError(f"--solver {args.solver}: the model switches (inverter={model.variants['inverter']}); "
                            f"use --solver rk4, which steps to every switching instant")
        check_run(model, args.t_end, dt=args.dt, dt_out=dt_out or DT_OUT, solver="cvodes", event_tol=args.event_tol,
                  labels=FLAGS, error=UserError)
        check_switched(model, model.p(), args.t_end, UserError, "--t-end")
    else:
        check_run(model, args.t_end, dt=args.dt, dt_out=dt_out, solver=args.solver, zoh=args.zoh,
                  event_tol=args.event_tol, labels=FLAGS, error=UserError)
    stroke = params.actuator.stroke
    x_cmd = None
    if "x_cmd" in model.inputs:
        try:
            x_cmd = parse_signal(DEFAULT_X_CMD if args.x_cmd is None else args.x_cmd, "length", bare="mm",
                                 stroke=stroke, duration=args.t_end)
        except ValueError as exc:
            raise UserError(f"--x-cmd {exc}") from None
    elif args.x_cmd is not None:
        raise UserError(f"--x-cmd: the model (airframe={model.variants.get('airframe')}) takes no rod command; "
                        f"it is commanded by {', '.join(n for n in model.inputs if n.endswith('_cmd'))} "
                        "(--input NAME=SIGNAL)")
    try:
        f_ext = parse_signal(args.f_ext, "force", bare="N", duration=args.t_end)
    except ValueError as exc:
        raise UserError(f"--f-ext {exc}") from None
    others = _named_inputs(args.input, model, stroke, args.t_end)
    given = _checked(args, model, dt_out, {"x_cmd": x_cmd, "f_ext": f_ext, **others})  # (a smaller default dt
    if model.switched or choose_solver(model, args.solver, args.zoh)[0] == "rk4":  # samples them finer still)
        args.dt = _step(args, model, user_dt, dt_out, {n: s for n, s in given.items() if s is not None})
    t0 = time.perf_counter()
    try:
        res = simulate(model, args.t_end, dt=args.dt, dt_out=dt_out, solver=args.solver,
                       zoh=args.zoh, event_tol=args.event_tol, progress=progress_of(args), from_trim=args.from_trim,
                       **{n: s for n, s in given.items() if s is not None})
    except (SignalError, SimulationError) as exc:
        raise _named(exc, model) from None
    written = []
    if out is not None:
        table = res.with_instantaneous() if args.instantaneous else res
        writer = {".csv": table.to_csv, ".mat": table.to_mat, ".npz": table.to_npz}[out.suffix.lower()]
        written.append(str(writer(out)))
    if plot is not None:
        written.append(_plot(args, model, res, given, plot))
    info = res.info
    return {
        "model": args.model,
        "variants": model.variants,
        "solver": info["solver"],
        "solver_requested": args.solver,
        "solver_reason": info.get("solver_reason"),
        "tolerance": info.get("tolerance"),
        "from_trim": args.from_trim,
        "t_end": args.t_end,
        **_final(model, res),
        "wall_time": time.perf_counter() - t0,
        "compute_time": info.get("compute_time"),
        "compile_time": info.get("compile_time", 0.0),
        "steps": info.get("steps"),
        "samples": len(res.t),
        "mode_switches": info.get("mode_switches"),
        **sampling_report(model, res, dt_out),
        **energy_report(model, res),
        "written": written,
    }


def _step(args, model, user_dt, dt_out, signals) -> float:
    """The RK4 step: --dt checked against RK4's stability limit at the run's largest
    load (refused above it, naming the limit and the mode) and with --zoh against the
    ECU's sample periods; without --dt simulate()'s own default
    (:func:`~ema_casadi.simulation.default_step`), checked against --t-end and --dt-out."""
    sampled = args.zoh or model.switched
    limit = rk4_step_limit(model, load=peak_load(model, signals, args.t_end), zoh=sampled)
    if user_dt is not None:
        text = limit.message(user_dt, "--dt")
        if text is not None:
            raise UserError(text)
        if args.zoh and not model.switched:  # split at the instants; refused where a step holds two
            sampling_split(model, user_dt, model.p(), UserError, "--dt")
        return user_dt
    dt = default_step(model, args.t_end, lambda: (signals, model.p()), sampled, dt_out or DT_OUT)
    if not model.switched:
        check_run(model, args.t_end, dt=dt, dt_out=dt_out, solver=args.solver, zoh=args.zoh,
                  event_tol=args.event_tol, labels={**FLAGS, "dt": f"the default step (inside RK4's stability limit "
                                                                   f"{limit.dt_max:.3g} s)"}, error=UserError)
    return dt


def _refuse_idle(args, model) -> None:
    """The flags the model leaves without effect (NO_EFFECT's rules that need it)."""
    refuse_dt(args.dt, True if model.switched else choose_solver(model, args.solver, args.zoh)[0])
    if not model.hybrid:
        no_effect(args, "--event-tol", "(the stick/slip instants of hybrid friction): this model has none")
    if model.switched:
        no_effect(args, "--zoh", "(a sampled ECU): with a switched model the ECU is always sampled")
    else:
        no_effect(args, "--instantaneous", "(the power and loss columns' sampled values): the model does not "
                  "switch, its columns are instantaneous already")


def _plot(args, model, res, given, plot) -> str:
    """The --plot PNG: a switched model's waveforms (rerun keeping every sub-interval),
    else the run's signals."""
    if model.switched:
        from ..plots._pwm import plot_switched

        full = simulate(model, args.t_end, dt=args.dt, decimate=1, from_trim=args.from_trim,
                        **{n: s for n, s in given.items() if s is not None})
        return str(plot_switched(full, plot))
    from ..plots._base import plot_simulation

    return str(plot_simulation(res, plot))


def sampling_report(model, res, dt_out) -> dict:
    """``dt_out_requested`` (s, or None), ``dt_out_used`` (a switched run's whole carrier
    periods) and what the power and loss columns hold (``power_columns``)."""
    info = res.info
    return {"dt_out_requested": dt_out, "dt_out_used": info.get("dt_out", dt_out) if model.switched else dt_out,
            "power_columns": info.get("power_columns", "instantaneous")}


def energy_report(model, res) -> dict:
    """``energies_J`` (every power and loss output, :meth:`SimResult.energies`: a switched
    run's own quadratures, else the trapezoid over the samples), ``stored_energy_change_J``
    (E_stored at the end minus at the start), ``balance_residual_J`` = int P_dc -
    dE_stored - sum of the losses - int P_load and ``balance_relative`` (that over int
    P_dc); None without those outputs."""
    E = res.energies()
    out = {"energies_J": E, "stored_energy_change_J": None, "balance_residual_J": None, "balance_relative": None}
    if "E_stored" in res.outputs:
        out["stored_energy_change_J"] = float(res["E_stored"][-1] - res["E_stored"][0])
    if {"P_dc", "P_load"} <= set(E) and out["stored_energy_change_J"] is not None:
        losses = sum(E[k] for k in model.outputs_of("loss") if k in E)
        r = E["P_dc"] - out["stored_energy_change_J"] - losses - E["P_load"]
        out["balance_residual_J"] = float(r)
        out["balance_relative"] = float(r / E["P_dc"]) if E["P_dc"] else None
    return out


#: Input names as the flags that set them.
_FLAG_OF = {"x_cmd": "--x-cmd", "f_ext": "--f-ext"}


def _checked(args, model, dt_out, given) -> dict:
    """The driving signals against the envelope and the sampling, before the run,
    naming the flags."""
    flags = {n: _FLAG_OF.get(n, f"--input {n}") for n in given}
    step = {f"--dt {args.dt:g} s": args.dt} if args.solver == "rk4" or model.switched else \
        {f"--dt-out {dt_out:g} s": dt_out} if dt_out is not None else {}  # else simulate() checks its plan
    # a command far beyond the stroke, a cavity temperature no network means: refused
    bounds = model.envelope()
    limits = {"x_cmd": (COMMAND_STROKES * model.params.actuator.stroke, f"{COMMAND_STROKES:g} x the stroke")}
    limits.update({n: (bounds[n], model.input_info[n].bound.why) for n in ("T_amb",) if n in bounds})
    check_inputs(model, {n: s for n, s in given.items() if s is not None}, args.t_end, step, flags, UserError,
                 limits)
    return given


def _named_inputs(items, model, stroke, t_end) -> dict:
    """``--input NAME=SIGNAL`` flags -> {name: Signal}, each parsed with its input's kind."""
    out = {}
    for name, text in key_values(items, "--input", "NAME=SIGNAL").items():
        if name in ("x_cmd", "f_ext"):
            raise UserError(f"--input {name}: use --{name.replace('_', '-')}")
        if name not in model.input_info:
            raise UserError(f"--input '{name}': unknown input; the model's inputs are {', '.join(model.inputs)}")
        kind = model.input_info[name].kind
        try:
            out[name] = parse_signal(text.strip(), kind, bare="mm" if kind == "length" else None,
                                     stroke=stroke, duration=t_end)
        except ValueError as exc:
            raise UserError(f"--input {name}: {exc}") from None
    return out


def _rel(x) -> str:
    return "-" if x is None else f"{x:.2e} of int P_dc"


def _final(model, res) -> dict:
    """The final values, their units, and the signals a model of several actuators reports."""
    return {"final": res.final(), "units": {k: res.units().get(k, "") for k in res.final()},
            "final_signals": [n for role in _FINAL_ROLES for n in model.outputs_with(role)]}


def report(r: dict) -> None:
    f = r["final"]
    tol = ", ".join(f"{k} {v:g}" for k, v in (r["tolerance"] or {}).items())
    why = f"{r['solver_requested']}: {r['solver_reason']}; " if r["solver_requested"] == "auto" else ""
    print(f"simulated {r['t_end']} s with {r['solver']} ({why}{tol}; {r['steps']} steps) in {r['wall_time']:.3f} s "
          f"(compile {r['compile_time']:.3f} s)")
    if r["mode_switches"] is not None:
        print(f"stick/slip mode switches: {r['mode_switches']}")
    if (r["dt_out_used"] is not None and r["dt_out_requested"] is not None
            and not math.isclose(r["dt_out_used"], r["dt_out_requested"], rel_tol=1e-9)):
        print(f"--dt-out {r['dt_out_requested']:g} s rounded to {r['dt_out_used']:g} s (whole carrier periods); "
              f"power and loss columns: {r['power_columns']}")
    if r["balance_residual_J"] is not None:
        print(f"energy: int P_dc = {r['energies_J']['P_dc']:.6g} J, stored change {r['stored_energy_change_J']:.4g} J, "
              f"balance residual {r['balance_residual_J']:.3g} J ({_rel(r['balance_relative'])})")
    from ..signals import format_fixed as fixed

    if all(k in f for k in ("x_rod", "v_rod", "i_q", "F_in")):
        print(f"final: x_rod = {fixed(f['x_rod'] * 1e3, 4)} mm, v_rod = {fixed(f['v_rod'] * 1e3, 3)} mm/s, "
              f"i_q = {fixed(f['i_q'], 3)} A, F_in = {fixed(f['F_in'], 1)} N")
    else:  # a model of several actuators: the surface, the channels' forces, the fight
        print("final: " + ", ".join(f"{k} = {f[k]:.6g} {r['units'][k]}" for k in r["final_signals"]))
    for w in r["written"]:
        print(f"wrote {w}")
