"""Operating points and exact linearisation (SPEC §4.2).

An operating point (trim) is a state ``x`` at which the model is at rest for given
inputs: ``f(x, u, p) = 0`` with ``u = (x_cmd, f_ext, eta, 0, 0, 0)``. Optionally the
rod moves at a constant velocity ``v_rod``; the point is then a relative equilibrium
(every derivative zero except the positions', which move at ``v_rod``; the model only
sees position differences, so the linearisation does not depend on where along the
path it is taken). The trim is solved on the model itself by Newton's method with the
CasADi AD Jacobian.

The linear model is the exact AD Jacobian ``A, B, C, D`` of the same CasADi Function at
that point, returned as :class:`LinearModel` (NumPy, no python-control import) or as a
named ``control.StateSpace`` (:func:`linearize`).

Small-signal policy for the non-smooth elements
-----------------------------------------------
Each is handled through the parameter vector (the model is never rebuilt):

``backlash="off"`` (default)
    ``B = 0``: the dead-zone spring and the play operator are written so that B = 0
    gives slope exactly 1, so the drive train is linear. ``"keep"`` leaves ``B``; at
    an unloaded point the rod then sits inside the gap and is *decoupled* from the
    screw in the linear model (a warning says so); under load the screw is preloaded
    on one flank and the result equals ``"off"``.
``friction="off"`` (default)
    Coulomb-type friction is left out of the small-signal model: seal and thrust-bearing
    friction ``F_seal = C_bear = 0`` (viscous ``c_v`` and ``b_m`` stay), the hybrid
    variant's stick band is closed (``eps = 0``, so the hybrid model linearises exactly
    like the smooth one), and the screw-nut efficiency switch - itself a load-dependent
    Coulomb friction - is frozen at its operating-point value ``g`` (the model is
    evaluated with ``eta = 1/g`` and ``eta_inv = g``, which makes the blend constant;
    the ``eta`` input's column is taken from the unfrozen model). Without this, the
    efficiency blend linearised at standstill under 30 kN adds ~660 N m s/rad of
    fictitious shaft damping (the motor's own b_m is 2e-4). At a moving operating point the Coulomb force is then
    absent from the trim too (use ``"smooth"`` to keep it).
``friction="smooth"``
    Linearise the smooth friction law and the efficiency blend as they are. At rest
    the result depends on the smoothing velocity ``v_s`` (slope F_r/v_s, ~1.5e6 N s/m
    with the reference set) and on the blend width; a warning says so. Not available
    for the hybrid variant (its Karnopp law has no meaningful slope).
Saturations (rate limit, current limit, voltage circle) must be inactive at the
point: the trim is solved with the limits lifted and then checked against them, so a
load above what the current limit can hold, or a speed above the rate or voltage
limit, raises :class:`OperatingPointError` naming the limit and the numbers.

Loop breaks (the paper's "Gain = 1" block)
------------------------------------------
Every loop's feedback is ``loop_flag * measurement + d`` (flags in the parameter
vector, injections ``d_x, d_w, d_i`` among the inputs). Opening a loop sets its flag
to 0 and its injection to the measurement's operating-point value, so the controller
sees the same signals and the Jacobian is taken at the same point. The loop transfer
at a break is ``L(s) = -G_{d -> measurement}(s)`` (negative-feedback convention: the
closed loop is L/(1+L)).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field, replace

import casadi as ca
import numpy as np

from .assembly import Model
from .components import REGISTRY
from .params import Parameters

__all__ = [
    "LOOPS", "LinearizationError", "OperatingPointError", "OperatingPoint", "LinearModel",
    "operating_point", "linear_model", "linearize", "loop_model", "loop_transfer",
    "signal_outputs", "jacobian_function",
]

#: Loop name -> (closure flag, injection input, fed-back measurement), outer to inner:
#: every loop a registered part declares (a model has its own in ``model.loops``).
LOOPS = {
    lp.name: (lp.flag, lp.injection, lp.measured)
    for values in REGISTRY.values() for cls in values.values() for lp in cls.loops
}
FRICTION_POLICIES = ("off", "smooth")
BACKLASH_POLICIES = ("off", "keep")
OUTER = ("closed", "open")

# saturation limits are lifted by this factor while solving the trim
_LIFT = 1e6


class LinearizationError(ValueError):
    """A linearisation request cannot be served (bad option, unsupported variant)."""


class OperatingPointError(LinearizationError):
    """No operating point exists or none was found; the one-line message names the
    limit that is exceeded and the numbers."""


def signal_outputs(model: Model) -> tuple[str, ...]:
    """Outputs that are signals (not powers, energies or the stick flag): the default
    outputs of a linear model."""
    return model.outputs_of("signal")


# ---------------------------------------------------------------------------------
_JAC: dict = {}


def jacobian_function(model: Model) -> ca.Function:
    """``J(x, u, p) -> (xdot, y, A, B, C, D)``: the model and its exact AD Jacobians.

    Built once per model and cached (a call costs tens of microseconds).
    """
    entry = _JAC.get(id(model.f))
    if entry is None or entry[0] is not model.f:
        x = ca.SX.sym("x", model.nx)
        u = ca.SX.sym("u", model.nu)
        p = ca.SX.sym("p", len(model.param_names))
        xdot, y = model.f(x, u, p)
        J = ca.Function(
            "ema_jacobians", [x, u, p],
            [xdot, y, ca.jacobian(xdot, x), ca.jacobian(xdot, u), ca.jacobian(y, x), ca.jacobian(y, u)],
            ["x", "u", "p"], ["xdot", "y", "A", "B", "C", "D"],
        )
        entry = (model.f, J)
        _JAC[id(model.f)] = entry
    return entry[1]


def _eval(model, x, u, p):
    return [np.array(v) for v in jacobian_function(model)(x, u, p)]


@dataclass
class OperatingPoint:
    """A trimmed operating point and the values the linearisation uses.

    Attributes
    ----------
    x, u, y : ndarray
        State, inputs and outputs (SI) at the point; ``u`` holds the true inputs
        (``eta`` the real efficiency, injections zero).
    p : ndarray
        Parameter vector with the small-signal policy applied, all loops closed.
    x_cmd, f_ext, v_rod : float
        The requested command (m), external force (N) and rod velocity (m/s).
    xdot : ndarray
        State derivative at the point (zero except the positions when moving).
    policy : dict
        ``friction``, ``backlash``, the parameter ``overrides`` applied and the
        frozen efficiency factor ``g_eff`` (None when not frozen).
    states, inputs, outputs, param_names : tuple of str
    residual : float
        Largest relative residual of the trim equations.
    """

    x: np.ndarray
    u: np.ndarray
    y: np.ndarray
    p: np.ndarray
    x_cmd: float
    f_ext: float
    v_rod: float
    xdot: np.ndarray
    policy: dict
    states: tuple
    inputs: tuple
    outputs: tuple
    param_names: tuple
    residual: float
    variants: dict = field(default_factory=dict)
    # evaluation point of the Jacobian (frozen efficiency): see module docstring
    u_lin: np.ndarray | None = None
    p_lin: np.ndarray | None = None

    def state(self, name: str) -> float:
        return float(self.x[self.states.index(name)])

    def output(self, name: str) -> float:
        return float(self.y[self.outputs.index(name)])

    def as_dict(self) -> dict:
        """JSON-ready summary (SI units)."""
        return {
            "x_cmd": self.x_cmd, "f_ext": self.f_ext, "v_rod": self.v_rod,
            "eta": float(self.u[self.inputs.index("eta")]),
            "states": {n: float(v) for n, v in zip(self.states, self.x)},
            "inputs": {n: float(v) for n, v in zip(self.inputs, self.u)},
            "outputs": {n: float(v) for n, v in zip(self.outputs, self.y)},
            "policy": self.policy,
            "residual": self.residual,
            "variants": dict(self.variants),
        }


def _policy_vector(model: Model, p: np.ndarray, friction: str, backlash: str) -> tuple[np.ndarray, dict]:
    if friction not in FRICTION_POLICIES:
        raise LinearizationError(f"friction policy '{friction}' unknown; choose one of {', '.join(FRICTION_POLICIES)}")
    if backlash not in BACKLASH_POLICIES:
        raise LinearizationError(f"backlash policy '{backlash}' unknown; choose one of {', '.join(BACKLASH_POLICIES)}")
    if friction == "smooth" and model.hybrid:
        raise LinearizationError(
            "friction policy 'smooth' linearises the smooth friction law; the hybrid (Karnopp) "
            "variant has no meaningful slope: use friction policy 'off'"
        )
    overrides = {}
    if backlash == "off":
        overrides["B"] = 0.0
    if friction == "off":
        overrides.update(F_seal=0.0, C_bear=0.0, eps=0.0)
    names = list(model.param_names)
    p = np.array(p, dtype=float)
    for k, v in overrides.items():
        p[names.index(k)] = v
    return p, overrides


def _along_travel(model: Model, p: np.ndarray, length: float) -> np.ndarray:
    """Every position-like state at rod travel ``length`` (m), the others 0: the
    initial guess at x_cmd (rod and nut aligned), or the state rate of a relative
    equilibrium moving at v_rod (m/s)."""
    travel = model.travel(p)
    return np.array([length / travel[n] if n in travel else 0.0 for n in model.states])


def _row_scale(A, B, x, u, target, size):
    """Size of each row's terms, every state at least at full scale."""
    return np.abs(A) @ (size + np.abs(x)) + np.abs(B) @ np.abs(u) + np.abs(target)


def _newton(model, x, u, p, target, size, tol, max_iter):
    """Least-squares Newton on f(x) = target. Minimum-norm steps leave directions the
    equations do not fix (e.g. the rigid screw's shaft angle inside the play, a P
    position loop's unused integrator) at the initial guess.

    Convergence: every row's residual below ``tol`` times the size of its terms at
    full scale (each state sized by its unit's full-scale value: stroke, rate limit,
    current limit, DC-link voltage), so that a row whose terms all vanish at the point
    is judged against what the row can carry, not against round-off.
    """
    rel = np.inf
    for _ in range(max_iter):
        xdot, _y, A, B, _C, _D = _eval(model, x, u, p)
        r = xdot.ravel() - target
        scale = _row_scale(A, B, x, u, target, size)
        rel = float(np.max(np.abs(r) / np.where(scale > 0, scale, 1.0)))
        if rel < tol:
            return x, rel, True
        dx = np.linalg.lstsq(A, -r, rcond=1e-13)[0]
        if not np.all(np.isfinite(dx)):
            break
        x = x + dx
    return x, rel, False


def _efficiency_factor(model: Model, y) -> float:
    """The screw-nut factor g (T_load = g F p/2pi) at the point: the screw part's
    output ``g_screw``."""
    return float(y[model.yindex("g_screw")])


def _check_limits(model: Model, op_y: np.ndarray, p: np.ndarray, f_ext: float, v_rod: float):
    names = model.param_names
    pv = dict(zip(names, p))
    y = dict(zip(model.outputs, op_y))
    where = f"at f_ext = {f_ext / 1e3:.4g} kN" + (f", v_rod = {v_rod * 1e3:.4g} mm/s" if v_rod else "")
    i_need, I_max = abs(y["i_cmd"]), pv["I_max"]
    if i_need >= I_max * (1 - 1e-9):
        est = f" (about {abs(f_ext) * I_max / i_need / 1e3:.3g} kN is the most it can hold here)" if f_ext else ""
        raise OperatingPointError(
            f"no operating point with unsaturated current {where}: it needs i_q = {i_need:.3g} A, "
            f"above the current limit I_max = {I_max:.3g} A{est}"
        )
    w_max = 2 * math.pi * pv["v_max"] / pv["p"]
    if abs(y["omega_cmd"]) >= w_max * (1 - 1e-9):
        raise OperatingPointError(
            f"no operating point below the rate limit {where}: the speed command "
            f"{abs(y['omega_cmd']) * pv['p'] / (2 * math.pi) * 1e3:.4g} mm/s reaches v_max = {pv['v_max'] * 1e3:.4g} mm/s"
        )
    v_lim = pv["k_v"] * pv["V_dc"] / math.sqrt(3)
    v_dq = math.hypot(y["v_d"], y["v_q"])
    if v_dq >= v_lim * (1 - 1e-9):
        raise OperatingPointError(
            f"no operating point below the voltage limit {where}: it needs |v_dq| = {v_dq:.4g} V, "
            f"above k_v V_dc/sqrt(3) = {v_lim:.4g} V"
        )


def _freeze_efficiency(model: Model, u, p, g):
    """Inputs and parameters that make the efficiency blend the constant g: 1/eta = eta_inv = g."""
    u, p = u.copy(), p.copy()
    u[model.inputs.index("eta")] = 1.0 / g
    p[model.param_names.index("eta_inv")] = g
    return u, p


def _trim(model, x, u, p, target, size, tol, max_iter):
    """Trim with the efficiency blend frozen at a value g, then g updated from the
    solution until it is consistent (then x is a trim of the real model too).

    The blend switches over ~0.1 W of transmitted power; under load its slope at
    standstill is so steep that Newton on the raw model leaves the switching band and
    fails. Frozen, the trim equations are smooth; at rest the blend is exactly at its
    midpoint and one pass suffices, at a moving point the second pass confirms it.
    Returns (x, y, residual), x None when not converged.
    """
    y = _eval(model, x, u, p)[1].ravel()
    g = _efficiency_factor(model, y)
    rel = np.inf
    for _ in range(10):
        x, rel, ok = _newton(model, x, *_freeze_efficiency(model, u, p, g), target, size, tol, max_iter)
        if not ok:
            return None, None, rel
        y = _eval(model, x, u, p)[1].ravel()
        g_new = _efficiency_factor(model, y)
        if abs(g_new - g) <= 1e-13 * abs(g):
            return x, y, rel
        g = g_new
    return None, None, rel


def operating_point(
    model: Model,
    x_cmd: float = 0.0,
    f_ext: float = 0.0,
    v_rod: float = 0.0,
    *,
    eta: float | None = None,
    friction: str = "off",
    backlash: str = "off",
    params: Parameters | None = None,
    p: np.ndarray | None = None,
    tol: float = 1e-14,
    max_iter: int = 50,
) -> OperatingPoint:
    """Trim the model: the state at rest (or moving at ``v_rod``) for given inputs.

    Parameters
    ----------
    model : Model
    x_cmd : float
        Commanded rod position (m); within the stroke.
    f_ext : float
        External rod force (N), positive pushes the rod in.
    v_rod : float
        Constant rod velocity (m/s); 0 for an equilibrium.
    eta : float, optional
        Screw efficiency input (-); default the parameter set's ``eta``.
    friction : {"off", "smooth"}
        Small-signal policy for Coulomb-type friction (module docstring).
    backlash : {"off", "keep"}
        Small-signal policy for the backlash.
    params, p : Parameters or ndarray, optional
        Parameter values (default the model's); ``p`` is the raw vector. Loop flags
        are closed for the trim whatever they say.
    tol : float
        Relative residual of the trim equations to reach (-).
    max_iter : int
        Newton iterations.

    Raises
    ------
    OperatingPointError
        No point with all saturations inactive (e.g. a load above what I_max holds, a
        speed above the rate limit), or Newton did not converge.
    LinearizationError
        Unknown policy, or ``friction="smooth"`` with the hybrid friction variant.
    """
    pv = np.asarray(p, float).copy() if p is not None else model.p(params)
    names = list(model.param_names)
    for loop in model.loops.values():
        pv[names.index(loop.flag)] = 1.0
    stroke = pv[names.index("stroke")]
    for label, val in (("x_cmd", x_cmd), ("f_ext", f_ext), ("v_rod", v_rod)):
        if not math.isfinite(val):
            raise OperatingPointError(f"{label} must be a finite number, got {val}")
    if abs(x_cmd) > stroke:
        raise OperatingPointError(f"x_cmd = {x_cmd * 1e3:.4g} mm is outside the stroke +-{stroke * 1e3:.4g} mm")
    p_pol, overrides = _policy_vector(model, pv, friction, backlash)
    if friction == "smooth":
        warnings.warn(
            "friction policy 'smooth': the linear model includes the slope of the smoothed "
            "Coulomb friction (F_r/v_s at rest) and of the efficiency blend, so it depends on v_s "
            "and the blend width, not only on the physics",
            stacklevel=2,
        )
    eta_v = float(pv[names.index("eta")] if eta is None else eta)
    u = model.u(x_cmd=x_cmd, f_ext=f_ext, eta=eta_v)
    target = _along_travel(model, p_pol, v_rod)
    # solve with the saturations lifted, then check the point against them
    p_trim = p_pol.copy()
    for k in ("I_max", "v_max", "V_dc"):
        p_trim[names.index(k)] *= _LIFT
    size = model.full_scale(p_pol)
    x = _along_travel(model, p_pol, x_cmd)
    shaft = model.state_with("shaft_angle")
    per_rad = model.travel(p_pol)[shaft]
    B_gap = p_pol[names.index("B")]
    if B_gap > 0:
        # inside the gap the spring has no slope and Newton cannot find the contact: start
        # from the backlash-free trim with the nut moved half the gap towards the flank
        # that carries the screw force
        p0 = p_trim.copy()
        p0[names.index("B")] = 0.0
        x0, y0, _ = _trim(model, x, u, p0, target, size, tol, max_iter)
        if x0 is not None:
            F_in = y0[model.yindex("F_in")]
            x = x0
            x[model.index(shaft)] += np.sign(F_in) * (B_gap / 2) / per_rad
    x, y_lifted, rel = _trim(model, x, u, p_trim, target, size, tol, max_iter)
    if x is None:
        raise OperatingPointError(
            f"the trim did not converge at x_cmd = {x_cmd * 1e3:.4g} mm, f_ext = {f_ext / 1e3:.4g} kN, "
            f"v_rod = {v_rod * 1e3:.4g} mm/s (relative residual {rel:.2g})"
        )
    _check_limits(model, y_lifted, p_pol, f_ext, v_rod)
    for play in model.states_with("play") if B_gap == 0 else ():
        # A play without backlash (rigid screw): the shaft angle is not fixed by the trim
        # (only the play output is fed back). Put the nut exactly at the rod - the model's
        # own x_in, so the gap is exactly 0 - where both edges of the play act and the AD
        # slope is 1; a gap of -1e-17 with a shaft speed of +1e-16 would select a slope of 0.
        i_phi, i_play = model.index(shaft), model.index(play)
        x[i_phi] = x[i_play] / per_rad
        x[i_play] = _eval(model, x, u, p_trim)[1].ravel()[model.yindex("x_in")]
    xdot, y, A, B = _eval(model, x, u, p_pol)[:4]
    xdot, y = xdot.ravel(), y.ravel()
    scale = _row_scale(A, B, x, u, target, size)
    if np.max(np.abs(xdot - target) / np.where(scale > 0, scale, 1.0)) > 1e-12:  # pragma: no cover
        raise OperatingPointError("a saturation is active at the trim (not caught by the limit check)")
    policy = {"friction": friction, "backlash": backlash, "overrides": overrides, "g_eff": None}
    u_lin, p_lin = u, p_pol
    if friction == "off":
        g = _efficiency_factor(model, y)
        u_lin, p_lin = _freeze_efficiency(model, u, p_pol, g)
        policy["g_eff"] = g
    if backlash == "keep":
        _warn_backlash_gap(model, y, p_pol)
    return OperatingPoint(
        x=x, u=u, y=y, p=p_pol, x_cmd=float(x_cmd), f_ext=float(f_ext), v_rod=float(v_rod),
        xdot=target, policy=policy, states=model.states, inputs=model.inputs,
        outputs=model.outputs, param_names=model.param_names, residual=rel,
        variants=dict(model.variants), u_lin=u_lin, p_lin=p_lin,
    )


def _warn_backlash_gap(model: Model, y, p):
    B = p[model.param_names.index("B")]
    if B <= 0:
        return
    gap = y[model.yindex("x_in")] - y[model.yindex("x_rod")]
    if abs(gap) < B / 2:
        warnings.warn(
            f"backlash kept: the operating point sits inside the {B * 1e6:.3g} um gap, so the linear "
            "model has the rod decoupled from the screw; use backlash='off' or a load",
            stacklevel=3,
        )


# ---------------------------------------------------------------------------------
@dataclass
class LinearModel:
    """A linear model ``dx = A x + B u, y = C x + D u`` in deviations from ``op``.

    Duck-compatible with ``control.StateSpace`` for the ``A, B, C, D`` attributes, so
    :mod:`ema_casadi.frequency` takes either; :meth:`to_statespace` makes the named
    python-control object.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    states: tuple
    inputs: tuple
    outputs: tuple
    op: OperatingPoint | None = None
    name: str = "ema"
    open_loops: tuple = ()

    def select(self, inputs=None, outputs=None, name: str | None = None) -> "LinearModel":
        """The sub-model from some inputs to some outputs (by name)."""
        ii = [self.inputs.index(n) for n in (inputs or self.inputs)]
        oo = [self.outputs.index(n) for n in (outputs or self.outputs)]
        return replace(
            self, B=self.B[:, ii], C=self.C[oo, :], D=self.D[np.ix_(oo, ii)],
            inputs=tuple(self.inputs[i] for i in ii), outputs=tuple(self.outputs[o] for o in oo),
            name=name or self.name,
        )

    def to_statespace(self):
        """The named ``control.StateSpace``."""
        import control

        return control.ss(self.A, self.B, self.C, self.D, states=list(self.states),
                          inputs=list(self.inputs), outputs=list(self.outputs), name=self.name)


def _loops(model: Model, names) -> tuple[str, ...]:
    if isinstance(names, str):
        names = (names,)
    out = tuple(names or ())
    for n in out:
        if n not in model.loops:
            raise LinearizationError(f"loop '{n}' unknown; choose one of {', '.join(model.loops)}")
    return out


def linear_model(
    model: Model,
    op: OperatingPoint | None = None,
    *,
    open_loops=(),
    inputs=None,
    outputs=None,
    **op_kwargs,
) -> LinearModel:
    """Exact AD linearisation at ``op`` as a :class:`LinearModel` (NumPy only).

    Parameters
    ----------
    model : Model
    op : OperatingPoint, optional
        Default: :func:`operating_point` ``(model, **op_kwargs)``.
    open_loops : sequence of {"position", "velocity", "current"}
        Loops opened at their break (flag 0, injection at the measured value).
    inputs, outputs : sequence of str, optional
        Default: all inputs; the signal outputs (:func:`signal_outputs`).
    """
    if op is None:
        op = operating_point(model, **op_kwargs)
    elif op_kwargs:
        raise LinearizationError(f"give either op or operating-point arguments, not both ({', '.join(op_kwargs)})")
    if op.states != model.states or op.variants != model.variants:
        raise LinearizationError("the operating point belongs to another model (variants differ)")
    open_loops = _loops(model, open_loops)
    outputs = tuple(outputs) if outputs is not None else signal_outputs(model)
    inputs = tuple(inputs) if inputs is not None else model.inputs
    for n in outputs:
        if n not in model.outputs:
            raise LinearizationError(f"output '{n}' unknown; outputs are {', '.join(model.outputs)}")
    for n in inputs:
        if n not in model.inputs:
            raise LinearizationError(f"input '{n}' unknown; inputs are {', '.join(model.inputs)}")
    names = list(model.param_names)
    u_lin, p_lin = op.u_lin.copy(), op.p_lin.copy()
    u_true, p_true = op.u.copy(), op.p.copy()
    for name in open_loops:
        loop = model.loops[name]
        for uu, pp in ((u_lin, p_lin), (u_true, p_true)):
            pp[names.index(loop.flag)] = 0.0
            uu[model.inputs.index(loop.injection)] = op.output(loop.measured)
    _, _, A, B, C, D = _eval(model, op.x, u_lin, p_lin)
    if op.policy.get("g_eff") is not None:
        # the eta column of the frozen model is that of the fake efficiency: take the real one
        k = model.inputs.index("eta")
        _, _, _, B_t, _, D_t = _eval(model, op.x, u_true, p_true)
        B[:, k], D[:, k] = B_t[:, k], D_t[:, k]
    ii = [model.inputs.index(n) for n in inputs]
    oo = [model.outputs.index(n) for n in outputs]
    lin = LinearModel(
        A=A, B=B[:, ii], C=C[oo, :], D=D[np.ix_(oo, ii)], states=model.states,
        inputs=inputs, outputs=outputs, op=op, open_loops=open_loops,
        name="ema" + "".join(f"_open_{n}" for n in open_loops),
    )
    bad = [outputs[i] for i in range(len(outputs)) if not np.all(np.isfinite(lin.C[i])) or not np.all(np.isfinite(lin.D[i]))]
    if bad or not (np.all(np.isfinite(lin.A)) and np.all(np.isfinite(lin.B))):
        raise LinearizationError(f"the Jacobian is not finite at this point (outputs: {', '.join(bad) or '-'})")
    return lin


def linearize(model: Model, op: OperatingPoint | None = None, **kwargs):
    """Exact AD linearisation as a named ``control.StateSpace``.

    Same arguments as :func:`linear_model`; the operating point travels with the
    :class:`LinearModel` (``linear_model(...).op``) - use that when you need both.
    """
    return linear_model(model, op, **kwargs).to_statespace()


def loop_model(model: Model, loop: str, op: OperatingPoint | None = None, *, outer: str = "closed",
               **op_kwargs) -> LinearModel:
    """The loop transfer L(s) at a break as a SISO :class:`LinearModel`.

    Parameters
    ----------
    loop : {"position", "velocity", "current"}
    outer : {"closed", "open"}
        ``"closed"`` (default): loop-at-a-time, every other loop closed (the margin the
        whole system has at that point). ``"open"``: the loops outside this one are
        opened too (the cascade-design view: inner loops closed, outer open).

    ``L = -G_{d -> measurement}`` with this loop open; input is the injection name,
    output ``-<measurement>``.
    """
    (loop,) = _loops(model, loop)
    if outer not in OUTER:
        raise LinearizationError(f"outer '{outer}' unknown; choose one of {', '.join(OUTER)}")
    order = list(model.loops)
    opened = [loop] + (order[: order.index(loop)] if outer == "open" else [])
    inj, meas = model.loops[loop].injection, model.loops[loop].measured
    lin = linear_model(model, op, open_loops=opened, inputs=[inj], outputs=[meas], **op_kwargs)
    return replace(lin, C=-lin.C, D=-lin.D, outputs=(f"-{meas}",), name=f"L_{loop}")


def loop_transfer(model: Model, loop: str, op: OperatingPoint | None = None, *, outer: str = "closed",
                  **op_kwargs):
    """:func:`loop_model` as a named ``control.StateSpace``."""
    return loop_model(model, loop, op, outer=outer, **op_kwargs).to_statespace()
