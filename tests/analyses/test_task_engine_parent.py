"""The task engine's waiting thread: with ``parent=True`` it is one of the workers
(every item still runs once); without work of its own it blocks instead of spinning."""

from __future__ import annotations

from ema_casadi._util._tasks import run_tasks


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
