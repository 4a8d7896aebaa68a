"""``simulate()``: validate the request, build the input signals, run a solver."""

from __future__ import annotations

import math
import time

import numpy as np

from ..assembly import Model
from ..params import Parameters
from ._cvodes import _simulate_cvodes, _simulate_cvodes_hybrid
from ._inputs import _input_signals
from ._result import SimResult, SimulationError
from ._rk4 import _simulate_rk4

SOLVERS = ("rk4", "cvodes")


def simulate(
    model: Model,
    t_end: float,
    x_cmd=0.0,
    f_ext=0.0,
    eta=None,
    *,
    dt: float = 1e-5,
    solver: str = "rk4",
    params: Parameters | None = None,
    p: np.ndarray | None = None,
    x0: np.ndarray | None = None,
    zoh: bool = False,
    decimate: int | None = None,
    dt_out: float | None = None,
    rtol: float = 1e-8,
    atol: float = 1e-11,
    event_tol: float = 1e-7,
    jit: bool = True,
    progress: bool = False,
    **signals,
) -> SimResult:
    """Simulate ``model`` from 0 to ``t_end`` (s).

    Parameters
    ----------
    model : Model
        From :func:`~ema_casadi.assembly.build_model`.
    t_end : float
        End time (s).
    x_cmd, f_ext, eta : Signal, float or str
        Commanded rod position (m), external force (N, positive pushes the rod in),
        screw efficiency (-, default the parameter set's eta).
    **signals : Signal, float or str
        Any other model input by name (``model.inputs``, e.g. the loop-break
        injections ``d_x``); strings in the unit of the input's quantity kind.
        Undriven inputs take their declared default.
    dt : float
        RK4 step (s); for ``cvodes`` the default output spacing when ``dt_out`` is not
        given.
    solver : {"rk4", "cvodes"}
    params, p : Parameters or array, optional
        Parameter values (default: the model's set); ``p`` is the raw vector.
    x0 : array, optional
        Initial state (default: at rest, all zero).
    zoh : bool
        Sampled ECU at its rates (rk4 only).
    decimate, dt_out : int or float, optional
        Keep every ``decimate``-th step, or one sample per ``dt_out`` seconds
        (default: every step for rk4, every ``dt`` for cvodes).
    rtol, atol : float
        CVODES tolerances.
    event_tol : float
        cvodes with hybrid friction: the stick/slip switching instants are located to
        within this time (s) before the integrator is restarted.
    jit : bool
        Compile the rollout to native code (cached on disk).
    progress : bool
        Progress bar on stderr.
    """
    _check_request(t_end, dt, solver, zoh, event_tol)
    pv = np.asarray(p, float) if p is not None else model.p(params)
    if pv.shape != (len(model.param_names),):
        raise SimulationError(f"p must have {len(model.param_names)} entries, got shape {pv.shape}")
    sig = _input_signals(model, {"x_cmd": x_cmd, "f_ext": f_ext, "eta": eta, **signals}, pv)
    x0 = model.x0() if x0 is None else np.asarray(x0, float)
    if decimate is None:
        decimate = max(1, int(round(dt_out / dt))) if dt_out else 1
    t_wall = time.perf_counter()
    if solver == "rk4":
        res = _simulate_rk4(model, t_end, sig, pv, x0, dt, zoh, decimate, jit, progress)
    elif model.hybrid:
        res = _simulate_cvodes_hybrid(model, t_end, sig, pv, x0, dt_out or dt * decimate, rtol, atol, event_tol,
                                      progress)
    else:
        res = _simulate_cvodes(model, t_end, sig, pv, x0, dt_out or dt * decimate, rtol, atol, progress)
    res.info["wall_time"] = time.perf_counter() - t_wall
    res.info.update(solver=solver, variants=dict(model.variants), t_end=t_end)
    return res


def _check_request(t_end, dt, solver, zoh, event_tol):
    if solver not in SOLVERS:
        raise SimulationError(f"solver '{solver}' unknown; choose one of {', '.join(SOLVERS)}")
    for name, val in (("t_end", t_end), ("dt", dt)):
        if not (isinstance(val, (int, float)) and math.isfinite(val) and val > 0):
            raise SimulationError(f"{name} must be a positive finite number of seconds, got {val!r}")
    if dt > t_end:
        raise SimulationError(f"dt ({dt} s) is longer than t_end ({t_end} s)")
    if zoh and solver != "rk4":
        raise SimulationError("zoh (sampled ECU) needs solver rk4")
    if not (math.isfinite(event_tol) and event_tol > 0):
        raise SimulationError(f"event_tol must be a positive number of seconds, got {event_tol!r}")
