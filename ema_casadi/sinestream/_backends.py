"""Where the points run: a thread pool on this machine (CasADi releases the GIL; every
thread has its own call buffers on the one integrator), or chunks of points on a Dask
distributed cluster (optional dependency). Both return index -> point dict.

Interrupts (the reliability contract, docs: reliability): on Ctrl-C/SIGTERM (or any exception in the waiting thread) the
pool stops submitting, cancels the pending points and does not wait for the batch:
running points see the stop flag at their next period. Dask futures are cancelled.

A remote scheduler that does not answer is not waited for forever: the connection and
the wait for a first worker are bounded (:mod:`ema_casadi._util._parallel`, shared with the
sweeps).
"""

from __future__ import annotations

import functools
import math
import threading
from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait

from .._util._parallel import cores as _cores
from .._util._parallel import dask_map
from ..simulation import progress_bar
from ._kernels import _settle, _stepper
from ._result import FreqRespError

__all__ = ["_cores", "_run_local", "_run_dask"]


def _run_local(tasks, params, build, settle, keep, progress, jobs) -> dict:
    """Points on a thread pool (hybrid points serially); -> index -> point dict."""
    results = {}
    n = len(tasks)
    stop = threading.Event()

    def work(task):
        idx, v, x0, pa = task
        _, step = _stepper(v, params, *build)
        return idx, _settle(step, x0, pa, pa[-3], pa[-2], settle, keep, stop)

    # a hybrid model (a part with a discrete map) is stepped through simulate(), serially
    hybrid = [_stepper(t[1], params, *build)[0].hybrid for t in tasks]
    parallel = [t for t, h in zip(tasks, hybrid, strict=True) if not h]
    serial = [t for t, h in zip(tasks, hybrid, strict=True) if h]
    done = 0
    progress_bar(0.0, progress, "freqresp")
    if parallel:
        # highest frequencies first: they take the most periods, so the pool ends evenly
        parallel.sort(key=lambda t: -t[3][-2])
        pool = ThreadPoolExecutor(max_workers=jobs)
        try:
            pending = {pool.submit(work, t) for t in parallel}
            while pending:
                finished, pending = wait(pending, timeout=0.2, return_when=FIRST_COMPLETED)
                for fut in finished:
                    idx, r = fut.result()
                    results[idx] = r
                    done += 1
                    progress_bar(done / n, progress, "freqresp")
        except BaseException:
            # an interrupt (or a failing point): no new points, none waited for; the
            # running ones stop at their next period
            stop.set()
            pool.shutdown(wait=False, cancel_futures=True)
            raise
        pool.shutdown(wait=True)
    for t in serial:
        idx, r = work(t)
        results[idx] = r
        done += 1
        progress_bar(done / n, progress, "freqresp")
    return results


def _dask_chunk(params, build, settle, keep, chunk) -> list:
    """Worker side of :func:`_run_dask`: run a chunk of points in this process."""
    return list(_run_local(chunk, params, build, settle, keep, False, 1).items())


def _run_dask(address, tasks, params, build, settle, keep, progress) -> dict:
    """Points in chunks on the Dask scheduler at ``address``; -> index -> point dict."""
    results = {}

    def chunks_of(n_workers):
        # a few chunks per worker thread: balance without per-point scheduling overhead
        size = max(1, math.ceil(len(tasks) / (4 * n_workers)))
        order = sorted(tasks, key=lambda t: -t[3][-2])
        n = math.ceil(len(tasks) / size)
        progress_bar(0.0, progress, "freqresp")
        return [order[i::n] for i in range(n)]

    def each(chunk_results):
        for idx, r in chunk_results:
            results[tuple(idx)] = r
        progress_bar(len(results) / len(tasks), progress, "freqresp")

    dask_map(address, functools.partial(_dask_chunk, params, build, settle, keep), chunks_of, each, FreqRespError)
    return results
