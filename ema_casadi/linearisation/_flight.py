"""Trim of the whole aircraft loop: airframe, flight-control law and actuator (SPEC §4.8).

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

from .._checks import instance
from ..assembly import Model
from ..params import Parameters
from ._common import _LIFT, OperatingPointError, _eval
from ._trim import (
    OperatingPoint,
    _check_limits,
    _efficiency_factor,
    _freeze_efficiency,
    _policy_vector,
    _row_scale,
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

    def residual(x, u):
        xdot, _y, A, B, _C, _D = _eval(model, x, u, p)
        r = np.concatenate([xdot.ravel(), x[ix] - vals])
        scale = np.concatenate([_row_scale(A, B, x, u, 0.0, size), np.abs(vals) + size[ix]])
        return r, r / np.where(scale > 0, scale, 1.0), A, B

    r, rs, A, B = residual(x, u)
    for _ in range(max_iter):
        rel = float(np.max(np.abs(rs)))
        if rel < tol:
            return x, u, rel
        J = np.zeros((len(r), model.nx + len(iu)))
        J[: model.nx, : model.nx] = A
        J[: model.nx, model.nx:] = B[:, iu]
        J[model.nx + np.arange(len(ix)), ix] = 1.0
        step = np.linalg.lstsq(J, -r, rcond=1e-13)[0]
        if not np.all(np.isfinite(step)):
            break
        for lam in (1.0, 0.5, 0.25, 0.125, 0.0625):
            x_n, u_n = x + lam * step[: model.nx], u.copy()
            u_n[iu] += lam * step[model.nx:]
            r_n, rs_n, A_n, B_n = residual(x_n, u_n)
            if np.all(np.isfinite(rs_n)) and np.max(np.abs(rs_n)) < max(rel, 1e-300) * (1 - 1e-4 * lam) or lam < 0.1:
                break
        x, u, r, rs, A, B = x_n, u_n, r_n, rs_n, A_n, B_n
    raise OperatingPointError(f"the flight trim did not converge (relative residual {float(np.max(np.abs(rs))):.2g})")


def flight_point(model: Model, *, params: Parameters | None = None, p: np.ndarray | None = None,
                 tol: float = 1e-12, max_iter: int = 60) -> OperatingPoint:
    """Trim the aircraft loop at the flight condition of the parameters (``V_0``, ``h_0``).

    Parameters
    ----------
    model : Model
        A model with an airframe (``airframe = "transport"`` or ``"b747"``).
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
    p_trim = p_pol.copy()
    for k in ("I_max", "v_max", "k_v"):
        p_trim[names.index(k)] *= _LIFT
    size = model.full_scale(p_pol)
    x = model.x0()
    for n, v in fix.items():
        x[model.index(n)] = v
    u = model.u(pv)
    u[[model.inputs.index(n) for n in free]] = 0.1  # a starting guess: some throttle, nose up
    g = _efficiency_factor(model, _eval(model, x, u, p_trim)[1].ravel())
    for _ in range(10):
        u_f, p_f = _freeze_efficiency(model, u, p_trim, g)
        x, u_f, rel = _newton(model, x, u_f, p_f, free, fix, size, tol, max_iter)
        u[[model.inputs.index(n) for n in free]] = u_f[[model.inputs.index(n) for n in free]]
        g_new = _efficiency_factor(model, _eval(model, x, u, p_trim)[1].ravel())
        if abs(g_new - g) <= 1e-13 * abs(g):
            break
        g = g_new
    y = _eval(model, x, u, p_pol)[1].ravel()
    _check_limits(model, y, p_pol, float(y[model.yindex("F_load_rod")]) if "F_load_rod" in model.outputs else 0.0,
                  0.0)
    u_lin, p_lin = _freeze_efficiency(model, u, p_pol, g)
    x_cmd = float(y[model.yindex("x_cmd")])
    return OperatingPoint(
        x=x, u=u, y=y, p=p_pol, x_cmd=x_cmd, f_ext=float(u[model.inputs.index("f_ext")]), v_rod=0.0,
        xdot=np.zeros(model.nx), policy={"friction": "off", "backlash": "off", "overrides": overrides, "g_eff": g,
                                         "trim_free": {n: float(u[model.inputs.index(n)]) for n in free},
                                         "trim_fix": fix},
        states=model.states, inputs=model.inputs, outputs=model.outputs, param_names=model.param_names,
        residual=rel, variants=dict(model.variants), u_lin=u_lin, p_lin=p_lin,
    )
