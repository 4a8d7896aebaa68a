"""Nonlinear frequency response by sine stream (like Simulink's frestimate).

For every load, amplitude and frequency the nonlinear model follows
x_cmd = A sin(2 pi f t) until the first harmonic of x_rod has settled (two successive
periods agree within --tol-db and --tol-deg, allowing for the transient still to
come); gain and phase of x_rod/x_cmd, the harmonic distortion and the first harmonic
of the motor current i_q are reported per point.

AMPLITUDES: comma list, 0.5% (of the 75 mm stroke), 0.5mm, 250um; a bare number is mm.
FREQS: comma list 0.1,1,5 or a log-spaced range F0-F1:N (0.1-30:40); Hz.
LOADS: comma list 0,10kN,30kN; a bare number is N (positive pushes the rod in); a
pulling load may follow its flag: --loads -30kN,0.
Grids above 100000 points (or 1e7 periods in the worst case, points x --max-periods)
are refused with the estimate.
The points go to --jobs local workers (processes, or threads with --threads), longest
first by an estimated cost, or to a Dask scheduler (--scheduler); the table is the same
to the last digit whichever runs them.
Every point has a status (converged, not_converged, failed) and a reason; a failed
point (it left the physical envelope, went non-finite or its integrator gave up) has
no values and makes the command exit with status 3 after writing the whole table.
Example: ema freqresp --amplitudes 0.5%,10% --freqs 0.1-30:40 --out fr.csv --plot fr.png
"""

from __future__ import annotations

import math

import numpy as np

from ..sinestream import check_grid, parse_amplitudes, parse_freqs, parse_loads, plot_bode, sine_stream
from . import UserError, add_progress, check_output_path, load, progress_of
from ._flags import NoEffect

COMMAND = "freqresp"
ORDER = 6
HELP = "nonlinear frequency response (sine stream): gain, phase, distortion per point"


#: Each flag -> the combinations where it has no effect (refused; docs: cli).
NO_EFFECT = {"--amplitudes": (), "--freqs": (), "--loads": (), "--scheduler": (), "--max-periods": (), "--tol-db": (),
             "--tol-deg": (), "--out": (), "--plot": (),
             "--jobs": (NoEffect(("--scheduler", "tcp://localhost:8786", "--jobs", "2"), "with --scheduler (the "
                                 "cluster's workers run the points)", lambda a: a.scheduler is not None),),
             "--threads": (NoEffect(("--scheduler", "tcp://localhost:8786", "--threads"), "with --scheduler (the "
                                    "cluster's workers run the points)", lambda a: a.scheduler is not None),)}

def add_arguments(p):
    p.add_argument("--amplitudes", default="0.5%,1%,2%,5%,10%", metavar="LIST",
                   help="command amplitudes (bare numbers in mm, %% of the stroke); default 0.5%%,1%%,2%%,5%%,10%%")
    p.add_argument("--freqs", default="0.1-30:40", metavar="LIST|F0-F1:N",
                   help="frequencies in Hz, a list or a log-spaced range; default 0.1-30:40")
    p.add_argument("--loads", default="0", metavar="LIST",
                   help="constant external forces (bare numbers in N); default 0")
    p.add_argument("--jobs", type=int, default=None, metavar="N",
                   help="local workers (processes; this process is one of them); default: all cores")
    p.add_argument("--threads", action="store_true", help="local workers are threads (default: processes)")
    p.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT",
                   help="run on a Dask distributed scheduler instead (needs ema_casadi[dask] here and on the workers)")
    p.add_argument("--max-periods", type=int, default=60, metavar="N",
                   help="periods after which a point that has not settled is reported as such; default 60")
    p.add_argument("--tol-db", type=float, default=0.01, help="settling tolerance on the gain (dB); default 0.01")
    p.add_argument("--tol-deg", type=float, default=0.1, help="settling tolerance on the phase (deg); default 0.1")
    p.add_argument("--out", default=None, metavar="FILE.csv",
                   help="write one row per point: variant, load_N, amplitude_m, freq_Hz, gain_db, phase_deg, ...")
    p.add_argument("--plot", default=None, metavar="FILE.png", help="Bode plot, one line per load and amplitude")
    add_progress(p)


def run(args) -> dict:
    out = check_output_path(args.out, (".csv",), "--out")
    plot = check_output_path(args.plot, (".png",), "--plot")
    if args.jobs is not None and args.jobs < 1:
        raise UserError(f"--jobs must be a positive integer, got {args.jobs}")
    if args.max_periods < 3:
        raise UserError(f"--max-periods must be at least 3, got {args.max_periods}")
    for flag, val in (("--tol-db", args.tol_db), ("--tol-deg", args.tol_deg)):
        if not (math.isfinite(val) and val > 0):
            raise UserError(f"{flag} must be a positive number, got {val}")
    if args.scheduler is not None and "://" not in args.scheduler:
        raise UserError(f"--scheduler {args.scheduler}: expected an address like tcp://host:8786")
    params, model = load(args)
    amplitudes = parse_amplitudes(args.amplitudes, params.actuator.stroke)
    freqs = parse_freqs(args.freqs)
    loads = parse_loads(args.loads)
    check_grid({"--loads": len(loads), "--amplitudes": len(amplitudes), "--freqs": len(np.unique(freqs))},
               args.max_periods, args.jobs or 1, "--max-periods")
    progress = progress_of(args)
    resp = sine_stream(params, amplitudes, freqs, loads, variants=model.variants, jobs=args.jobs,
                       backend="threads" if args.threads else "processes", scheduler=args.scheduler,
                       max_periods=args.max_periods, tol_db=args.tol_db,
                       tol_deg=args.tol_deg, progress=progress)
    written = []
    if out is not None:
        written.append(str(resp.to_csv(out)))
    if plot is not None:
        written.append(str(plot_bode(resp, plot, stroke=params.actuator.stroke,
                                     title="sine stream x_rod/x_cmd")))
    points = [{k: v for k, v in r.items() if k != "variant"} for r in resp.rows()]
    return {
        "model": args.model,
        "variants": model.variants,
        "axes": {k: v for k, v in resp.to_dict()["axes"].items() if k != "variant"},
        "units": {"load_N": "N", "amplitude_m": "m", "freq_Hz": "Hz", **resp.to_dict()["units"]},
        "points": points,
        "not_converged": resp.info["not_converged"],
        "failed": resp.info["failed"],
        "failure": resp.failure(),
        "wall_time": resp.info["wall_time"],
        "simulated_time": resp.info["simulated_time"],
        "periods_total": resp.info["periods_total"],
        "jobs": resp.info["jobs"],
        "backend": resp.info["backend"],
        "scheduler": resp.info["scheduler"],
        "written": written,
    }


def report(r: dict) -> None:
    amps = r["axes"]["amplitude"]
    table = {(p["load_N"], p["amplitude_m"], p["freq_Hz"]): p for p in r["points"]}
    for f_ext in r["axes"]["load"]:
        print(f"load {f_ext / 1e3:g} kN: gain (dB) / phase (deg) of x_rod/x_cmd")
        print(f"{'f (Hz)':>9s} " + " ".join(f"{a * 1e3:>16.4g}mm" for a in amps))
        for f in r["axes"]["frequency"]:
            cells = []
            for a in amps:
                pt = table[f_ext, a, f]
                mark = " " if pt["converged"] else ("!" if pt.get("status") == "failed" else "*")
                cells.append(f"{pt['gain_db']:8.2f} /{pt['phase_deg']:7.1f}{mark}")
            print(f"{f:9.3g} " + " ".join(f"{c:>18s}" for c in cells))
    bad = r["failed"]
    n = r["not_converged"] - bad  # failed points are not converged either
    print(f"{len(r['points'])} points, {r['periods_total']} periods ({r['simulated_time']:.1f} s simulated) "
          f"in {r['wall_time']:.2f} s" + (f"; {n} not settled (*)" if n else "")
          + (f"; {bad} failed (!)" if bad else ""))
    for w in r["written"]:
        print(f"wrote {w}")
