"""Operating points: trim of the model by Newton on its AD Jacobian (package docstring)."""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np

from .._util._checks import instance, integer, number, vector
from .._util._notebook import Summarised
from ..model.assembly import AssemblyError, Model
from ..model.components import POLICIES, SIGNAL_KEYS
from ..model.params import Parameters
from ..optimisation import newton_step
from ._common import _LIFT, LinearizationError, OperatingPointError, _eval

#: The keys of a trim request in files, reports and the keyword conveniences of
#: :func:`operating_point` (the command, the load and the rod velocity), and the efficiency's.
REQUEST_KEYS = tuple(SIGNAL_KEYS[r] for r in ("command", "load", "rod_velocity"))
ETA = SIGNAL_KEYS["efficiency"]


@dataclass(repr=False)
class OperatingPoint(Summarised):
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
    eta : float or None
        The screw-efficiency input at the point (-); None for a model without one.
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
    eta: float | None = None

    def _facts(self) -> dict:
        shown = (f"{self.x_cmd * 1e3:.4g} mm", f"{self.f_ext / 1e3:.4g} kN", f"{self.v_rod * 1e3:.4g} mm/s")
        return {**dict(zip(REQUEST_KEYS, shown, strict=True)),
                "policy": ", ".join(f"{k} {v}" for k, v in self.policy.items() if isinstance(v, str)) or None,
                "states": len(self.states), "residual": f"{self.residual:.2g}"}

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

    def request(self) -> dict:
        """The requested command (m), load (N) and rod velocity (m/s) by their keys in
        files and reports (:data:`REQUEST_KEYS`: ``x_cmd``, ``f_ext``, ``v_rod``)."""
        return dict(zip(REQUEST_KEYS, (self.x_cmd, self.f_ext, self.v_rod), strict=True))

    def as_dict(self) -> dict:
        """JSON-ready summary (SI units)."""
        return {
            **self.request(), ETA: self.eta,
            "states": {n: float(v) for n, v in zip(self.states, self.x, strict=False)},
            "inputs": {n: float(v) for n, v in zip(self.inputs, self.u, strict=False)},
            "outputs": {n: float(v) for n, v in zip(self.outputs, self.y, strict=False)},
            "policy": self.policy,
            "residual": self.residual,
            "variants": dict(self.variants),
        }


def _policy_vector(model: Model, p: np.ndarray, friction: str, backlash: str) -> tuple[np.ndarray, dict]:
    """The parameter vector with the small-signal policies the parts declare applied."""
    try:
        fr = model.small_signal(friction=friction)
        # the policies not chosen here at their defaults (a real sensor's quantisation off)
        rest = model.small_signal(**{k: v[0] for k, v in POLICIES.items() if k not in ("friction", "backlash")})
        overrides = {**rest, **model.small_signal(backlash=backlash), **fr}
    except AssemblyError as exc:
        raise LinearizationError(str(exc)) from None
    return _with(model, p, overrides), overrides


def _with(model: Model, p: np.ndarray, values: dict) -> np.ndarray:
    """A copy of the parameter vector ``p`` with ``values`` (name -> SI value) set."""
    names = list(model.param_names)
    p = np.array(p, dtype=float)
    for k, v in values.items():
        p[names.index(k)] = v
    return p


def _along_travel(model: Model, p: np.ndarray, length: float) -> np.ndarray:
    """Every position-like state at rod travel ``length`` (m), the others 0: the
    initial guess at x_cmd (rod and nut aligned), or the state rate of a relative
    equilibrium moving at v_rod (m/s)."""
    travel = model.travel(p)
    return np.array([length / travel[n] if n in travel else 0.0 for n in model.states])


def _row_scale(A, B, x, u, target, size):
    """Size of each row's terms, every state at least at full scale."""
    return np.abs(A) @ (size + np.abs(x)) + np.abs(B) @ np.abs(u) + np.abs(target)


def _rest_rows(model: Model, rest: dict, x, y, C):
    """Residual and Jacobian rows of the memory states held at a signal (their ``rest``
    rule, ``rest``: state -> signal): x_s - y_signal = 0."""
    r = np.array([x[model.index(n)] - y[model.yindex(sig)] for n, sig in rest.items()])
    J = np.zeros((len(rest), model.nx))
    for row, (n, sig) in enumerate(rest.items()):
        J[row] = -C[model.yindex(sig)]
        J[row, model.index(n)] += 1.0
    return r, J, [model.index(n) for n in rest]


def _newton(model, x, u, p, target, size, tol, max_iter):
    """Least-squares Newton on f(x) = target and the rest rules of memory states.
    Minimum-norm steps leave directions the equations do not fix (e.g. a P position
    loop's unused integrator) at the initial guess.

    Convergence: every row's residual below ``tol`` times the size of its terms at
    full scale (each state sized by its unit's full-scale value: stroke, rate limit,
    current limit, DC-link voltage), so that a row whose terms all vanish at the point
    is judged against what the row can carry, not against round-off.
    """
    rel = np.inf
    rest = model.rest_states(p)
    for _ in range(max_iter):
        if rest:  # each iterate with its memory states exactly at their signal (an edge of a play)
            x = _hold_at_rest(model, x, u, p, rest)
        xdot, y, A, B, C, _D = _eval(model, x, u, p)
        r_rest, J_rest, i_rest = _rest_rows(model, rest, x, y.ravel(), C)
        r = np.concatenate([xdot.ravel() - target, r_rest])
        scale = np.concatenate([_row_scale(A, B, x, u, target, size), size[i_rest] + np.abs(x[i_rest])])
        rel = float(np.max(np.abs(r) / np.where(scale > 0, scale, 1.0)))
        if rel < tol:
            return x, rel, True
        dx = newton_step(np.vstack([A, J_rest]), r, least_squares=True, rcond=1e-13)
        if not np.all(np.isfinite(dx)):
            break
        x = x + dx
    return x, rel, False


def _hold_at_rest(model: Model, x, u, p, rest: dict | None = None):
    """The memory states set exactly to their rest signal (``rest``: state -> signal,
    default the model's at ``p``)."""
    rest = model.rest_states(p) if rest is None else rest
    if not rest:
        return x
    x = x.copy()
    y = _eval(model, x, u, p)[1].ravel()
    for n, sig in rest.items():
        x[model.index(n)] = y[model.yindex(sig)]
    return x


def _frozen_values(model: Model, y) -> dict[str, float]:
    """The values at the point of the outputs the parts' freezes read (``g_screw``)."""
    return {fz.signal: float(y[model.yindex(fz.signal)]) for fz in model.freezes}


def _lifted(model: Model, p: np.ndarray) -> np.ndarray:
    """p with every trim limit lifted (its ``lift`` parameters times _LIFT)."""
    names = list(model.param_names)
    p = np.array(p, dtype=float)
    for lim in model.trim_limits:
        for k in lim.lift:
            p[names.index(k)] *= _LIFT
    return p


def _check_limits(model: Model, op_y: np.ndarray, p: np.ndarray, f_ext: float, v_rod: float):
    """OperatingPointError naming the first trim limit the point reaches."""
    P = model.pdict(p)
    y = dict(zip(model.outputs, op_y, strict=False))
    where = f"at f_ext = {f_ext / 1e3:.4g} kN" + (f", v_rod = {v_rod * 1e3:.4g} mm/s" if v_rod else "")
    for lim in model.trim_limits:
        need, top = float(lim.value(y, P)), float(lim.limit(P))
        if need >= top * (1 - 1e-9):
            est = ""
            if lim.holds_load and f_ext:
                est = f" (about {abs(f_ext) * top / need / 1e3:.3g} kN is the most it can hold here)"
            k, unit, g = lim.scale, lim.unit, f".{lim.digits}g"
            raise OperatingPointError(
                f"no operating point within the {lim.what} {where}: it needs {lim.symbol} = {need * k:{g}} {unit}, "
                f"above the {lim.what} {lim.why} = {top * k:{g}} {unit}{est}"
            )


def _freeze_efficiency(model: Model, u, p, frozen: dict):
    """Inputs and parameters that make the blends the parts freeze constant at the
    ``frozen`` values (signal -> value; the screw-nut factor g: 1/eta = eta_inv = g)."""
    u = u.copy()
    values = {}
    for fz in model.freezes:
        v = frozen[fz.signal]
        for name, fn in fz.inputs.items():
            u[model.inputs.index(name)] = fn(v)
        values.update({name: fn(v) for name, fn in fz.params.items()})
    return u, _with(model, p, values)


def small_signal_point(model: Model, u, p, friction: str = "off", backlash: str = "off"):
    """Inputs and parameters of a small-signal model without an operating point (a
    guess): the policies applied (the parts' overrides) and, with friction ``off``, the
    blends the parts freeze held at their nominal values (the screw-nut factor driving
    the load, 1/eta). Returns (u, p).

    Parameters
    ----------
    model : Model
        The assembled model.
    u, p : array_like
        Inputs and parameter vector (SI).
    friction, backlash : str
        Small-signal policies (:data:`~ema_casadi.model.components.POLICIES`).
    """
    q, _ = _policy_vector(model, p, friction, backlash)
    u = np.array(u, dtype=float)
    fz = model.freezes if friction == "off" and all(f.nominal for f in model.freezes) else ()
    if not fz:
        return u, q
    # the nominal value is that of the inputs at their defaults: only the parameters are set
    P = model.pdict(q)
    values = {name: fn(float(f.nominal(P))) for f in fz for name, fn in f.params.items()}
    return u, _with(model, q, values)


def _consistent(new: dict, old: dict) -> bool:
    return all(abs(new[k] - old[k]) <= 1e-13 * abs(old[k]) for k in old)


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
    g = _frozen_values(model, y)
    rel = np.inf
    for _ in range(10):
        x, rel, ok = _newton(model, x, *_freeze_efficiency(model, u, p, g), target, size, tol, max_iter)
        if not ok:
            return None, None, rel
        y = _eval(model, x, u, p)[1].ravel()
        g_new = _frozen_values(model, y)
        if _consistent(g_new, g):
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
    inputs: dict | None = None,
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
    inputs : dict, optional
        Input name or role (:data:`~ema_casadi.model.components.INPUT_ROLES`) -> value (SI):
        ``{"load": -30e3}`` is ``f_ext=-30e3``, ``{"ambient_temperature": 60.0}`` holds
        ``T_amb``; ``x_cmd``, ``f_ext`` and ``eta`` are the conveniences for the command,
        load and efficiency roles (not both ways at once).

    Raises
    ------
    OperatingPointError
        No point with all saturations inactive (e.g. a load above what I_max holds, a
        speed above the rate limit), or Newton did not converge.
    LinearizationError
        Unknown policy, or ``friction="smooth"`` with the hybrid friction variant.
    """
    x_cmd, f_ext, eta, extra = _by_role(model, inputs, x_cmd, f_ext, eta)
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
    values = {model.input_with("command"): x_cmd, model.input_with("load"): f_ext, **extra}
    if eta is not None:
        values[model.input_with("efficiency")] = eta
    u = model.u(pv, **values)
    target = _along_travel(model, p_pol, v_rod)
    x, y, rel = _solve(model, x_cmd, f_ext, v_rod, u, p_pol, target, tol, max_iter)
    policy = {"friction": friction, "backlash": backlash, "overrides": overrides, "g_eff": None}
    u_lin, p_lin = u, p_pol
    if friction == "off" and model.freezes:
        frozen = _frozen_values(model, y)
        u_lin, p_lin = _freeze_efficiency(model, u, p_pol, frozen)
        policy["g_eff"] = next(iter(frozen.values()))
    _warn_seeds(model, y, p_pol, {"friction": friction, "backlash": backlash})
    return OperatingPoint(
        x=x, u=u, y=y, p=p_pol, x_cmd=float(x_cmd), f_ext=float(f_ext), v_rod=float(v_rod),
        xdot=target, policy=policy, states=model.states, inputs=model.inputs,
        outputs=model.outputs, param_names=model.param_names, residual=rel,
        variants=dict(model.variants), u_lin=u_lin, p_lin=p_lin, eta=efficiency(model, u),
    )


def efficiency(model: Model, u: np.ndarray) -> float | None:
    """The screw-efficiency input in ``u`` (-); None if the model has none."""
    names = model.inputs_with("efficiency")
    return float(u[model.inputs.index(names[0])]) if names else None


def _by_role(model, inputs, x_cmd, f_ext, eta):
    """(x_cmd, f_ext, eta, other inputs by name) of a trim request whose ``inputs`` name
    inputs or roles: the command, load and efficiency go to their keywords."""
    if inputs is None:
        return x_cmd, f_ext, eta, {}
    from ..model import AssemblyError

    if not isinstance(inputs, dict):
        raise OperatingPointError(f"inputs: expected a dict name or role -> value, got {type(inputs).__name__}")
    given = {"command": x_cmd != 0.0, "load": f_ext != 0.0, "efficiency": eta is not None}
    out, extra = {"command": x_cmd, "load": f_ext, "efficiency": eta}, {}
    for key, value in inputs.items():
        try:
            name = model.input_name(key)
        except AssemblyError as exc:
            raise OperatingPointError(f"inputs: {exc}") from None
        role = next((r for r in out if name in model.inputs_with(r)), None)
        if role is None:
            number(value, f"inputs[{key!r}]", OperatingPointError, unit=model.input_info[name].unit)
            extra[name] = float(value)
        elif given[role]:
            raise OperatingPointError(f"inputs: '{key}' drives {name}, which is already given")
        else:
            out[role] = value
    return out["command"], out["load"], out["efficiency"], extra


def _check_request(model, x_cmd, f_ext, v_rod, eta, params, p, tol, max_iter) -> None:
    """Types and values of a trim request: OperatingPointError naming the argument."""
    err = OperatingPointError
    instance(model, Model, "model", err, " (from build_model)")
    for name, val, unit in zip(REQUEST_KEYS, (x_cmd, f_ext, v_rod), ("m", "N", "m/s"), strict=True):
        if isinstance(val, str):
            raise err(f"{name}: expected a number in {unit}, got str {val!r} (text with units is for the "
                      "command line; ema_casadi.signals.parse_quantity reads it)")
        number(val, name, err, unit=unit)
    if eta is not None:
        number(eta, ETA, err, unit="-", positive=True)
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
    for label, val in zip(REQUEST_KEYS, (x_cmd, f_ext, v_rod), strict=True):
        if not math.isfinite(val):
            raise OperatingPointError(f"{label} must be a finite number, got {val}")
    if abs(x_cmd) > stroke:
        raise OperatingPointError(f"{REQUEST_KEYS[0]} = {x_cmd * 1e3:.4g} mm is outside the stroke "
                                  f"+-{stroke * 1e3:.4g} mm")
    # far beyond what the actuator can hold or reach there is no point to solve for (and
    # the Newton iteration meets overflowing numbers): refused by the model's envelope
    bounds = model.envelope(pv)
    load, speed = model.input_with("load"), model.output_with("rod_velocity")
    for label, val, info in ((load, f_ext, model.input_info[load]), (speed, v_rod, model.output_info[speed])):
        if info is not None and info.bound is not None and abs(val) > bounds[label]:
            raise OperatingPointError(f"{label} = {val:.4g} {info.unit} is beyond the physical envelope "
                                      f"{bounds[label]:.4g} {info.unit} ({info.bound.why}); no operating point "
                                      "within the current limit")
    return pv


def _seeded(model: Model, x, u, p_trim, target, size, tol, max_iter):
    """The starting state moved by the parts' seeds (:class:`~ema_casadi.model.components.Seed`):
    where a policy's ``off`` overrides change the parameters (a backlash gap), trim with
    them first, then move each seeded state by its offset from that point."""
    P = model.pdict(p_trim)
    for name, s in model.state_info.items():
        if s.seed is None:
            continue
        off = model.small_signal(**{s.seed.policy: "off"})
        if all(getattr(P, k) == v for k, v in off.items()):
            continue
        x0, y0, _ = _trim(model, x, u, _with(model, p_trim, off), target, size, tol, max_iter)
        if x0 is not None:
            x = x0
            x[model.index(name)] += s.seed.offset(P, dict(zip(model.outputs, y0, strict=True)))
    return x


def _solve(model: Model, x_cmd, f_ext, v_rod, u, p_pol, target, tol, max_iter):
    """Trim with the saturations lifted, then the point checked against them.
    Returns (x, y, relative residual)."""
    p_trim = _lifted(model, p_pol)
    size = model.full_scale(p_pol)
    x = _seeded(model, _along_travel(model, p_pol, x_cmd), u, p_trim, target, size, tol, max_iter)
    x, y_lifted, rel = _trim(model, x, u, p_trim, target, size, tol, max_iter)
    if x is None:
        raise OperatingPointError(
            f"the trim did not converge at x_cmd = {x_cmd * 1e3:.4g} mm, f_ext = {f_ext / 1e3:.4g} kN, "
            f"v_rod = {v_rod * 1e3:.4g} mm/s (relative residual {rel:.2g})"
        )
    _check_limits(model, y_lifted, p_pol, f_ext, v_rod)
    x = _hold_at_rest(model, x, u, p_trim)
    xdot, y, A, B = _eval(model, x, u, p_pol)[:4]
    xdot, y = xdot.ravel(), y.ravel()
    scale = _row_scale(A, B, x, u, target, size)
    if np.max(np.abs(xdot - target) / np.where(scale > 0, scale, 1.0)) > 1e-12:  # pragma: no cover
        raise OperatingPointError("a saturation is active at the trim (not caught by the limit check)")
    return x, y, rel


def _warn_seeds(model: Model, y, p, policies: dict):
    """The warnings of the seeds whose policy is not ``off`` at this point (the nut
    inside the backlash gap: the linear model has the rod decoupled from the screw)."""
    P = model.pdict(p)
    yd = dict(zip(model.outputs, y, strict=True))
    for s in model.state_info.values():
        if s.seed is not None and s.seed.warn is not None and policies.get(s.seed.policy) != "off":
            text = s.seed.warn(P, yd)
            if text:
                warnings.warn(text, stacklevel=3)
