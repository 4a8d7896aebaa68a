"""Ctrl-C and SIGTERM (the reliability contract, docs: reliability): a run stops within about a second, leaving nothing.

The ``ema`` command line installs :func:`handling` first thing. On the first SIGINT
or SIGTERM its handler records the signal and raises :class:`Interrupted` in the main
thread (a ``BaseException``, like ``KeyboardInterrupt``, so ``except Exception`` does
not swallow it). CasADi turns an exception raised inside one of its calls into a
``RuntimeError`` ("rhs failed: KeyboardInterrupt"), so code that catches CasADi's
errors asks :func:`check` first, and long loops (simulation chunks, sine-stream
periods on worker threads, which never see signals) poll :func:`requested`.

A signal that arrives before :func:`handling` — while the ``ema`` process is still
importing its command line — is recorded by :func:`record_early` and replayed by
:func:`replay_early` as soon as the handling starts.

IPOPT asks :func:`check` at the end of every iteration (the optimisation layer's
callback: ``ema_casadi.optimisation.solve_ipopt``) and stops there. Work that cannot be
interrupted from Python (a long compiled evaluation): a watchdog started by the first
signal ends the process ``grace`` seconds later with the same status, after the
caller's ``on_timeout`` has removed the temporary files.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading

__all__ = ["Interrupted", "handling", "requested", "check", "exit_status", "record_early", "replay_early", "finished",
           "interruptible"]

SIGNALS = (signal.SIGINT, signal.SIGTERM)

_received: int | None = None
_early: int | None = None
_watchdog = None
_on_timeout = None
_on_signal = None
_grace = 1.0
_cancel = threading.Event()
_finished = False
_pid = None  # the process whose handling() has a watchdog (the ema process itself)


class Interrupted(BaseException):
    """SIGINT or SIGTERM arrived; ``signum`` says which.

    Parameters
    ----------
    signum : int
        The signal number.
    """

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def exit_status(signum: int) -> int:
    """The shell's status for a run ended by ``signum``: 128 + signum (130 SIGINT, 143 SIGTERM).

    Parameters
    ----------
    signum : int
        The signal number.
    """
    return 128 + int(signum)


def requested() -> int | None:
    """The signal number once SIGINT/SIGTERM arrived under :func:`handling`, else None."""
    return _received


def check() -> None:
    """Raise :class:`Interrupted` if a signal arrived (call where CasADi may have eaten it)."""
    if _received is not None:
        raise Interrupted(_received)


def record_early() -> None:
    """In the ``ema`` process only (``python -m ema_casadi.cli`` or the ``ema`` script):
    record SIGINT/SIGTERM from now until :func:`handling` takes over."""
    argv = list(getattr(sys, "orig_argv", ()))
    cli = "-m" in argv and argv[argv.index("-m") + 1 : argv.index("-m") + 2] == ["ema_casadi.cli"]
    if not (cli or os.path.basename(sys.argv[0] if sys.argv else "") == "ema"):
        return
    if threading.current_thread() is threading.main_thread():
        for s in SIGNALS:
            if signal.getsignal(s) is not signal.SIG_IGN:  # ignored by the parent: stays ignored
                signal.signal(s, _record)


def _record(signum, frame):
    global _early
    if _early is None:
        _early = signum


def replay_early() -> None:
    """Handle a signal :func:`record_early` kept (call first thing inside :func:`handling`)."""
    global _early
    if _early is not None:
        signum, _early = _early, None
        _handler(signum, None)


def finished() -> None:
    """The work is done and reported (the ``ema`` process only): SIGINT and SIGTERM are
    ignored from now on, through the end of :func:`handling` and the interpreter's
    shutdown, so that a signal in the last moments cannot kill the process silently
    (the default action) after a complete run."""
    global _finished
    if threading.current_thread() is threading.main_thread():
        _finished = True
        for s in SIGNALS:
            signal.signal(s, signal.SIG_IGN)


def _handler(signum, frame):
    global _received, _watchdog
    if _received is not None:
        return  # the first one is being handled: let the cleanup finish
    _received = signum
    if _on_signal is not None:
        _on_signal(signum)
    if _on_timeout is not None:
        _watchdog = threading.Thread(target=_watch, args=(signum,), name="ema-interrupt-watchdog", daemon=True)
        _watchdog.start()
    raise Interrupted(signum)


def _watch(signum):
    if not _cancel.wait(_grace):
        _on_timeout(signum)


@contextlib.contextmanager
def handling(on_timeout=None, grace: float = 1.0, on_signal=None):
    """Handle SIGINT and SIGTERM while the block runs (main thread only; elsewhere a no-op).

    Parameters
    ----------
    on_timeout : callable, optional
        ``on_timeout(signum)``, called on the watchdog thread when the block has not
        ended ``grace`` seconds after the first signal; it is expected to clean up and
        end the process. None: no watchdog.
    grace : float
        Seconds the run gets to unwind by itself (s).
    on_signal : callable, optional
        ``on_signal(signum)``, called in the handler on the first signal, before the
        run is interrupted (e.g. to silence what the unwinding prints).
    """
    global _received, _on_timeout, _on_signal, _grace, _watchdog, _finished
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    global _pid
    previous = {s: signal.getsignal(s) for s in SIGNALS}
    _received, _watchdog, _on_timeout, _on_signal, _grace = None, None, on_timeout, on_signal, grace
    _pid = os.getpid() if on_timeout is not None else None
    _finished = False
    _cancel.clear()
    for s in SIGNALS:
        if previous[s] is not signal.SIG_IGN:  # ignored by the parent (a background job): stays ignored
            signal.signal(s, _handler)
    try:
        yield
    finally:
        _cancel.set()
        for s, h in previous.items():
            signal.signal(s, signal.SIG_IGN if _finished else h)
        _received, _on_timeout, _on_signal, _watchdog, _pid = None, None, None, None, None


#: How often the parent of :func:`interruptible` looks for a signal and the answer (s).
POLL_S = 0.05


def interruptible(fn, *args):
    """``fn(*args)`` where a signal ends it at once, even inside a long compiled call.

    Python runs a signal handler only between bytecodes; CasADi's C++ (building an NLP's
    derivatives: 22 s CPU before IPOPT's first iteration at 2000 collocation intervals)
    holds the interpreter, and the watchdog thread cannot run either. In the ``ema``
    process (under :func:`handling` with a watchdog) the call therefore runs in a forked
    child whose answer (or error, the error family pickling whole) comes back through a
    pipe, while this process polls its signal flag every :data:`POLL_S`: a signal kills
    the child and raises :class:`Interrupted` here. Elsewhere (a script, a worker, a
    test calling ``main()``) it is a plain call.

    Parameters
    ----------
    fn : callable
        The work; its answer and errors must pickle.
    *args
        Its arguments (inherited by the fork, not pickled).
    """
    if _pid != os.getpid() or threading.current_thread() is not threading.main_thread() or os.name != "posix":
        return fn(*args)
    import multiprocessing

    ctx = multiprocessing.get_context("fork")
    recv, send = ctx.Pipe(duplex=False)
    child = ctx.Process(target=_child, args=(send, fn, args), daemon=True)
    for stream in (sys.stdout, sys.stderr):  # nothing buffered here that the child would write again
        stream.flush()
    child.start()
    send.close()
    try:
        while not recv.poll(POLL_S):
            check()
            if not child.is_alive() and not recv.poll(0):
                from ._errors import RunError

                raise RunError(f"the solver's process ended without an answer (exit status {child.exitcode})")
        kind, value = recv.recv()
    finally:
        if child.is_alive():
            child.kill()
        child.join()
    if kind == "error":
        raise value
    return value


def _child(send, fn, args):
    """The forked child of :func:`interruptible`: the parent signals it by killing it."""
    global _pid, _on_timeout
    _pid, _on_timeout = None, None
    for s in SIGNALS:
        signal.signal(s, signal.SIG_IGN)
    with contextlib.suppress(Exception):  # Linux: killed with its parent
        import ctypes

        ctypes.CDLL(None).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    try:
        answer = ("value", fn(*args))
    except BaseException as exc:  # noqa: BLE001 - sent to the parent, raised there
        answer = ("error", exc)
    try:
        send.send(answer)
    except Exception as exc:  # noqa: BLE001 - an answer that does not pickle
        from ._errors import RunError

        send.send(("error", RunError(f"{type(exc).__name__}: {exc}")))
    send.close()
