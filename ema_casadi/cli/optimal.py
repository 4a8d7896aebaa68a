"""Optimal moves of the actuator (docs: optimal-control): the minimum-time, minimum-energy
(from the DC link) or minimum-heat (in the winding) move of the rod within the limits the
model's parts declare (the current limit, the voltage circle, the stroke, the rated rod
speed, the rated temperatures), by direct multiple shooting with IPOPT on the model's
smooth variant, or by Radau collocation where the model is stiff (under load: --method).
--through drive (default) takes the motor voltages as the control: the drive's
capability; --through ecu the rod command with the cascade in the loop: a command
profile for the real ECU. The command profile is replayed in the full model beside the
ECU's own step of the same size; --out DIR writes command.csv (readable by
ema simulate --x-cmd DIR/command.csv:x_cmd), optimum.csv, replay.csv and move.png.
--envelope instead tabulates the top rod speed against load, the largest load held and
the minimum move time over distance, at soak temperatures (--temperatures, degC, with a
thermal network: --variant thermal=lumped); --out DIR writes envelope.csv and envelope.png.
Exit status 3 (one line naming the binding limit) when no move within the limits exists.
Example: ema optimal --move 10mm --json
Example: ema optimal --move 10mm --objective energy --duration 0.3 --out opt
Example: ema optimal --envelope --variant thermal=lumped --json
"""

from __future__ import annotations

import time
from pathlib import Path

from .._util._parallel import cores
from . import UserError, add_progress, load, stage
from ._flags import NoEffect, new_output_folder, output_folder

COMMAND = "optimal"
ORDER = 14
HELP = "minimum-time, -energy or -heat moves within the drive's limits; command shaping; the envelope"
#: The files --out DIR holds.
MOVE_FILES = ("command.csv", "optimum.csv", "replay.csv", "move.png")
ENVELOPE_FILES = ("envelope.csv", "envelope.png")

_ENV = NoEffect((), "with --envelope (it runs its own moves: --distances, --loads)", lambda a: a.envelope)
_MOVE = NoEffect((), "without --envelope (it sets the envelope's grid)", lambda a: not a.envelope)


_ECU = NoEffect((), "with --through ecu (a shaped two-parameter command through the commissioned cascade)",
               lambda a: a.through == "ecu" and not a.envelope)


def _env(flag, *value):
    return (NoEffect(("--envelope", flag, *value), _ENV.why, _ENV.when),)


NO_EFFECT = {
    "--move": _env("--move", "5mm"), "--load": _env("--load", "5kN"), "--objective": _env("--objective", "energy"),
    "--duration": (NoEffect(("--duration", "0.3"), "with --objective time (the duration is what it minimises)",
                            lambda a: a.objective == "time" and not a.envelope),) + _env("--duration", "0.3"),
    "--from": _env("--from", "5mm"), "--through": _env("--through", "ecu"),
    "--intervals": (NoEffect(("--through", "ecu", "--intervals", "20"), _ECU.why, _ECU.when),),
    "--method": _env("--method", "collocation") + (NoEffect(("--through", "ecu", "--method", "collocation"), _ECU.why,
                                                            _ECU.when),),
    "--field-weakening": _env("--field-weakening") + (NoEffect(("--through", "ecu", "--field-weakening"), _ECU.why,
                                                               _ECU.when),),
    "--zoh": _env("--zoh"), "--out": (), "--envelope": (),
    "--loads": (NoEffect(("--loads", "0,10kN"), _MOVE.why, _MOVE.when),),
    "--distances": (NoEffect(("--distances", "1mm,10mm"), _MOVE.why, _MOVE.when),),
    "--temperatures": (NoEffect(("--temperatures", "20,120"), _MOVE.why, _MOVE.when),),
}


def add_arguments(p):
    add_progress(p)
    p.add_argument("--move", default="10mm", metavar="DIST", help="the move (bare numbers mm); default 10mm")
    p.add_argument("--load", default="0", metavar="FORCE",
                   help="constant rod load (bare numbers N, + pushes the rod in); default 0")
    p.add_argument("--objective", default="time",
                   help="time | energy (from the DC link) | heat (in the winding); default time")
    p.add_argument("--duration", default=None, metavar="T", help="the move's duration (s) for energy and heat")
    p.add_argument("--from", dest="start", default="0", metavar="X0", help="start position (bare numbers mm); "
                                                                          "default 0")
    p.add_argument("--through", default="drive",
                   help="drive: the motor voltages as the control (the drive's capability); ecu: the rod command "
                        "with the cascade in the loop (a command profile); default drive")
    p.add_argument("--intervals", type=int, default=None, help="shooting intervals; default 40")
    p.add_argument("--method", default="auto", help="the transcription: auto (default: multiple shooting where "
                   "intervals x RK4 substeps <= 400, else collocation: a stiff model under load), shooting, "
                   "collocation (Radau IIA of degree 3 on the same grid)")
    p.add_argument("--field-weakening", action="store_true",
                   help="allow field weakening (lift the FOC's i_d >= 0): above the commissioned drive's bound")
    p.add_argument("--zoh", action="store_true", help="replay with the sampled ECU (RK4)")
    p.add_argument("--out", default=None, metavar="DIR", help=f"write {', '.join(MOVE_FILES)} (--envelope: "
                                                             "envelope.csv, envelope.png)")
    p.add_argument("--envelope", action="store_true",
                   help="the performance envelope: top rod speed against load, largest load held, minimum move "
                        "time over distance")
    p.add_argument("--loads", default=None, help="envelope loads opposing the move (list, bare numbers N); "
                                                 "default 10 from 0 to 0.9 x the load the screw holds")
    p.add_argument("--distances", default=None, help="envelope distances (list, bare numbers mm); default 1,2,5,10,20")
    p.add_argument("--temperatures", default=None, help="envelope soak temperatures (list, degC; a thermal network); "
                                                        "default 20 and 20 K below the lowest rated thermal node")


def _quantity(text: str, kind: str, bare: str, flag: str, stroke: float) -> float:
    from ..signals import SignalError, parse_quantity

    try:
        return parse_quantity(text, kind, bare, stroke=stroke)
    except (SignalError, ValueError) as exc:
        raise UserError(f"{flag} {text}: {exc}") from None


def _request(args, params):
    from ..optimal import INTERVALS

    stroke = params.actuator.stroke  # the names (objective, through, method): checked by the API's check_request
    duration = None
    if args.duration is not None:
        from ._options import seconds

        try:
            duration = seconds(args.duration)
        except Exception as exc:  # argparse.ArgumentTypeError
            raise UserError(f"--duration: {exc}") from None
    return {"move": _quantity(args.move, "length", "mm", "--move", stroke),
            "load": _quantity(args.load, "force", "N", "--load", stroke),
            "start": _quantity(args.start, "length", "mm", "--from", stroke),
            "objective": args.objective, "duration": duration, "through": args.through,
            "intervals": INTERVALS if args.intervals is None else args.intervals,
            "field_weakening": args.field_weakening, "method": args.method}


def run(args) -> dict:
    if args.envelope:
        return run_envelope(args)
    from ..optimal import Infeasible, check_request, optimal_move

    t0 = time.perf_counter()
    params, model = load(args)
    req = _request(args, params)
    # every value checked before the solve (and before the output folder is made)
    check_request(model, req["move"], req["load"], req["objective"], req["duration"], req["start"],
                  req["through"], req["intervals"], req["method"])
    out = Path(args.out) if args.out is not None else None
    top = new_output_folder(args.out, MOVE_FILES) if out else None
    stage(args, "optimal move", 0.1, f"{req['objective']}, through {req['through']}")
    try:
        res = optimal_move(model, zoh=args.zoh, **req)
    except Infeasible as exc:
        return {"model": args.model, "request": req, "failure": f"infeasible: {exc}",
                "wall_time_s": time.perf_counter() - t0}
    stage(args, "optimal move", 1.0, "replayed")
    written = []
    if out is not None:
        with output_folder(out, top) as folder:
            written = write_move(res, folder, out)
    return {"model": args.model, "variants": model.variants, "request": req, **res.as_dict(),
            "ecu_rate_limit_m_s": params.control.v_max, "written": written, "wall_time_s": time.perf_counter() - t0}


def _list(text, kind, bare, flag, stroke):
    if text is None:
        return None
    return [_quantity(t, kind, bare, flag, stroke) for t in text.split(",")]


def run_envelope(args) -> dict:
    """``--envelope``: the table (and envelope.csv, envelope.png)."""
    import numpy as np

    from ..optimal import performance_envelope

    t0 = time.perf_counter()
    params, model = load(args)
    stroke = params.actuator.stroke
    loads = _list(args.loads, "force", "N", "--loads", stroke)
    distances = _list(args.distances, "length", "mm", "--distances", stroke)
    temps = None
    if args.temperatures is not None:
        try:
            temps = [float(t) for t in args.temperatures.split(",")]
        except ValueError:
            raise UserError(f"--temperatures {args.temperatures}: expected degC numbers, e.g. 20,120") from None
    out = Path(args.out) if args.out is not None else None
    top = new_output_folder(args.out, ENVELOPE_FILES) if out else None
    intervals = 30 if args.intervals is None else args.intervals  # 0 is refused, not the default
    env = performance_envelope(model, loads, distances, temps, intervals=intervals, jobs=cores())
    written = []
    if out is not None:
        with output_folder(out, top) as folder:
            from .._util._files import write_text

            head = ["load_N"] + [f"v_top_m_s_at_{T if T is not None else 'ref'}" for T in env.temperatures]
            rows = np.column_stack([env.loads, *(env.top_speed[T] for T in env.temperatures)])
            write_text(folder / "envelope.csv", ",".join(head) + "\n" + "".join(
                ",".join(f"{v:.10g}" for v in row) + "\n" for row in rows))
            env.plot(folder / ENVELOPE_FILES[1])
            written += [str(out / n) for n in ENVELOPE_FILES]
    return {"model": args.model, "variants": model.variants, **env.as_dict(), "written": written,
            "wall_time_s": time.perf_counter() - t0}


def write_move(res, folder: Path, shown: Path) -> list:
    """The command profile, the optimum's nodes, the replay and the figure into ``folder``
    (named as in ``shown``)."""
    import numpy as np

    from ..signals import write_series

    t, x = res.command_profile
    write_series(folder / MOVE_FILES[0], ["time", res.command], ["s", "m"], np.column_stack([t, x]))
    names, units, data = res.series()
    write_series(folder / MOVE_FILES[1], names, units, data)
    names = [MOVE_FILES[0], MOVE_FILES[1]]
    if res.replay is not None:
        res.replay.to_csv(folder / MOVE_FILES[2])
        names.append(MOVE_FILES[2])
    res.plot(folder / MOVE_FILES[3])
    names.append(MOVE_FILES[3])
    return [str(shown / n) for n in names]


def report(r: dict) -> None:
    if r.get("failure"):
        return
    if "top_speed_m_s" in r:
        _report_envelope(r)
        return
    from ..signals import format_quantity as q

    what = {"time": "minimum time", "energy": "minimum energy from the DC link", "heat": "minimum heat in the winding"}
    cost = q(r["cost"], "s") if r["objective"] == "time" else q(r["cost"], "J")
    print(f"optimal move ({what[r['objective']]}, through the {'ECU' if r['through'] == 'ecu' else 'drive'}): "
          f"{q(r['move'], 'm')} from {q(r['start'], 'm')} under {q(r['load'], 'N')} in {q(r['duration'], 's')}, "
          f"cost {cost}")
    ip = r["ipopt"]
    if r["through"] == "ecu":
        print(f"  {ip['solver']}: {ip['status']} after {ip['iterations']} runs, {ip['solve_time_s']:.2f} s; "
              f"overshoot {ip['overshoot']:.3g} x the move, back to the target at {q(ip['t_return'], 's')}")
    else:
        how = (f"{ip['intervals']} intervals x {ip['substeps']} RK4 substeps" if ip["method"] == "shooting" else
               f"{ip['intervals']} intervals, Radau IIA collocation; RK4 would need {ip['substeps']} substeps")
        print(f"  IPOPT {ip['status']} in {ip['iterations']} iterations, {ip['solve_time_s']:.2f} s ({how}); "
              f"limits the optimum runs on: {', '.join(r['binding']) or 'none'}")
    rep = r.get("replay") or {}
    if "failed" in rep:
        print(f"  replay failed: {rep['failed']}")
    elif rep:
        _report_replay(r, rep)
    for w in r["written"]:
        print(f"wrote {w}")


def _report_replay(r: dict, rep: dict) -> None:
    """The three runs side by side: the optimum (the solved problem), its replay (the
    command profile through the full model and its ECU) and the ECU's own step."""
    from ..signals import format_quantity as q

    print(f"  into the 2 % band: optimum {q(r['duration'], 's')}, replay {q(rep['settling_time_s'], 's')}, "
          f"ECU's own step {q(r['ecu_step_settling_time_s'], 's')}")
    v_max = r.get("ecu_rate_limit_m_s")
    if r["through"] == "drive" and v_max is not None and rep["settling_time_s"] > r["duration"]:
        print(f"    (the replay is later than the optimum: its command passes through the ECU, which holds the rod to "
              f"its {q(v_max, 'm/s', 3)} rate limit; the optimum drives the motor voltages directly)")
    print("  peaks against the limits: optimum = the solved move; replay = its command profile through the full "
          "model and its ECU; ECU step = the ECU's own step of the same size")
    print(f"    {'rating':16s} {'limit':>11s} {'optimum':>12s} {'replay':>11s} {'ECU step':>11s}  replay")
    for k, c in rep["ratings"].items():
        verdict = "ok" if c["within"] else "EXCEEDED" if c["role"] != "strategy" else \
            "left (the ECU's drive strategy, not a limit: its loops' own tracking)"
        m = r["margins"].get(k)
        on = "-" if m is None else "on it" if k in r["binding"] else \
            f"{100 * m:.0f} % below" if c["limit"] else "off it"
        unit, lim = c["unit"], c["limit"]
        print(f"    {k:16s} {q(lim, unit):>11s} {on:>12s} {q(c['peak'], unit, scale=lim or None):>11s} "
              f"{q(c['ecu_step_peak'], unit, scale=lim or None):>11s}  {verdict}")
    e_step = rep["ecu_step_link_energy_J"]  # None: the ECU's step ran over another window
    beside = f" (ECU step {q(e_step, 'J')})" if e_step is not None else ""
    print(f"  energy from the DC link over {q(rep['window_s'], 's')}: replay {q(rep['link_energy_J'], 'J')}{beside}")


def _report_envelope(r: dict) -> None:
    from ..signals import format_quantity as q

    print(f"performance envelope ({r['wall_time_s']:.1f} s)")
    for T, v in r["top_speed_m_s"].items():
        at = "at the parameter set's temperatures" if T == "None" else f"at {T} °C"
        print(f"  {at}: largest load held {q(r['largest_force_N'][T], 'N')}; top speed "
              + ", ".join(f"{q(s, 'm/s')} @ {q(F, 'N', 3)}" for F, s in zip(r["loads_N"], v, strict=True)))
        print("    minimum time " + ", ".join(f"{q(t, 's')} @ {q(d, 'm')}"
                                           for d, t in zip(r["distances_m"], r["min_time_s"][T], strict=True)))
