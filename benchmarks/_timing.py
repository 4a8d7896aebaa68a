"""Shared timing helper of the benchmarks."""

import statistics
import time


def timed(fn, repeat: int, warmup: bool = False):
    """Median wall time (s) of ``repeat`` calls of ``fn`` and the last result;
    ``warmup`` makes one untimed call first (compiles or loads what it needs)."""
    if warmup:
        fn()
    times, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), out
