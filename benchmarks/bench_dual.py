"""Benchmark: two actuators on one surface (``models/elevator_dual.toml``).

Targets: building the dual model and running ``ema margins`` on it (process start to
exit) under 10 s on 2 cores; a 1 s simulation of the dual model under 2x the time of two
single-actuator runs of the same scenario (a 5 mm step at 0.01 s, the solver the
toolkit picks: the compiled RODAS4 on both).

Usage::

    .venv/bin/python benchmarks/bench_dual.py [--repeat 21] [--json]

The dual and the single runs alternate, so that both see the same load; each is timed
in CPU time (``time.process_time``: this process, all its threads) and in wall time.
Reports medians, the ratio dual / (2 x single) of the medians in both, the RODAS4 step
counts of both runs, and the machine's load average before and after: wall times taken
while other jobs run are upper bounds, CPU times much less so.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DUAL = ROOT / "models" / "elevator_dual.toml"
SINGLE = ROOT / "models" / "cesa_ema.toml"
COUNTS = ("steps", "rejected_steps", "f_evals", "jacobian_evals", "lu_decompositions")


def _child_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=21)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)

    import ema_casadi as ema

    load0 = os.getloadavg()[0]
    ema_cli = [sys.executable, "-m", "ema_casadi.cli"]
    margins_wall, margins_cpu = [], []
    for _ in range(min(args.repeat, 5)):  # a process each: 5 are enough for a median
        t0, c0 = time.perf_counter(), _child_cpu()
        subprocess.run([*ema_cli, "margins", str(DUAL), "--json"], check=True, capture_output=True)
        margins_wall.append(time.perf_counter() - t0)
        margins_cpu.append(_child_cpu() - c0)
    t0 = time.perf_counter()
    dual = ema.build_model(ema.load_parameters(DUAL))
    t_build = time.perf_counter() - t0
    single = ema.build_model(ema.load_parameters(SINGLE))
    step = ema.Signal.step(0.005, 0.01)
    for m in (dual, single):  # compile once: the runs below time the integration
        ema.simulate(m, 0.01, x_cmd=step)
    times = {"dual": ([], []), "single": ([], [])}
    info = {}
    for _ in range(args.repeat):
        for name, m in (("dual", dual), ("single", single)):
            t0, c0 = time.perf_counter(), time.process_time()
            res = ema.simulate(m, 1.0, x_cmd=step)
            times[name][0].append(time.perf_counter() - t0)
            times[name][1].append(time.process_time() - c0)
            info[name] = {k: res.info[k] for k in COUNTS}
    med = {name: (statistics.median(w), statistics.median(c)) for name, (w, c) in times.items()}
    res = {"build_dual_model_s": t_build, "ema_margins_dual_cli_s": statistics.median(margins_wall),
           "ema_margins_dual_cli_cpu_s": statistics.median(margins_cpu),
           "simulate_dual_1s_s": med["dual"][0], "simulate_single_1s_s": med["single"][0],
           "simulate_dual_1s_cpu_s": med["dual"][1], "simulate_single_1s_cpu_s": med["single"][1],
           "dual_over_two_singles": med["dual"][0] / (2 * med["single"][0]),
           "dual_over_two_singles_cpu": med["dual"][1] / (2 * med["single"][1]),
           "dual_counts": info["dual"], "single_counts": info["single"],
           "load_average": [load0, os.getloadavg()[0]]}
    if args.json:
        print(json.dumps(res, indent=1))
        return
    print(f"load average {load0:.2f} before, {res['load_average'][1]:.2f} after")
    print(f"build the dual model                     {t_build:8.3f} s")
    print(f"ema margins on it (process, target 10 s) {res['ema_margins_dual_cli_s']:8.3f} s wall, "
          f"{res['ema_margins_dual_cli_cpu_s']:.3f} s CPU")
    for label, k in (("CPU ", 1), ("wall", 0)):
        print(f"1 s simulation, {label}: dual {1e3 * med['dual'][k]:.2f} ms, single {1e3 * med['single'][k]:.2f} ms: "
              f"dual / (2 x single) = {med['dual'][k] / (2 * med['single'][k]):.2f} (target < 2)")
    for name in ("dual", "single"):
        print(f"RODAS4 {name:6s} " + ", ".join(f"{k} {v}" for k, v in info[name].items()))


if __name__ == "__main__":
    main()
