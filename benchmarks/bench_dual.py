"""Benchmark: two actuators on one surface (``models/elevator_dual.toml``).

Targets: building the dual model and running ``ema margins`` on it (process start to
exit) under 10 s on 2 cores; a 1 s simulation of the dual model under 2x the time of two
single-actuator runs of the same scenario (a 5 mm step at 0.01 s, the solver the
toolkit picks: the compiled RODAS4 on both).

Usage::

    .venv/bin/python benchmarks/bench_dual.py [--repeat 5] [--json]

Reports medians. The machine's load average is printed with the results: numbers
taken while other jobs run are upper bounds.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DUAL = ROOT / "models" / "elevator_dual.toml"
SINGLE = ROOT / "models" / "cesa_ema.toml"


def _median_time(fn, repeat):
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)

    import ema_casadi as ema

    load0 = os.getloadavg()[0]
    ema_cli = [sys.executable, "-m", "ema_casadi.cli"]
    t_margins = _median_time(lambda: subprocess.run([*ema_cli, "margins", str(DUAL), "--json"], check=True,
                                                    capture_output=True), args.repeat)
    t0 = time.perf_counter()
    dual = ema.build_model(ema.load_parameters(DUAL))
    t_build = time.perf_counter() - t0
    single = ema.build_model(ema.load_parameters(SINGLE))
    step = ema.Signal.step(0.005, 0.01)
    for m in (dual, single):  # compile once: the runs below time the integration
        ema.simulate(m, 0.01, x_cmd=step)
    t_dual = _median_time(lambda: ema.simulate(dual, 1.0, x_cmd=step), args.repeat)
    t_single = _median_time(lambda: ema.simulate(single, 1.0, x_cmd=step), args.repeat)
    res = {"build_dual_model_s": t_build, "ema_margins_dual_cli_s": t_margins, "simulate_dual_1s_s": t_dual,
           "simulate_single_1s_s": t_single, "dual_over_two_singles": t_dual / (2 * t_single),
           "load_average": load0}
    if args.json:
        print(json.dumps(res, indent=1))
        return
    print(f"load average {load0:.2f}")
    print(f"build the dual model                    {t_build:8.3f} s")
    print(f"ema margins on it (process, target 10 s) {t_margins:8.3f} s")
    print(f"1 s simulation: dual {t_dual:.3f} s, single {t_single:.3f} s: dual / (2 x single) = "
          f"{t_dual / (2 * t_single):.2f} (target < 2)")


if __name__ == "__main__":
    main()
