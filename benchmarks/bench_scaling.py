"""Benchmark: how the reference Monte Carlo of ``bench_sweep.py`` scales with the number
of workers, on local processes and on a Dask ``LocalCluster`` (1 thread per worker).

For each worker count: the wall time per run (the pool's start included; a Dask
cluster is started and warmed before it is timed), the speed-up and parallel efficiency
against 1 worker (timed on ``--base-runs`` runs, its time per run the base), the
parent's CPU per run (``getrusage(RUSAGE_SELF)``) and whether the
rows equal those of 1 worker. The Markdown table names the machine (cores, CPU model).

Usage (a 16-core machine, about 5 minutes at ~9 ms a run on one core)::

    python benchmarks/bench_scaling.py --runs 20000 --workers 1,2,4,8,16 --out scaling.md

On a shared machine the wall times move with the other sessions' load; the parent's
CPU per run does not.
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from bench_sweep import ROOT, description  # noqa: E402

import ema_casadi as ema  # noqa: E402
from ema_casadi._util._parallel import cores  # noqa: E402
from ema_casadi.sweeps import parse_sweep, sweep  # noqa: E402


def machine() -> str:
    model = platform.processor() or "unknown CPU"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{cores()} cores available ({os.cpu_count()} logical), {model}, {platform.system()}"


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def timed(spec, **kw):
    t0, c0 = time.perf_counter(), _cpu()
    res = sweep(spec, **kw)
    return res, time.perf_counter() - t0, _cpu() - c0


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=2000, help="Monte Carlo runs (default 2000)")
    ap.add_argument("--workers", default="1,2", help="worker counts, comma-separated (default 1,2)")
    ap.add_argument("--base-runs", type=int, default=2000,
                    help="runs timed on 1 worker, the base of the speed-up (default 2000)")
    ap.add_argument("--dask-workers", default=None,
                    help="worker counts also run on Dask (default: 2 and the largest count)")
    ap.add_argument("--no-dask", action="store_true", help="local processes only")
    ap.add_argument("--out", type=Path, help="also write the Markdown table to this file")
    ap.add_argument("--quick", action="store_true", help="200 runs, 1 and 2 workers (run_all.py --quick)")
    args = ap.parse_args()
    if args.quick:
        args.runs, args.base_runs, args.workers = min(args.runs, 200), min(args.base_runs, 50), "1,2"
    counts = [int(w) for w in args.workers.split(",")]
    params = ema.load_parameters(ROOT / "models" / "cesa_ema.toml")
    spec = parse_sweep(description(args.runs), params, "bench_scaling")
    sweep(parse_sweep(description(2), params), jobs=1)  # the compiled output map in the disk cache
    dask_counts = ([] if args.no_dask else [int(w) for w in args.dask_workers.split(",")] if args.dask_workers
                   else sorted({2, max(counts)} & set(counts) - {1}))
    first = parse_sweep(description(min(args.runs, args.base_runs)), params, "bench_scaling")
    res, wall, cpu = timed(first, jobs=1)
    base = wall / len(first.runs)  # s per run on 1 worker
    ref = res.rows
    rows = [("local processes", 1, len(first.runs), wall, cpu, True)]
    for n in counts:
        for kind in ("local processes", *(["Dask LocalCluster"] if n in dask_counts else [])):
            if n == 1 and kind == "local processes":
                continue
            if kind == "local processes":
                res, wall, cpu = timed(spec, jobs=n)
            else:
                from dask.distributed import LocalCluster

                with LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0") as cl:
                    sweep(parse_sweep(description(2 * n), params), scheduler=cl.scheduler_address)  # workers warm
                    res, wall, cpu = timed(spec, scheduler=cl.scheduler_address)
            rows.append((kind, n, args.runs, wall, cpu, res.rows[: len(ref)] == ref))
            print(rows[-1], flush=True)
    lines = [f"Machine: {machine()}; Python {platform.python_version()}; {args.runs} runs of the reference "
             "Monte Carlo (benchmarks/bench_sweep.py).", "",
             "| backend | workers | wall per run | speed-up | efficiency | parent's CPU per run | rows as 1 worker |",
             "|---|---|---|---|---|---|---|"]
    for kind, n, runs, wall, cpu, same in rows:
        per = wall / runs
        lines.append(f"| {kind} | {n} | {per * 1e3:.2f} ms | {base / per:.2f}x | {base / per / n * 100:.0f} % | "
                     f"{cpu / runs * 1e3:.3f} ms | {'yes' if same else 'NO'} |")
    lines += ["", f"1 worker: {len(first.runs)} runs in this process (its CPU is the runs' own); the others: "
              "pool start included, Dask workers started and warmed before the timing."]
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        args.out.write_text(text, encoding="utf-8")


if __name__ == "__main__":
    main()
