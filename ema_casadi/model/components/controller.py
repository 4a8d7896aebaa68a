"""Electronic control unit: cascade position -> velocity -> current (docs: physics).

Each loop is a PI (or P) law with an output limit and an anti-windup law, chosen by
the option ``anti_windup``, declared once (:class:`Loops`, the base of the outer-loop parts
and of the current controllers the motor parts bring; see ``docs/guide/ecu-structure.md``)
and read in one place (:func:`integral_rate`):

``backcalc`` (default)
    Back-calculation: the integrator state ``z`` (kept in output units) is driven back
    by the limit excess at the rate K_i/K_p (tracking time = integral time),
    z' = K_i e + (K_i/K_p)(u_sat - u).
``clamping``
    Conditional integration: the integrator stops while the output is limited and the
    error drives it further into the limit, z' = K_i [e - g(d+) max(e, 0) - g(d-) min(e, 0)]
    with the excess d = u - u_sat, d+ = max(d, 0), d- = max(-d, 0) and the gate
    g(d) = s^2 (3 - 2 s), s = min(d/w, 1), a smooth switch over the band
    w = w_aw u_lim (:func:`clamping_rate`). A negative ``w_aw`` puts the band below the
    limit, as some ECUs clamp: the excess is then taken over (1 + w_aw) u_lim and the
    integrator is fully stopped at the limit (:func:`clamping_band`).

The shape of each switch is a declared parameter of ``[control]``, so a fit can free it
like any other: ``w_aw`` (-, the clamping band as a fraction of the limit, 0.01 on the
reference set), ``k_bc`` (-, the back-calculation rate in units of K_i/K_p, 1) and
``w_knee`` (-, the smooth limit's knee, 0.05). ``w_aw`` is signed: > 0 the band
runs from the limit to (1 + w_aw) of it, < 0 from (1 + w_aw) of it to the limit.

Both are continuous in the state, so variable-step solvers see no jump, and at an
unsaturated operating point (d = 0 nearby) the anti-windup terms and their derivatives
vanish: linearisations and margins are the same for both.

The option ``limit_shape`` gives the form of the rate limit (position loop) and the
current limit (speed loop): ``clip`` (default, a hard clip) or ``smooth`` (exactly linear
up to (1 - w_knee) of the limit, then a quadratic knee reaching the limit at
(1 + w_knee) of it: :func:`soft_clip`). The current loop's voltage limit is always
the hard one (the linear-SVPWM circle of the FOC, a clip for the dc motor).

Loop breaks (the paper's "Gain = 1" block): each loop's feedback is
``loop_flag*measurement + d`` where ``d`` is an injection input. With the flag at 1 and
``d = 0`` the loop is closed; with the flag at 0 the loop is open at that point and
the response to ``d`` is minus the open-loop transfer L.
"""

from __future__ import annotations

import math

import casadi as ca

from ._part import Gain, Hold, Input, Limit, Loop, Output, Part, State, der
from ._ports import Port

__all__ = [
    "clamp", "soft_clip", "limit", "clamping_rate", "clamping_band", "integral_rate", "pi_law", "position_law",
    "velocity_law", "current_law_simple", "current_law_foc", "Loops",
    "PositionP", "PositionPI", "FocCurrent", "PiCurrent", "POSITION_LOOP", "VELOCITY_LOOP", "CURRENT_LOOP",
    "ANTI_WINDUP", "LIMIT_SHAPES", "SWITCH_PARAMS",
]

SQRT3 = 3**0.5

#: Anti-windup laws (option ``anti_windup``), first the default.
ANTI_WINDUP = ("backcalc", "clamping")
#: Forms of the rate and current limits (option ``limit_shape``), first the default.
LIMIT_SHAPES = ("clip", "smooth")
#: The parameters that shape the ECU's switches (``[control]``): the clamping band
#: ``w_aw`` (-; the integrator is fully stopped once the excess u - u_sat reaches
#: w_aw u_lim: 0.24 A on the speed loop, 1.0 rad/s on the rate limit, 1.5 V on the
#: voltage limit of the reference set), the back-calculation rate ``k_bc`` (-, in K_i/K_p)
#: and the smooth limit's knee ``w_knee`` (-).
SWITCH_PARAMS = ("w_aw", "k_bc", "w_knee")


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


def soft_clip(u, lim, knee):
    """Smooth (C1) limit to +-lim: u itself for |u| <= (1 - knee) lim, the limit for
    |u| >= (1 + knee) lim, a quadratic knee between: u - q(u - a) + q(-u - a) with
    a = (1 - knee) lim, b = knee lim and q(r) = min(max(r, 0), 2b)^2 / (4b) + max(r - 2b, 0).

    Parameters
    ----------
    u : SX
        The value (any unit).
    lim : SX
        The limit (the unit of ``u``), positive.
    knee : SX or float
        Half-width of the knee as a fraction of ``lim`` (-), positive (the parameter ``w_knee``).
    """
    a, b = (1 - knee) * lim, knee * lim

    def q(r):
        k = ca.fmin(ca.fmax(r, 0), 2 * b)
        return k**2 / (4 * b) + ca.fmax(r - 2 * b, 0)

    return u - q(u - a) + q(-u - a)


def limit(u, lim, shape="clip", knee=None):
    """The symmetric limit +-lim of ``shape`` (:data:`LIMIT_SHAPES`): :func:`clamp` or
    :func:`soft_clip` with the knee ``knee``.

    Parameters
    ----------
    u : SX
        The value (any unit).
    lim : SX
        The limit (the unit of ``u``).
    shape : {"clip", "smooth"}
        The form of the limit.
    knee : SX or float
        The smooth limit's knee half-width (-); required by ``shape = "smooth"``.
    """
    if shape == "clip":
        return clamp(u, -lim, lim)
    if shape == "smooth":
        if knee is None:
            raise ValueError("the smooth limit needs its knee (the parameter w_knee)")
        return soft_clip(u, lim, knee)
    raise ValueError(f"limit shape '{shape}' not one of {LIMIT_SHAPES}")


def _gate(d, w):
    """Smooth switch from 0 (d <= 0) to 1 (d >= w): s^2 (3 - 2 s), s = min(max(d, 0)/w, 1)."""
    s = ca.fmin(ca.fmax(d, 0) / w, 1)
    return s**2 * (3 - 2 * s)


def clamping_rate(e, excess, K_i, w):
    """Integrator rate of clamping anti-windup (conditional integration), output units/s:
    K_i [e - g(d) max(e, 0) - g(-d) min(e, 0)] with d the limit excess u - u_sat and g
    the gate :func:`_gate` of width ``w``: the integration that would drive the output
    further into the limit is stopped, the one that brings it back is kept.

    Parameters
    ----------
    e : SX
        Control error (input unit).
    excess : SX
        u - u_sat, the amount by which the limit cuts the output (output unit).
    K_i : SX
        Integral gain (output unit per input unit and second).
    w : SX
        Width of the gate (output unit), positive.
    """
    return K_i * (e - _gate(excess, w) * ca.fmax(e, 0) - _gate(-excess, w) * ca.fmin(e, 0))


def clamping_band(u, u_sat, u_lim, w_aw):
    """(excess, width) for :func:`clamping_rate` with the signed band ``w_aw`` (-):
    ``w_aw > 0`` the excess over the limit, u - u_sat, and the width w_aw u_lim (the
    integrator fully stopped at (1 + w_aw) u_lim); ``w_aw < 0`` the excess over the
    band's start (1 + w_aw) u_lim and the width |w_aw| u_lim (fully stopped at the
    limit). Continuous in ``w_aw`` except at 0, which the parameter check excludes.

    Parameters
    ----------
    u, u_sat : SX
        Output before and after the limit (output unit).
    u_lim : SX
        The limit (output unit).
    w_aw : SX
        The band as a signed fraction of the limit (-).
    """
    below = ca.fmin(w_aw, 0)
    start = u_lim * (1 + below)
    excess = ca.if_else(w_aw < 0, u - clamp(u, -start, start), u - u_sat)
    return excess, ca.fmax(ca.fabs(w_aw), 1e-6) * u_lim


def integral_rate(e, u, u_sat, K_p, K_i, band, P, anti_windup="backcalc"):
    """The integrator rate of a PI whose output ``u`` the limit cuts to ``u_sat``, by its
    anti-windup law (output units/s): back-calculation, z' = K_i e + k_bc (K_i/K_p)(u_sat - u),
    or clamping, :func:`clamping_rate` over ``band``. The one place that reads the option
    ``anti_windup``.

    Parameters
    ----------
    e : SX
        Control error (input unit).
    u, u_sat : SX
        The output before and after the limit (output unit).
    K_p, K_i : SX
        Proportional (output unit per input unit) and integral gain (the same per second).
    band : tuple of SX
        (excess, width) of the clamping law (output unit): :func:`clamping_band` of a
        scalar limit, the voltage circle's for the FOC.
    P : SimpleNamespace
        Parameter symbols by flat name (uses ``k_bc``).
    anti_windup : {"backcalc", "clamping"}
        The law.
    """
    if anti_windup == "backcalc":
        return K_i * e + (P.k_bc * (K_i / K_p)) * (u_sat - u)
    if anti_windup == "clamping":
        excess, width = band
        return clamping_rate(e, excess, K_i, width)
    raise ValueError(f"anti-windup '{anti_windup}' not one of {ANTI_WINDUP}")


def pi_law(e, z, K_p, K_i, u_lim, P, u_ff=0, anti_windup="backcalc", shape="clip"):
    """PI with symmetric limit +-u_lim, feed-forward and anti-windup.

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
    P : SimpleNamespace
        Parameter symbols by flat name (uses the switch shapes ``w_aw``, ``k_bc``, ``w_knee``, -).
    u_ff : SX or float
        Feed-forward added before the limit (output unit).
    anti_windup : {"backcalc", "clamping"}
        The anti-windup law (:func:`integral_rate`; the clamping band :func:`clamping_band`
        of w_aw u_lim).
    shape : {"clip", "smooth"}
        The form of the limit (:func:`limit`, knee ``w_knee``).
    """
    u = K_p * e + z + u_ff
    u_sat = limit(u, u_lim, shape, P.w_knee if shape == "smooth" else None)
    return u_sat, u, integral_rate(e, u, u_sat, K_p, K_i, clamping_band(u, u_sat, u_lim, P.w_aw), P, anti_windup)


def position_law(x_cmd, x_fb, z_x, P, integral: bool, anti_windup="backcalc", shape="clip"):
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
        Parameter symbols by flat name (uses ``p``, ``v_max``, ``K_x``, ``K_i_x`` and the
        switch shapes :data:`SWITCH_PARAMS`).
    integral : bool
        PI (True) or P (False) law.
    anti_windup : {"backcalc", "clamping"}
        The PI's anti-windup law (:func:`pi_law`).
    shape : {"clip", "smooth"}
        The form of the rate limit (:func:`limit`).
    """
    k = 2 * ca.pi / P.p
    e = x_cmd - x_fb
    omega_max = k * P.v_max
    if not integral:
        return limit(k * P.K_x * e, omega_max, shape, P.w_knee if shape == "smooth" else None), None
    w, _, z_dot = pi_law(e, z_x, k * P.K_x, k * P.K_i_x, omega_max, P, anti_windup=anti_windup, shape=shape)
    return w, z_dot


def velocity_law(omega_cmd, omega_fb, z_w, P, anti_windup="backcalc", shape="clip"):
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
        Parameter symbols by flat name (uses ``K_p_w``, ``T_i_w``, ``I_max`` and the switch
        shapes :data:`SWITCH_PARAMS`).
    anti_windup : {"backcalc", "clamping"}
        The PI's anti-windup law (:func:`pi_law`).
    shape : {"clip", "smooth"}
        The form of the current limit (:func:`limit`).
    """
    i_cmd, _, z_dot = pi_law(omega_cmd - omega_fb, z_w, P.K_p_w, P.K_p_w / P.T_i_w, P.I_max, P,
                             anti_windup=anti_windup, shape=shape)
    return i_cmd, z_dot


def current_law_simple(i_cmd, i_fb, omega, z_i, P, v_dc=None, anti_windup="backcalc"):
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
        Parameter symbols by flat name (uses ``pp``, ``psi``, ``K_p_i``, ``K_i_i``, ``k_v``, ``V_dc``,
        ``w_aw``, ``k_bc``).
    v_dc : SX, optional
        Measured DC-link voltage (V) the limit follows; default ``P.V_dc``.
    anti_windup : {"backcalc", "clamping"}
        The PI's anti-windup law (:func:`pi_law`).
    """
    K_e = 1.5 * P.pp * P.psi
    v_lim = 1.5 * P.k_v * (P.V_dc if v_dc is None else v_dc) / SQRT3
    v, _, z_dot = pi_law(i_cmd - i_fb, z_i, 1.5 * P.K_p_i, 1.5 * P.K_i_i, v_lim, P, u_ff=K_e * omega,
                         anti_windup=anti_windup)
    return v, z_dot


def current_law_foc(i_q_cmd, i_d_fb, i_q_fb, i_d, i_q, omega, z_d, z_q, P, v_dc=None, anti_windup="backcalc"):
    """Field-oriented current control in the rotor dq frame -> (v_d, v_q) (V).

    i_d* = 0; PI on i_d and i_q with back-EMF / cross-coupling decoupling
    (v_d -= omega_e L_q i_q, v_q += omega_e (L_d i_d + psi)); the voltage vector is
    scaled onto the linear-SVPWM circle |v_dq| <= k_v V_dc / sqrt(3).
    Anti-windup per axis on the excess v_k_u - v_k of that axis: back-calculation, or
    clamping (:func:`clamping_rate`, band w_aw times the circle's radius).
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
        ``K_i_i``, ``k_v``, ``V_dc``, ``w_aw``, ``k_bc``).
    v_dc : SX, optional
        Measured DC-link voltage (V) the limit follows; default ``P.V_dc``.
    anti_windup : {"backcalc", "clamping"}
        The anti-windup law.
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
    # the clamping band on the circle: the excess over the radius (1 + min(w_aw, 0)) v_lim, per axis
    inner = ca.fmin(1, v_lim * (1 + ca.fmin(P.w_aw, 0)) / mag)
    w = ca.fmax(ca.fabs(P.w_aw), 1e-6) * v_lim
    return (v_d, v_q, integral_rate(e_d, v_d_u, v_d, P.K_p_i, P.K_i_i, (v_d_u - inner * v_d_u, w), P, anti_windup),
            integral_rate(e_q, v_q_u, v_q, P.K_p_i, P.K_i_i, (v_q_u - inner * v_q_u, w), P, anti_windup))


# ---- parts --------------------------------------------------------------------------
# the loops feed back the sensed signals (the sensor parts provide them)
POSITION_LOOP = Loop("position", flag="loop_x", injection="d_x", measured="x_s", rate="f_s_x")
VELOCITY_LOOP = Loop("velocity", flag="loop_w", injection="d_w", measured="omega_s", rate="f_s_w")
CURRENT_LOOP = Loop("current", flag="loop_i", injection="d_i", measured="i_q_s", rate="f_s_i")


class Loops(Part):
    """The base of the ECU's loop parts: the option ``anti_windup``, declared here once."""

    options = {"anti_windup": ANTI_WINDUP}
    option_params = {"anti_windup": {"backcalc": ("k_bc",), "clamping": ("w_aw",)}}  # the band: clamping's

    @property
    def anti_windup(self) -> str:
        """The anti-windup law the part's PI loops use (:data:`ANTI_WINDUP`)."""
        return self.opt.get("anti_windup", ANTI_WINDUP[0])


def _omega_max(P):
    return 2 * math.pi * P.v_max / P.p


#: The saturations of the outer loops, which a trim keeps inactive.
_LIMITS = (
    Limit("current", "current limit", "i_q", lambda y, P: abs(y["i_cmd"]), lambda P: P.I_max, "I_max",
          lift=("I_max",), unit="A", holds_load=True, digits=3),
    Limit("rod_speed", "rate limit", "the rod speed command", lambda y, P: abs(y["omega_cmd"]) * P.p / (2 * math.pi),
          lambda P: P.v_max, "v_max", lift=("v_max",), unit="mm/s", scale=1e3),
)
#: Tunable gains of the outer loops; K_i_x may start at zero: then it is scaled linearly
#: from K_x^2/4 (the PI zero at K_x/4, its natural size).
_K_X = Gain("K_x", "position")
_K_I_X = Gain("K_i_x", "position", zero_scale=lambda ref: ref["K_x"] ** 2 / 4)
_SPEED_GAINS = (Gain("K_p_w", "velocity"), Gain("T_i_w", "velocity", kind="time"))


class PositionP(Loops):
    """ECU outer loops: P position loop (rate-limited) and PI speed loop (docs: physics)."""

    family, value = "controller", "P"
    reads = (Port("x_s", "m", "the measured rod position"), Port("omega_s", "rad/s", "the measured motor speed"),)
    doc = "position P loop -> speed PI loop -> current command"
    inputs = (
        Input("x_cmd", "m", "length", "commanded rod position", roles=("command",)),
        Input("d_x", "m", "length", "injection at the position feedback (loop break)", injection=True),
        Input("d_w", "rad/s", "angular_velocity", "injection at the speed feedback (loop break)", injection=True),
    )
    outputs = (
        Output("omega_cmd", "rad/s", "motor speed command of the position loop"),
        Output("i_cmd", "A", "q-current command of the speed loop", roles=("current_command",)),
    )
    params = ("K_x", "K_p_w", "T_i_w", "v_max", "p", "I_max", "loop_x", "loop_w", "f_s_x", "f_s_w", *SWITCH_PARAMS)
    trim_limits = _LIMITS
    gains = (_K_X, *_SPEED_GAINS)
    loops = (POSITION_LOOP, VELOCITY_LOOP)
    holds = (Hold("omega_cmd", "rad/s", "position"), Hold("i_cmd", "A", "velocity"))
    states = (
        State("z_w", "A", "speed-loop integral part", roles=("controller_integral",),
              scale=lambda P: P.I_max, loop="velocity"),
    )
    options = {**Loops.options, "limit_shape": LIMIT_SHAPES}
    option_params = {**Loops.option_params, "limit_shape": {"smooth": ("w_knee",)}}  # the clip has no knee
    integral = False
    smooth = {"limit_shape": "smooth"}  # the clip's corners

    def signals(self):
        aw = self.anti_windup
        shape = self.opt.get("limit_shape", LIMIT_SHAPES[0])

        def position(b):
            z = b["z_x"] if self.integral else 0
            w, z_dot = position_law(b["x_cmd"], b.feedback(POSITION_LOOP), z, b.P, self.integral, aw, shape)
            return (w, z_dot) if self.integral else w

        def velocity(b):
            return velocity_law(b["omega_cmd"], b.feedback(VELOCITY_LOOP), b["z_w"], b.P, aw, shape)

        out = {("i_cmd", der("z_w")): velocity}
        out[("omega_cmd", der("z_x")) if self.integral else "omega_cmd"] = position
        return out


class PositionPI(PositionP):
    """ECU outer loops with a PI position loop (integral action: hunting studies)."""

    value = "PI"
    doc = "position PI loop -> speed PI loop -> current command"
    params = PositionP.params + ("K_i_x",)
    gains = (_K_X, _K_I_X, *_SPEED_GAINS)
    states = (
        State("z_x", "rad/s", "position-loop integral part", roles=("controller_integral",),
              scale=_omega_max, loop="position"),
        *PositionP.states,
    )
    integral = True


# ---- the current controllers: brought by the motor parts (Part.brings) ------------------
def _volts(P):
    return P.V_dc


#: The voltage limit of the current controller (the linear-SVPWM circle), which a trim
#: keeps inactive; lifted through k_v, not V_dc (V_dc also sets the switching losses,
#: which heat the inverter node of a thermal network).
_VOLTAGE = (Limit("voltage", "voltage limit", "|v_dq|", lambda y, P: math.hypot(y["v_d"], y["v_q"]),
                  lambda P: P.k_v * P.V_dc / math.sqrt(3), "k_v V_dc/sqrt(3)", lift=("k_v",), unit="V"),)
_CURRENT_GAINS = (Gain("K_p_i", "current"), Gain("K_i_i", "current"))
_CURRENT_PARAMS = ("pp", "psi", "K_p_i", "K_i_i", "k_v", "V_dc", "loop_i", "f_s_i", "w_aw", "k_bc")
_D_I = Input("d_i", "A", "current", "injection at the q-current feedback (loop break)", injection=True)


class FocCurrent(Loops):
    """The PMSM's field-oriented current controller (:func:`current_law_foc`): PI on the
    d and q currents from the current sensors, decoupling, the linear-SVPWM voltage
    circle; its references held between current-loop samples. Brought by the PMSM part."""

    family, value = "controller", "foc"
    reads = (
        Port("i_cmd", "A", "the current command"),
        Port("i_d_s", "A", "the measured d current"),
        Port("i_q_s", "A", "the measured q current"),
        Port("omega_s", "rad/s", "the measured motor speed"),
        Port("v_dc", "V", "the DC-link voltage"),
    )
    doc = "FOC current loop: dq PI with decoupling, voltage circle"
    inputs = (_D_I,)
    params = ("L_d", "L_q", *_CURRENT_PARAMS)
    trim_limits = _VOLTAGE
    gains = _CURRENT_GAINS
    loops = (CURRENT_LOOP,)
    holds = (Hold("v_d_ref", "V", "current"), Hold("v_q_ref", "V", "current"))
    states = (
        State("z_d", "V", "d-current integral part", roles=("controller_integral",), scale=_volts, loop="current"),
        State("z_q", "V", "q-current integral part", roles=("controller_integral",), scale=_volts, loop="current"),
    )

    def signals(self):
        def current_law(b):
            # feedback from the current sensors; the decoupling terms from the same readings
            i_d, i_q = b["i_d_s"], b["i_q_s"]
            return current_law_foc(b["i_cmd"], i_d, b.feedback(CURRENT_LOOP), i_d, i_q, b["omega_s"], b["z_d"],
                                   b["z_q"], b.P, b["v_dc"], self.anti_windup)

        return {("v_d_ref", "v_q_ref", der("z_d"), der("z_q")): current_law}


class PiCurrent(Loops):
    """The dc motor's current PI (:func:`current_law_simple`) with back-EMF feed-forward;
    its reference (as v_q = v/1.5, v_d = 0) held between current-loop samples. Brought
    by the dc motor part."""

    family, value = "controller", "pi"
    reads = (
        Port("i_cmd", "A", "the current command"),
        Port("i_q_s", "A", "the measured q current"),
        Port("omega_s", "rad/s", "the measured motor speed"),
        Port("v_dc", "V", "the DC-link voltage"),
    )
    doc = "current PI of the dc equivalent, back-EMF feed-forward"
    inputs = (_D_I,)
    params = _CURRENT_PARAMS
    trim_limits = _VOLTAGE
    gains = _CURRENT_GAINS
    loops = (CURRENT_LOOP,)
    holds = FocCurrent.holds
    states = (
        State("z_i", "V", "current integral part", roles=("controller_integral",), scale=_volts, loop="current"),
    )

    def signals(self):
        def current_law(b):
            v, z_dot = current_law_simple(b["i_cmd"], b.feedback(CURRENT_LOOP), b["omega_s"], b["z_i"], b.P,
                                          b["v_dc"], self.anti_windup)
            return 0, v / 1.5, z_dot

        return {("v_d_ref", "v_q_ref", der("z_i")): current_law}
