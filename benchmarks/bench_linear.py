"""Benchmark: operating point, linearisation and margins against their targets.

Targets: linearisation plus all three loops' margins under 50 ms once the model is
built; ``ema margins --json`` from process start to exit under 3 s.

Usage::

    .venv/bin/python benchmarks/bench_linear.py [--repeat 20] [--json]

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
MODEL = ROOT / "models" / "cesa_ema.toml"


def _median_time(fn, repeat):
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=20)
    ap.add_argument("--cli-repeat", type=int, default=3)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)

    import ema_casadi as ema
    from ema_casadi import frequency as fr
    from ema_casadi import linearisation as lz

    load0 = os.getloadavg()[0]
    params = ema.load_parameters(MODEL)
    t0 = time.perf_counter()
    model = ema.build_model(params)
    t_build = time.perf_counter() - t0
    t0 = time.perf_counter()
    lz.jacobian_function(model)  # first use builds the cached Jacobian Function
    t_jac = time.perf_counter() - t0

    res = {
        "build_model_s": t_build,
        "jacobian_function_first_use_s": t_jac,
        "operating_point_s": _median_time(lambda: lz.operating_point(model), args.repeat),
        "operating_point_loaded_s": _median_time(lambda: lz.operating_point(model, 0.0, 30e3), args.repeat),
        "linear_model_s": _median_time(lambda: lz.linear_model(model), args.repeat),
        "loop_margins_all_s": _median_time(lambda: fr.loop_margins(model, lz.operating_point(model)), args.repeat),
    }
    res["linearise_plus_margins_s"] = _median_time(
        lambda: (lz.linear_model(model, lz.operating_point(model, 0.0, 10e3)),
                 fr.loop_margins(model, lz.operating_point(model, 0.0, 10e3))), args.repeat)
    ema_exe = Path(sys.executable).with_name("ema")
    cmd = [str(ema_exe), "margins", str(MODEL), "--json"] if ema_exe.exists() else \
        [sys.executable, "-m", "ema_casadi.cli", "margins", str(MODEL), "--json"]
    cli = []
    for _ in range(args.cli_repeat):
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, capture_output=True, cwd=ROOT)
        cli.append(time.perf_counter() - t0)
    res["cli_margins_json_s"] = statistics.median(cli)
    res["load_average_1min"] = [load0, os.getloadavg()[0]]
    res["targets"] = {"linearise_plus_margins_s": 0.050, "cli_margins_json_s": 3.0}
    if args.json:
        json.dump(res, sys.stdout, indent=1)
        print()
        return
    for k, v in res.items():
        if k.endswith("_s"):
            print(f"{k:34s} {v * 1e3:9.2f} ms")
    print(f"load average (1 min) before/after: {res['load_average_1min'][0]:.2f} / {res['load_average_1min'][1]:.2f}"
          f" on {os.cpu_count()} cores")


if __name__ == "__main__":
    main()
