"""Many independent items on many workers at a cost per item that does not grow with
their number: the engine under the sweeps (faults' healthy runs among them),
identification's multi-start, design's verification (threads), the sine stream's Dask
path and :func:`process_map` (the performance envelope).

What the items share (a sweep's spec, a model's parameters: the *payload*) reaches each
worker once: a local process gets it, pickled once, through the pool's initializer; a
thread reads it from this process; a Dask worker gets it scattered once. A task carries
only what identifies its items (run indices, points) and is a few hundred bytes
whatever the number of items.

Tasks are sized from measured times: each worker's first task is a single item (it
also pays the worker's start-up: imports, model build, compiled code), later tasks
hold as many items as fill :data:`TARGET_SECONDS` at the measured CPU seconds per
unit of cost (the CPU time of the thread that ran the task: the machine's other load
does not shrink the tasks, and with them the cost of this process per item), and
near the end at most a third of each worker's share of what is left, so that the
workers end together. Items are taken in the caller's order (longest first where
their costs differ). At most two tasks per worker are in flight: the waiting and the
bookkeeping of this process do not grow with the number of items.

With ``parent=True`` this thread is one of the ``jobs`` workers: it runs tasks itself
from the start (while the ``jobs - 1`` worker processes import and build their models)
and between receiving results, one item at a time so that the workers are not kept
waiting for their next task, so the start-up of one worker is not waited for and
the others' is overlapped with work. With ``keep_workers=True`` the worker processes
stay for the next call (their imports and models are not paid again).

On an interrupt (or any error) nothing more is submitted, the pending tasks are
cancelled and a process pool's workers are ended.
"""

from __future__ import annotations

import os
import pickle
import time
from collections import deque

__all__ = ["TARGET_SECONDS", "Plan", "run_tasks", "worker_payload", "process_map"]

#: Seconds of work a task aims at (the per-task cost of this process is amortised over
#: them; an interrupted sweep loses at most one task per worker).
TARGET_SECONDS = 0.25
#: Tasks in flight per worker (one running, one queued).
IN_FLIGHT = 2
#: Environment variables that set the BLAS threads of a worker process.
_BLAS_ENV = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")

_PAYLOADS: dict = {}  # token -> payload, in this process
_WARM: set = set()  # tokens whose first task ran in this process


class Plan:
    """Task sizes from measured times (module docstring).

    Parameters
    ----------
    workers : int
        Workers the tasks go to.
    target : float
        Seconds a task aims at (s).
    """

    def __init__(self, workers: int, target: float = TARGET_SECONDS):
        self.workers, self.target = max(1, workers), target
        self.rate = None  # seconds per unit of cost, from warm tasks
        self.cold_rate = None  # the same from first tasks (start-up included)
        self.startup = []  # seconds of each first task beyond its items' measured time
        self.tasks = 0
        self.pool_start = None  # seconds to start the local worker processes

    def take(self, queue: deque, costs: dict | None, left_cost: float) -> list:
        """The next task's items, taken from the front of ``queue``."""
        rate = self.rate if self.rate is not None else self.cold_rate
        budget = self.target / rate if rate else 0.0
        budget = min(budget, left_cost / (3 * self.workers)) if budget else 0.0
        chunk, cost = [queue.popleft()], 0.0
        cost += _cost(costs, chunk[0])
        while queue and cost + _cost(costs, queue[0]) <= budget:
            chunk.append(queue.popleft())
            cost += _cost(costs, chunk[-1])
        self.tasks += 1
        return chunk

    def record(self, cost: float, seconds: float, cold: bool) -> None:
        """A finished task: the cost of its items and its measured seconds."""
        per = seconds / max(cost, 1e-12)
        if cold:
            self.cold_rate = per if self.cold_rate is None else min(self.cold_rate, per)
            self.startup.append(seconds)
        else:
            self.rate = per if self.rate is None else 0.7 * self.rate + 0.3 * per

    def summary(self) -> dict:
        """Tasks, seconds per item (warm) and the first tasks' seconds (start-up)."""
        return {"tasks": self.tasks, "seconds_per_cost": self.rate, "pool_start_seconds": self.pool_start,
                "first_task_seconds": max(self.startup) if self.startup else None}


def _cost(costs, item) -> float:
    return 1.0 if costs is None else costs[item]


def worker_payload(token: str):
    """The payload of ``token`` in this worker (set by the pool's initializer)."""
    return _PAYLOADS[token]


def _init_process(parent: int, token: str, blob: bytes) -> None:
    from ._parallel import worker_init

    worker_init(parent)
    _PAYLOADS[token] = pickle.loads(blob)


def _task(token: str, function, chunk: list):
    """One task on a local worker: ``function(payload, chunk)``, its CPU seconds, and
    whether it was this worker's first."""
    t0 = time.thread_time()
    cold = token not in _WARM
    _WARM.add(token)
    out = function(_PAYLOADS[token], chunk)
    return out, time.thread_time() - t0, cold


def _dask_task(token: str, function, payload, chunk: list):
    """One task on a Dask worker (the payload is the scattered one, resolved there)."""
    t0 = time.thread_time()
    cold = token not in _WARM
    if cold:
        from ._parallel import heap_for_large_buffers

        heap_for_large_buffers()
    _WARM.add(token)
    out = function(payload, chunk)
    return out, time.thread_time() - t0, cold


def run_tasks(function, payload, items, each, *, jobs: int = 1, backend: str = "processes",
              scheduler: str | None = None, error: type = RuntimeError, costs: dict | None = None,
              on_abort=None, blas_threads: int | None = 1, target: float = TARGET_SECONDS,
              parent: bool = False, keep_workers: bool = False) -> dict:
    """Run ``function(payload, chunk)`` over chunks of ``items``; ``each(result)`` in this
    thread as each chunk finishes (any order).

    Parameters
    ----------
    function : callable
        Module-level (picklable): ``function(payload, chunk) -> result``.
    payload : object
        What every task shares; sent once per worker.
    items : sequence
        Small picklable identifiers (run indices, points), in the order to run them.
    each : callable
        ``each(result)``.
    jobs : int
        Local workers; 1 runs in this thread.
    backend : {"processes", "threads"}
        The local pool.
    scheduler : str, optional
        Address of a Dask scheduler instead of the local pool.
    error : type
        The exception for a scheduler that does not answer or has no worker.
    costs : dict, optional
        Item -> relative cost (default 1 each): tasks hold equal measured time.
    on_abort : callable, optional
        Called on an interrupt or an error before the pool is ended (a thread pool's
        stop flag).
    blas_threads : int, optional
        BLAS threads of each local worker process unless the environment sets them
        (None: the library's default).
    target : float
        Seconds a task aims at (s).
    parent : bool
        This thread is one of the ``jobs`` workers (module docstring); the items run in
        this process must give the same results as in a worker.
    keep_workers : bool
        Local worker processes stay for the next call with the same number of workers
        (their start-up paid once per session); its payload reaches each of them with
        its first tasks. They end with this process, or on an interrupt or an error.

    Returns
    -------
    dict
        ``tasks``, ``seconds_per_cost`` (warm) and ``first_task_seconds`` (start-up).
    """
    queue = deque(items)
    left = [float(sum(_cost(costs, i) for i in queue))]
    if not queue:
        return Plan(1).summary()
    workers = 1 if (jobs == 1 and not scheduler) else jobs
    plan = Plan(workers, target)

    def take(one=False):  # one: a single item (this thread's own, in the parent mode)
        chunk = [queue.popleft()] if one else plan.take(queue, costs, left[0])
        cost = float(sum(_cost(costs, i) for i in chunk))
        left[0] -= cost
        return chunk, cost

    if scheduler:
        from ._dask_tasks import run_on_dask

        run_on_dask(scheduler, function, payload, take, queue, plan, each, error, _dask_task, _token())
    elif workers == 1:
        token = _token()
        _PAYLOADS[token] = payload
        try:
            while queue:
                chunk, cost = take()
                out, seconds, cold = _task(token, function, chunk)
                plan.record(cost, seconds, cold)
                each(out)
        finally:
            _PAYLOADS.pop(token, None)
    else:
        _run_pool(function, payload, take, queue, plan, each, jobs, backend, on_abort, blas_threads, parent,
                  keep_workers)
    return plan.summary()


def _token() -> str:
    return f"{os.getpid()}-{time.perf_counter_ns()}-{id(object())}"


def _run_pool(function, payload, take, queue, plan, each, jobs, backend, on_abort, blas_threads, parent,
              keep) -> None:
    from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait

    from ._parallel import end_pool

    token = _token()
    helpers = jobs - 1 if parent else jobs
    started = []  # seconds from the pool's creation to each worker process's start
    blob, acked = None, set()  # a kept pool: the payload travels with the tasks until every worker has it
    if backend == "threads" or parent:
        _PAYLOADS[token] = payload
    if backend == "threads":
        pool = ThreadPoolExecutor(max_workers=helpers)
        started = [0.0] * helpers
    else:
        pool, started = _process_pool(helpers, blas_threads, token, payload, keep, parent, plan)
        if keep:
            blob = pickle.dumps(payload)
    pending = {}

    def submit(chunk):
        if keep and backend != "threads":
            return pool.submit(_kept_task, token, blob if len(acked) < helpers else None, function, chunk)
        return pool.submit(_task, token, function, chunk)

    def fill():  # with parent, tasks go only to workers that have started
        while queue and len(pending) < IN_FLIGHT * (len(started) if parent else helpers):
            chunk, cost = take()
            pending[submit(chunk)] = cost

    try:
        fill()
        while pending or queue:
            if parent and queue:  # this thread's own item (one: the workers wait no longer), then theirs
                chunk, cost = take(one=True)
                out, seconds, cold = _task(token, function, chunk)
                plan.record(cost, seconds, cold)
                each(out)
            ready, _ = wait(pending, timeout=0 if parent and queue else 0.2, return_when=FIRST_COMPLETED)
            for fut in ready:
                cost = pending.pop(fut)
                out, seconds, cold, *pid = fut.result()
                acked.update(pid)
                plan.record(cost, seconds, cold)
                each(out)
            fill()
    except BaseException:
        if on_abort is not None:
            on_abort()
        _KEPT.pop((helpers, blas_threads), None)
        end_pool(pool)
        raise
    finally:
        _PAYLOADS.pop(token, None)
    if parent and backend != "threads" and len(started) == helpers and plan.pool_start is None:
        plan.pool_start = max(started)
    if keep and backend != "threads":
        return  # the workers wait for the next call
    if parent and len(started) < helpers:  # workers still starting when this thread had done everything
        end_pool(pool)
        return
    pool.shutdown(wait=True)


def process_map(function, items, jobs: int) -> list:
    """``[function(item) for item in items]`` on ``jobs`` worker processes (spawn), in
    the items' order, through :func:`run_tasks`: the items reach
    each worker once, a task carries their indices. On an interrupt (or any error)
    nothing more is started, the pending items are cancelled and the workers are ended.
    The caller checks the main guard
    (:func:`~ema_casadi._util._parallel.check_main_guard`) before any work.

    Parameters
    ----------
    function : callable
        Picklable (a module-level function).
    items : sequence
        Picklable arguments, one call each.
    jobs : int
        Worker processes (at most ``len(items)``; one runs in this thread).
    """
    items, out = list(items), {}
    run_tasks(_map_chunk, (function, items), range(len(items)), out.update, jobs=max(1, min(jobs, len(items))))
    return [out[i] for i in range(len(items))]


def _map_chunk(payload, chunk) -> dict:
    function, items = payload
    return {i: function(items[i]) for i in chunk}


class _blas_env:
    """The BLAS thread variables set to ``n`` (where the environment leaves them unset)
    while the worker processes start; restored after."""

    def __init__(self, n):
        self.n, self.set = n, []

    def __enter__(self):
        if self.n is not None:
            self.set = [k for k in _BLAS_ENV if k not in os.environ]
            for k in self.set:
                os.environ[k] = str(int(self.n))
        return self

    def __exit__(self, *exc):
        for k in self.set:
            os.environ.pop(k, None)
        return False


#: Process pools kept between calls (``keep_workers``): (workers, BLAS threads) -> pool.
_KEPT: dict = {}


def _process_pool(helpers, blas_threads, token, payload, keep, parent, plan):
    """A process pool of ``helpers`` workers and the list its workers' start times go
    into: a kept one (started, ``plan.pool_start`` 0) or a new one (its initializer
    sets the payload unless the pool is kept)."""
    from concurrent.futures import wait

    from ._parallel import process_pool

    pool = _KEPT.get((helpers, blas_threads)) if keep else None
    if pool is not None and not getattr(pool, "_broken", False) and not getattr(pool, "_shutdown_thread", False):
        plan.pool_start = 0.0
        return pool, [0.0] * helpers
    if keep and not _KEPT:
        import atexit

        atexit.register(_end_kept)
    quiet_resource_tracker()
    t0, started = time.perf_counter(), []
    with _blas_env(blas_threads):
        pool = (process_pool(helpers) if keep else
                process_pool(helpers, initializer=_init_process, initargs=(token, pickle.dumps(payload))))
        starts = [pool.submit(int, 0) for _ in range(helpers)]  # every worker starts under that environment
        for f in starts:
            f.add_done_callback(lambda _: started.append(time.perf_counter() - t0))
        if not parent:
            wait(starts)
            plan.pool_start = time.perf_counter() - t0
    if keep:
        _KEPT[helpers, blas_threads] = pool
    return pool, started


def _kept_task(token: str, blob: bytes | None, function, chunk: list):
    """A task on a kept worker: the payload from ``blob`` where this worker has not got
    it (a kept worker holds the latest call's only), then :func:`_task`, and this
    worker's pid (the caller stops sending the payload once every worker has it)."""
    if token not in _PAYLOADS:
        _PAYLOADS.clear()
        _PAYLOADS[token] = pickle.loads(blob)
    return (*_task(token, function, chunk), os.getpid())


def quiet_resource_tracker() -> None:
    """Start multiprocessing's resource tracker without its warnings: after an interrupt
    the ``ema`` process ends at once (the reliability contract, docs: reliability) and
    the tracker would otherwise print "leaked semaphore objects" on the terminal after
    the one line."""
    from multiprocessing import resource_tracker

    old = os.environ.get("PYTHONWARNINGS")
    os.environ["PYTHONWARNINGS"] = ",".join(filter(None, [old, "ignore::UserWarning"]))
    try:
        resource_tracker.ensure_running()
    finally:
        if old is None:
            del os.environ["PYTHONWARNINGS"]
        else:
            os.environ["PYTHONWARNINGS"] = old


def _end_kept() -> None:
    """At exit: the kept pools shut down while the interpreter is whole."""
    for pool in list(_KEPT.values()):
        pool.shutdown(wait=True, cancel_futures=True)
    _KEPT.clear()
