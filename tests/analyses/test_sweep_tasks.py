"""The task engine: what travels to a worker does not grow with the number of items,
every item is run once, tasks are taken in the caller's order and sized from measured
times (no timing is asserted: the plan is fed stated times)."""

from __future__ import annotations

import os
import pickle
import platform
import subprocess
import sys
from collections import deque
from concurrent.futures import ThreadPoolExecutor

import pytest

from ema_casadi._util._tasks import Plan, run_tasks


def _sum_items(payload, chunk):
    return [(i, payload[i]) for i in chunk]


def _submitted_sizes(monkeypatch, n):
    sizes, got = [], {}
    real = ThreadPoolExecutor.submit

    def submit(self, fn, *args, **kwargs):
        sizes.append((len(pickle.dumps(args)), len(args[-1])))
        return real(self, fn, *args, **kwargs)

    monkeypatch.setattr(ThreadPoolExecutor, "submit", submit)
    payload = [float(i) for i in range(n)]
    run_tasks(_sum_items, payload, range(n), lambda out: got.update(out), jobs=2, backend="threads")
    assert got == {i: float(i) for i in range(n)}  # every item once, with the shared payload
    return sizes


def test_a_task_carries_item_identifiers_not_the_payload(monkeypatch):
    """The pickled arguments of a task are at most 200 bytes plus 8 per item it runs,
    whether the payload holds 50 or 200 000 items (it reaches a worker once, not with
    each task; a pickled int index is at most 5 bytes)."""
    for n in (50, 200_000):
        sizes = _submitted_sizes(monkeypatch, n)
        assert all(size <= 200 + 8 * items for size, items in sizes), n


def test_tasks_follow_the_callers_order_and_grow_to_the_measured_target():
    """Longest first: items leave in the given order. Before a measurement a task is
    one item; at a measured 10 ms per unit of cost a 0.25 s target is 25 units, capped
    near the end by a third of each worker's share of what is left."""
    plan = Plan(workers=2, target=0.25)
    queue = deque(range(1000))
    assert plan.take(queue, None, 1000.0) == [0]
    plan.record(1.0, 0.5, cold=True)  # a first task: start-up included
    plan.record(1.0, 0.01, cold=False)
    assert plan.take(queue, None, 999.0) == list(range(1, 26))
    assert len(plan.take(queue, None, 30.0)) == 5  # 30 / (3 x 2)
    # with costs: a task holds 25 units, an item above them alone
    costs = {"long": 30.0, "mid": 20.0, "short": 5.0, "last": 1.0}
    queue = deque(["long", "mid", "short", "last"])
    assert plan.take(queue, costs, 1e6) == ["long"]
    assert plan.take(queue, costs, 1e6) == ["mid", "short"]


_FAULTS = """
import resource, sys, threading
import numpy as np
from ema_casadi._util._parallel import heap_for_large_buffers
if sys.argv[1] == "fixed":
    heap_for_large_buffers()
def calls(out):
    a = np.ones(2**17)
    guard = np.ones(2**15)  # holds the heap's top above a's buffer
    del a
    f0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(100):
        np.ones(2**17).sum()
    out.append(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - f0)
    del guard
out = []
calls(out)
worker = threading.Thread(target=calls, args=(out,))  # a thread's own heap (a Dask task's)
worker.start()
worker.join()
print(*out)
"""


@pytest.mark.skipif(platform.libc_ver()[0] != "glibc", reason="glibc's malloc tunables")
def test_a_worker_under_a_fixed_trim_threshold_takes_large_buffers_from_its_heap():
    """Where the environment sets MALLOC_TRIM_THRESHOLD_ (Dask's workers), glibc maps
    every buffer above 128 KiB apart: a 1 MiB buffer (256 pages) made 100 times faults
    its pages in each time, in the main thread and in another one (measured 257 a
    call; at least 200 asserted). After heap_for_large_buffers the freed buffer is
    reused from the heap (measured 1 fault in all 100 calls in the main thread, none
    in the other; at most 1 a call asserted)."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("MALLOC_")}
    env["MALLOC_TRIM_THRESHOLD_"] = "65536"
    faults = {m: [int(f) for f in subprocess.run([sys.executable, "-c", _FAULTS, m], env=env, capture_output=True,
                                                 text=True, check=True).stdout.split()]
              for m in ("plain", "fixed")}
    assert min(faults["plain"]) >= 100 * 200, faults
    assert max(faults["fixed"]) <= 100, faults
