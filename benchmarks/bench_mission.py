"""Benchmark: the 20-minute reference mission (models/mission_regional.toml) on the full
model (thermal = lumped, hybrid friction, iron loss on; compiled RK4 at 1e-4 s), and on
the fast path (the same model at 2e-4 s), against a reference at 5e-5 s.

Reported per run: wall time of run_mission (median of the repeats; the compiled rollout
is loaded from the cache by a warm-up, so compilation is excluded), its CPU time, the
worst temperature difference per node against the full model and against the 5e-5 s
reference, and the peak winding temperature. The machine's load average is printed
before and after: this is a shared 2-core machine, and wall times move with it.

Usage: python benchmarks/bench_mission.py [--quick]   (--quick: 1 repeat, no 5e-5 s reference)
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from pathlib import Path

import numpy as np

import ema_casadi as ema
from ema_casadi.mission import load_mission, parse_mission, run_mission

ROOT = Path(__file__).resolve().parent.parent
NODES = ("T_w", "T_h", "T_s", "T_inv")


def run(params, mission, dt, repeat):
    walls, cpus, res = [], [], None
    for _ in range(repeat):
        w0, c0 = time.perf_counter(), time.process_time()
        res = run_mission(params, mission, dt=dt)
        walls.append(time.perf_counter() - w0)
        cpus.append(time.process_time() - c0)
    return statistics.median(walls), statistics.median(cpus), res


def worst(a, b):
    return {n: float(np.max(np.abs(np.interp(b.t, a.t, a[n]) - b[n]))) for n in NODES}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="1 repeat, no 5e-5 s reference")
    args = ap.parse_args()
    repeat = 1 if args.quick else 3
    params = ema.load_parameters(ROOT / "models" / "cesa_ema.toml")
    mission = load_mission(ROOT / "models" / "mission_regional.toml", params)
    print(f"load average before: {os.getloadavg()}", flush=True)
    warm = parse_mission({"segment": [{"duration": 2.0, "T_amb": 20.0}]}, params, "warm-up")
    for dt in (1e-4, 2e-4, 5e-5):
        t0 = time.perf_counter()
        run_mission(params, warm, dt=dt)
        print(f"warm-up dt={dt:g}: {time.perf_counter() - t0:.2f} s (compile or load of the rollout)", flush=True)
    rows = {}
    for label, dt in (("full model", 1e-4), ("fast path", 2e-4)):
        rows[label] = (dt, *run(params, mission, dt, repeat))
        wall, cpu, res = rows[label][1:]
        print(f"{label:10s} dt={dt:g} s: {wall:6.2f} s wall, {cpu:6.2f} s CPU, peak T_w "
              f"{res['T_w'].max():.3f} degC, {res.info['steps']} steps", flush=True)
    ref = None if args.quick else run(params, mission, 5e-5, 1)[2]
    full = rows["full model"][3]
    print("\n| path | step | wall time | CPU time | worst vs full model | worst vs 5e-5 s |")
    print("|---|---|---|---|---|---|")
    for label, (dt, wall, cpu, res) in rows.items():
        vs_full = worst(full, res)
        vs_ref = worst(ref, res) if ref is not None else {}
        fmt = ", ".join(f"{n} {v:.3f} K" for n, v in vs_full.items()) if label != "full model" else "-"
        fmt_ref = ", ".join(f"{n} {v:.3f} K" for n, v in vs_ref.items()) if vs_ref else "-"
        print(f"| {label} | {dt:g} s | {wall:.1f} s | {cpu:.1f} s | {fmt} | {fmt_ref} |")
    print(f"\nload average after: {os.getloadavg()}")


if __name__ == "__main__":
    main()
