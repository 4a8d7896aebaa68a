"""Where the points run: the task engine of :mod:`ema_casadi._util._tasks` (the one
under the sweeps), on local processes, threads or a Dask distributed cluster.

What the points share (parameters, variants, options, every point's starting state:
the :class:`Grid`) reaches each worker once; a task carries only point indices. Each
worker builds its period maps once (:func:`~ema_casadi.sinestream._kernels._stepper`,
cached per process) and keeps them for all its tasks. Points are taken longest first
by their estimated cost (:func:`point_costs`), so the pool ends with the short ones,
and tasks are sized from the measured seconds per unit of cost.

Every point is computed from the same inputs by the same code whatever the worker,
so the table is the same, to the last digit, for any number of workers.

Interrupts (the reliability contract, docs: reliability): on Ctrl-C/SIGTERM (or any
exception in the waiting thread) nothing more is submitted, the pending tasks are
cancelled and a process pool's workers are ended; running points on threads see the
stop flag at their next period. Dask futures are cancelled.
"""

from __future__ import annotations

import math
import os
import threading
import time
from dataclasses import dataclass

import numpy as np

from .._util._parallel import cores as _cores
from .._util._tasks import run_tasks
from ..simulation import progress_bar
from ._kernels import _settle, _stepper
from ._result import FreqRespError

__all__ = ["_cores", "Grid", "run_points", "point_costs", "worth_processes", "BACKENDS"]

#: Local pools: worker processes (started by spawn) or threads of this process.
BACKENDS = ("processes", "threads")
#: Estimated periods of a point, ``PERIODS_LINEAR + PERIODS_PER_RATIO * max(rho - 1, 0)``
#: with rho the linear rod speed demand over the rate limit: fitted on the paper's Fig.
#: 14a grid (2.5 + 1.6 (rho - 1), correlation 0.97 with the measured CPU time).
PERIODS_LINEAR = 2.5
PERIODS_PER_RATIO = 1.6
#: RK4 steps (hybrid friction, compiled) that cost one CVODES period of the smooth
#: model: 0.45 us a step against 5.4 ms a period on the reference model (2-core x86-64;
#: the switched bridge's steps cost 0.8 us: its points are underestimated by ~2x).
RK4_STEPS_PER_PERIOD = 12000.0

#: A worker process's start-up (interpreter, imports, the grid, its period map: 0.26 to
#: 0.31 s of CPU measured on a 2-core x86-64) in CVODES periods of the reference model
#: (5.4 to 6.3 ms each). Worker processes are started only for a grid whose estimated
#: cost is at least twice that (:func:`worth_processes`).
STARTUP_PERIODS = 50.0
#: Seconds of work a task aims at: the longest task stays within 1/20 of the paper's
#: Fig. 14a grid (4.5 s on one core), so that 16 workers can share it evenly.
TARGET_SECONDS = 0.1

_RAN = False  # a task has run in this process (a kept worker's later calls pay no start-up)
_STOP = threading.Event()  # set on an interrupt: threads stop at their next period


@dataclass(frozen=True)
class Grid:
    """What every task of a sine stream shares (sent once per worker): the parameter
    set, the variants, the build and settling options, the axes (SI units) and every
    point's starting state, index -> state."""

    params: object
    variants: tuple
    build: tuple
    settle: object
    keep: bool
    pv: np.ndarray
    loads: np.ndarray
    amplitudes: np.ndarray
    freqs: np.ndarray
    x0: dict

    def pa(self, idx) -> np.ndarray:
        """``[p; A; f; F_ext]`` of the point ``idx`` = (variant, load, amplitude, frequency)."""
        _, il, ia, jf = idx
        return np.r_[self.pv, self.amplitudes[ia], self.freqs[jf], self.loads[il]]


def _points(grid: Grid, chunk: list) -> tuple:
    """The task: the points ``chunk`` (indices) in this worker -> (index, point dict,
    CPU seconds of its periods) for each, the seconds spent building period maps (once
    per worker and variant), and this process's id, whether this is its first task ever
    and its CPU seconds since it started at the task's start and end (a first task's
    start: the process's start-up, interpreter, imports, the payload)."""
    global _RAN
    out, build, cpu0, fresh = [], 0.0, time.process_time(), not _RAN
    _RAN = True
    for idx in chunk:
        t0 = time.perf_counter()
        _, step = _stepper(grid.variants[idx[0]], grid.params, *grid.build)
        build += time.perf_counter() - t0
        pa = grid.pa(idx)
        c0 = time.thread_time()
        r = _settle(step, grid.x0[idx], pa, pa[-3], pa[-2], grid.settle, grid.keep, _STOP)
        out.append((idx, r, time.thread_time() - c0))
    return out, build, (os.getpid(), fresh, cpu0, time.process_time())


def point_costs(grid: Grid, rho: dict) -> dict:
    """Index -> estimated cost of each point, in periods of the CVODES map.

    A smooth point costs about the same per period at every frequency (time is in
    periods), and takes ``PERIODS_LINEAR`` periods where the linear starting guess holds
    and more where the rate limit bends the response (``rho``: the linear rod speed
    demand over the limit). A point stepped by fixed-step RK4 (hybrid friction, the
    switched bridge) costs its steps per period, which grow as the frequency falls;
    they are converted to CVODES periods at :data:`RK4_STEPS_PER_PERIOD`.
    """
    out = {}
    for idx, r in rho.items():
        periods = PERIODS_LINEAR + PERIODS_PER_RATIO * max(r - 1.0, 0.0)
        step = _stepper(grid.variants[idx[0]], grid.params, *grid.build)[1]
        steps = getattr(step, "steps_per_period", None)
        out[idx] = periods * (1.0 if steps is None else steps(grid.pa(idx)) / RK4_STEPS_PER_PERIOD)
    return out



def worth_processes(costs: dict) -> bool:
    """Whether worker processes pay for their start-up on a grid of these estimated
    costs: with this process computing from the start, two workers take about
    (W + S) / 2 of one's W (S the start-up), at most 3/4 of it where W >= 2 S."""
    return math.fsum(costs.values()) >= 2 * STARTUP_PERIODS


def run_points(grid: Grid, items: list, costs: dict, *, jobs: int, backend: str, scheduler: str | None,
               progress: bool) -> tuple[dict, dict]:
    """Run the points ``items`` (indices, any order) -> (index -> point dict, timings:
    ``point_seconds`` index -> CPU seconds, ``point_cost`` index -> estimated cost
    (``costs``), ``task_seconds`` the CPU seconds of each
    task's points, ``build_seconds`` of the period maps, ``worker_cpu`` (CPU seconds of
    each worker process: its start-up where it started for this call, what it spent on
    this call, start-up included, and its points), ``points_here`` (CPU seconds of the
    points run in this process), the engine's plan summary)."""
    results, seconds, tasks, workers = {}, {}, [], {}
    build = [0.0]
    order = sorted(items, key=lambda i: -costs[i])  # longest first: the pool ends with the short points
    n = len(order)
    progress_bar(0.0, progress, "freqresp")

    def each(task):
        points, b, (pid, fresh, cpu0, cpu1) = task
        build[0] += b
        tasks.append(math.fsum(s for _, _, s in points))
        # start-up (its first task ever: the CPU before it), CPU from the process's start
        # (fresh) or this call's first task, CPU at the last, points; tasks arrive in any order
        seen = workers.get(pid, (0.0, cpu0, cpu1, 0.0))
        workers[pid] = (cpu0 if fresh else seen[0], 0.0 if fresh else min(seen[1], cpu0), max(seen[2], cpu1),
                        seen[3] + tasks[-1])
        for idx, r, s in points:
            results[tuple(idx)] = r
            seconds[tuple(idx)] = s
        progress_bar(len(results) / n, progress, "freqresp")

    _STOP.clear()
    serial = []
    if backend == "threads" and not scheduler:
        # the fixed-step points (simulate(): hybrid friction, the switched bridge) run
        # in this thread after the others
        rk4 = {i for i in order if hasattr(_stepper(grid.variants[i[0]], grid.params, *grid.build)[1],
                                            "steps_per_period")}
        order, serial = [i for i in order if i not in rk4], [i for i in order if i in rk4]
    plan = run_tasks(_points, grid, order, each, jobs=jobs, backend=backend, scheduler=scheduler,
                     error=FreqRespError, costs=costs, on_abort=_STOP.set, target=TARGET_SECONDS,
                     parent=True, keep_workers=True) if order else {}
    if serial:
        run_tasks(_points, grid, serial, each, jobs=1, costs=costs)
    here = workers.pop(os.getpid(), (0.0, 0.0, 0.0, 0.0))[3]
    used = sorted((w[0], w[2] - w[1], w[3]) for w in workers.values())
    return results, {"point_seconds": seconds, "point_cost": costs, "task_seconds": tasks, "build_seconds": build[0],
                     "worker_cpu": used, "points_here": here, **plan}
