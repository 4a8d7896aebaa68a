"""Electronic control unit: cascade position -> velocity -> current (docs: physics).

Each loop is a PI (or P) law with an output clamp and back-calculation anti-windup:
the integrator state ``z`` is kept in output units and is driven back by the clamp
excess at the rate K_i/K_p (tracking time = integral time). Back-calculation is
continuous, so variable-step solvers and linearisation see no switching, and at an
unsaturated operating point the anti-windup term vanishes from the Jacobian.

Loop breaks (the paper's "Gain = 1" block): each loop's feedback is
``loop_flag*measurement + d`` where ``d`` is an injection input. With the flag at 1 and
``d = 0`` the loop is closed; with the flag at 0 the loop is open at that point and
the response to ``d`` is minus the open-loop transfer L.
"""

from __future__ import annotations

import math

import casadi as ca

from ._part import Hold, Input, Loop, Output, Part, State, der

__all__ = [
    "clamp", "pi_law", "position_law", "velocity_law", "current_law_simple", "current_law_foc",
    "PositionP", "PositionPI", "POSITION_LOOP", "VELOCITY_LOOP",
]

SQRT3 = 3**0.5


def clamp(u, lo, hi):
    """Saturate ``u`` to [lo, hi].

    Parameters
    ----------
    u : SX
        The value (any unit).
    lo, hi : SX
        The limits (the unit of ``u``).
    """
    return ca.fmin(ca.fmax(u, lo), hi)


def pi_law(e, z, K_p, K_i, u_lim, u_ff=0):
    """PI with symmetric clamp +-u_lim, feed-forward and back-calculation anti-windup.

    Returns (u_sat, u_unsat, z_dot). ``z`` is the integral part in output units.

    Parameters
    ----------
    e : SX
        Control error (input unit).
    z : SX
        Integral part (output unit).
    K_p : SX
        Proportional gain (output unit per input unit).
    K_i : SX
        Integral gain (output unit per input unit and second).
    u_lim : SX
        Output limit, symmetric (output unit).
    u_ff : SX or float
        Feed-forward added before the clamp (output unit).
    """
    u = K_p * e + z + u_ff
    u_sat = clamp(u, -u_lim, u_lim)
    z_dot = K_i * e + (K_i / K_p) * (u_sat - u)
    return u_sat, u, z_dot


def position_law(x_cmd, x_fb, z_x, P, integral: bool):
    """Position loop on rod position (m) -> motor speed command omega_cmd (rad/s).

    omega_cmd = (2 pi/p)(K_x e + K_i_x int e), clamped to the rate limit
    omega_max = 2 pi v_max / p. Returns (omega_cmd, z_x_dot or None).

    Parameters
    ----------
    x_cmd : SX
        Commanded rod position (m).
    x_fb : SX
        Fed-back rod position (m).
    z_x : SX or None
        Integral part (rad/s); unused without ``integral``.
    P : SimpleNamespace
        Parameter symbols by flat name (uses ``p``, ``v_max``, ``K_x``, ``K_i_x``).
    integral : bool
        PI (True) or P (False) law.
    """
    k = 2 * ca.pi / P.p
    e = x_cmd - x_fb
    omega_max = k * P.v_max
    if not integral:
        return clamp(k * P.K_x * e, -omega_max, omega_max), None
    w, _, z_dot = pi_law(e, z_x, k * P.K_x, k * P.K_i_x, omega_max)
    return w, z_dot


def velocity_law(omega_cmd, omega_fb, z_w, P):
    """Speed PI (rad/s) -> current command (A, q axis), clamped to +-I_max.

    Returns (i_cmd, z_w_dot).

    Parameters
    ----------
    omega_cmd : SX
        Speed command (rad/s).
    omega_fb : SX
        Fed-back motor speed (rad/s).
    z_w : SX
        Integral part (A).
    P : SimpleNamespace
        Parameter symbols by flat name (uses ``K_p_w``, ``T_i_w``, ``I_max``).
    """
    i_cmd, _, z_dot = pi_law(omega_cmd - omega_fb, z_w, P.K_p_w, P.K_p_w / P.T_i_w, P.I_max)
    return i_cmd, z_dot


def current_law_simple(i_cmd, i_fb, omega, z_i, P, v_dc=None):
    """Current PI of the 1-phase (dc-equivalent) motor -> winding voltage (V).

    Gains are the PMSM q-axis gains x1.5 and the voltage limit 1.5*k_v*V_dc/sqrt(3)
    (the power-invariant equivalent, docs: physics), plus back-EMF feed-forward
    K_e*omega, the counterpart of FOC decoupling. Returns (v, z_i_dot).

    Parameters
    ----------
    i_cmd : SX
        Current command (A).
    i_fb : SX
        Fed-back winding current (A).
    omega : SX
        Motor speed (rad/s), for the back-EMF feed-forward.
    z_i : SX
        Integral part (V).
    P : SimpleNamespace
        Parameter symbols by flat name (uses ``pp``, ``psi``, ``K_p_i``, ``K_i_i``, ``k_v``, ``V_dc``).
    v_dc : SX, optional
        Measured DC-link voltage (V) the limit follows; default ``P.V_dc``.
    """
    K_e = 1.5 * P.pp * P.psi
    v_lim = 1.5 * P.k_v * (P.V_dc if v_dc is None else v_dc) / SQRT3
    v, _, z_dot = pi_law(i_cmd - i_fb, z_i, 1.5 * P.K_p_i, 1.5 * P.K_i_i, v_lim, u_ff=K_e * omega)
    return v, z_dot


def current_law_foc(i_q_cmd, i_d_fb, i_q_fb, i_d, i_q, omega, z_d, z_q, P, v_dc=None):
    """Field-oriented current control in the rotor dq frame -> (v_d, v_q) (V).

    i_d* = 0; PI on i_d and i_q with back-EMF / cross-coupling decoupling
    (v_d -= omega_e L_q i_q, v_q += omega_e (L_d i_d + psi)); the voltage vector is
    scaled onto the linear-SVPWM circle |v_dq| <= k_v V_dc / sqrt(3).
    Returns (v_d, v_q, z_d_dot, z_q_dot).

    Parameters
    ----------
    i_q_cmd : SX
        q-current command (A).
    i_d_fb, i_q_fb : SX
        Fed-back d and q currents (A).
    i_d, i_q : SX
        The d and q currents for the decoupling terms (A).
    omega : SX
        Motor (mechanical) speed (rad/s).
    z_d, z_q : SX
        Integral parts (V).
    P : SimpleNamespace
        Parameter symbols by flat name (uses ``pp``, ``psi``, ``L_d``, ``L_q``, ``K_p_i``,
        ``K_i_i``, ``k_v``, ``V_dc``).
    v_dc : SX, optional
        Measured DC-link voltage (V) the limit follows; default ``P.V_dc``.
    """
    omega_e = P.pp * omega
    e_d = 0 - i_d_fb
    e_q = i_q_cmd - i_q_fb
    v_d_u = P.K_p_i * e_d + z_d - omega_e * P.L_q * i_q
    v_q_u = P.K_p_i * e_q + z_q + omega_e * (P.L_d * i_d + P.psi)
    v_lim = P.k_v * (P.V_dc if v_dc is None else v_dc) / SQRT3
    mag = ca.sqrt(v_d_u**2 + v_q_u**2 + 1e-12)
    scale = ca.fmin(1, v_lim / mag)
    v_d, v_q = scale * v_d_u, scale * v_q_u
    w_aw = P.K_i_i / P.K_p_i
    z_d_dot = P.K_i_i * e_d + w_aw * (v_d - v_d_u)
    z_q_dot = P.K_i_i * e_q + w_aw * (v_q - v_q_u)
    return v_d, v_q, z_d_dot, z_q_dot


# ---- parts --------------------------------------------------------------------------
# the loops feed back the sensed signals (the sensor parts provide them)
POSITION_LOOP = Loop("position", flag="loop_x", injection="d_x", measured="x_s", rate="f_s_x")
VELOCITY_LOOP = Loop("velocity", flag="loop_w", injection="d_w", measured="omega_s", rate="f_s_w")


def _omega_max(P):
    return 2 * math.pi * P.v_max / P.p


class PositionP(Part):
    """ECU outer loops: P position loop (rate-limited) and PI speed loop (docs: physics)."""

    family, value = "controller", "P"
    doc = "position P loop -> speed PI loop -> current command"
    inputs = (
        Input("x_cmd", "m", "length", "commanded rod position"),
        Input("d_x", "m", "length", "injection at the position feedback (loop break)", injection=True),
        Input("d_w", "rad/s", "angular_velocity", "injection at the speed feedback (loop break)", injection=True),
    )
    outputs = (
        Output("omega_cmd", "rad/s", "motor speed command of the position loop"),
        Output("i_cmd", "A", "q-current command of the speed loop"),
    )
    params = ("K_x", "K_p_w", "T_i_w", "v_max", "p", "I_max", "loop_x", "loop_w", "f_s_x", "f_s_w")
    loops = (POSITION_LOOP, VELOCITY_LOOP)
    holds = (Hold("omega_cmd", "rad/s", "position"), Hold("i_cmd", "A", "velocity"))
    states = (
        State("z_w", "A", "speed-loop integral part", roles=("controller_integral",),
              scale=lambda P: P.I_max, loop="velocity"),
    )
    integral = False

    def signals(self):
        def position(b):
            z = b["z_x"] if self.integral else 0
            w, z_dot = position_law(b["x_cmd"], b.feedback(POSITION_LOOP), z, b.P, self.integral)
            return (w, z_dot) if self.integral else w

        def velocity(b):
            return velocity_law(b["omega_cmd"], b.feedback(VELOCITY_LOOP), b["z_w"], b.P)

        out = {("i_cmd", der("z_w")): velocity}
        out[("omega_cmd", der("z_x")) if self.integral else "omega_cmd"] = position
        return out


class PositionPI(PositionP):
    """ECU outer loops with a PI position loop (integral action: hunting studies)."""

    value = "PI"
    doc = "position PI loop -> speed PI loop -> current command"
    params = PositionP.params + ("K_i_x",)
    states = (
        State("z_x", "rad/s", "position-loop integral part", roles=("controller_integral",),
              scale=_omega_max, loop="position"),
        *PositionP.states,
    )
    integral = True
