"""Forward sensitivities of the compiled RODAS4 driver: the states at chosen sample
times and their derivatives with respect to chosen directions in the parameters (``W``)
and in the initial state (``S0``). One interface for every analysis that needs exact
derivatives of a trajectory: identification (the Jacobian of the residuals), periodic
orbits (the monodromy matrix: ``S0`` the identity, ``W`` zero) and experiment design
(the Fisher information).

The driver is the simulation's own (``simulation/_c/rosenbrock.c``), compiled with
``EMA_NS`` directions and ``_c/sensitivity.c`` appended: on every accepted step the
step's formulas are differentiated at its own step size, so the sensitivities are the
exact derivatives of the computed trajectory (not of a finite-difference neighbour),
at the cost of a Jacobian-vector product per stage and direction and a second
directional derivative per step, with the step's LU reused. One library per model and
number of directions, cached on disk; the parameter directions are data, so any set of
free parameters of that size runs on it. Input tables are evaluated by time, not by
segment, so the steps need not stop at every row of a record (2000 rows a second);
the error control sees the kinks of the interpolated input.
"""

from __future__ import annotations

import ctypes
import time
from pathlib import Path

import casadi as ca
import numpy as np

from .._util._compiled import compile_source
from .._util._interrupts import check as check_interrupt
from . import _rosenbrock as _ros
from ._envelope import RunFailed

_SENS = Path(__file__).with_name("_c") / "sensitivity.c"


def _jvp(ns):
    def make(x, u, p, xdot):
        V = ca.SX.sym("V", x.numel(), ns)
        W = ca.SX.sym("W", p.numel(), ns)
        d = ca.jtimes(xdot, ca.vertcat(x, p), ca.vertcat(V, W))
        return ca.Function("ros_jvp", [x, u, p, V, W], [ca.densify(d)], {"cse": True})
    return make


def _dj(ns):
    def make(x, u, p, xdot):
        ud = ca.SX.sym("ud", u.numel())
        K = ca.SX.sym("K", x.numel(), _ros_stages())
        V = ca.SX.sym("V", x.numel(), ns)
        W = ca.SX.sym("W", p.numel(), ns)
        F = ca.vertcat(ca.vec(ca.jtimes(xdot, x, K)), ca.jtimes(xdot, u, ud), xdot)
        d = ca.jtimes(F, ca.vertcat(x, p), ca.vertcat(V, W))
        return ca.Function("ros_dj", [x, u, ud, p, K, V, W], [ca.densify(d)], {"cse": True})
    return make


def _ros_stages() -> int:
    return 6  # ROS_S of the driver (RODAS4)


def sensitivity_library(model, ns: int):
    """The compiled driver with ``ns`` sensitivity directions, cached with the model and
    on disk (call it ahead to keep the compile out of a timing).

    Parameters
    ----------
    model : Model
        The assembled model.
    ns : int
        Number of sensitivity directions.

    Returns
    -------
    tuple
        The driver's entry point (None without a C compiler) and its build info.
    """
    key = ("rosenbrock_sens", ns)
    if key not in model.cache:
        parts = [_ros._DRIVER.read_bytes(), _SENS.read_bytes(), Path(_ros.__file__).read_bytes(),
                 Path(__file__).read_bytes(), model.f.serialize(), str(ns)]
        path, info = compile_source(
            f"rosenbrock_sens_{model.nx}_{ns}", parts,
            lambda: _ros._source(model, (_jvp(ns), _dj(ns)), {"EMA_NS": ns, "EMA_TABLE_BY_TIME": 1},
                                 _SENS.read_text()),
            ("-funroll-loops",))
        fn = None
        if path is not None:
            fn = ctypes.CDLL(str(path)).ema_ros_sens_run
            fn.restype = ctypes.c_int
            ptr = ctypes.c_void_p
            fn.argtypes = [ptr, ptr, ctypes.c_int, ptr, ptr, ctypes.c_int, ptr, ctypes.c_int, ptr, ptr, ptr,
                           ctypes.c_long, ptr, ctypes.POINTER(ctypes.c_int), ptr, ptr, ptr, ctypes.c_int, ptr,
                           ctypes.c_long, ptr]
        model.cache[key] = (fn, info)
    return model.cache[key]


#: Room for recorded step sizes per sample (the reference records take 1-4 steps per
#: sample at 2 kHz); a run that needs more is re-run with room for all.
_STEPS_PER_SAMPLE = 16
#: A replayed step whose error estimate exceeds this many times the tolerance ends the
#: replay: the run is made again with steps chosen by the error control (far from where
#: a grid was chosen the dynamics may need other steps; replayed blindly, a stiff
#: mode can then grow without bound).
REPLAY_LIMIT = 30.0


def forward_sensitivities(model, sig: dict, grid: np.ndarray, pv: np.ndarray, x0: np.ndarray, W: np.ndarray,
                          S0: np.ndarray, rtol: float, atol: float, steps: np.ndarray | None = None,
                          room: int | None = None, rows: bool = False) -> tuple[np.ndarray, np.ndarray, dict]:
    """States at the samples ``grid`` and their forward sensitivities along directions
    in the parameters (``W``) and in the initial state (``S0``): direction j of sample k is
    dx(t_k)/dp · W[:, j] + dx(t_k)/dx0 · S0[:, j] (``W = 0``, ``S0 = I``: the
    state-transition matrix, a periodic orbit's monodromy matrix at t = T). Without
    ``steps`` the error control chooses the steps (returned in ``info["step_sizes"]``);
    with them exactly those are taken, so the result is a smooth function of ``pv``; a
    replay whose error estimate exceeds :data:`REPLAY_LIMIT` times the tolerance falls back
    to chosen steps. Returns X (nx x n), S (n x ns x nx: sample, direction, state) and
    info; raises RunFailed when the driver gives up or the states go non-finite.

    Parameters
    ----------
    model : Model
        The assembled model (continuous: no hybrid friction, no sampled ECU).
    sig : dict
        Input signals by input name, as simulate builds them.
    grid, pv, x0, W, S0 : numpy.ndarray
        Sample times (s, from 0, ascending), the parameter vector, the initial state, the
        parameter directions (n_p x ns) and the initial-state directions (nx x ns).
    rtol, atol : float
        Tolerances of the error control.
    steps, room, rows : optional
        Step sizes (s) to replay (an earlier ``info["step_sizes"]``); how many step sizes
        to make room for (default 16 per sample); stop at every row of a table input too.
    """
    ns = W.shape[1]
    fn, cinfo = sensitivity_library(model, ns)
    if fn is None:
        raise RunFailed("forward sensitivities need a C compiler (the compiled RODAS4 with sensitivities)", 0.0, None)
    n = len(grid)
    t_end = float(grid[-1])
    # steps land on the breakpoints of steps, ramps, sines, not on a table's rows: the
    # driver finds a table's piece from the time (EMA_TABLE_BY_TIME), its kinks are left
    # to the error control (a record's input is a table of one row per sample)
    cuts = {b for s in sig.values() for term in s.terms if rows or term.kind != "table" for b in term.breakpoints()
            if 0 < b < t_end}
    edges = np.array(sorted({0.0, t_end, *cuts}), float)
    terms, tab = _ros._encode(model, sig)
    Xt = np.empty((n, model.nx))
    SX = np.empty((n, ns, model.nx))
    Xt[0] = x0
    SX[0] = np.asarray(S0, float).T
    state = np.concatenate([[0.0, min(_ros.H0, t_end), 0.0, 0.0, 0.0, 0.0], x0]).astype(float)
    S = np.array(np.asarray(S0, float).T, order="C")  # a copy (the driver writes it): column-major nx x ns
    Wc = np.ascontiguousarray(np.asarray(W, float).T)
    stats = np.zeros(len(_ros._STATS))
    opt = np.array([rtol, atol, t_end, _ros.H_FLOOR, _ros.MAX_FORCED, REPLAY_LIMIT])
    pv = np.ascontiguousarray(pv, float)
    grid = np.ascontiguousarray(grid, float)
    mode = 1 if steps is None else 2
    hs = np.zeros(room or _STEPS_PER_SAMPLE * n + 1000) if steps is None else np.ascontiguousarray(steps, float)
    hs_n = np.zeros(1)
    n_done = ctypes.c_int(0)
    done = 1
    t0 = time.perf_counter()
    while done < n:
        check_interrupt()
        status = fn(pv.ctypes.data, terms.ctypes.data, len(terms), tab.ctypes.data, edges.ctypes.data, len(edges),
                    grid[done:].ctypes.data, n - done, state.ctypes.data, Xt[done:].ctypes.data, opt.ctypes.data,
                    _ros.ATTEMPTS_PER_CALL, stats.ctypes.data, ctypes.byref(n_done), Wc.ctypes.data,
                    S.ctypes.data, SX[done:].ctypes.data, mode, hs.ctypes.data, len(hs), hs_n.ctypes.data)
        good = np.all(np.isfinite(Xt[done : done + n_done.value]))
        done += n_done.value
        if status in (-5, -6):  # the replayed grid does not fit these parameters: choose the steps
            return forward_sensitivities(model, sig, grid, pv, x0, W, S0, rtol, atol, rows=rows)
        if status < 0 or not good:
            what = _ros._failure(status, state[1], rtol, atol) if status < 0 else "non-finite states"
            raise RunFailed(what, float(state[0]), None)
    k = int(hs_n[0])
    if mode == 1 and k > len(hs):  # more steps than room: again with room for all
        return forward_sensitivities(model, sig, grid, pv, x0, W, S0, rtol, atol, room=k + 16, rows=rows)
    info = {"compute_time": time.perf_counter() - t0, **dict(zip(_ros._STATS, stats.astype(int).tolist(),
                                                                 strict=True)), **cinfo,
            "step_sizes": hs[:k].copy() if mode == 1 else steps}
    return Xt.T, SX, info

