"""Assembly: the only place that wires the components into one model (SPEC §2).

:func:`build_model` takes a variant dict and returns a :class:`Model` whose CasADi
Function ``f(x, u, p) -> (xdot, y)`` has named states, inputs and outputs and takes the
parameters as an input vector, so one compiled model serves simulation, linearisation,
sweeps, tuning and export.

For sampled (zero-order-hold) control the same wiring is also exposed split in two:
``f_held(x, u, p, h)`` (plant with the controller outputs ``h`` held) and
``sample(x, u, p, h, flags)`` (one ECU update of the loops whose flag is 1).

With ``hybrid`` friction the model is a hybrid system: besides the continuous ``f``
it carries the discrete map ``project(x_prev, x, u, p) -> (x_next, stick)`` that an
integrator applies after each step (or at each located switching instant): it sets the
velocity of the friction contact (elastic screw: ``v_rod``; rigid screw: ``omega``) to
zero when the rod enters the dead band with the stick condition holding, so a held rod
cannot creep. For ``smooth`` friction ``project`` is the identity.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from types import SimpleNamespace

import casadi as ca
import numpy as np

from .components import ballscrew, controller, friction, inverter, motor
from .params import Parameters, validate_variants

__all__ = ["Model", "build_model", "INPUTS", "OUTPUTS", "HOLD"]

#: Top-level inputs (SI): command, external force (positive pushes the rod in),
#: screw efficiency, and the loop-break injections at the position (m), speed (rad/s)
#: and q-current (A) feedback.
INPUTS = ("x_cmd", "f_ext", "eta", "d_x", "d_w", "d_i")

#: Named outputs, the same for every variant (SI units; see OUTPUT_UNITS).
OUTPUTS = (
    "x_rod", "v_rod", "x_in", "omega", "i_d", "i_q", "v_d", "v_q", "T_m", "F_in",
    "F_friction", "omega_cmd", "i_cmd", "stick",
    "P_elec", "P_inv_cond", "P_inv_sw", "P_cu", "P_screw_nut", "P_friction",
    "P_viscous", "P_contact", "P_load", "E_stored",
)
OUTPUT_UNITS = {
    "x_rod": "m", "v_rod": "m/s", "x_in": "m", "omega": "rad/s", "i_d": "A", "i_q": "A",
    "v_d": "V", "v_q": "V", "T_m": "N*m", "F_in": "N", "F_friction": "N",
    "omega_cmd": "rad/s", "i_cmd": "A", "stick": "1",
    "P_elec": "W", "P_inv_cond": "W", "P_inv_sw": "W", "P_cu": "W", "P_screw_nut": "W",
    "P_friction": "W", "P_viscous": "W", "P_contact": "W", "P_load": "W", "E_stored": "J",
}
OUTPUT_DOCS = {
    "x_rod": "rod position, the sensor signal", "v_rod": "rod velocity",
    "x_in": "nut-side position phi*p/(2 pi)", "omega": "motor speed",
    "i_d": "d-axis current (0 for the dc motor)",
    "i_q": "q-axis current (the dc motor's current)",
    "v_d": "d-axis voltage (0 for the dc motor)",
    "v_q": "q-axis voltage (dc motor: its voltage / 1.5)",
    "T_m": "motor torque", "F_in": "screw force on the rod", "F_friction": "rod friction force",
    "omega_cmd": "speed command", "i_cmd": "q-current command", "stick": "1 while stuck (hybrid)",
    "P_elec": "electrical power into the windings", "P_inv_cond": "inverter conduction loss",
    "P_inv_sw": "inverter switching loss", "P_cu": "copper loss",
    "P_screw_nut": "screw-nut efficiency loss", "P_friction": "seal/bearing (Coulomb) friction loss",
    "P_viscous": "viscous loss (rod and shaft)", "P_contact": "contact-damping loss",
    "P_load": "power delivered to the load, F_ext*v_rod",
    "E_stored": "kinetic + spring + magnetic energy",
}

#: Controller outputs held between ECU samples in ZOH mode.
HOLD = ("omega_cmd", "i_cmd", "v_d", "v_q")


@dataclass
class Model:
    """An assembled EMA model.

    Attributes
    ----------
    variants : dict
        The complete variant choice.
    params : Parameters
        Default numeric parameters (the model itself is parametric).
    states, inputs, outputs, param_names : tuple of str
        Names of the entries of x, u, y and p.
    f : casadi.Function
        ``f(x, u, p) -> (xdot, y)``, continuous controller.
    f_held, sample : casadi.Function
        The ZOH split (see module docstring).
    project : casadi.Function
        ``project(x_prev, x, u, p) -> (x_next, stick)``: the discrete stick-entry map of
        hybrid friction (identity and stick = 0 for smooth friction); ``x_prev`` is the
        state at the start of the step that ended in ``x``.
    """

    variants: dict
    params: Parameters
    states: tuple
    inputs: tuple
    outputs: tuple
    param_names: tuple
    f: ca.Function
    f_held: ca.Function
    sample: ca.Function
    state_units: dict = field(default_factory=dict)
    project: ca.Function | None = None
    _p0: np.ndarray | None = field(default=None, repr=False, compare=False)

    @property
    def hybrid(self) -> bool:
        """True for hybrid (stick-slip) friction: integrate with :attr:`project`."""
        return self.variants.get("friction") == "hybrid"

    @property
    def nx(self) -> int:
        return len(self.states)

    @property
    def nu(self) -> int:
        return len(self.inputs)

    @property
    def ny(self) -> int:
        return len(self.outputs)

    def p(self, params: Parameters | None = None, **overrides) -> np.ndarray:
        """Numeric parameter vector (defaults: the model's own set)."""
        if params is None and not overrides:  # the common case, cached (params are frozen)
            if self._p0 is None:
                self._p0 = self.params.vector()
            return self._p0.copy()
        return (params or self.params).vector(**overrides)

    def u(self, **values: float) -> np.ndarray:
        """Numeric input vector; eta defaults to the parameter set's efficiency."""
        d = {"eta": self.params.screw.eta}
        d.update(values)
        for k in d:
            if k not in self.inputs:
                raise KeyError(f"unknown input '{k}'; inputs are {', '.join(self.inputs)}")
        return np.array([d.get(k, 0.0) for k in self.inputs], dtype=float)

    def x0(self) -> np.ndarray:
        """Initial state: at rest, all zero, the rod centred in the backlash gap."""
        return np.zeros(self.nx)

    def index(self, name: str) -> int:
        """Index of a state by name."""
        return self.states.index(name)

    def yindex(self, name: str) -> int:
        """Index of an output by name."""
        return self.outputs.index(name)


class _States:
    """Collects named state symbols and their derivatives in order."""

    def __init__(self):
        self.names, self.units, self.sym, self.dot = [], {}, {}, {}

    def add(self, name, unit):
        s = ca.SX.sym(name)
        self.names.append(name)
        self.units[name] = unit
        self.sym[name] = s
        return s

    def vector(self):
        return ca.vertcat(*[self.sym[n] for n in self.names])

    def dot_vector(self):
        return ca.vertcat(*[self.dot[n] for n in self.names])


def build_model(params: Parameters, variants: dict | None = None) -> Model:
    """Assemble the EMA for a variant choice.

    Parameters
    ----------
    params : Parameters
        Parameter set; its ``variants`` are the defaults.
    variants : dict, optional
        Overrides, e.g. ``{"motor": "dc", "screw": "rigid"}`` (SPEC §6). Unknown keys or
        values raise :class:`~ema_casadi.params.ParameterError` listing the allowed ones.
    """
    v = dict(params.variants)
    v.update(variants or {})
    v = validate_variants(v)
    params = dataclasses.replace(params, variants=v)

    names = Parameters.names()
    p = ca.SX.sym("p", len(names))
    P = SimpleNamespace(**{n: p[i] for i, n in enumerate(names)})
    u = ca.SX.sym("u", len(INPUTS))
    U = SimpleNamespace(**{n: u[i] for i, n in enumerate(INPUTS)})

    S = _States()
    pos_integral = v["controller"] == "PI"
    if pos_integral:
        S.add("z_x", "rad/s")
    S.add("z_w", "A")
    if v["motor"] == "pmsm":
        S.add("z_d", "V")
        S.add("z_q", "V")
        S.add("i_d", "A")
        S.add("i_q", "A")
    else:
        S.add("z_i", "V")
        S.add("i", "A")
    S.add("phi", "rad")
    S.add("omega", "rad/s")
    if v["screw"] == "elastic":
        S.add("x_rod", "m")
        S.add("v_rod", "m/s")
    else:
        S.add("x_play", "m")
    X = S.sym
    x = S.vector()
    hybrid = v["friction"] == "hybrid"
    contact_state = {}  # friction-contact quantities of the continuous plant (for project)

    # ---- plant quantities that do not depend on the voltage ----------------------
    r = ballscrew.lead_ratio(P)
    omega = X["omega"]
    x_in, v_in = X["phi"] * r, omega * r
    if v["screw"] == "elastic":
        x_rod, v_rod = X["x_rod"], X["v_rod"]
    else:
        x_rod, v_rod = X["x_play"], v_in
    if v["motor"] == "pmsm":
        i_d, i_q = X["i_d"], X["i_q"]
    else:
        i_d, i_q = 0, X["i"]

    # ---- controller --------------------------------------------------------------
    x_fb = P.loop_x * x_rod + U.d_x
    w_fb = P.loop_w * omega + U.d_w
    iq_fb = P.loop_i * i_q + U.d_i

    def position(z):
        return controller.position_law(U.x_cmd, x_fb, z, P, pos_integral)

    def velocity(w_cmd):
        return controller.velocity_law(w_cmd, w_fb, X["z_w"], P)

    def current(i_cmd):
        """-> (v_d, v_q (q-axis equivalent), dict of integrator rates, v applied)."""
        if v["motor"] == "pmsm":
            vd, vq, zd, zq = controller.current_law_foc(
                i_cmd, i_d, iq_fb, i_d, i_q, omega, X["z_d"], X["z_q"], P
            )
            return vd, vq, {"z_d": zd, "z_q": zq}
        vv, zi = controller.current_law_simple(i_cmd, iq_fb, omega, X["z_i"], P)
        return 0, vv / 1.5, {"z_i": zi}

    z_x = X.get("z_x", 0)
    w_cmd, zx_dot = position(z_x)
    i_cmd, zw_dot = velocity(w_cmd)
    vd_c, vq_c, zi_dots = current(i_cmd)
    ctrl_dots = dict(zi_dots, z_w=zw_dot)
    if pos_integral:
        ctrl_dots["z_x"] = zx_dot
    ctrl_names = [n for n in S.names if n in ctrl_dots]

    # ---- plant, given the applied (held or continuous) controller outputs --------
    def plant(w_cmd, i_cmd, vd, vq):
        dots, y = {}, {}
        vd_w, vq_w = inverter.ideal(vd), inverter.ideal(vq)
        if v["motor"] == "pmsm":
            did, diq, T, P_elec, P_cu, E_mag = motor.pmsm(i_d, i_q, vd_w, vq_w, omega, P)
            dots.update(i_d=did, i_q=diq)
        else:
            di, T, P_elec, P_cu, E_mag = motor.dc(i_q, 1.5 * vq_w, omega, P)
            dots["i"] = di
        F_r = friction.sliding_level(U.f_ext, P)
        shape, strib = v["friction_shape"], v["stribeck"] == "on"
        J_rot = P.J_m + P.J_s
        dots["phi"] = omega
        stick = 0
        if v["screw"] == "elastic":
            F_in, delta, E_spring, P_contact, _ = ballscrew.elastic(X["phi"], omega, x_rod, v_rod, P)
            g = ballscrew.efficiency_factor(F_in, omega, U.eta, P)
            T_load = r * F_in * g
            dots["omega"] = motor.shaft(omega, T, T_load, J_rot, P)
            dots["x_rod"] = v_rod
            if hybrid:
                F_app = F_in - U.f_ext - P.c_v * v_rod
                F_hold = ca.substitute(F_app, X["v_rod"], 0)
                F_fr, F_c, stick = friction.hybrid(v_rod, F_app, F_r, P, F_hold)
                dots["v_rod"] = ca.if_else(stick, 0, (F_app - F_c) / P.M)
            else:
                F_fr, F_c = friction.smooth(v_rod, F_r, P, shape, strib)
                dots["v_rod"] = (F_in - U.f_ext - F_fr) / P.M
            P_screw_nut = T_load * omega - F_in * v_in
            E_kin = 0.5 * J_rot * omega**2 + 0.5 * P.M * v_rod**2
        else:
            J_eq = J_rot + P.M * r**2
            if hybrid:
                # the friction that holds the shaft (omega-dot = 0): the net motor torque
                # referred to the rod through the screw, minus the load and viscous force
                T_net = T - P.b_m * omega
                g_hold = ballscrew.efficiency_factor(T_net / r, omega, U.eta, P)
                F_app = T_net / (r * g_hold) - U.f_ext - P.c_v * v_in
                F_hold = ca.substitute(F_app, omega, 0)
                F_fr, F_c, stick = friction.hybrid(v_in, F_app, F_r, P, F_hold)
            else:
                F_fr, F_c = friction.smooth(v_in, F_r, P, shape, strib)
            F_load = U.f_ext + F_fr
            g = ballscrew.efficiency_factor(F_load, omega, U.eta, P)
            T_load = r * F_load * g
            dots["omega"] = motor.shaft(omega, T, T_load, J_eq, P)
            if hybrid:
                dots["omega"] = ca.if_else(stick, 0, dots["omega"])
            dots["x_play"] = ballscrew.play_rate(x_in, v_in, X["x_play"], P.B)
            F_in = F_load + P.M * r * dots["omega"]
            P_screw_nut = T_load * omega - F_load * v_in
            E_spring, P_contact = 0, 0
            E_kin = 0.5 * J_eq * omega**2
        contact_state["v"] = v_rod
        contact_state["F_hold"] = F_hold if hybrid else 0
        contact_state["F_r"] = F_r
        I_hat = ca.sqrt(i_d**2 + i_q**2)
        P_cond, P_sw = inverter.averaged_losses(I_hat, P)
        y.update(
            x_rod=x_rod, v_rod=v_rod, x_in=x_in, omega=omega, i_d=i_d, i_q=i_q,
            v_d=vd_w, v_q=vq_w, T_m=T, F_in=F_in, F_friction=F_fr,
            omega_cmd=w_cmd, i_cmd=i_cmd, stick=stick,
            P_elec=P_elec, P_inv_cond=P_cond, P_inv_sw=P_sw, P_cu=P_cu,
            P_screw_nut=P_screw_nut, P_friction=F_c * v_rod,
            P_viscous=P.c_v * v_rod**2 + P.b_m * omega**2, P_contact=P_contact,
            P_load=U.f_ext * v_rod, E_stored=E_kin + E_spring + E_mag,
        )
        return dots, y

    # continuous controller
    dots, y = plant(w_cmd, i_cmd, vd_c, vq_c)
    contact = dict(contact_state)
    S.dot = dict(dots, **ctrl_dots)
    yv = ca.vertcat(*[y[n] for n in OUTPUTS])
    f = ca.Function("f", [x, u, p], [S.dot_vector(), yv], ["x", "u", "p"], ["xdot", "y"])

    # ZOH split: plant with held controller outputs; controller integrators frozen
    h = ca.SX.sym("h", len(HOLD))
    dots_h, y_h = plant(h[0], h[1], h[2], h[3])
    dots_h.update({n: 0 for n in ctrl_names})
    S.dot = dots_h
    f_held = ca.Function(
        "f_held", [x, u, p, h], [S.dot_vector(), ca.vertcat(*[y_h[n] for n in OUTPUTS])],
        ["x", "u", "p", "h"], ["xdot", "y"],
    )

    # one ECU update: loops run position -> velocity -> current when flagged, each
    # integrating its state by forward Euler over its own sample period
    flags = ca.SX.sym("flags", 3)
    T_s = {"x": 1 / P.f_s_x, "w": 1 / P.f_s_w, "i": 1 / P.f_s_i}
    w_new, zx_rate = position(z_x)
    w_h = ca.if_else(flags[0], w_new, h[0])
    i_new, zw_rate = velocity(w_h)
    i_h = ca.if_else(flags[1], i_new, h[1])
    vd_new, vq_new, zi_rates = current(i_h)
    vd_h = ca.if_else(flags[2], vd_new, h[2])
    vq_h = ca.if_else(flags[2], vq_new, h[3])
    x_new = {n: X[n] for n in S.names}
    if pos_integral:
        x_new["z_x"] = X["z_x"] + flags[0] * T_s["x"] * zx_rate
    x_new["z_w"] = X["z_w"] + flags[1] * T_s["w"] * zw_rate
    for n, rate in zi_rates.items():
        x_new[n] = X[n] + flags[2] * T_s["i"] * rate
    sample = ca.Function(
        "sample", [x, u, p, h, flags],
        [ca.vertcat(*[x_new[n] for n in S.names]), ca.vertcat(w_h, i_h, vd_h, vq_h)],
        ["x", "u", "p", "h", "flags"], ["x_next", "h_next"],
    )
    project = _projection(x, u, p, P, S, contact, v, hybrid)
    return Model(
        variants=v, params=params, states=tuple(S.names), inputs=INPUTS, outputs=OUTPUTS,
        param_names=tuple(names), f=f, f_held=f_held, sample=sample, state_units=S.units,
        project=project,
    )


def _projection(x, u, p, P, S, contact, v, hybrid):
    """``project(x_prev, x, u, p) -> (x_next, stick)``, see the module docstring.

    The stick test uses the applied force with the contact at rest, as ``f`` does.
    """
    x_prev = ca.SX.sym("x_prev", x.numel())
    if not hybrid:
        return ca.Function("project", [x_prev, x, u, p], [x, ca.SX(0)],
                           ["x_prev", "x", "u", "p"], ["x_next", "stick"])
    k = S.names.index("v_rod" if v["screw"] == "elastic" else "omega")
    contact_fn = ca.Function("contact", [x, u, p], [contact["v"], contact["F_hold"], contact["F_r"]])
    v_prev = contact_fn(x_prev, u, p)[0]
    v_now, F_hold, F_r = contact_fn(x, u, p)
    stick = friction.stick_entry(v_prev, v_now, F_hold, F_r, P)
    x_new = ca.vertcat(x[:k], ca.if_else(stick, 0, x[k]), x[k + 1 :])
    return ca.Function("project", [x_prev, x, u, p], [x_new, stick],
                       ["x_prev", "x", "u", "p"], ["x_next", "stick"])
