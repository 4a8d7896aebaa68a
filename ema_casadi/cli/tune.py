"""Tune the cascade's gains by nonlinear optimisation (CasADi Opti + IPOPT).

The free gains (--free) are chosen to maximise the closed-loop bandwidth or minimise
the step tracking error (--objective), subject in every load case (--loads) to: gain
and phase margins on the position, velocity and current loops (--gm/--pm, or a
sensitivity peak --ms), overshoot (--overshoot), current and voltage within their
limits on a step of --step, optional minimum bandwidth and eigenvalue bound; and the
cascade's own requirements: each loop with its outer loops open unconditionally stable
with the same margins, each inner loop's crossover at least --separation times the
next outer one's (default 3), and the current command's response to position-sensor
noise bounded (--sensor-noise, --command-noise: by default 1 um may move it by at most
0.5 % of I_max at any frequency). The default objective maximises the worst-case -3 dB
bandwidth under all of these, with a small penalty on moving the gains from the file's.
The
result is verified independently (fresh linearisation, the toolkit's margins, a
nonlinear step simulation) and written as a parameter file (--out). From start gains
that already meet every requirement the result is never worse than the start: should
IPOPT fail there, the best verified iterate (or the start itself) is returned, and
the first line of the report says so.
Example: ema tune --loads 0,15kN,30kN --gm 6 --pm 45 --overshoot 5 --out tuned.toml --plot-dir tune_plots
"""

from __future__ import annotations

import math
from pathlib import Path

from .._util._files import atomic_dir
from ..signals import SignalError, parse_quantity
from . import UserError, add_progress, check_output_dir, check_output_path, load, stage
from ._flags import NoEffect

#: The files --plot-dir receives (the folder is replaced whole: it may hold only these).
PLOT_FILES = ("tune_bode.png", "tune_step.png", "tune_cascade.png")

COMMAND = "tune"
ORDER = 7
HELP = "tune the loop gains by IPOPT (margins, overshoot, limits; several load cases)"


_MS = NoEffect((), "with --ms (the sensitivity peak sets the margins every loop must reach)",
               lambda a: a.ms is not None)
#: Each flag -> the combinations where it has no effect (refused; docs: cli).
NO_EFFECT = {"--free": (), "--loads": (), "--objective": (), "--ms": (), "--overshoot": (), "--bandwidth-min": (),
             "--sigma": (), "--step": (), "--rate-ratio": (), "--separation": (), "--command-noise": (),
             "--start-scale": (), "--hessian": (), "--max-iter": (), "--sim-step": (), "--out": (), "--plot-dir": (),
             "--gm": (NoEffect(("--ms", "1.5", "--gm", "8"), _MS.why, _MS.when),),
             "--pm": (NoEffect(("--ms", "1.5", "--pm", "50"), _MS.why, _MS.when),),
             "--sensor-noise": (NoEffect(("--command-noise", "0", "--sensor-noise", "2um"), "with --command-noise 0 "
                                         "(the noise bound is off)", lambda a: a.command_noise == 0),)}

def add_arguments(p):
    add_progress(p)
    from ..tuning import GAINS, OBJECTIVES

    p.add_argument("--free", default=None, metavar="G1,G2,...",
                   help=f"gains to tune, comma-separated from {', '.join(GAINS)}; default all that act "
                        "(K_i_x only with controller=PI)")
    p.add_argument("--loads", default="0", metavar="F1,F2,...",
                   help="load cases f_ext, comma-separated: 15kN, 500N (a bare number is N); default 0")
    p.add_argument("--objective", choices=OBJECTIVES, default="bandwidth",
                   help="bandwidth (maximise the worst-case -3 dB frequency, default) or tracking "
                        "(minimise the step's integrated squared error)")
    p.add_argument("--gm", type=float, default=6.0, metavar="DB", help="gain margin of every loop (dB); default 6")
    p.add_argument("--pm", type=float, default=45.0, metavar="DEG", help="phase margin of every loop (deg); default 45")
    p.add_argument("--ms", type=float, default=None, metavar="MS",
                   help="instead of --gm/--pm: sensitivity peak |1/(1+L)| <= MS on every loop")
    p.add_argument("--overshoot", type=float, default=5.0, metavar="PCT", help="step overshoot limit (%%); default 5")
    p.add_argument("--bandwidth-min", type=float, default=None, metavar="HZ",
                   help="closed-loop x_rod/x_cmd at least -3 dB up to HZ")
    p.add_argument("--sigma", type=float, default=0.0, metavar="PER_S",
                   help="closed-loop eigenvalues left of -SIGMA (1/s); default 0")
    p.add_argument("--step", default="0.1mm", metavar="LENGTH",
                   help="step the loops must follow inside the current and voltage limits: 0.1mm, "
                        "0.5%% (of the stroke), a bare number is mm; default 0.1mm")
    p.add_argument("--rate-ratio", type=float, default=10.0, metavar="R",
                   help="keep each loop's gain below 1 above its ECU sample rate / R (the linear model "
                        "has no sample delay); 0 switches it off; default 10")
    p.add_argument("--separation", type=float, default=3.0, metavar="RATIO",
                   help="each inner loop's gain crossover (outer loops open) at least RATIO times the next "
                        "outer loop's; 0 switches it off; default 3")
    p.add_argument("--sensor-noise", default="1um", metavar="LENGTH",
                   help="position-sensor noise amplitude the current command must not amplify beyond "
                        "--command-noise (a bare number is mm); default 1um")
    p.add_argument("--command-noise", type=float, default=0.5, metavar="PCT",
                   help="largest current-command amplitude --sensor-noise may cause at any frequency (%% of "
                        "I_max); 0 switches the bound off; default 0.5")
    p.add_argument("--start-scale", type=float, default=1.0, metavar="FACTOR",
                   help="start from FACTOR times the file's gains (T_i_w kept); default 1")
    p.add_argument("--hessian", choices=("exact", "limited-memory"), default="limited-memory",
                   help="IPOPT Hessian: exact (AD, default) or limited-memory (L-BFGS)")
    p.add_argument("--max-iter", type=int, default=200, help="IPOPT iteration limit; default 200")
    p.add_argument("--sim-step", default="1mm", metavar="LENGTH",
                   help="nonlinear step simulated before and after (0 skips it); default 1mm")
    p.add_argument("--out", default=None, metavar="FILE.toml", help="parameter file with the tuned gains")
    p.add_argument("--plot-dir", default=None, metavar="DIR",
                   help="write tune_bode.png, tune_step.png and tune_cascade.png (before/after) into the "
                        "folder DIR, assembled beside it and moved into place; an existing DIR is replaced "
                        "whole (refused if it holds other files)")


def _length(text, flag, stroke):
    try:
        return parse_quantity(str(text), "length", "mm", stroke=stroke)
    except SignalError as exc:
        raise UserError(f"{flag} {exc}") from None


def _loads(text) -> list[float]:
    out = []
    for part in str(text).split(","):
        if not part.strip():
            raise UserError(f"--loads '{text}': empty entry; expected forces like 0,15kN,30kN")
        try:
            out.append(parse_quantity(part, "force", "N"))
        except SignalError as exc:
            raise UserError(f"--loads {exc}") from None
    return out


def run(args) -> dict:
    from ..tuning import Requirements, default_free, plot_tuning, scaled_gains, tune

    out = check_output_path(args.out, (".toml",), "--out")
    plot_dir = check_output_dir(args.plot_dir, PLOT_FILES, "--plot-dir")
    for flag, val, ok, what in (
        ("--gm", args.gm, args.gm > 0, "a positive number of dB"),
        ("--pm", args.pm, 0 < args.pm < 90, "between 0 and 90 deg"),
        ("--overshoot", args.overshoot, args.overshoot >= 0, "a non-negative percentage"),
        ("--sigma", args.sigma, args.sigma >= 0, "a non-negative rate (1/s)"),
        ("--start-scale", args.start_scale, args.start_scale > 0, "positive"),
        ("--rate-ratio", args.rate_ratio, args.rate_ratio == 0 or args.rate_ratio >= 1, "0 (off) or at least 1"),
        ("--separation", args.separation, args.separation == 0 or args.separation >= 1, "0 (off) or at least 1"),
        ("--command-noise", args.command_noise, args.command_noise >= 0, "a non-negative percentage"),
    ):
        if not (math.isfinite(val) and ok):
            raise UserError(f"{flag} must be {what}, got {val:g}")
    if args.ms is not None and not (math.isfinite(args.ms) and args.ms > 1):
        raise UserError(f"--ms must be above 1, got {args.ms:g}")
    if args.bandwidth_min is not None and not (math.isfinite(args.bandwidth_min) and args.bandwidth_min > 0):
        raise UserError(f"--bandwidth-min must be a positive frequency (Hz), got {args.bandwidth_min:g}")
    if args.max_iter < 1:
        raise UserError(f"--max-iter must be at least 1, got {args.max_iter}")
    loads = _loads(args.loads)
    params, model = load(args)
    stroke = params.actuator.stroke
    step = _length(args.step, "--step", stroke)
    if not step > 0:
        raise UserError(f"--step must be a positive length, got {args.step}")
    sim_step = _length(args.sim_step, "--sim-step", stroke)
    sensor_noise = _length(args.sensor_noise, "--sensor-noise", stroke)
    if not sensor_noise > 0:
        raise UserError(f"--sensor-noise must be a positive length, got {args.sensor_noise}")
    if args.free is None:
        free = default_free(model)
    else:
        free = tuple(g.strip() for g in args.free.split(",") if g.strip())
    req = Requirements(gm_db=args.gm, pm_deg=args.pm, ms=args.ms, overshoot=args.overshoot / 100,
                       bandwidth_min_hz=args.bandwidth_min, sigma=args.sigma, step=step,
                       rate_ratio=args.rate_ratio, separation=args.separation, sensor_noise=sensor_noise,
                       command_noise=args.command_noise / 100)
    start = scaled_gains(params, args.start_scale, free) if args.start_scale != 1.0 else None
    stage(args, "tune", 0.0, f"IPOPT on {len(loads)} load case(s), then the verification")
    res = tune(params, model=model, free=free, loads=loads, objective=args.objective, requirements=req,
               start=start, max_iter=args.max_iter, hessian=args.hessian, verify_step=sim_step)
    stage(args, "tune", 0.9 if plot_dir is not None else 1.0, "plots" if plot_dir is not None else "done")
    if not res.success:
        raise UserError(res.message)
    written = []
    if out is not None:
        written.append(str(res.write(out)))
    if plot_dir is not None:
        before = params.replace(**res.gains_before)
        with atomic_dir(plot_dir) as tmp:
            written.extend(str(plot_dir / Path(w).name) for w in plot_tuning(res, model, before, tmp))
        stage(args, "tune", 1.0, "done")
    r = res.to_dict()
    for key in ("before", "after"):
        nl = r[key].get("nonlinear_step")
        if nl:
            r[key]["nonlinear_step"] = {k: v for k, v in nl.items() if k not in ("t", "x_rod", "i_q")}
    r.update(model=args.model, written=written)
    return r


def _fmt(v, spec):
    return "-" if v is None else ("inf" if isinstance(v, float) and math.isinf(v) else format(v, spec))


def _margin_text(m: dict) -> str:
    from ..frequency import margin_text

    return margin_text(m)


def report(r: dict) -> None:
    req = r["requirements"]
    if req["ms"] is not None:
        bound = f"Ms <= {req['ms']:g}"
    else:
        bound = f"GM >= {req['gm_db']:g} dB, PM >= {req['pm_deg']:g} deg"
    print(f"{r['message']}")
    print(f"objective {r['objective']}: {r['objective_value']:.4g}{' Hz' if r['objective'] == 'bandwidth' else ''}; "
          f"IPOPT {r['status']}, {r['iterations']} iterations in {r['rounds']} solve(s), "
          f"{r['solve_time_s']:.2f} s (build {r['build_time_s']:.2f} s)")
    print(f"requirements: {bound} (loop-at-a-time, and unconditionally with the outer loops open), "
          f"separation >= {req['separation']:g}, overshoot <= {100 * req['overshoot']:g} %, limits on a "
          f"{req['step'] * 1e3:g} mm step, {req['sensor_noise'] * 1e6:g} µm sensor noise -> <= "
          f"{100 * req['command_noise']:g} % I_max; loads {', '.join(f'{f / 1e3:g} kN' for f in r['loads_N'])}")
    if r["active"]:
        from ..tuning import Requirements, describe_constraint

        rq = Requirements(**req)
        print("limited by: " + "; ".join(dict.fromkeys(describe_constraint(a, rq) for a in r["active"])))
    from ..model.params import Parameters
    from ..signals import unit_text

    units = Parameters.units()
    print(f"  {'gain':6s} {'unit':>10s} {'before':>12s} {'after':>12s}")
    for g, v in r["gains_after"].items():
        print(f"  {g:6s} {unit_text(units.get(g, '1')):>10s} {r['gains_before'][g]:12.5g} {v:12.5g}")
    for key in ("before", "after"):
        v = r[key]
        down = float(v["worst"].get("gm_down_db", math.inf))
        grm = f", gain-reduction margin {down:.2f} dB" if math.isfinite(down) else ""
        print(f"{key}: worst GM {_fmt(float(v['worst']['gm_db']), '.2f')} dB{grm}, PM {v['worst']['pm_deg']:.2f} deg, "
              f"bandwidth {v['worst']['bandwidth_hz']:.3g} Hz")
        for label, d in v["loads"].items():
            loops = "; ".join(f"{n} {_margin_text(m)}" for n, m in d["loops"].items())
            print(f"  {label:>7s} loop-at-a-time: {loops}")
            c = d["outer_open"]
            fc = ", ".join(f"{n} {'/'.join(f'{f:.3g}' for f in m['gain_crossovers_hz']) or '-'} Hz"
                           for n, m in c["loops"].items())
            sep = ", ".join(f"{n} {x:.3g}x" for n, x in c["separation"].items())
            print(f"  {'':>7s} outer loops open: " + "; ".join(f"{n} {_margin_text(m)}" for n, m in c["loops"].items()))
            noise = c["noise_gain_A_per_m"]
            print(f"  {'':>7s} crossovers {fc}; separation {sep}"
                  + (f"; noise gain {noise:.3g} A/m" if noise is not None else ""))
            st = d["step"]
            print(f"  {'':>7s} step overshoot {100 * st['overshoot']:.2f} %, "
                  f"settles {_fmt(1e3 * st['settling_time_s'], '.1f')} ms, peaks {st['i_q_peak_A']:.3g} A, "
                  f"{st['v_dq_peak_V']:.4g} V")
        nl = v.get("nonlinear_step")
        if nl:
            print(f"  nonlinear {nl['amp_m'] * 1e3:g} mm step: overshoot {100 * nl['overshoot']:.2f} %, "
                  f"settles (2 %) in {_fmt(1e3 * nl['settling_time_s'], '.1f')} ms")
    for w in r["written"]:
        print(f"wrote {w}")
