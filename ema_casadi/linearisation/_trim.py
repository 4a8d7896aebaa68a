"""Operating points: trim of the model by Newton on its AD Jacobian (package docstring)."""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np

from .._util._checks import instance, integer, number, vector
from ..model.assembly import Model
from ..model.params import Parameters
from ._common import _LIFT, BACKLASH_POLICIES, FRICTION_POLICIES, LinearizationError, OperatingPointError, _eval


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
        Names of the entries of x, u, y and p.
    residual : float
        Largest relative residual of the trim equations.
    variants : dict
        The model's variants (a point belongs to one model).
    u_lin, p_lin : ndarray
        Where the Jacobian is evaluated: ``u`` and ``p`` with the efficiency blend
        frozen (friction policy ``off``; package docstring).
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
        """A state's value at the point (SI).

        Parameters
        ----------
        name : str
            State name.
        """
        return float(self.x[self.states.index(name)])

    def output(self, name: str) -> float:
        """An output's value at the point (SI).

        Parameters
        ----------
        name : str
            Output name.
        """
        return float(self.y[self.outputs.index(name)])

    def as_dict(self) -> dict:
        """JSON-ready summary (SI units)."""
        return {
            "x_cmd": self.x_cmd, "f_ext": self.f_ext, "v_rod": self.v_rod,
            "eta": float(self.u[self.inputs.index("eta")]),
            "states": {n: float(v) for n, v in zip(self.states, self.x, strict=False)},
            "inputs": {n: float(v) for n, v in zip(self.inputs, self.u, strict=False)},
            "outputs": {n: float(v) for n, v in zip(self.outputs, self.y, strict=False)},
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
    # what the parts declare for every small-signal analysis (a sensor's quantisation off)
    overrides = {k: v for part in model.parts for k, v in part.small_signal.items()}
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
    pv = dict(zip(names, p, strict=False))
    y = dict(zip(model.outputs, op_y, strict=False))
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
            f"{abs(y['omega_cmd']) * pv['p'] / (2 * math.pi) * 1e3:.4g} mm/s reaches "
            f"v_max = {pv['v_max'] * 1e3:.4g} mm/s"
        )
    v_lim = pv["k_v"] * pv["V_dc"] / math.sqrt(3)
    v_dq = math.hypot(y["v_d"], y["v_q"])
    if v_dq >= v_lim * (1 - 1e-9):
        raise OperatingPointError(
            f"no operating point below the voltage limit {where}: it needs |v_dq| = {v_dq:.4g} V, "
            f"above k_v V_dc/sqrt(3) = {v_lim:.4g} V"
        )


def _freeze_efficiency(model: Model, u, p, g):
    """Inputs and parameters that make the efficiency blend the constant g: 1/eta = eta_inv = g
    (and the thermal network's eta(T_s) switched off, so that the eta input drives the screw)."""
    u, p = u.copy(), p.copy()
    u[model.inputs.index("eta")] = 1.0 / g
    p[model.param_names.index("eta_inv")] = g
    p[model.param_names.index("feedback_eta")] = 0.0
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
    _check_request(model, x_cmd, f_ext, v_rod, eta, params, p, tol, max_iter)
    pv = _request_vector(model, params, p, x_cmd, f_ext, v_rod)
    p_pol, overrides = _policy_vector(model, pv, friction, backlash)
    if friction == "smooth":
        warnings.warn(
            "friction policy 'smooth': the linear model includes the slope of the smoothed "
            "Coulomb friction (F_r/v_s at rest) and of the efficiency blend, so it depends on v_s "
            "and the blend width, not only on the physics",
            stacklevel=2,
        )
    eta_v = float(pv[model.param_names.index("eta")] if eta is None else eta)
    u = model.u(pv, x_cmd=x_cmd, f_ext=f_ext, eta=eta_v)
    target = _along_travel(model, p_pol, v_rod)
    x, y, rel = _solve(model, x_cmd, f_ext, v_rod, u, p_pol, target, tol, max_iter)
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


def _check_request(model, x_cmd, f_ext, v_rod, eta, params, p, tol, max_iter) -> None:
    """Types and values of a trim request: OperatingPointError naming the argument."""
    err = OperatingPointError
    instance(model, Model, "model", err, " (from build_model)")
    for name, val, unit in (("x_cmd", x_cmd, "m"), ("f_ext", f_ext, "N"), ("v_rod", v_rod, "m/s")):
        if isinstance(val, str):
            raise err(f"{name}: expected a number in {unit}, got str {val!r} (text with units is for the "
                      "command line; ema_casadi.signals.parse_quantity reads it)")
        number(val, name, err, unit=unit)
    if eta is not None:
        number(eta, "eta", err, unit="-", positive=True)
    if params is not None:
        instance(params, Parameters, "params", err, " (from load_parameters)")
    if p is not None:
        vector(p, "p", err, len(model.param_names), " (the model's parameter vector)")
    number(tol, "tol", err, positive=True)
    integer(max_iter, "max_iter", err, minimum=1)


def _request_vector(model: Model, params, p, x_cmd, f_ext, v_rod) -> np.ndarray:
    """The parameter vector of a trim request (loops closed), the request checked."""
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
    return pv


def _solve(model: Model, x_cmd, f_ext, v_rod, u, p_pol, target, tol, max_iter):
    """Trim with the saturations lifted, then the point checked against them.
    Returns (x, y, relative residual)."""
    names = list(model.param_names)
    p_trim = p_pol.copy()
    # the voltage limit is lifted through k_v, not V_dc: V_dc also sets the switching losses
    # (which heat the inverter node of a thermal network)
    for k in ("I_max", "v_max", "k_v"):
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
    return x, y, rel


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
