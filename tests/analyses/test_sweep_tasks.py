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
