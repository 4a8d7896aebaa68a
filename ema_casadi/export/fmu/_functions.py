"""The CasADi Functions every fixed-step export carries (C, CasADi, co-simulation FMU).

``ema_f(x, u, p) -> (xdot, y)``
    The right-hand side (``model.f``).
``ema_init(x0, u, p) -> xa``
    The augmented start state. With hybrid friction: the initial state projected into
    a consistent mode (``model.project``), then the stick flag and a zero switch count
    (``xa = [x; stick; mode_switches]``); otherwise ``xa = x0``.
``ema_step(xa, U3, p, h) -> xa_next``
    One step of the toolkit's own fixed-step RK4 (``rk4_step_function(model,
    count_modes=model.hybrid)``): the hybrid stick-slip projection and the switch count
    are inside. ``U3`` holds the inputs at t, t + h/2 and t + h in its three columns.
``ema_out(xa, u, p) -> y``
    The outputs at ``xa`` with inputs ``u``; with hybrid friction ``stick`` is the mode
    the step decided (as ``ema.simulate`` reports it).
``ema_sim(xa0, U, p, h) -> (XA, Y)``
    ``n`` steps in one call (``mapaccum`` of ``ema_step``): ``U`` is ``nu x 3n`` (the
    three columns of each step side by side), ``XA`` and ``Y`` hold the state and the
    outputs (inputs at the step's end) after each step. Chain calls for longer runs.

Loop-break flags of the sampled ECU are not used: the exports run the continuous ECU
(``zoh=False``), as ``ema.simulate`` does by default.
"""

from __future__ import annotations

import casadi as ca

from ...model.assembly import Model
from ...simulation import rk4_step_function

__all__ = ["fixed_step_functions", "augmented_names", "SIM_STEPS"]

#: Steps per call of ``ema_sim`` (the CasADi export's rollout).
SIM_STEPS = 1000


def augmented_names(model: Model) -> list[str]:
    """Names of the entries of ``xa`` (the states, then ``stick``, ``mode_switches``).

    Parameters
    ----------
    model : Model
        The assembled model.
    """
    return list(model.states) + ([model.output_with("stuck"), "mode_switches"] if model.hybrid else [])


def fixed_step_functions(model: Model, n_sim: int | None = None, prefix: str = "ema") -> dict:
    """``{name: Function}`` for ``f``, ``init``, ``step``, ``out`` (and ``sim``).

    Parameters
    ----------
    model : Model
        The assembled model.
    n_sim : int, optional
        Steps per call of ``<prefix>_sim``; without it no rollout is built.
    prefix : str
        Prefix of the Function names.
    """
    nx, nu, npar = model.nx, model.nu, len(model.param_names)
    rk4 = rk4_step_function(model, zoh=False, count_modes=model.hybrid)
    nxa = rk4.size1_in(0)
    xa, U3 = ca.SX.sym("xa", nxa), ca.SX.sym("U3", nu, 3)
    x, u, p, h = ca.SX.sym("x", nx), ca.SX.sym("u", nu), ca.SX.sym("p", npar), ca.SX.sym("h")
    opts = {"cse": True}
    fns = {}
    xdot, y = model.f(x, u, p)
    fns["f"] = ca.Function(f"{prefix}_f", [x, u, p], [xdot, y], ["x", "u", "p"], ["xdot", "y"], opts)
    if model.hybrid:
        xp, stick = model.project(x, x, u, p)
        xa0 = ca.vertcat(xp, stick, 0)
    else:
        xa0 = x
    fns["init"] = ca.Function(f"{prefix}_init", [x, u, p], [xa0], ["x0", "u", "p"], ["xa"], opts)
    step = rk4(xa, U3, ca.DM.zeros(len(model.loops)), p, h)
    fns["step"] = ca.Function(f"{prefix}_step", [xa, U3, p, h], [step], ["xa", "U3", "p", "h"], ["xa_next"], opts)
    y_out = model.f(xa[:nx], u, p)[1]
    if model.hybrid:
        k = model.yindex(model.output_with("stuck"))
        y_out = ca.vertcat(y_out[:k], xa[nx], y_out[k + 1 :])
    fns["out"] = ca.Function(f"{prefix}_out", [xa, u, p], [y_out], ["xa", "u", "p"], ["y"], opts)
    if n_sim:
        fns["sim"] = _rollout(fns["step"], fns["out"], nxa, nu, npar, n_sim, f"{prefix}_sim")
    return fns


def _rollout(step, out, nxa, nu, npar, n, name):
    xa0, U = ca.MX.sym("xa0", nxa), ca.MX.sym("U", nu, 3 * n)
    p, h = ca.MX.sym("p", npar), ca.MX.sym("h")
    XA = step.mapaccum("steps", n)(xa0, U, p, h)
    u_end = U[:, ca.Slice(2, 3 * n, 3)]
    Y = out.map(n)(XA, u_end, p)
    return ca.Function(name, [xa0, U, p, h], [XA, Y], ["xa0", "U", "p", "h"], ["XA", "Y"])
