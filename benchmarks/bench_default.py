"""Benchmark: the default ``ema.simulate(model, 1.0, x_cmd, f_ext)`` (solver "auto", the
default sample spacing) on the reference scenario against every solver at its fastest
setting that keeps the rod within 0.1 um of a tight CVODES reference.

Scenario: the reference set (pmsm, elastic screw, smooth friction, ideal inverter), 1 s;
x_cmd = 1 mm step at 0.01 s + 0.375 mm 1 Hz sine from 0.5 s; f_ext = 30 kN from t = 0.
Reference: CVODES at rtol 1e-10, atol 1e-13. Each solver is run on a short ladder of
settings (coarse to fine) and kept at the first that meets 0.1 um; all runs keep the
same samples (every 1e-4 s, the default) so the output costs the same. Wall times are
medians of repeated runs after a first run that compiles (or loads) the code; the
ratio "default / fastest" is measured in one run, alternating the two, 15 rounds.

Usage: python benchmarks/bench_default.py
"""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from _timing import timed  # noqa: E402

import ema_casadi as ema  # noqa: E402
from ema_casadi import Signal  # noqa: E402

T_END = 1.0
TOL = 0.1e-6  # m
X_CMD = Signal.step(1e-3, 0.01) + Signal.sine(0.375e-3, 1.0, 0.5)
F_EXT = 30e3


def main():
    model = ema.build_model(ema.load_parameters())
    ref = ema.simulate(model, T_END, X_CMD, F_EXT, solver="cvodes", rtol=1e-10, atol=1e-13)["x_rod"]

    def err(res):
        return float(np.abs(res["x_rod"] - ref).max())

    def default():
        return ema.simulate(model, T_END, X_CMD, F_EXT)

    runs = {}
    first = default()  # compiles or loads the solver's library
    wall, res = timed(default, 7)
    runs["default: simulate(model, 1.0, x_cmd, f_ext)"] = (default, wall, err(res), _setting(res))
    ladders = {
        "rosenbrock": [1e-4, 3e-5, 1e-5, 3e-6, 1e-6, 3e-7, 1e-7, 1e-8],
        "cvodes": [1e-4, 3e-5, 1e-5, 3e-6, 1e-6, 3e-7, 1e-7, 1e-8],
        "rk4": [2e-5, 1e-5, 5e-6, 2.5e-6],
    }
    def previous():  # the default before solver="auto": RK4 at 1e-5 s, every step kept
        return ema.simulate(model, T_END, X_CMD, F_EXT, solver="rk4", dt=1e-5, decimate=1)

    previous()
    wall, res = timed(previous, 3)
    res = ema.simulate(model, T_END, X_CMD, F_EXT, solver="rk4", dt=1e-5)  # its error on the common grid
    runs["previous default: rk4, dt 1e-5 s, every step kept"] = (previous, wall, err(res), "rk4, dt 1e-05")
    for solver, settings in ladders.items():
        errors = []
        for s in settings:
            if solver == "rk4":
                def run(s=s):
                    return ema.simulate(model, T_END, X_CMD, F_EXT, solver="rk4", dt=s)
            else:
                def run(s=s, solver=solver):
                    return ema.simulate(model, T_END, X_CMD, F_EXT, solver=solver, rtol=s, atol=s * 1e-3)
            res = run()
            errors.append(err(res))
            if err(res) <= TOL:
                wall, res = timed(run, 7 if solver != "rk4" else 3)
                runs[f"{solver} at its fastest"] = (run, wall, err(res), _setting(res))
                break
        else:
            print(f"{solver}: no setting reached {TOL * 1e6:g} um (smallest error {min(errors) * 1e6:.2f} um at "
                  f"{settings[int(np.argmin(errors))]:g})", flush=True)

    fastest = min((k for k in runs if k.endswith("at its fastest")), key=lambda k: runs[k][1])
    t_def, t_fast = [], []
    for _ in range(15):
        for name, acc in (("default: simulate(model, 1.0, x_cmd, f_ext)", t_def), (fastest, t_fast)):
            t0 = time.perf_counter()
            runs[name][0]()
            acc.append(time.perf_counter() - t0)
    ratio = statistics.median(t_def) / statistics.median(t_fast)
    for name, acc in (("default: simulate(model, 1.0, x_cmd, f_ext)", t_def), (fastest, t_fast)):
        fn, _, e, setting = runs[name]
        runs[name] = (fn, statistics.median(acc), e, setting)  # the table shows the alternating medians
    print(f"default: {first.info['solver']} ({first.info['solver_reason']}), tolerance {first.info['tolerance']}, "
          f"{len(first.t)} samples")
    print(f"alternating, 15 rounds: default {statistics.median(t_def) * 1e3:.1f} ms, {fastest} "
          f"{statistics.median(t_fast) * 1e3:.1f} ms: ratio {ratio:.2f} (goal <= 2); error of the default "
          f"{runs['default: simulate(model, 1.0, x_cmd, f_ext)'][2] * 1e6:.4f} um (goal <= 0.1 um)\n")
    best = runs[fastest][1]
    print("| run | setting | wall time, median (ms) | max error vs CVODES 1e-10 (um) | ratio to fastest |")
    print("|---|---|---|---|---|")
    for name, (_, wall, e, setting) in runs.items():
        print(f"| {name} | {setting} | {wall * 1e3:.1f} | {e * 1e6:.4f} | {wall / best:.2f}x |")


def _setting(res) -> str:
    tol = res.info.get("tolerance") or {}
    return res.info["solver"] + ", " + ", ".join(f"{k} {v:g}" for k, v in tol.items())


if __name__ == "__main__":
    main()
