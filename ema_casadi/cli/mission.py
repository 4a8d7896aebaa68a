"""A flight mission through the thermal network (docs: missions): temperatures, losses and
energy per part and per segment, peaks against the limits stated in the mission file.

MISSION.toml holds [[segment]] tables (duration, x_cmd, f_ext, T_amb) run back to back
on the full model (thermal = lumped, hybrid friction, iron loss on; compiled RK4 at
--dt); the format is in the docs (missions) and in models/mission_regional.toml.
MODEL.toml comes first, MISSION.toml second (or by --mission); without them the
packaged reference set and mission run. A single file that is a mission is refused
(name it with --mission). Writes OUT/<mission>.csv (1 s rows: time, then a Unit: row,
temperatures in degC, mean losses in W; the layout of every time series, so
--x-cmd OUT/<mission>.csv:x_cmd replays it), OUT/<mission>.png (temperatures and
losses, segments shaded) and OUT/<mission>_summary.json; OUT defaults to out/mission.
--from-trim starts at the operating point of the first segment's values.
Exit status: 2 for a mistake in a file or flag, 3 when the run leaves the physical
envelope (rod beyond the stroke, current beyond its limit, non-finite state).
Example: ema mission models/cesa_ema.toml models/mission_regional.toml --out out/mission
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from .._util._resources import REFERENCE_MISSION
from ..mission import FAST_DT
from . import UserError, add_progress, jsonable, progress_of, second_file
from ._flags import NoEffect, new_output_folder, output_folder
from ._options import seconds

COMMAND = "mission"
#: The mission run without a MISSION.toml (packaged): ~20 minutes of a regional-jet flight.
DEFAULT_MISSION = REFERENCE_MISSION
#: The output folder without --out: a folder of its own, beside the demo's files in out/.
DEFAULT_OUT = "out/mission"
ORDER = 9
HELP = "flight mission: temperatures, losses, energy per part and segment, peaks vs limits"


#: Each flag -> the combinations where it has no effect (refused; docs: cli).
NO_EFFECT = {"--mission": (), "--out": (), "--from-trim": (), "--fast": (), "--dt-out": (), "--csv-dt": (),
             "--dt": (NoEffect(("--fast", "--dt", "1e-4"), "with --fast (it sets the step): give --fast or --dt, "
                               "not both", lambda a: a.fast),)}

def add_arguments(p):
    p.add_argument("mission", metavar="MISSION.toml", nargs="?", default=None,
                   help=f"mission file (segments, limits), after MODEL.toml; default: the packaged {DEFAULT_MISSION}")
    p.add_argument("--mission", dest="mission_file", default=None, metavar="MISSION.toml",
                   help="the mission file by name (with or without MODEL.toml)")
    p.add_argument("--out", default=DEFAULT_OUT, metavar="DIR",
                   help="folder for <mission>.csv, <mission>.png and <mission>_summary.json (created with its "
                        f"parents); default {DEFAULT_OUT}")
    p.add_argument("--from-trim", action="store_true",
                   help="start at the trimmed operating point of the first segment's command and load (default: "
                        "at rest, all states zero)")
    p.add_argument("--dt", type=seconds, default=None,
                   help="RK4 step (s); default the largest step at most 1e-4 (the hybrid friction's) inside RK4's "
                        "stability limit at the mission's largest load, dividing --dt-out")
    p.add_argument("--fast", action="store_true",
                   help=f"the fast path: the same model at {FAST_DT:g} s, about twice as fast (worst temperature "
                        "difference to the full model 0.16 K on models/mission_regional.toml; docs: missions)")
    p.add_argument("--dt-out", type=seconds, default=0.01,
                   help="spacing of the kept samples the energies are integrated from (s); default 0.01")
    p.add_argument("--csv-dt", type=seconds, default=1.0, help="row spacing of the CSV (s); default 1")
    add_progress(p)


def _check(args) -> Path:
    if args.fast and args.dt is not None:
        raise UserError("--fast sets the step; give --fast or --dt, not both")
    args.dt = FAST_DT if args.fast else args.dt  # None: run_mission's, inside RK4's stability limit
    for flag, val in (("--dt", args.dt), ("--dt-out", args.dt_out), ("--csv-dt", args.csv_dt)):
        if val is not None and not (math.isfinite(val) and val > 0):
            raise UserError(f"{flag} must be a positive number of seconds, got {val}")
    k = args.dt_out / (args.dt or args.dt_out)
    if round(k) < 1 or abs(k - round(k)) > 1e-9 * k:
        raise UserError(f"--dt-out {args.dt_out:g} s must be a whole multiple of the step --dt {args.dt:g} s")
    if args.csv_dt < args.dt_out:
        raise UserError(f"--csv-dt ({args.csv_dt} s) must not be shorter than --dt-out ({args.dt_out} s)")
    if not args.out.strip():
        raise UserError("--out: empty path; name the output folder")
    out = Path(args.out)
    for folder in (out, *out.parents):
        if folder.exists() and not folder.is_dir():
            raise UserError(f"--out {out}: {folder} exists and is not a folder")
    return out


def run(args) -> dict:
    from ..mission import load_mission, run_mission
    from ..model.params import load_parameters

    out = _check(args)
    args.mission = second_file(args, args.mission, args.mission_file, flag="--mission", what="mission",
                               key="segment", default=DEFAULT_MISSION)
    from ..model.components import validate_variants

    validate_variants(dict(args.variant), "--variant")
    stem = Path(args.mission).stem
    names = {"csv": f"{stem}.csv", "png": f"{stem}.png", "json": f"{stem}_summary.json"}
    paths = {k: out / n for k, n in names.items()}
    top = new_output_folder(out, names.values())  # the outputs checked before any work
    params = load_parameters(args.model)
    mission = load_mission(args.mission, params)
    res = run_mission(params, mission, dict(args.variant), dt=args.dt, dt_out=args.dt_out,
                      progress=progress_of(args), from_trim=args.from_trim)
    from .._util._files import write_text

    summary = res.summary()
    summary["written"] = [str(p) for p in paths.values()]
    with output_folder(out, top) as folder:  # whole, or not at all
        res.to_csv(folder / names["csv"], dt=args.csv_dt)
        res.plot(folder / names["png"])
        write_text(folder / names["json"], json.dumps(jsonable(summary), indent=1) + "\n")
    return summary


def report(r: dict) -> None:
    run = r["run"]
    print(f"{r['mission']}: {r['duration_s']:.0f} s of mission in {run['wall_time']:.1f} s "
          + (f"({run['steps']} carrier periods of the switched bridge, RK4 at most {run['dt']:g} s per "
             f"sub-interval, " if run.get("switched") else f"({run['steps']} RK4 steps of {run['dt']:g} s, ")
          + f"{run['mode_switches']} stick/slip switches)")
    print("peak temperatures (°C):")
    for n, p in r["peaks"].items():
        state = "ok" if p["ok"] else "EXCEEDED"
        print(f"  {n:5s} {p['node']:9s} {p['peak_degC']:7.1f} at {p['t_peak_s']:6.0f} s ({p['segment']}), "
              f"limit {p['limit_degC']:g}: {state} (margin {p['margin_K']:.1f} K)")
    parts = list(r["energy_by_part_J"])
    print(f"{'segment':18s} {'s':>5s} {'T_amb °C':>11s} {'T_w °C end/peak':>15s} "
          + " ".join(f"{p + ' J':>10s}" for p in parts) + f" {'in J':>9s}")
    for s in r["segments"]:
        ta = s["T_amb_degC"]
        tw = f"{s['temperature_end_degC']['T_w']:.1f}/{s['temperature_peak_degC']['T_w']:.1f}"
        print(f"{s['name'][:18]:18s} {s['duration_s']:5.0f} {ta['min']:5.0f}..{ta['max']:<4.0f} {tw:>15s} "
              + " ".join(f"{s['energy_by_part_J'][p]:10.0f}" for p in parts) + f" {s['energy_J']['P_dc']:9.0f}")
    e = r["energy_J"]
    print(f"{'total':18s} {r['duration_s']:5.0f} {'':11s} {'':15s} "
          + " ".join(f"{r['energy_by_part_J'][p]:10.0f}" for p in parts) + f" {e['P_dc']:9.0f}")
    hb = r["heat_balance"]
    print(f"heat: losses {hb['losses_J']:.0f} J = stored {hb['stored_heat_J']:.0f} J + to ambient "
          f"{hb['heat_to_ambient_J']:.0f} J (residual {100 * hb['relative_residual']:+.3f} %)")
    print("limits: " + ("all held" if r["limits_ok"] else "EXCEEDED"))
    for w in r.get("written", []):
        print(f"wrote {w}")
