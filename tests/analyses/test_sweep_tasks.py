"""The task engine: what travels to a worker does not grow with the number of items,
every item is run once, tasks are taken in the caller's order and sized from measured
times (no timing is asserted: the plan is fed stated times)."""

from __future__ import annotations

import pickle
from collections import deque
from concurrent.futures import ThreadPoolExecutor

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


def _items_and_thread(payload, chunk):
    import threading

    return [(i, payload[i], threading.get_ident()) for i in chunk]


def test_with_parent_this_thread_is_one_of_the_workers():
    """parent=True: jobs - 1 pool workers and this thread share the items; every item
    runs once, with the shared payload, and this thread runs some of them itself."""
    import threading

    got, threads = {}, []

    def each(out):
        for i, v, ident in out:
            assert i not in got
            got[i] = v
            threads.append(ident)

    payload = [float(i) for i in range(300)]
    summary = run_tasks(_items_and_thread, payload, range(300), each, jobs=2, backend="threads", parent=True,
                        costs={i: 1.0 for i in range(300)})
    assert got == {i: float(i) for i in range(300)}
    assert threading.get_ident() in threads and len(set(threads)) == 2  # this thread and the pool's
    assert summary["tasks"] >= 2


def _sleep_items(payload, chunk):
    import time

    time.sleep(payload * len(chunk))
    return list(chunk)


def test_the_waiting_thread_does_not_spin():
    """While the workers sleep through 20 items of 20 ms (0.2 s of wall on two), the
    thread that waits for them uses almost no CPU: below 0.05 s for its submitting,
    receiving and waking every 0.2 s (measured ~2 ms; a busy wait would take ~0.2 s)."""
    import time

    for parent in (False, True):
        got = []
        c0 = time.thread_time()
        run_tasks(_sleep_items, 0.02, range(20), got.extend, jobs=2 + parent, backend="threads", parent=parent)
        assert sorted(got) == list(range(20))
        assert time.thread_time() - c0 < 0.05, parent
