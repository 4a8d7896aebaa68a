"""The symbolic interval integrator: a CasADi Function for direct multiple shooting.

``F(x, u, p, dt) -> x_next`` (or ``F(x, u, p, h, dt)`` with the held controller outputs
``h`` of :attr:`~ema_casadi.model.assembly.Model.f_held` as inputs) advances the model by
one interval of length ``dt`` (s) with the inputs (and holds) constant over it, by
``substeps`` classical RK4 steps of ``dt / substeps`` written symbolically (one compiled
substep Function called in a chain), so the interval length is an argument (a free final
time in an optimal control problem) and every derivative, of any order, is exact
(CasADi's algorithmic differentiation). CasADi's implicit collocation integrator was tried
first: its Newton iteration fails on the reference model's switches (screw-nut efficiency,
dead zone), so the explicit form is what is offered.

Continuous models only: a hybrid part's discrete map (stick-slip) or a switched bridge
is not part of the Function; choose their smooth variants.
"""

from __future__ import annotations

import casadi as ca

from .._util._checks import integer
from ..model.assembly import Model
from ._result import SimulationError

__all__ = ["interval_function"]


def interval_function(model: Model, *, held: bool = False, substeps: int = 10, quadrature: tuple = ()) -> ca.Function:
    """One shooting interval of ``model`` as a CasADi Function with exact derivatives.

    Parameters
    ----------
    model : Model
        A continuous model (no hybrid part; :attr:`Model.hybrid` is False).
    held : bool
        Use :attr:`Model.f_held` (the controller outputs ``h`` are inputs of the
        Function, the controller integrators frozen): the drive driven by its held
        references. Default: the continuous model ``f`` with the cascade in the loop.
    substeps : int
        Classical RK4 steps per interval, each ``dt / substeps`` long: keep it within
        RK4's stability limit of the configuration (the simulation's fixed-step
        default, 1e-5 s, on the reference model).
    quadrature : tuple of str
        Outputs whose sum is integrated over the interval by the same RK4 substeps (an
        energy from a power, J from W): the Function then has a second output ``q``.

    Returns
    -------
    casadi.Function
        ``F(x, u, p, dt) -> x_next`` (``F(x, u, p, h, dt)`` when ``held``; ``-> (x_next, q)``
        with a quadrature); x, u, p in ``model.states``, ``model.inputs``,
        ``model.param_names`` order (SI), dt in s.
    """
    if not isinstance(model, Model):
        raise SimulationError(f"model: expected a Model (from build_model), got {type(model).__name__}")
    if model.hybrid:
        raise SimulationError("model: a hybrid part (stick-slip friction) has a discrete map the interval Function "
                              "cannot carry; choose friction = smooth")
    substeps = integer(substeps, "substeps", SimulationError, minimum=1)
    quadrature = tuple(quadrature)
    unknown = [n for n in quadrature if n not in model.outputs]
    if unknown:
        raise SimulationError(f"quadrature: {unknown} are not outputs of the model")
    key = ("interval_function", held, substeps, quadrature)
    if key in model.cache:
        return model.cache[key]
    x = ca.SX.sym("x", model.nx)
    u = ca.SX.sym("u", model.nu)
    p = ca.SX.sym("p", len(model.param_names))
    dt = ca.SX.sym("dt")
    h = ca.SX.sym("h", len(model.holds))

    rows = [model.yindex(n) for n in quadrature]

    def rate(xs):
        xdot, y = model.f_held(xs, u, p, h) if held else model.f(xs, u, p)
        return xdot, sum(y[i] for i in rows) if rows else 0

    k = dt / substeps
    k1, q1 = rate(x)
    k2, q2 = rate(x + k / 2 * k1)
    k3, q3 = rate(x + k / 2 * k2)
    k4, q4 = rate(x + k * k3)
    x1 = x + k / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    dq = k / 6 * (q1 + 2 * q2 + 2 * q3 + q4)
    args = [x, u, p, h, dt] if held else [x, u, p, dt]
    names = ["x", "u", "p", "h", "dt"] if held else ["x", "u", "p", "dt"]
    step = ca.Function("rk4_substep", args, [x1, dq] if rows else [x1])
    xs = [ca.MX.sym(n, a.shape[0]) for n, a in zip(names, args, strict=True)]
    x_next, q = xs[0], 0
    for _ in range(substeps):
        if rows:
            x_next, dq_i = step(x_next, *xs[1:])
            q = q + dq_i
        else:
            x_next = step(x_next, *xs[1:])
    if rows:
        F = ca.Function("F", xs, [x_next, q], names, ["x_next", "q"])
        model.cache[key] = F
        return F
    F = ca.Function("F", xs, [x_next], names, ["x_next"])
    model.cache[key] = F
    return F
