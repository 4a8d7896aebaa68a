"""The Dask side of :func:`~ema_casadi._util._tasks.run_tasks`: the payload scattered
once to every worker, the same task sizes as the local pool, at most two tasks per
worker thread in flight, results taken as they finish.

A remote scheduler that does not answer is not waited for forever (the bounds of
:mod:`ema_casadi._util._parallel`); on any exception here (an interrupt included) the
submitted futures are cancelled.
"""

from __future__ import annotations

from ._parallel import connect, worker_threads

__all__ = ["run_on_dask"]


def run_on_dask(address: str, function, payload, take, queue, plan, each, error: type, task, token: str) -> None:
    """Tasks of ``queue`` (sized by ``take()``) on the Dask scheduler at ``address``.

    Parameters
    ----------
    address : str
        ``tcp://host:port``.
    function : callable
        ``function(payload, chunk)``, importable on the workers.
    payload : object
        Scattered once (broadcast) to every worker.
    take : callable
        ``take() -> (chunk, cost)``: the next task.
    queue : deque
        The items not yet taken.
    plan : Plan
        Records each finished task's measured time.
    each : callable
        ``each(result)`` in this thread as each task finishes.
    error : type
        The exception for a scheduler that does not answer or has no worker.
    task : callable
        ``task(token, function, payload, chunk) -> (result, seconds, first)``, run on a worker.
    token : str
        Names this run's payload on the workers.
    """
    from dask.distributed import as_completed

    client = connect(address, error)
    pending = {}
    try:
        threads = worker_threads(client, address, error)
        plan.workers = threads
        [shared] = client.scatter([payload], broadcast=True, hash=False)
        done = as_completed()

        def submit():
            chunk, cost = take()
            fut = client.submit(task, token, function, shared, chunk, pure=False)
            pending[fut] = cost
            done.add(fut)

        while queue and len(pending) < 2 * threads:
            submit()
        for fut in done:
            out, seconds, cold = fut.result()
            plan.record(pending.pop(fut), seconds, cold)
            each(out)
            if queue:
                submit()
    except BaseException:
        if pending:
            client.cancel(list(pending))
        raise
    finally:
        client.close(timeout=2)
