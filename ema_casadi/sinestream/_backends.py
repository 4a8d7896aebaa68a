"""Where the points run: a thread pool on this machine (CasADi releases the GIL; every
thread has its own call buffers on the one integrator), or chunks of points on a Dask
distributed cluster (optional dependency). Both return index -> point dict."""

from __future__ import annotations

import math
import os
from concurrent.futures import ThreadPoolExecutor, as_completed

from ..simulation import progress_bar
from ._kernels import _settle, _stepper
from ._result import FreqRespError


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not on Linux
        return os.cpu_count() or 1


def _run_local(tasks, params, build, settle, keep, progress, jobs) -> dict:
    """Points on a thread pool (hybrid points serially); -> index -> point dict."""
    results = {}
    n = len(tasks)

    def work(task):
        idx, v, x0, pa = task
        _, step = _stepper(v, params, *build)
        return idx, _settle(step, x0, pa, pa[-3], pa[-2], settle, keep)

    parallel = [t for t in tasks if t[1]["friction"] != "hybrid"]
    serial = [t for t in tasks if t[1]["friction"] == "hybrid"]
    done = 0
    progress_bar(0.0, progress, "freqresp")
    if parallel:
        # highest frequencies first: they take the most periods, so the pool ends evenly
        parallel.sort(key=lambda t: -t[3][-2])
        with ThreadPoolExecutor(max_workers=jobs) as pool:
            for fut in as_completed([pool.submit(work, t) for t in parallel]):
                idx, r = fut.result()
                results[idx] = r
                done += 1
                progress_bar(done / n, progress, "freqresp")
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
    try:
        from dask.distributed import Client
        from dask.distributed import as_completed as dask_completed
    except ImportError:
        raise FreqRespError("--scheduler needs Dask: pip install 'ema_casadi[dask]' (dask[distributed])") from None
    try:
        client = Client(address, timeout="10s")
    except Exception as exc:  # noqa: BLE001 - any connection problem is the user's address
        first = str(exc).splitlines()[0] if str(exc) else ""
        raise FreqRespError(f"scheduler {address}: cannot connect ({type(exc).__name__}: {first})") from None
    try:
        n_workers = max(1, sum(w.get("nthreads", 1) for w in client.scheduler_info().get("workers", {}).values()))
        # a few chunks per worker thread: balance without per-point scheduling overhead
        size = max(1, math.ceil(len(tasks) / (4 * n_workers)))
        order = sorted(tasks, key=lambda t: -t[3][-2])
        chunks = [order[i::math.ceil(len(tasks) / size)] for i in range(math.ceil(len(tasks) / size))]
        futures = [client.submit(_dask_chunk, params, build, settle, keep, c, pure=False) for c in chunks]
        results, done = {}, 0
        progress_bar(0.0, progress, "freqresp")
        for fut in dask_completed(futures):
            for idx, r in fut.result():
                results[tuple(idx)] = r
                done += 1
            progress_bar(done / len(tasks), progress, "freqresp")
        return results
    finally:
        client.close()
