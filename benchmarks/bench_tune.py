"""Benchmark: gain tuning over three load cases (target: under 30 s).

The acceptance problem: every gain x 0.2 of the reference, loads 0, 15 and 30 kN,
bandwidth objective, GM >= 6 dB, PM >= 45 deg, overshoot <= 5 %, current and voltage
limits on a 0.1 mm step. Timed per run: building the Opti problem(s), IPOPT, and the
whole ``tune()`` call (which adds the independent verification before and after:
fresh linearisations, margins, python-control linear and 1 mm nonlinear steps). With
``--hessian both`` the L-BFGS variant is timed too.

Then plain ``ema tune --json`` (the reference set's one-load tune from its own gains),
as a user runs it: a fresh process each time, wall time from start to exit, imports
included (target: under 10 s), with either Hessian.

Usage::

    .venv/bin/python benchmarks/bench_tune.py [--repeat 3] [--hessian exact|limited-memory|both] [--json] [--quick]

Reports medians and the iteration counts. The machine's load average is printed with
the results: numbers taken while other jobs run are upper bounds.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
LOADS = (0.0, 15e3, 30e3)
TARGET_S = 30.0
PLAIN_TARGET_S = 10.0


def _plain(hessian: str, repeat: int) -> dict:
    """Wall times (s) of ``ema tune --json --hessian H`` in fresh processes."""
    import subprocess

    times, out = [], {}
    for _ in range(repeat):
        t0 = time.perf_counter()
        run = subprocess.run([sys.executable, "-m", "ema_casadi.cli", "tune", "--json", "--hessian", hessian],
                             capture_output=True, text=True, check=True)
        times.append(time.perf_counter() - t0)
        out = json.loads(run.stdout)
    return {"wall_s": statistics.median(times), "runs_s": times, "status": out["status"],
            "iterations": out["iterations"], "fallback": out.get("fallback")}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--hessian", choices=("exact", "limited-memory", "both"), default="both")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--quick", action="store_true", help="one run, exact Hessian only (run_all.py --quick)")
    args = ap.parse_args(argv)
    if args.quick:
        args.repeat, args.hessian = 1, "exact"

    t_import = time.perf_counter()
    import control  # noqa: F401 - the verification's; its import is timed here, once, not per run

    import ema_casadi as ema
    from ema_casadi import tuning as T

    t_import = time.perf_counter() - t_import
    params = ema.load_parameters(ROOT / "models" / "cesa_ema.toml")
    model = ema.build_model(params)
    start = T.scaled_gains(params, 0.2, T.default_free(model))
    hessians = ("exact", "limited-memory") if args.hessian == "both" else (args.hessian,)
    rows = {}
    for hess in hessians:
        runs = []
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            res = T.tune(params, model=model, loads=LOADS, start=start, hessian=hess)
            runs.append({"total_s": time.perf_counter() - t0, "solve_s": res.solve_time,
                         "build_s": res.build_time, "iterations": res.iterations, "rounds": res.rounds,
                         "status": res.status, "success": res.success, "bandwidth_hz": res.objective_value})
        med = {k: statistics.median(r[k] for r in runs) for k in ("total_s", "solve_s", "build_s")}
        rows[hess] = {"median": med, "runs": runs}
    plain = {h: _plain(h, args.repeat) for h in hessians}
    load = os.getloadavg()
    result = {"import_s": t_import, "load_average": load, "target_s": TARGET_S, "results": rows,
              "plain_ema_tune": plain, "plain_target_s": PLAIN_TARGET_S}
    if args.json:
        json.dump(result, sys.stdout, indent=1)
        print()
        return 0
    print(f"three-load tuning from 0.2 x reference gains, {args.repeat} runs each "
          f"(load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} on {os.cpu_count()} cores)")
    print("\n| Hessian | IPOPT status | iterations (rounds) | build (s) | IPOPT (s) | tune() total (s) "
          "| bandwidth (Hz) | < 30 s |")
    print("|---|---|---|---|---|---|---|---|")
    for hess, r in rows.items():
        m, run = r["median"], r["runs"][-1]
        print(f"| {hess} | {run['status']} | {run['iterations']} ({run['rounds']}) | {m['build_s']:.2f} | "
              f"{m['solve_s']:.2f} | {m['total_s']:.2f} | {run['bandwidth_hz']:.2f} | "
              f"{'yes' if m['total_s'] < TARGET_S else 'NO'} |")
    print(f"\nplain `ema tune --json` (fresh process, imports included), median of {args.repeat}:")
    print("\n| Hessian | IPOPT status | iterations | wall (s) | < 10 s |")
    print("|---|---|---|---|---|")
    for hess, r in plain.items():
        print(f"| {hess} | {r['status']} | {r['iterations']} | {r['wall_s']:.2f} | "
              f"{'yes' if r['wall_s'] < PLAIN_TARGET_S else 'NO'} |")
    print(f"\nimport of ema_casadi + python-control (once per process, not included): {t_import:.2f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
