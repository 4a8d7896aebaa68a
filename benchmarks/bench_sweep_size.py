"""Benchmark: the reference Monte Carlo of ``bench_sweep.py`` at growing run counts, on
local processes: does the parent's cost per run stay constant, and its memory bounded?

For each run count: the wall time and the workers' CPU per run, the parent's CPU per
run (``getrusage(RUSAGE_SELF)``: submitting tasks, receiving rows, the journal, the
table), and the peak memory of the parent and of the parent with its workers (resident
sizes summed, sampled every 0.2 s by a separate monitor process so that the sampling
costs the parent nothing; psutil, which Dask brings, else the parent's and the largest
worker's peaks from ``getrusage``). Each sweep writes its table and journal in a
temporary folder, as ``ema sweep --out`` does.

Usage::

    python benchmarks/bench_sweep_size.py                 # 1 000 and 10 000 runs
    python benchmarks/bench_sweep_size.py --slow          # and 100 000 (~15 min idle, 2 cores)
    python benchmarks/bench_sweep_size.py --duration 0.1  # a cheaper run (0.1 s simulated)

``--duration`` shortens the simulated scenario (the command's sine then never starts:
a cheaper run that costs the parent the same); the table says so.
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from bench_scaling import machine  # noqa: E402
from bench_sweep import ROOT, description  # noqa: E402

import ema_casadi as ema  # noqa: E402
from ema_casadi.sweeps import parse_sweep, sweep  # noqa: E402

#: Polls the resident memory of a process and its descendants until its stdin closes;
#: prints the peak sum (bytes).
MONITOR = """
import select, sys, psutil
root, peak = psutil.Process(int(sys.argv[1])), 0
while not select.select([sys.stdin], [], [], 0.2)[0]:
    total = 0
    for p in [root, *root.children(recursive=True)]:
        try:
            total += p.memory_info().rss
        except psutil.Error:
            pass
    peak = max(peak, total)
print(peak)
"""


def _cpu(who) -> float:
    r = resource.getrusage(who)
    return r.ru_utime + r.ru_stime


class Memory:
    """The peak resident memory of this process and its workers (module docstring)."""

    def __enter__(self):
        try:
            import psutil  # noqa: F401
        except ImportError:
            self.proc = None
        else:
            self.proc = subprocess.Popen([sys.executable, "-c", MONITOR, str(os.getpid())], stdin=subprocess.PIPE,
                                         stdout=subprocess.PIPE, text=True)
        return self

    def __exit__(self, *exc):
        self.peak = None
        if self.proc is not None:
            out, _ = self.proc.communicate("")
            self.peak = int(out) if out.strip() else None
        return False


def one(params, runs, jobs, duration, folder):
    desc = description(runs)
    desc["scenario"]["duration"] = duration
    spec = parse_sweep(desc, params, "bench_sweep_size")
    w0, c0, k0 = time.perf_counter(), _cpu(resource.RUSAGE_SELF), _cpu(resource.RUSAGE_CHILDREN)
    with Memory() as mem:
        res = sweep(spec, Path(folder) / f"sweep_{runs}.csv", jobs=jobs)
        wall, parent = time.perf_counter() - w0, _cpu(resource.RUSAGE_SELF) - c0
        workers = _cpu(resource.RUSAGE_CHILDREN) - k0  # the pool's workers, ended and waited for
    assert res.info["failed"] == 0, res.failed()[:1]
    self_peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    child_peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * 1024
    total = mem.peak if mem.peak is not None else self_peak + jobs * child_peak
    return {"runs": runs, "wall": wall / runs, "workers": workers / runs, "parent": parent / runs,
            "parent_mb": self_peak / 2**20, "total_mb": total / 2**20, "sampled": mem.peak is not None,
            "load": os.getloadavg()[0]}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="1000,10000", help="run counts, comma-separated (default 1000,10000)")
    ap.add_argument("--slow", action="store_true", help="also 100 000 runs (~15 minutes on 2 idle cores)")
    ap.add_argument("--jobs", type=int, default=2, help="local worker processes (default 2)")
    ap.add_argument("--duration", type=float, default=1.0,
                    help="simulated seconds of each run (default 1.0, the reference; shorter is cheaper)")
    ap.add_argument("--out", type=Path, help="also write the Markdown table to this file")
    ap.add_argument("--quick", action="store_true", help="200 and 1000 runs (run_all.py --quick)")
    args = ap.parse_args()
    sizes = [int(s) for s in args.sizes.split(",")] + ([100_000] if args.slow else [])
    if args.quick:
        sizes = [200, 1000]
    params = ema.load_parameters(ROOT / "models" / "cesa_ema.toml")
    sweep(parse_sweep(description(2), params), jobs=1)  # the compiled output map in the disk cache
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for n in sizes:
            rows.append(one(params, n, args.jobs, args.duration, folder))
            print(rows[-1], flush=True)
    what = ("the reference Monte Carlo (benchmarks/bench_sweep.py)" if args.duration == 1.0 else
            f"the reference Monte Carlo shortened to {args.duration:g} s simulated (a cheaper run)")
    lines = [f"Machine: {machine()}; Python {platform.python_version()}; {args.jobs} local processes; "
             f"{what}; table and journal written.", "",
             "| runs | wall per run | workers' CPU per run | parent's CPU per run | parent's peak memory | "
             "peak memory, parent + workers | load average at the end |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        runs = format(r["runs"], ",").replace(",", " ")
        lines.append(f"| {runs} | {r['wall'] * 1e3:.2f} ms | {r['workers'] * 1e3:.2f} ms | "
                     f"{r['parent'] * 1e3:.3f} ms | {r['parent_mb']:.0f} MB | {r['total_mb']:.0f} MB"
                     f"{'' if r['sampled'] else ' (bound)'} | {r['load']:.1f} |")
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        args.out.write_text(text, encoding="utf-8")


if __name__ == "__main__":
    main()
