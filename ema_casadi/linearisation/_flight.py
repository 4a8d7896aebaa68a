"""Trim of the whole aircraft loop: airframe, flight-control law and actuator (docs: aircraft).

The airframe part declares what its trim solves for (``trim_free``: the throttle and
the attitude command) and which states it fixes (``trim_fix``: airspeed and altitude
at the flight condition's parameters ``V_0``, ``h_0``); the trim solves
``f(x, u, p) = 0`` together with those, by least-squares Newton on the AD Jacobian of
the augmented system, with the actuator's small-signal policy of
:func:`~ema_casadi.linearisation.operating_point` (friction and backlash ``off``, the
screw-nut efficiency frozen at its operating value, saturations lifted and then
checked). The result is an :class:`~ema_casadi.linearisation.OperatingPoint`, so
``linear_model``, ``loop_model`` (with the ``aircraft`` loop) and the margins serve it
unchanged.
"""

from __future__ import annotations

import numpy as np

from .._util._checks import instance
from ..model.assembly import Model
from ..model.params import Parameters
from ..optimisation import newton_step
from ._common import OperatingPointError, _eval
from ._trim import (
    OperatingPoint,
    _check_limits,
    _consistent,
    _freeze_efficiency,
    _frozen_values,
    _hold_at_rest,
    _lifted,
    _policy_vector,
    _row_scale,
    efficiency,
)

__all__ = ["flight_point"]


def _spec(model: Model, pv):
    """Free inputs and fixed states (with their values) declared by the parts."""
    free, fix = [], {}
    P = model.pdict(pv)
    for part in model.parts:
        free += list(part.trim_free)
        for name, val in part.trim_fix.items():
            fix[name] = float(getattr(P, val)) if isinstance(val, str) else float(val)
    if not free:
        raise OperatingPointError("the model has no outer loop to trim (airframe = none): use operating_point")
    return free, fix


def _newton(model, x, u, p, free, fix, size, tol, max_iter):
    """Least-squares Newton with backtracking on [f(x, u) ; x_fix - value] over (x, u_free)."""
    iu = [model.inputs.index(n) for n in free]
    ix = [model.index(n) for n in fix]
    vals = np.array(list(fix.values()))

    rest = model.rest_states(p)
    ip = [model.index(n) for n in rest]
    k_in = [model.yindex(sig) for sig in rest.values()]

    def residual(x, u):
        # a memory state (a play without backlash rests anywhere): held at its rest signal
        xdot, y, A, B, C, D = _eval(model, x, u, p)
        r = np.concatenate([xdot.ravel(), x[ix] - vals, x[ip] - y.ravel()[k_in]])
        scale = np.concatenate([_row_scale(A, B, x, u, 0.0, size), np.abs(vals) + size[ix], size[ip]])
        Jp = np.zeros((len(ip), model.nx + len(iu)))
        for row, j in enumerate(ip):
            Jp[row, : model.nx] = -C[k_in[row]]
            Jp[row, j] += 1.0
            Jp[row, model.nx:] = -D[k_in[row], iu]
        return r, r / np.where(scale > 0, scale, 1.0), A, B, Jp

    r, rs, A, B, Jp = residual(x, u)
    for _ in range(max_iter):
        rel = float(np.max(np.abs(rs)))
        if rel < tol:
            return x, u, rel
        J = np.zeros((len(r), model.nx + len(iu)))  # rows: f, fixed states, plays
        J[: model.nx, : model.nx] = A
        J[: model.nx, model.nx:] = B[:, iu]
        J[model.nx + np.arange(len(ix)), ix] = 1.0
        J[model.nx + len(ix):] = Jp
        step = newton_step(J, r, least_squares=True, rcond=1e-13)
        if not np.all(np.isfinite(step)):
            break
        for lam in (1.0, 0.5, 0.25, 0.125, 0.0625):
            x_n, u_n = x + lam * step[: model.nx], u.copy()
            u_n[iu] += lam * step[model.nx:]
            r_n, rs_n, A_n, B_n, Jp_n = residual(x_n, u_n)
            if np.all(np.isfinite(rs_n)) and np.max(np.abs(rs_n)) < max(rel, 1e-300) * (1 - 1e-4 * lam) or lam < 0.1:
                break
        x, u, r, rs, A, B, Jp = x_n, u_n, r_n, rs_n, A_n, B_n, Jp_n
    rows = [*(f"d{n}/dt" for n in model.states), *fix, *rest]
    worst = rows[int(np.argmax(np.abs(rs)))]
    raise OperatingPointError(f"the flight trim did not converge (relative residual {float(np.max(np.abs(rs))):.2g}"
                              f" in {worst})")


def _frozen_trim(model, x, u, p_trim, free, fix, size, tol, max_iter):
    """Newton with the efficiency blend frozen at g, g updated until consistent (as
    operating_point). Returns (x, u, g, relative residual)."""
    iu = [model.inputs.index(n) for n in free]
    g = _frozen_values(model, _eval(model, x, u, p_trim)[1].ravel())
    for _ in range(10):
        u_f, p_f = _freeze_efficiency(model, u, p_trim, g)
        x, u_f, rel = _newton(model, x, u_f, p_f, free, fix, size, tol, max_iter)
        u[iu] = u_f[iu]
        g_new = _frozen_values(model, _eval(model, x, u, p_trim)[1].ravel())
        if _consistent(g_new, g):
            break
        g = g_new
    return x, u, g, rel


def flight_point(model: Model, *, f_ext: float = 0.0, params: Parameters | None = None,
                 p: np.ndarray | None = None, tol: float = 1e-12, max_iter: int = 60) -> OperatingPoint:
    """Trim the aircraft loop at the flight condition of the parameters (``V_0``, ``h_0``).

    Parameters
    ----------
    model : Model
        A model with an airframe (``airframe = "transport"`` or ``"b747"``).
    f_ext : float
        External rod force (N) on top of the surface's, positive pushes the rod in.
    params, p : Parameters or ndarray, optional
        Parameter values (default the model's); ``p`` the raw vector. Loops are closed.
    tol : float
        Relative residual to reach (-).
    max_iter : int
        Newton iterations.

    Raises
    ------
    OperatingPointError
        No outer loop to trim, no convergence, or a saturation active at the point.
    """
    instance(model, Model, "model", OperatingPointError, " (from build_model)")
    pv = np.asarray(p, float).copy() if p is not None else model.p(params)
    names = list(model.param_names)
    for loop in model.loops.values():
        pv[names.index(loop.flag)] = 1.0
    p_pol, overrides = _policy_vector(model, pv, "off", "off")
    free, fix = _spec(model, p_pol)
    p_trim = _lifted(model, p_pol)
    size = model.full_scale(p_pol)
    x = model.x0()
    for n, v in fix.items():
        x[model.index(n)] = v
    u = model.u(pv)
    u[[model.inputs.index(n) for n in free]] = 0.1  # a starting guess: some throttle, nose up
    j_load = model.inputs.index(model.input_with("load"))
    for load in np.linspace(0.0, float(f_ext), 4) if f_ext else (0.0,):  # an extra load by continuation
        u[j_load] = load
        x, u, g, rel = _frozen_trim(model, x, u, p_trim, free, fix, size, tol, max_iter)
    # memory states exactly at their rest signal, as operating_point does (the play at the
    # nut, where both edges act: AD slope 1); the airframe fixes the shaft angle through the surface
    x = _hold_at_rest(model, x, u, p_trim)
    y = _eval(model, x, u, p_pol)[1].ravel()
    _check_limits(model, y, p_pol, float(y[model.yindex("F_load_rod")]) if "F_load_rod" in model.outputs else 0.0,
                  0.0)
    u_lin, p_lin = _freeze_efficiency(model, u, p_pol, g)
    x_cmd = float(y[model.yindex(model.output_with("rod_command"))])
    return OperatingPoint(
        x=x, u=u, y=y, p=p_pol, x_cmd=x_cmd, f_ext=float(u[j_load]), v_rod=0.0,
        xdot=np.zeros(model.nx), policy={"friction": "off", "backlash": "off", "overrides": overrides,
                                         "g_eff": next(iter(g.values()), None),
                                         "trim_free": {n: float(u[model.inputs.index(n)]) for n in free},
                                         "trim_fix": fix},
        states=model.states, inputs=model.inputs, outputs=model.outputs, param_names=model.param_names,
        residual=rel, variants=dict(model.variants), u_lin=u_lin, p_lin=p_lin, eta=efficiency(model, u),
    )
