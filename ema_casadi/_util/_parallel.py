"""Where independent work runs, shared by the sine stream and the sweeps: the cores of
this machine, and a Dask distributed cluster (optional dependency).

A remote scheduler that does not answer is not waited for forever: the connection
(handshake included) is bounded by :data:`SCHEDULER_TIMEOUT` and the wait for a first
worker by :data:`WORKERS_TIMEOUT` (seconds; environment variables
``EMA_CASADI_SCHEDULER_TIMEOUT`` and ``EMA_CASADI_WORKERS_TIMEOUT`` override them).
On any exception in the waiting thread (an interrupt included) the submitted futures
are cancelled.
"""

from __future__ import annotations

import os
import threading

__all__ = ["SCHEDULER_TIMEOUT", "WORKERS_TIMEOUT", "cores", "connect", "timeout", "worker_threads",
           "check_main_guard", "die_with_parent", "worker_init", "heap_for_large_buffers", "process_pool", "end_pool"]

#: Seconds to connect to a Dask scheduler, handshake included.
SCHEDULER_TIMEOUT = 10.0
#: Seconds to wait for the scheduler's first worker.
WORKERS_TIMEOUT = 30.0
#: The largest buffer (bytes) a worker's malloc takes from its heap rather than mapping
#: it apart (glibc's own ceiling for its adaptive threshold).
MMAP_THRESHOLD = 32 * 2**20
#: Bytes a worker's malloc keeps at the top of a heap when it returns memory to the
#: system (a run's buffers are not given back and faulted in again at every call).
TOP_PAD = 16 * 2**20


def cores() -> int:
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not on Linux
        return os.cpu_count() or 1


def worker_init(parent: int) -> None:
    """Initializer of a local pool's worker process: it leaves Ctrl-C to its parent
    (which ends the pool) and dies with it (:func:`die_with_parent`). This module is
    light to import, so a spawned worker runs this within moments of starting, before
    the toolkit's heavy imports.

    Parameters
    ----------
    parent : int
        The pid of the process that made the pool.
    """
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    die_with_parent(parent=parent)
    heap_for_large_buffers()


def heap_for_large_buffers() -> None:
    """Large buffers from the heap again in a worker process whose environment sets
    ``MALLOC_TRIM_THRESHOLD_``: a Dask worker's (Dask's nanny sets it to 64 KiB, and
    leaves it in the environment of the process that started a ``LocalCluster``, so
    that a process pool started there later inherits it too).

    Setting that variable also freezes glibc's mmap threshold at 128 KiB: every larger
    buffer of a simulation is then mapped, faulted in page by page and unmapped at each
    call; and the heap of a thread (a Dask task runs in one) is trimmed down to 64 KiB
    after each call and faulted in again. Measured on the reference Monte Carlo
    (``benchmarks/bench_sweep.py``): 3 300 page faults and 6.8 ms of system time per
    run, 2.5 times the run's CPU time; in a thread still 650 faults and 1.4 ms after
    the mmap threshold alone. This sets the mmap threshold to :data:`MMAP_THRESHOLD`,
    where glibc's adaptive rule would take it, and keeps :data:`TOP_PAD` at the top of
    a heap when it is trimmed (20 faults a run, as without the variable); memory
    beyond that is still returned to the system. Where ``MALLOC_MMAP_THRESHOLD_`` or
    ``MALLOC_TOP_PAD_`` is set too, the environment's choice is kept; nothing changes
    off glibc.
    """
    if "MALLOC_TRIM_THRESHOLD_" not in os.environ:
        return
    try:
        import ctypes

        libc = ctypes.CDLL(None)
        if "MALLOC_MMAP_THRESHOLD_" not in os.environ:
            libc.mallopt(-3, MMAP_THRESHOLD)  # M_MMAP_THRESHOLD
        if "MALLOC_TOP_PAD_" not in os.environ:
            libc.mallopt(-2, TOP_PAD)  # M_TOP_PAD
    except (OSError, AttributeError):  # pragma: no cover - not glibc
        pass


def die_with_parent(poll: float = 0.2, parent: int | None = None) -> None:
    """Make this worker process end when its parent dies, even by SIGKILL (no orphans
    computing for nobody): on Linux the kernel sends SIGKILL on the parent's death
    (``prctl(PR_SET_PDEATHSIG)``); everywhere a daemon thread also polls the parent's
    pid every ``poll`` seconds and ends the process when it changes.

    Parameters
    ----------
    poll : float
        Seconds between the watchdog's checks (s).
    parent : int, optional
        The parent's pid as the parent saw it (default: the parent now): a parent that
        died before this call is noticed.
    """
    import signal

    parent = os.getppid() if parent is None else parent
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, int(signal.SIGKILL), 0, 0, 0)  # PR_SET_PDEATHSIG = 1
    except (OSError, AttributeError):  # pragma: no cover - not Linux
        pass
    if os.getppid() != parent:  # the parent died before the death signal was set
        os._exit(1)

    def watch():
        while os.getppid() == parent:
            threading.Event().wait(poll)
        os._exit(1)

    threading.Thread(target=watch, name="ema-parent-watchdog", daemon=True).start()


def check_main_guard(error: type, what: str) -> None:
    """Refuse, with one line, to start worker processes from a script that calls this
    outside ``if __name__ == "__main__":``.

    Worker processes are started by *spawn*: each imports the main script again, so an
    unguarded call runs the work once more in every worker (which then fails in
    confusing ways). Two checks, before any work: in a worker while it imports the
    script (spawn's bootstrapping), and in the script itself (the top-level statement
    running now lies outside every ``if __name__ == "__main__":`` block). Interactive
    sessions, notebooks and ``python -c`` have no script and pass.

    Parameters
    ----------
    error : type
        The exception raised.
    what : str
        The call, for the message (``"sweep(jobs=2)"``).
    """
    import multiprocessing
    import sys

    fix = (f"{what} starts worker processes, which import the main script again: put the call under "
           "'if __name__ == \"__main__\":' (or use jobs=1, or threads)")
    if getattr(multiprocessing.current_process(), "_inheriting", False):
        raise error(fix + " (this is a worker importing the unguarded script)")
    main = sys.modules.get("__main__")
    path = getattr(main, "__file__", None)
    if not path or getattr(main, "__spec__", None) is not None:  # no script, or python -m (a module)
        return
    frame = sys._getframe(1)
    while frame is not None and not (frame.f_code.co_name == "<module>" and frame.f_globals.get("__name__") ==
                                     "__main__" and frame.f_code.co_filename == path):
        frame = frame.f_back
    if frame is not None and not _inside_main_guard(path, frame.f_lineno):
        raise error(f"{path}, line {frame.f_lineno}: " + fix)


def _inside_main_guard(path: str, line: int) -> bool:
    """True when ``line`` of the script lies in an ``if __name__ == "__main__":`` block
    (or the script cannot be read: then nothing is refused)."""
    import ast

    try:
        with open(path, encoding="utf-8") as fh:
            tree = ast.parse(fh.read())
    except (OSError, SyntaxError, ValueError):
        return True
    for node in tree.body:
        if isinstance(node, ast.If) and _is_main_test(node.test):
            end = node.end_lineno or node.lineno
            if node.lineno <= line <= end:
                return True
    return False


def _is_main_test(test) -> bool:
    import ast

    if not (isinstance(test, ast.Compare) and len(test.ops) == 1 and isinstance(test.ops[0], ast.Eq)):
        return False
    sides = [test.left, test.comparators[0]]
    names = [s.id for s in sides if isinstance(s, ast.Name)]
    texts = [s.value for s in sides if isinstance(s, ast.Constant)]
    return names == ["__name__"] and texts == ["__main__"]


def timeout(name: str, default: float, error: type) -> float:
    """Seconds from the environment variable ``name`` (default ``default``); ``error``
    when it is not a number.

    Parameters
    ----------
    name : str
        The environment variable.
    default : float
        Its default (s).
    error : type
        The exception raised.
    """
    try:
        return float(os.environ.get(name, default))
    except ValueError:
        raise error(f"{name}={os.environ[name]!r}: expected a number of seconds") from None


def connect(address: str, error: type, wait: float | None = None):
    """A Dask Client for ``address``, or ``error`` after ``wait`` seconds (default
    :data:`SCHEDULER_TIMEOUT` or its environment variable).

    ``Client(address, timeout=...)`` does not bound the handshake with a server that
    accepts the connection and never answers, so the connection is made on a helper
    thread and abandoned (daemon) when it does not finish in time.

    Parameters
    ----------
    address : str
        ``tcp://host:port``.
    error : type
        The exception raised (one line naming the address).
    wait : float, optional
        Seconds allowed.
    """
    try:
        from dask.distributed import Client
    except ImportError:
        raise error("a Dask scheduler needs Dask: pip install 'ema_casadi[dask]' (dask[distributed])") from None
    wait = timeout("EMA_CASADI_SCHEDULER_TIMEOUT", SCHEDULER_TIMEOUT, error) if wait is None else wait
    box = {}

    def run():
        try:
            box["client"] = Client(address, timeout=f"{wait}s")
        except Exception as exc:  # noqa: BLE001 - any connection problem is the user's address
            box["error"] = exc

    helper = threading.Thread(target=run, name="ema-dask-connect", daemon=True)
    helper.start()
    helper.join(wait + 1.0)
    if helper.is_alive():
        raise error(f"scheduler {address}: no answer within {wait:g} s (is it a Dask scheduler?)")
    if "error" in box:
        exc = box["error"]
        first = str(exc).splitlines()[0] if str(exc) else ""
        raise error(f"scheduler {address}: cannot connect ({type(exc).__name__}: {first})")
    return box["client"]


def worker_threads(client, address: str, error: type) -> int:
    """The threads of the cluster's workers, once at least one has joined (``error``
    when none joins within ``EMA_CASADI_WORKERS_TIMEOUT``)."""
    wait_workers = timeout("EMA_CASADI_WORKERS_TIMEOUT", WORKERS_TIMEOUT, error)
    try:
        client.wait_for_workers(1, timeout=wait_workers)
    except TimeoutError:
        raise error(f"scheduler {address}: no worker joined within {wait_workers:g} s") from None
    return max(1, sum(w.get("nthreads", 1) for w in client.scheduler_info().get("workers", {}).values()))


def process_pool(jobs: int, initializer=None, initargs: tuple = ()):
    """A pool of ``jobs`` worker processes (spawn) whose workers leave Ctrl-C to this
    process and die with it (:func:`worker_init`: killed, no orphans).

    Parameters
    ----------
    jobs : int
        Worker processes.
    initializer : callable, optional
        Called as ``initializer(parent_pid, *initargs)`` in each worker instead of
        :func:`worker_init` (it calls that first).
    initargs : tuple
        Its further arguments.
    """
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    return ProcessPoolExecutor(max_workers=jobs, mp_context=multiprocessing.get_context("spawn"),
                               initializer=initializer or worker_init, initargs=(os.getpid(), *initargs))


def end_pool(pool) -> None:
    """Stop a pool at once (on an interrupt or an error): nothing more is started, the
    pending work is cancelled and a process pool's workers are ended.

    Parameters
    ----------
    pool : concurrent.futures.Executor
        A process or thread pool.
    """
    procs = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for proc in procs:
        proc.terminate()
