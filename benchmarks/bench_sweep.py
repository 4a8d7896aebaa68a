"""Benchmark: a Monte Carlo sweep of the reference scenario (1 s; 1 mm step at 0.01 s,
0.375 mm 1 Hz sine from 0.5 s; pmsm + elastic + smooth + ideal) with F_seal +-50 % and
C +-30 % drawn uniformly, on 2 cores:

- ``ema_casadi.sweeps`` on 2 local processes (the simulate path and setting of
  ``bench_sim.py``: the compiled RODAS4 (solver rosenbrock) at rtol 3e-4, 1 ms samples; metrics: step overshoot and peak
  i_q), wall time from the call to the table (pool start included) and per run;
- the same runs with scipy ``solve_ivp`` LSODA on the peers' NumPy right-hand side
  (``numpy_model.py``, restarted at the command's breakpoints, rtol 3e-4 as in
  ``bench_sim.py``) in 2 processes: the ratio of the wall times;
- the same sweep on a Dask ``LocalCluster`` (2 worker processes, 1 thread each): the
  overhead per run against the local processes (cluster start reported apart).

The parent's CPU per run (``getrusage(RUSAGE_SELF)``; it must not grow with the run
count) and its peak memory are printed with the local sweep. The peak rod positions
of both are compared (a check that the same runs were made).
On a shared machine the wall times move with the other sessions' load, so the CPU time
per run of both (serial, in this process, the first ``--cpu-runs`` runs, alternating
blocks of 5) is reported too: the ratio that load does not move.

Usage: python benchmarks/bench_sweep.py [--runs 1000] [--quick] [--no-dask] [--no-lsoda]
"""

from __future__ import annotations

import argparse
import resource
import sys
import time
from multiprocessing import get_context
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
import numpy_model  # noqa: E402

import ema_casadi as ema  # noqa: E402
from ema_casadi import Signal  # noqa: E402
from ema_casadi.sweeps import parse_sweep, sweep  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
X_CMD = Signal.step(1e-3, 0.01) + Signal.sine(0.375e-3, 1.0, 0.5)
RTOL = 3e-4
#: the fastest method of bench_sim.py at <= 0.1 um (0.044 um at this rtol)
SOLVER = "rosenbrock"


def description(runs: int) -> dict:
    return {"sweep": {"seed": 15, "samples": runs},
            "parameters": {"F_seal": {"distribution": "uniform", "low": 0.5, "high": 1.5, "relative": True},
                           "C": {"distribution": "uniform", "low": 0.7, "high": 1.3, "relative": True}},
            "scenario": {"duration": 1.0, "x_cmd": "step:1mm@0.01+sine:0.375mm@1@0.5", "solver": SOLVER,
                         "dt": 1e-3, "rtol": RTOL, "atol": RTOL * 1e-3},
            "metrics": {"step": {"at": 0.01, "amplitude": 1e-3}, "peak": {"signals": ["i_q", "x_rod"]}}}


def lsoda_run(P):
    """Peak |x_rod| of one run with LSODA (the breakpoints of bench_sim.py)."""
    from scipy.integrate import solve_ivp

    def f(t, x):
        return numpy_model.rhs(t, x, float(X_CMD(t)), 0.0, P["eta"], P)

    x0, peak = np.zeros(9), 0.0
    grid = np.linspace(0, 1.0, 1001)
    for a, b in ((0.0, 0.01), (0.01, 0.5), (0.5, 1.0)):
        sel = grid[(grid >= a) & (grid <= b)]
        sol = solve_ivp(f, (a, b), x0, method="LSODA", t_eval=sel, rtol=RTOL, atol=RTOL * 1e-3)
        peak = max(peak, float(np.abs(sol.y[7]).max()))
        x0 = sol.y[:, -1]
    return peak


def _cpu(who) -> float:
    """User + system CPU seconds of this process (RUSAGE_SELF) or its ended children."""
    r = resource.getrusage(who)
    return r.ru_utime + r.ru_stime


def cpu_ratio(spec, params, n):
    """CPU time per run of the sweep's own worker and of LSODA, serial, alternating."""
    from ema_casadi.sweeps._run import _run_one, _worker_for

    worker, base = _worker_for(spec), params.as_dict()
    _run_one(worker, spec.runs[0])
    t_ours = t_peer = 0.0
    runs = spec.runs[:n]
    for i in range(0, len(runs), 5):
        c0 = time.process_time()
        for r in runs[i : i + 5]:
            _run_one(worker, r)
        c1 = time.process_time()
        for r in runs[i : i + 5]:
            lsoda_run({**base, **r.values})
        t_ours, t_peer = t_ours + c1 - c0, t_peer + time.process_time() - c1
    print(f"CPU time per run, serial, {len(runs)} runs: ema_casadi {t_ours / len(runs) * 1e3:.2f} ms, "
          f"LSODA {t_peer / len(runs) * 1e3:.1f} ms: ratio {t_peer / t_ours:.1f}x", flush=True)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=1000, help="Monte Carlo runs (default 1000)")
    ap.add_argument("--jobs", type=int, default=2, help="workers of every method (default 2)")
    ap.add_argument("--no-dask", action="store_true", help="skip the Dask LocalCluster")
    ap.add_argument("--no-lsoda", action="store_true", help="skip the LSODA peer")
    ap.add_argument("--quick", action="store_true", help="100 runs (run_all.py --quick)")
    ap.add_argument("--cpu-runs", type=int, default=40, help="runs timed in CPU time, each method (default 40)")
    args = ap.parse_args()
    if args.quick:
        args.runs = min(args.runs, 100)
    params = ema.load_parameters(ROOT / "models" / "cesa_ema.toml")
    spec = parse_sweep(description(args.runs), params, "bench_sweep")
    sweep(parse_sweep(description(2), params), jobs=1)  # the compiled output map in the disk cache
    t0 = time.perf_counter()
    sweep(parse_sweep(description(args.jobs), params), jobs=args.jobs)  # one run per worker
    t_start = time.perf_counter() - t0  # ~ starting the pool (spawn, imports, model build)
    t0, c0 = time.perf_counter(), _cpu(resource.RUSAGE_SELF)
    ours = sweep(spec, jobs=args.jobs)
    t_ours, c_parent = time.perf_counter() - t0, _cpu(resource.RUSAGE_SELF) - c0
    assert ours.info["failed"] == 0, ours.failed()[:1]
    print(f"ema_casadi sweep, {args.runs} runs on {args.jobs} processes: {t_ours:.2f} s "
          f"({t_ours / args.runs * 1e3:.2f} ms per run, pool start included; a pool with one run per worker "
          f"takes {t_start:.2f} s); the parent's CPU {c_parent / args.runs * 1e3:.3f} ms per run, peak memory "
          f"{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB (parent)", flush=True)
    if not args.no_lsoda:
        base = params.as_dict()
        Ps = [{**base, **r.values} for r in spec.runs]
        t0 = time.perf_counter()
        with get_context("spawn").Pool(args.jobs) as pool:
            peaks = pool.map(lsoda_run, Ps, chunksize=max(1, args.runs // (4 * args.jobs)))
        t_peer = time.perf_counter() - t0
        diff = float(np.max(np.abs(np.array(peaks) - ours.column("peak_x_rod"))))
        print(f"scipy LSODA (NumPy RHS), same runs on {args.jobs} processes: {t_peer:.2f} s "
              f"({t_peer / args.runs * 1e3:.1f} ms per run); ratio {t_peer / t_ours:.1f}x "
              f"(peak x_rod agrees within {diff * 1e6:.3f} um)", flush=True)
    if not args.no_lsoda and args.cpu_runs > 0:
        cpu_ratio(spec, params, args.cpu_runs)
    if not args.no_dask:
        from dask.distributed import LocalCluster

        t0 = time.perf_counter()
        with LocalCluster(n_workers=args.jobs, threads_per_worker=1, processes=True,
                          dashboard_address=":0") as cluster:
            t_cluster = time.perf_counter() - t0
            sweep(parse_sweep(description(2), params), scheduler=cluster.scheduler_address)  # workers warm
            t0 = time.perf_counter()
            on_dask = sweep(spec, scheduler=cluster.scheduler_address)
            t_dask = time.perf_counter() - t0
        same = on_dask.rows == ours.rows
        # against the local pool without its start (the cluster's workers were warm)
        overhead = (t_dask - (t_ours - t_start)) / args.runs
        print(f"Dask LocalCluster ({args.jobs} workers x 1 thread; cluster start {t_cluster:.1f} s): {t_dask:.2f} s; "
              f"overhead {overhead * 1e3:+.2f} ms per run against the local processes without their start; "
              f"rows {'identical' if same else 'DIFFERENT'}", flush=True)


if __name__ == "__main__":
    main()
