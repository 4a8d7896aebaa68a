"""The physical-envelope monitor of every run (the reliability contract, docs: reliability: no silent garbage).

A run is *failed*, never a result, when a state or output leaves the envelope its
part declares (:meth:`~ema_casadi.model.assembly.Model.envelope`: the rod beyond the stroke
with end stops off, a current above 3 x I_max, a speed above 3 x the no-load
speed, ...), when a value is not finite, or when the integrator gives up (CVODES
``CV_TOO_MUCH_WORK``, ``CV_CONV_FAILURE``, ``CV_ERR_FAILURE``, ``CV_ILL_INPUT``, ...).
The API raises :class:`RunFailed` with the reason, the time and the result up to the
failure; the CLI ends with exit status 3 and one line.

CasADi prints an integrator's complaint and the inputs of the failed call on
``sys.stderr``; :func:`captured_stderr` collects it per thread, so the reason can
quote CVODES's own line and nothing else reaches the terminal.
"""

from __future__ import annotations

import contextlib
import io
import re
import sys
import threading
from dataclasses import dataclass

import numpy as np

from .._util._errors import RunError

__all__ = ["RunFailed", "AnalysisFailed", "GaveUp", "Monitor", "Violation", "captured_stderr", "integrator_failure",
           "monitor_for"]


class RunFailed(RunError):
    """A run that left the physical envelope, went non-finite or whose integrator
    failed; not a user mistake (so not a :class:`SimulationError`).

    Parameters
    ----------
    what : str
        The reason without the time, one line ("x_rod = 0.08 m beyond its envelope ...").
    time : float
        Simulated time of the failure (s).
    result : SimResult, optional
        The run up to the failure (its last sample is the failing one where it could
        be computed); its ``info`` gets ``status`` "failed" and the ``reason``.

    Attributes
    ----------
    reason : str
        ``what`` with the time: the one-line message.
    """

    def __init__(self, what: str, time: float, result=None):
        self.what, self.time, self.result = what, float(time), result
        self.reason = f"{what} at t = {self.time:.6g} s"
        if result is not None:
            result.info.update(status="failed", reason=self.reason)
        super().__init__(self.reason)


class AnalysisFailed(RunFailed):
    """An analysis that ended without a result and at no instant of a run (a fit that did
    not converge, a design that could not be made): the reason alone, one line (the
    command line: exit status 3).

    Parameters
    ----------
    what : str
        The reason, one line.
    """

    def __init__(self, what: str):
        super().__init__(what, 0.0, None)
        self.reason = what
        self.args = (what,)


@dataclass(frozen=True)
class Violation:
    """The first sample of a run outside its envelope.

    Attributes
    ----------
    index : int
        Column of the checked samples.
    time : float
        Its time (s).
    what : str
        The reason without the time.
    finite_before : bool
        The sample before it was finite and inside the envelope.
    """

    index: int
    time: float
    what: str
    finite_before: bool


def monitor_for(model, p) -> Monitor:
    """The model's :class:`Monitor` at parameter vector ``p``, built once per vector
    (cached on the model: a sweep or a sine stream reuses it).

    Parameters
    ----------
    model : Model
        The assembled model.
    p : array_like
        Parameter vector (SI).
    """
    cache = model.cache.setdefault("monitors", {})
    key = np.asarray(p, float).tobytes()
    mon = cache.get(key)
    if mon is None:
        if len(cache) >= 64:
            cache.pop(next(iter(cache)))
        mon = cache[key] = Monitor(model, p)
    return mon


class Monitor:
    """Checks samples of a run against the model's envelope at one parameter vector.

    Parameters
    ----------
    model : Model
        The assembled model.
    p : array_like
        Parameter vector (SI).
    """

    def __init__(self, model, p):
        env = model.envelope(p)
        self.model = model
        # per group (states, outputs, inputs): names, declarations, bounded rows, bounds
        self._groups = []
        for kind, names, info in (("state", model.states, model.state_info),
                                  ("output", model.outputs, model.output_info),
                                  ("input", model.inputs, model.input_info)):
            rows = np.array([i for i, n in enumerate(names) if n in env], int)
            self._groups.append((kind, names, info, rows, np.array([env[names[i]] for i in rows], float)))

    def first(self, t, X, Y=None, U=None) -> Violation | None:
        """The first sample outside the envelope or not finite, or None.

        Parameters
        ----------
        t : array_like
            Sample times (s), one per column.
        X : ndarray or None
            States (nx x n, SI); None checks only the others.
        Y : ndarray, optional
            Outputs (ny x n, SI).
        U : ndarray, optional
            Inputs (nu x n, SI).
        """
        data = [None if Z is None else np.asarray(Z, float).reshape(len(g[1]), -1)
                for Z, g in zip((X, Y, U), self._groups, strict=True)]
        if all(self._inside(Z, g[3], g[4]) for Z, g in zip(data, self._groups, strict=True) if Z is not None):
            return None  # the common case, decided without a per-sample mask
        n = next(Z.shape[1] for Z in data if Z is not None)
        bad = np.zeros(n, bool)
        for Z, (_, _, _, rows, b) in zip(data, self._groups, strict=True):
            if Z is not None:
                bad |= ~np.all(np.isfinite(Z), axis=0)
                if len(rows):
                    with np.errstate(invalid="ignore"):
                        bad |= np.any(np.abs(Z[rows]) > b[:, None], axis=0)
        if not bad.any():
            return None
        j = int(np.argmax(bad))
        return Violation(j, float(np.asarray(t, float).ravel()[j]), self._what(data, j), j > 0)

    @staticmethod
    def _inside(Z, rows, b) -> bool:
        if not np.isfinite(Z).all():
            return False
        return not len(rows) or bool((np.abs(Z[rows]).max(axis=1) <= b).all())

    def _what(self, data, j) -> str:
        # a non-finite value first (the plainer reason); inputs first (the cause), then
        # outputs (the signals users know: x_rod rather than the shaft angle)
        order = (2, 1, 0)
        for g in order:
            Z, (kind, names, _, _, _) = data[g], self._groups[g]
            if Z is not None:
                nf = np.nonzero(~np.isfinite(Z[:, j]))[0]
                if len(nf):
                    return f"non-finite {kind} {names[nf[0]]} = {Z[nf[0], j]}"
        for g in order:
            Z, (kind, names, info, rows, b) = data[g], self._groups[g]
            if Z is not None and len(rows):
                over = np.nonzero(np.abs(Z[rows, j]) > b)[0]
                if len(over):
                    k = over[0]
                    name = names[rows[k]]
                    unit = self.model.units.get(name, "")
                    value, bound = _distinct(float(Z[rows[k], j]), float(b[k]))
                    return (f"{kind} {name} = {value} {unit} left its physical envelope |{name}| <= "
                            f"{bound} {unit} ({info[name].bound.why})")
        raise AssertionError("no violation at the flagged sample")  # pragma: no cover


def _distinct(value: float, bound: float) -> tuple[str, str]:
    """``value`` and ``bound`` with 4 significant digits, or as many more as it takes for
    the magnitude of the one to read differently from the other (0.07601 vs 0.076)."""
    for digits in range(4, 18):
        v, b = f"{value:.{digits}g}", f"{bound:.{digits}g}"
        if f"{abs(value):.{digits}g}" != b:
            return v, b
    return repr(value), repr(bound)


# -- what CasADi prints -----------------------------------------------------------------
class _PerThreadStderr(io.TextIOBase):
    """``sys.stderr`` while captures are open: a thread with an open capture writes
    into it, every other thread to the stream that was there before."""

    def __init__(self, real):
        self.real = real
        self.local = threading.local()

    def write(self, s):
        buf = getattr(self.local, "buf", None)
        return (buf if buf is not None else self.real).write(s)

    def flush(self):
        if getattr(self.local, "buf", None) is None:
            self.real.flush()

    def __getattr__(self, name):
        return getattr(self.real, name)


_capture_lock = threading.Lock()
_capture_state = {"count": 0, "proxy": None}


@contextlib.contextmanager
def captured_stderr():
    """Collect what is written to ``sys.stderr`` from this thread (CasADi's and
    CVODES's messages) in the yielded ``StringIO``; other threads write as before."""
    with _capture_lock:
        if _capture_state["count"] == 0:
            _capture_state["proxy"] = _PerThreadStderr(sys.stderr)
            sys.stderr = _capture_state["proxy"]
        _capture_state["count"] += 1
        proxy = _capture_state["proxy"]
    buf = io.StringIO()
    saved = getattr(proxy.local, "buf", None)
    proxy.local.buf = buf
    try:
        yield buf
    finally:
        proxy.local.buf = saved
        with _capture_lock:
            _capture_state["count"] -= 1
            if _capture_state["count"] == 0:
                if sys.stderr is proxy:
                    sys.stderr = proxy.real
                _capture_state["proxy"] = None


_FLAGS = {
    "CV_TOO_MUCH_WORK": "too many steps (max_num_steps) without reaching the output time",
    "CV_TOO_MUCH_ACC": "the accuracy asked for is beyond machine precision",
    "CV_ERR_FAILURE": "the error test failed repeatedly or with |h| = hmin",
    "CV_CONV_FAILURE": "the Newton iteration failed to converge repeatedly or with |h| = hmin",
    "CV_LSETUP_FAIL": "the linear-solver setup failed",
    "CV_LSOLVE_FAIL": "the linear solve failed",
    "CV_RHSFUNC_FAIL": "the right-hand side failed",
    "CV_REPTD_RHSFUNC_ERR": "the right-hand side failed repeatedly",
    "CV_ILL_INPUT": "illegal input (typically a non-finite state or right-hand side)",
}
_T_RE = re.compile(r"At t\s*=\s*([-+0-9.eE]+)")


class GaveUp(RunError):
    """An integrator gave up (the one such exception of the package): ``what`` (one line)
    and ``time``, the integrator's time where it did (s, or the normalised time of a
    sine-stream period). Callers turn it into a failed run (:class:`RunFailed`, a failed point).

    Parameters
    ----------
    what : str
        Why, one line.
    time : float
        Where (s).
    """

    def __init__(self, what: str, time: float):
        super().__init__(what)
        self.what, self.time = what, time


def integrator_failure(exc: BaseException, log: str, to_time=None, default_time: float = 0.0):
    """``(what, time)`` for an integrator that gave up, from CasADi's error and what it
    printed.

    Parameters
    ----------
    exc : BaseException
        CasADi's error (a RuntimeError naming the CVODES flag).
    log : str
        What CasADi printed meanwhile (:func:`captured_stderr`).
    to_time : callable, optional
        Maps the integrator's own time (CVODES's "At t = ...") to simulated time (s),
        for integrators in normalised time.
    default_time : float
        Time reported when CVODES named none (s).
    """
    text = str(exc)
    flag = next((f for f in _FLAGS if f in text), None)
    what = "CVODES failed: " + (f"{_FLAGS[flag]} ({flag})" if flag else (text.splitlines() or ["?"])[-1].strip())
    m = _T_RE.search(log) or _T_RE.search(text)
    t = float(m.group(1)) if m else None
    if t is None:
        return what, default_time
    return what, (to_time(t) if to_time else t)
