"""Where the points run: a thread pool on this machine (CasADi releases the GIL; every
thread has its own call buffers on the one integrator), or chunks of points on a Dask
distributed cluster (optional dependency). Both return index -> point dict.

Interrupts (SPEC §7): on Ctrl-C/SIGTERM (or any exception in the waiting thread) the
pool stops submitting, cancels the pending points and does not wait for the batch:
running points see the stop flag at their next period. Dask futures are cancelled.

A remote scheduler that does not answer is not waited for forever: the connection
(handshake included) is bounded by :data:`SCHEDULER_TIMEOUT` and the wait for a first
worker by :data:`WORKERS_TIMEOUT` (seconds; environment variables
``EMA_CASADI_SCHEDULER_TIMEOUT`` and ``EMA_CASADI_WORKERS_TIMEOUT`` override them).
"""

from __future__ import annotations

import math
import os
import threading
from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait

from ..simulation import progress_bar
from ._kernels import _settle, _stepper
from ._result import FreqRespError

#: Seconds to connect to a Dask scheduler, handshake included.
SCHEDULER_TIMEOUT = 10.0
#: Seconds to wait for the scheduler's first worker.
WORKERS_TIMEOUT = 30.0


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not on Linux
        return os.cpu_count() or 1


def _run_local(tasks, params, build, settle, keep, progress, jobs) -> dict:
    """Points on a thread pool (hybrid points serially); -> index -> point dict."""
    results = {}
    n = len(tasks)
    stop = threading.Event()

    def work(task):
        idx, v, x0, pa = task
        _, step = _stepper(v, params, *build)
        return idx, _settle(step, x0, pa, pa[-3], pa[-2], settle, keep, stop)

    parallel = [t for t in tasks if t[1]["friction"] != "hybrid"]
    serial = [t for t in tasks if t[1]["friction"] == "hybrid"]
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


def _timeout(name: str, default: float) -> float:
    try:
        return float(os.environ.get(name, default))
    except ValueError:
        raise FreqRespError(f"{name}={os.environ[name]!r}: expected a number of seconds") from None


def _connect(address: str, timeout: float):
    """A Dask Client for ``address``, or FreqRespError after ``timeout`` seconds.

    ``Client(address, timeout=...)`` does not bound the handshake with a server that
    accepts the connection and never answers, so the connection is made on a helper
    thread and abandoned (daemon) when it does not finish in time."""
    from dask.distributed import Client

    box = {}

    def connect():
        try:
            box["client"] = Client(address, timeout=f"{timeout}s")
        except Exception as exc:  # noqa: BLE001 - any connection problem is the user's address
            box["error"] = exc

    helper = threading.Thread(target=connect, name="ema-dask-connect", daemon=True)
    helper.start()
    helper.join(timeout + 1.0)
    if helper.is_alive():
        raise FreqRespError(f"scheduler {address}: no answer within {timeout:g} s (is it a Dask scheduler?)")
    if "error" in box:
        exc = box["error"]
        first = str(exc).splitlines()[0] if str(exc) else ""
        raise FreqRespError(f"scheduler {address}: cannot connect ({type(exc).__name__}: {first})")
    return box["client"]


def _run_dask(address, tasks, params, build, settle, keep, progress) -> dict:
    """Points in chunks on the Dask scheduler at ``address``; -> index -> point dict."""
    try:
        from dask.distributed import as_completed as dask_completed
    except ImportError:
        raise FreqRespError("--scheduler needs Dask: pip install 'ema_casadi[dask]' (dask[distributed])") from None
    client = _connect(address, _timeout("EMA_CASADI_SCHEDULER_TIMEOUT", SCHEDULER_TIMEOUT))
    futures = []
    try:
        wait_workers = _timeout("EMA_CASADI_WORKERS_TIMEOUT", WORKERS_TIMEOUT)
        try:
            client.wait_for_workers(1, timeout=wait_workers)
        except TimeoutError:
            raise FreqRespError(f"scheduler {address}: no worker joined within {wait_workers:g} s") from None
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
    except BaseException:
        if futures:
            client.cancel(futures)
        raise
    finally:
        client.close(timeout=2)
