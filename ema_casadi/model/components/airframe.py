"""Airframe, elevator surface and pitch flight-control law: the outer loop (docs: physics).

``airframe = "none" | "transport" | "b747"`` (data: Stevens & Lewis and Bryson, docs: aircraft; SI inside):

``transport``
    The Stevens & Lewis medium transport (Aircraft Control and Simulation, 2nd ed., §3.6), nonlinear longitudinal:
    states V_T, alpha, theta, q, h; inputs throttle ``delta_t`` and the vertical gust
    ``w_g`` (m/s, up positive, an angle-of-attack increment w_g/V_T on the aerodynamics).
``b747``
    The Bryson 747 (Control of Spacecraft and Aircraft, 1994) at Mach 0.8, 40 000 ft, linear: states u, w, q,
    theta (deviations); the gust adds to w in the aerodynamic (w) column.

Both drive the elevator from the rod through the horn (an engineering estimate, docs: aircraft): exact crank
kinematics L(delta) = sqrt(a^2 + r^2 - 2 a r cos(phi_0 + delta)), x = L(delta) - L(0),
with the rod perpendicular to the horn at neutral (cos phi_0 = r/a), so the effective
arm r_e = dx/d delta = a r sin(phi_0 + delta)/L is r at neutral. The hinge moment
H = qbar S_e c_e (C_h0 + C_h_a alpha + C_h_d delta) (positive trailing edge down) loads
the rod with -H/r_e (a moment driving the surface back to neutral pushes the rod in:
positive, like f_ext); the surface inertia moves with the rod as the mass J_e/r_e^2
(``masses``), and the rod also feels its velocity term (1/2) dm/dx v^2 (Lagrange with a
position-dependent mass).

The flight-control law (docs: aircraft), pitch-attitude hold with rate damping:
delta_cmd = K_q q + K_th (theta - theta_cmd) + z, dz/dt = K_ith (theta - theta_cmd),
then x_cmd = r sin(delta_cmd) clamped to the stroke. It closes the loop ``aircraft``
with its break at the actuator command: x_cmd = loop_a x_cmd_fcs + d_fcs, so with an
airframe the actuator's ``x_cmd`` is this internal signal (no longer a model input)
and ``theta_cmd`` is. With a sampled ECU the law runs at f_s_a (80 Hz).
"""

from __future__ import annotations

import casadi as ca

from ._part import Hold, Input, Loop, Output, Part, State, der
from ._ports import Port

__all__ = [
    "atmosphere", "crank", "hinge_moment", "pitch_law", "transport_rates",
    "AIRCRAFT_LOOP", "B747_A", "B747_B", "B747_U0", "B747_H", "Transport", "B747", "CONDITIONS",
]

FT = 0.3048
#: Stevens & Lewis atmosphere in SI: rho0 (kg/m^3), lapse (1/m),
#: exponent, temperature at sea level and above 35 000 ft (K), gas constant (J/(kg K))
RHO0, LAPSE, EXPO = 2.377e-3 * 14.593902937206364 / FT**3, 0.703e-5 / FT, 4.14
T0, T_TROP, H_TROP, R_AIR = 519 / 1.8, 390 / 1.8, 35000 * FT, 1716.3 * FT**2 * 1.8

#: Bryson 747 (Control of Spacecraft and Aircraft, 1994), states u, w (m/s), q (rad/s), theta (rad); input delta_e (rad)
B747_U0 = 774 * FT
B747_H = 40000 * FT
_A_US = ((-0.003, 0.039, 0.0, -32.2), (-0.065, -0.319, 774.0, 0.0),
         (0.0002, -0.00101, -0.429, 0.0), (0.0, 0.0, 1.0, 0.0))
_B_US = (1.0, -18.0, -1.16, 0.0)
# to SI: rows u, w scale lengths (ft -> m), columns u, w inverse; q, theta are angles
_SC = (FT, FT, 1.0, 1.0)
B747_A = tuple(tuple(_A_US[i][j] * _SC[i] / _SC[j] for j in range(4)) for i in range(4))
B747_B = tuple(_B_US[i] * _SC[i] for i in range(4))


def atmosphere(h):
    """Density (kg/m^3) and temperature (K) at altitude h (m), Stevens & Lewis.

    Parameters
    ----------
    h : SX or float
        Altitude (m).
    """
    s = 1 - LAPSE * h
    rho = RHO0 * s**EXPO
    T = ca.if_else(h >= H_TROP, T_TROP, T0 * s) if isinstance(h, ca.SX) else (T_TROP if h >= H_TROP else T0 * s)
    return rho, T


def crank(x, P):
    """Surface angle delta (rad) and effective arm r_e = dx/d delta (m) at rod stroke x (m).

    Parameters
    ----------
    x : SX
        Rod stroke from neutral (m), positive out (trailing edge down).
    P : SimpleNamespace
        Parameters (uses ``a_pin``, ``r_horn``).
    """
    a, r = P.a_pin, P.r_horn
    L = ca.sqrt(a**2 - r**2) + x
    phi = ca.acos((a**2 + r**2 - L**2) / (2 * a * r))
    return phi - ca.acos(r / a), a * r * ca.sin(phi) / L


def hinge_moment(qbar, alpha, delta, P):
    """Hinge moment H (N m, positive trailing edge down): the engineering estimate of docs: aircraft.

    Parameters
    ----------
    qbar : SX
        Dynamic pressure (Pa).
    alpha : SX
        Angle of attack (rad).
    delta : SX
        Surface angle (rad).
    P : SimpleNamespace
        Parameters (uses ``S_c_e``, ``C_h0``, ``C_h_a``, ``C_h_d``).
    """
    return qbar * P.S_c_e * (P.C_h0 + P.C_h_a * alpha + P.C_h_d * delta)


def pitch_law(q, theta, theta_cmd, z, P):
    """Pitch-attitude hold with rate damping (docs: aircraft), in rad.

    Returns (delta_cmd (rad), dz/dt (rad/s)).

    Parameters
    ----------
    q, theta, theta_cmd, z : SX
        Pitch rate (rad/s), attitude, its command and the integral part (rad).
    P : SimpleNamespace
        Parameters (uses ``K_q``, ``K_th``, ``K_ith``).
    """
    e = theta - theta_cmd
    return P.K_q * q + P.K_th * e + z, P.K_ith * e


def transport_rates(V, alpha, theta, q, h, delta_t, delta_e, w_g, P):
    """The medium transport's state rates (Stevens & Lewis, in SI) and the load factor.

    Returns (dV, dalpha, dtheta, dq, dh, n_z, qbar, alpha_aero).

    Parameters
    ----------
    V, alpha, theta, q, h : SX
        Airspeed (m/s), angle of attack (rad), attitude (rad), pitch rate (rad/s), altitude (m).
    delta_t, delta_e : SX
        Throttle (-) and elevator (rad, trailing edge down).
    w_g : SX
        Vertical gust (m/s, up positive).
    P : SimpleNamespace
        Parameters of the [airframe] table.
    """
    rho, _ = atmosphere(h)
    qbar = 0.5 * rho * V**2
    thrust = (P.T_stat + V * P.dT_dV) * ca.fmax(delta_t, 0)
    a_aero = alpha + w_g / V
    C_L = P.C_L0 + P.C_L_a * a_aero
    C_m = P.dC_m + P.C_m0 + P.C_m_a * a_aero + P.C_m_de * delta_e + C_L * (P.x_cg - 0.25)
    C_D = P.dC_D + P.C_D0 + P.C_D_cls * C_L**2
    gamma = theta - alpha
    qS = qbar * P.S_w
    dV = (thrust * ca.cos(alpha) - qS * C_D) / P.m_ac - P.g_0 * ca.sin(gamma)
    da = (-thrust * ca.sin(alpha) - qS * C_L + P.m_ac * (V * q + P.g_0 * ca.cos(gamma))) / (P.m_ac * V + qS * P.C_L_ad)
    dq = (qS * P.c_w * (C_m + 0.5 * P.c_w * (P.C_m_q * q + P.C_m_ad * da) / V) + thrust * P.z_E) / P.I_yy
    n_z = V * (q - da) / P.g_0 + ca.cos(gamma)
    return dV, da, q, dq, V * ca.sin(gamma), n_z, qbar, a_aero


AIRCRAFT_LOOP = Loop("aircraft", flag="loop_a", injection="d_fcs", measured="x_cmd_fcs", rate="f_s_a")
_INPUTS = (
    Input("theta_cmd", "rad", "angle", "commanded pitch attitude", roles=("attitude_command",)),
    Input("w_g", "m/s", "rate", "vertical gust velocity, up positive", roles=("gust",)),
    Input("d_fcs", "m", "length", "injection at the actuator command (aircraft loop break)", injection=True),
)
_OUTPUTS = (
    Output("delta_e", "rad", "elevator angle, trailing edge down", roles=("elevator",)),
    Output("delta_cmd", "rad", "elevator command of the flight-control law", roles=("elevator_command",)),
    Output("x_cmd_fcs", "m", "rod command of the flight-control law, r sin(delta_cmd) clamped to the stroke",
           roles=("law_command",)),
    Output("x_cmd", "m", "actuator command: loop_a x_cmd_fcs + d_fcs", roles=("rod_command",)),
    Output("H_hinge", "N*m", "hinge moment, positive trailing edge down"),
    Output("F_surf_rod", "N", "surface load on the rod (hinge moment and inertia), positive pushes in",
           roles=("surface_load",)),
    Output("M_surf_rod", "kg", "surface inertia referred to the rod, J_e/r_e^2", kind="aux"),
    Output("n_z", "1", "normal load factor at the centre of gravity", roles=("load_factor",)),
)
_PARAMS = ("r_horn", "a_pin", "S_c_e", "C_h0", "C_h_a", "C_h_d", "J_e", "K_q", "K_th", "K_ith", "f_s_a",
           "stroke", "loop_a")


_LANDING = {"C_L0": 1.0, "C_D0": 0.08, "C_m0": -0.20, "dC_D": 0.02, "dC_m": -0.05,
            "K_q": 2.0, "K_th": 4.0, "K_ith": 1.0}
#: Flight conditions: name -> flat parameter values (SI): trim airspeed V_0 and altitude
#: h_0 of the transport, its configuration (Stevens & Lewis's table) and the flight-control
#: gains (§4). The 747 (linear, Mach 0.8 at 40 000 ft) reads only the gains.
CONDITIONS = {
    "cruise_sl": {"V_0": 500 * FT, "h_0": 0.0},
    "cruise_30k": {"V_0": 800 * FT, "h_0": 30000 * FT},
    "landing": {"V_0": 250 * FT, "h_0": 0.0, **_LANDING},
}


class _Airframe(Part):
    """What both airframes share: surface, horn, hinge load and the flight-control law;
    a subclass provides ``_rates(b, delta)`` -> (state rates by name, qbar, alpha_aero, n_z)."""

    family = "airframe"
    reads = (
        Port("v_rod_mech", "m/s", "the rod's mechanical velocity"),
        Port("x_rod_mech", "m", "the rod's mechanical position"),
    )
    conditions = CONDITIONS
    inputs = _INPUTS
    outputs = _OUTPUTS
    loops = (AIRCRAFT_LOOP,)
    holds = (Hold("x_cmd_fcs", "m", "aircraft"),)
    # the flight loop (minutes of flight, trim at a flight condition) runs with the
    # averaged bridge: the switched bridge's continuous model is that average, and its
    # duty clip stalls the whole-loop trim's Newton iteration
    requires = {"inverter": ("ideal",)}
    stored = ("E_surface",)
    loads = ("F_surf_rod",)
    masses = ("M_surf_rod",)
    _z = State("z_th", "rad", "pitch-law integral part (elevator, rad)", roles=("controller_integral",),
               scale=lambda P: 0.5, loop="aircraft")

    def signals(self):
        def surface(b):
            delta, r_e = crank(b["x_rod_mech"], b.P)
            return delta, r_e, b.P.J_e / r_e**2

        def law(b):
            d_cmd, z_dot = pitch_law(b["q"], b["theta"], b["theta_cmd"], b["z_th"], b.P)
            x = b.P.r_horn * ca.sin(d_cmd)
            return d_cmd, ca.fmin(ca.fmax(x, -b.P.stroke), b.P.stroke), z_dot

        def rod_load(b):
            a, r = b.P.a_pin, b.P.r_horn
            L = ca.sqrt(a**2 - r**2) + b["x_rod_mech"]
            phi = b["delta_e"] + ca.acos(r / a)
            r_e = b["r_e"]
            dm_dx = -2 * b.P.J_e * (a * r * ca.cos(phi) - r_e**2) / (L * r_e**4)
            return -b["H_hinge"] / r_e + 0.5 * dm_dx * b["v_rod_mech"] ** 2

        out = {
            ("delta_e", "r_e", "M_surf_rod"): surface,
            ("delta_cmd", "x_cmd_fcs", der("z_th")): law,
            "x_cmd": lambda b: b.feedback(AIRCRAFT_LOOP),
            "H_hinge": lambda b: hinge_moment(b["qbar"], b["alpha_aero"], b["delta_e"], b.P),
            "F_surf_rod": rod_load,
            "E_surface": lambda b: 0.5 * b["M_surf_rod"] * b["v_rod_mech"] ** 2,
        }
        names = tuple(der(s.name) for s in self.states if s.name != "z_th")
        out[(*names, "qbar", "alpha_aero", "n_z")] = lambda b: self._rates(b, b["delta_e"])
        return out

    def _rates(self, b, delta):  # pragma: no cover - abstract
        raise NotImplementedError


_AC_PARAMS = ("S_w", "c_w", "m_ac", "I_yy", "T_stat", "dT_dV", "z_E", "C_L_a", "C_m_a", "C_m_de", "C_m_q",
              "C_m_ad", "C_L_ad", "C_D_cls", "x_cg", "C_L0", "C_D0", "C_m0", "dC_D", "dC_m", "g_0", "V_0", "h_0")


class Transport(_Airframe):
    """Stevens & Lewis medium transport, nonlinear longitudinal (Aircraft Control and Simulation, 2nd ed., §3.6)."""

    value = "transport"
    doc = "Stevens & Lewis medium transport, nonlinear longitudinal, pitch-attitude hold"
    states = (
        State("V_T", "m/s", "true airspeed", roles=("airspeed",), x0=152.4, scale=lambda P: P.V_0),
        State("alpha", "rad", "angle of attack", roles=("angle_of_attack",), x0=0.0101, scale=lambda P: 0.2),
        State("theta", "rad", "pitch attitude", roles=("pitch_attitude",), x0=0.0101, scale=lambda P: 0.2),
        State("q", "rad/s", "pitch rate", roles=("pitch_rate",), scale=lambda P: 0.2),
        State("h", "m", "altitude", roles=("altitude",), scale=lambda P: 1000.0 + P.h_0),
        _Airframe._z,
    )
    inputs = (Input("delta_t", "1", "dimensionless", "throttle, 0 to 1"), *_INPUTS)
    params = _PARAMS + _AC_PARAMS
    trim_free = ("delta_t", "theta_cmd")
    trim_fix = {"V_T": "V_0", "h": "h_0"}

    def _rates(self, b, delta):
        dV, da, dth, dq, dh, n_z, qbar, a_aero = transport_rates(
            b["V_T"], b["alpha"], b["theta"], b["q"], b["h"], b["delta_t"], delta, b["w_g"], b.P)
        return dV, da, dth, dq, dh, qbar, a_aero, n_z


class B747(_Airframe):
    """Bryson's Boeing 747 at Mach 0.8, 40 000 ft, linear longitudinal (Control of Spacecraft and Aircraft, 1994)."""

    value = "b747"
    doc = "Boeing 747, Mach 0.8 at 40 000 ft, linear longitudinal (Bryson), pitch-attitude hold"
    states = (
        State("u", "m/s", "axial velocity deviation", scale=lambda P: 10.0),
        State("w", "m/s", "normal velocity deviation (down positive)", scale=lambda P: 10.0),
        State("q", "rad/s", "pitch rate", roles=("pitch_rate",), scale=lambda P: 0.2),
        State("theta", "rad", "pitch attitude deviation", roles=("pitch_attitude",), scale=lambda P: 0.2),
        _Airframe._z,
    )
    params = _PARAMS
    trim_free = ("theta_cmd",)
    trim_fix = {"theta": 0.0}

    def _rates(self, b, delta):
        x = [b["u"], b["w"] + b["w_g"], b["q"], b["theta"]]
        rates = [sum(B747_A[i][j] * x[j] for j in range(4) if B747_A[i][j]) + B747_B[i] * delta for i in range(4)]
        rates[3] = b["q"]  # kinematic, no gust
        rho, _ = atmosphere(B747_H)
        qbar = 0.5 * rho * B747_U0**2
        n_z = 1 - (rates[1] - B747_U0 * b["q"]) / 9.80665
        return (*rates, qbar, (b["w"] + b["w_g"]) / B747_U0, n_z)

