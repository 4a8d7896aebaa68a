"""Benchmark: the reference fault table and the healthy runs of ``ema faults``.

- the reference fault table (``models/faults_reference.toml``: each fault kind at one
  severity, 0.5 s after its onset, plus the no-fault case; 11 runs of 0.6 s at RK4
  12.5 us on hybrid friction (inside RK4's 0.26 ms stability limit there; the smooth
  law held under the table's 5 kN would need 2.46 us), sampled ECU, real sensors,
  monitors), wall time from the call to the rows
  (model build and the compiled library's load included; its compilation is cached);
- ``--healthy N`` healthy runs (default 1000) of the same scenario's ``[healthy]``
  setting (0.3 s, RK4 31.25 us) with sensor noise and +-5 % friction and stiffness,
  through the sweep engine on 2 local processes: the wall time, the false alarms and
  each monitor's margin (the largest healthy statistic against its threshold).

The targets: the table under 10 s, 1000 healthy runs under 30 s on 2 cores. The
machine's load average is printed beside the times (they move with it), and the CPU
time of the work (this process and its worker processes): on two free cores the wall
time is about the CPU time over the two workers, which other jobs' load inflates far
less than the wall time.

Usage: python benchmarks/bench_faults.py [--healthy 1000] [--quick]
"""

from __future__ import annotations

import argparse
import os
import resource
import time
from pathlib import Path

import ema_casadi as ema
from ema_casadi.faults import healthy_runs, load_faults

ROOT = Path(__file__).resolve().parent.parent


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--healthy", type=int, default=1000, help="healthy runs (default 1000)")
    ap.add_argument("--quick", action="store_true", help="100 healthy runs")
    args = ap.parse_args()
    n = 100 if args.quick else args.healthy
    params = ema.load_parameters(ROOT / "models" / "cesa_ema.toml")
    spec = load_faults(ROOT / "models" / "faults_reference.toml", params)
    load0 = os.getloadavg()[0]
    t0, c0 = time.perf_counter(), _cpu()
    res = ema.run_faults(faults=spec)
    t_table, c_table = time.perf_counter() - t0, _cpu() - c0
    t0, c0 = time.perf_counter(), _cpu()
    h = healthy_runs(spec, n, jobs=2)
    t_healthy, c_healthy = time.perf_counter() - t0, _cpu() - c0
    load1 = os.getloadavg()[0]
    print("| what | runs | wall time (s) | CPU time (s) | CPU / 2 cores (s) | target (s) | load average |")
    print("|---|---|---|---|---|---|---|")
    print(f"| reference fault table | {len(res.rows)} | {t_table:.1f} | {c_table:.1f} | {c_table / 2:.1f} | 10 | "
          f"{load0:.1f} |")
    print(f"| healthy runs, 2 processes | {n} | {t_healthy:.1f} | {c_healthy:.1f} | {c_healthy / 2:.1f} | "
          f"{30 * n / 1000:g} | {load1:.1f} |")
    print(f"false alarms: {h['false_alarms']} of {n} healthy runs ({h['failed']} failed); no-fault case: "
          f"{res.false_alarms() or 'none'}")
    for latch, m in h.get("margins", {}).items():
        print(f"margin {latch}: healthy max {m['healthy_max']:.4g} {m['unit']} of {m['threshold']:.4g} "
              f"({m['margin']:.0%} below)")


def _cpu() -> float:
    """User + system CPU time (s) of this process and its ended worker processes."""
    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


if __name__ == "__main__":
    main()
