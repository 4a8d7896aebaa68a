"""Ballscrew / reductor (docs: physics): ``rigid`` one-mass and ``elastic`` two-mass."""

from __future__ import annotations

import math

import casadi as ca

from ._part import MARGIN, Bound, Input, Output, Part, Rating, Seed, State, der
from ._ports import Port
from .motor import no_load_speed, shaft

__all__ = [
    "lead_ratio", "efficiency_factor", "dead_zone", "elastic", "play_rate", "held_force",
    "OVERTRAVEL", "Elastic", "Rigid", "F_EXT", "ETA", "held_at_rest", "lock_rate", "locked_factor", "TAU_LOCK",
]

#: The efficiency switch's former fixed width (W), the default of ``P_blend``.
_P_REF = 0.1


def lead_ratio(P):
    """Rod travel per shaft radian, p / (2 pi) (m/rad).

    Parameters
    ----------
    P : SimpleNamespace
        Parameter symbols by flat name (uses the lead ``p``, m).
    """
    return P.p / (2 * ca.pi)


def efficiency_factor(F, omega, eta, P, eta_inv=None):
    """Factor g in T_load = (p/2 pi) F g: 1/eta when the motor drives the load
    (F omega > 0), eta_inv when the load back-drives, switched on the transmitted power
    q = F omega p/(2 pi) (W) with the weight w = (1 + tanh(q/P_blend))/2 of the driving
    value: g = w/eta + (1 - w) eta_inv. ``P_blend`` (W, a parameter, 0.1 W on the
    reference set) is the width of the switch; ``P_blend = 0`` is the exact switch
    w = (1 + sign(q))/2 (w = 1/2 at q = 0). An exact switch makes a sliding mode on q = 0
    while a load is held at standstill, which variable-step solvers pay for in steps
    (``docs/guide/ecu-structure.md``); 0.1 W moves reference trajectories by < 0.25 um.

    Parameters
    ----------
    F : SX
        Force the nut transmits to the rod (N).
    omega : SX
        Shaft speed (rad/s).
    eta : SX
        Direct efficiency of the screw-nut (-).
    P : SimpleNamespace
        Parameter symbols by flat name (uses ``p``, m, ``P_blend``, W, and ``eta_inv``, -,
        unless given).
    eta_inv : SX, optional
        Inverse efficiency of the screw-nut (-); default ``P.eta_inv``.
    """
    eta_inv = P.eta_inv if eta_inv is None else eta_inv
    q = F * omega * lead_ratio(P)
    # q/P_blend written (q/0.1)(0.1/P_blend): at the default 0.1 W the factor is 1 and the
    # values and derivatives are those of the former constant 0.1 W, bit for bit (a plain
    # q/P_blend reorders the derivative's products); the exact switch where P_blend = 0
    w = 0.5 * (1 + ca.if_else(P.P_blend > 0, ca.tanh((q / _P_REF) * (_P_REF / P.P_blend)), ca.sign(q)))
    return w / eta + (1 - w) * eta_inv


#: Decay time of the lock memory where it is off (``x_lock = 0``, s): the state then
#: only relaxes to 0, decoupled from everything.
TAU_LOCK = 1e-3
#: Force floor of the memory's pre-sliding damping (N): keeps it smooth through F = 0.
F_LOCK = 1e3


def lock_rate(F, omega, z, P):
    """Rate of the screw-nut's self-locking memory z in [-1, 1] (1/s): where it is in the
    band between the back-driven (z = -1, g = eta_inv) and the driving (z = +1, g = 1/eta)
    torque factor. A Dahl-type pre-sliding law in the shaft angle,
    dz/dt = (u - |u| z) / phi_lock with u = omega sign(F) and phi_lock = x_lock (2 pi/p):
    the shaft turning under load moves z to the edge of the way the power flows within
    ``x_lock`` of rod travel; at standstill dz/dt = 0, so z (and the transmitted torque's
    place in the band) is kept, as stiction keeps a force. ``x_lock = 0`` is no memory:
    z decays with TAU_LOCK and the factor is the blend over ``P_blend``.

    Parameters
    ----------
    F : SX
        Force the nut transmits to the rod (N).
    omega : SX
        Shaft speed (rad/s).
    z : SX
        The memory state (-).
    P : SimpleNamespace
        Parameter symbols by flat name (uses ``p``, m, and ``x_lock``, m).
    """
    u = omega * ca.sign(F)
    memory = (u - ca.fabs(u) * z) * lead_ratio(P) / ca.fmax(P.x_lock, 1e-30)
    return ca.if_else(P.x_lock > 0, memory, -z / TAU_LOCK)


def locked_factor(F, omega, z, eta, P, eta_inv=None):
    """Screw-nut torque factor g with the self-locking memory: g_mid + g_half z, the
    band (eta_inv, 1/eta) at the place z holds; with ``x_lock = 0`` the blend
    :func:`efficiency_factor` (the smooth model the linearisation, the model-exchange
    FMU and identification use: the small-signal policy ``screw_lock = "off"``).

    Parameters
    ----------
    F : SX
        Force the nut transmits to the rod (N).
    omega : SX
        Shaft speed (rad/s).
    z : SX
        The memory state (-), :func:`lock_rate`.
    eta : SX
        Direct efficiency (-).
    P : SimpleNamespace
        Parameter symbols by flat name (``p``, ``P_blend``, ``x_lock``, ``eta_inv``).
    eta_inv : SX, optional
        Inverse efficiency (-); default ``P.eta_inv``.
    """
    eta_inv = P.eta_inv if eta_inv is None else eta_inv
    g_half = 0.5 * (1 / eta - eta_inv)
    # pre-sliding damping (LuGre's sigma_1): z + tau_1 dz/dt, tau_1 = 2 sqrt(J phi_lock / k),
    # critical on the pre-sliding spring k = (p/2 pi)(|F| + F_LOCK) g_half of the shaft
    # inertia (without it the memory rings and the ringing's rectification walks z to the
    # middle of the band); tau_1 dz/dt is 0 in steady sliding (z at an edge)
    phi_lock = ca.fmax(P.x_lock, 1e-30) / lead_ratio(P)
    tau_1 = 2 * ca.sqrt((P.J_m + P.J_s) * phi_lock / (lead_ratio(P) * (ca.fabs(F) + F_LOCK) * g_half))
    zd = z + tau_1 * lock_rate(F, omega, z, P)
    g_mem = 0.5 * (1 / eta + eta_inv) + g_half * ca.fmin(ca.fmax(zd, -1), 1)
    return ca.if_else(P.x_lock > 0, g_mem, efficiency_factor(F, omega, eta, P, eta_inv))


def dead_zone(delta, B):
    """Dead zone of total width B: 0 inside |delta| <= B/2, delta -+ B/2 outside.

    Written as fmax(delta - B/2, 0) + fmin(delta + B/2, 0) so that with B = 0 the AD
    slope at delta = 0 is exactly 1 (two half-slopes), not 1/2.

    Parameters
    ----------
    delta : SX
        Deflection across the gap (m).
    B : SX
        Backlash, the total gap width (m).
    """
    return ca.fmax(delta - B / 2, 0) + ca.fmin(delta + B / 2, 0)


def elastic(phi, omega, x_rod, v_rod, P):
    """Two-mass screw: dead-zone spring (eq. 2) plus contact damping.

    Delta = x_in - x_rod with x_in = phi p/(2 pi);
    F_in = C dz(Delta) + c_c dDelta/dt while in contact (|Delta| >= B/2).
    Returns (F_in (N), Delta (m), E_spring (J), P_contact (W), in_contact).

    Parameters
    ----------
    phi : SX
        Shaft angle (rad).
    omega : SX
        Shaft speed (rad/s).
    x_rod : SX
        Rod position (m).
    v_rod : SX
        Rod velocity (m/s).
    P : SimpleNamespace
        Parameter symbols by flat name (uses ``p``, ``B``, ``C``, ``c_c``).
    """
    x_in = phi * lead_ratio(P)
    v_in = omega * lead_ratio(P)
    delta = x_in - x_rod
    d_delta = v_in - v_rod
    dz = dead_zone(delta, P.B)
    contact = ca.fabs(delta) >= P.B / 2
    F_damp = ca.if_else(contact, P.c_c * d_delta, 0)
    F_in = P.C * dz + F_damp
    return F_in, delta, 0.5 * P.C * dz**2, F_damp * d_delta, contact


def play_rate(x_in, v_in, x_play, B):
    """Play (hysteresis) operator of width B as an ODE: the rate of x_play (m/s), which
    follows the input only while the input pushes on an edge of the gap.

    Parameters
    ----------
    x_in : SX
        Input position, the nut side (m).
    v_in : SX
        Input velocity (m/s).
    x_play : SX
        Output position, the rod side (m).
    B : SX
        Backlash, the total gap width (m).
    """
    gap = x_in - x_play
    return ca.if_else(gap >= B / 2, ca.fmax(v_in, 0), 0) + ca.if_else(gap <= -B / 2, ca.fmin(v_in, 0), 0)


# ---- parts: the screw owns the drive-train mechanics (shaft and rod) ------------------
# Signals every screw provides besides its outputs: x_in, v_in (nut side), v_contact
# (velocity at the friction contact), F_drive (force driving the contact: screw or
# referred motor force minus the rod load, before friction and viscous), x_rod_mech,
# v_rod_mech (the rod's mechanical motion: what an end stop touches; the rigid screw's
# x_rod is the position signal after the play), T_load. The screw-nut efficiencies are
# the signals eta_screw and eta_inv_screw of the thermal part (the eta input and the
# parameter eta_inv with thermal = "off"; functions of the screw temperature with "lumped").
def held_force(P):
    """Largest rod force the motor holds through the screw at the current limit,
    K_t I_max / ((p/2 pi) eta_inv) (N; 61.7 kN on the reference set).

    Parameters
    ----------
    P : SimpleNamespace
        Parameter values by flat name (uses ``pp``, ``psi``, ``I_max``, ``p``, ``eta_inv``).
    """
    return 1.5 * P.pp * P.psi * P.I_max / (P.p / (2 * math.pi) * P.eta_inv)


# ---- physical envelope (docs: reliability): what a run may do before it is garbage ------
#: How far the rod may pass the stroke without end stops (m): a real rod would hit
#: its housing there, so a model rod beyond it is running away. The end-stop part
#: widens this ``overtravel`` limit by the stops' own deflection.
OVERTRAVEL = 1e-3
_TRAVEL = Bound(lambda E: E.stroke + E.overtravel, "stroke + overtravel")
_NUT_ANGLE = Bound(lambda E: (E.stroke + E.overtravel) / lead_ratio(E), "stroke + overtravel, at the nut")
_SPEED = Bound(lambda E: MARGIN * no_load_speed(E), f"{MARGIN:g} x the no-load speed V_dc/K_e")
_ROD_SPEED = Bound(lambda E: MARGIN * no_load_speed(E) * lead_ratio(E), f"{MARGIN:g} x the no-load speed, at the rod")
_FORCE = Bound(lambda E: MARGIN * held_force(E), f"{MARGIN:g} x the largest force the motor holds")
# the elastic rod also rings on the screw spring: a load step F excites F/sqrt(C M)
# (1.1 m/s at 30 kN on the reference set), so its bound adds that of the largest load
_RINGING_ROD = Bound(lambda E: MARGIN * no_load_speed(E) * lead_ratio(E)
                     + MARGIN * held_force(E) / math.sqrt(E.C * E.M),
                     f"{MARGIN:g} x the no-load speed at the rod + its ringing under the largest load step")
def held_at_rest(P):
    """Largest rod force the current limit holds at standstill, where the screw-nut
    factor sits at the middle of its blend, (1/eta + eta_inv)/2: K_t I_max / ((p/2 pi) g)
    (N; 54.5 kN on the reference set).

    Parameters
    ----------
    P : SimpleNamespace
        Parameter values by flat name (uses ``pp``, ``psi``, ``I_max``, ``p``, ``eta``, ``eta_inv``).
    """
    return 1.5 * P.pp * P.psi * P.I_max / (lead_ratio(P) * (0.5 / P.eta + 0.5 * P.eta_inv))


#: Envelope limits: the overtravel, and the load the actuator holds at standstill
#: (``held_load``: what a mission's load profile is checked against before it runs).
_LIMITS = {"overtravel": lambda P: OVERTRAVEL, "held_load": held_at_rest}

F_EXT = Input("f_ext", "N", "force", "external rod force, positive pushes the rod in", bound=_FORCE, roles=("load",))
ETA = Input("eta", "1", "dimensionless", "screw-nut efficiency (a thermal model may drive it)", default="eta",
            roles=("efficiency",))
# declared by the thermal parts, which pass it on as eta_screw (or replace it by eta(T_s))


#: Small-signal policy: backlash "off" closes the gap (dead zone and play have slope 1 at B = 0).
#: The efficiency switch widened (``switch_width``): 1 W and 10 W of transmitted power (the
#: reference's own 0.1 W is 8 mrad/s of shaft speed against 15 kN).
_SMALL_SIGNAL = {"backlash": {"off": {"B": 0.0}},
                 "switch_width": {"wide": {"P_blend": 1.0}, "wider": {"P_blend": 10.0}}}
#: The elastic screw's self-locking memory: "off" (the default of linearisation, trim and
#: every smooth use) is the blend over P_blend; "keep" linearises the pre-sliding memory.
_SMALL_SIGNAL_LOCK = {**_SMALL_SIGNAL, "screw_lock": {"off": {"x_lock": 0.0}}}
#: Inside the gap the spring has no slope and a trim's Newton cannot find the contact:
#: start from the backlash-free trim with the nut moved half the gap towards the flank
#: that carries the screw force.
def _inside_gap(P, y):
    if P.B > 0 and abs(y["x_in"] - y["x_rod"]) < P.B / 2:
        return (f"backlash kept: the operating point sits inside the {P.B * 1e6:.3g} um gap, so the linear "
                "model has the rod decoupled from the screw; use backlash='off' or a load")
    return None


_GAP_SEED = Seed("backlash", lambda P, y: math.copysign(1.0, y["F_in"]) * (P.B / 2) / lead_ratio(P)
                 if y["F_in"] != 0 else 0.0, warn=_inside_gap)


def _shaft_states(contact: bool):
    # with the rigid screw (contact at the shaft) only the play reads the shaft angle:
    # without backlash at rest nothing restores it (a neutral mode)
    return (
        State("phi", "rad", "shaft angle", roles=("shaft_angle",), scale=lambda P: P.stroke / lead_ratio(P),
              travel=lead_ratio, bound=_NUT_ANGLE, neutral=contact, seed=_GAP_SEED),
        State("omega", "rad/s", "motor speed", roles=("shaft_speed",) + (("contact_velocity",) if contact else ()),
              scale=lambda P: P.v_max / lead_ratio(P), bound=_SPEED),
    )


def _outputs(rod_speed: Bound) -> tuple:
    return (
        Output("x_rod", "m", "rod position, the sensor signal", bound=_TRAVEL, roles=("rod_position",)),
        Output("v_rod", "m/s", "rod velocity", bound=rod_speed, roles=("rod_velocity",)),
        Output("x_in", "m", "nut-side position phi*p/(2 pi)", bound=_TRAVEL, roles=("nut_position",)),
        Output("omega", "rad/s", "motor speed", bound=_SPEED, roles=("motor_speed",)),
        Output("F_in", "N", "screw force on the rod", roles=("screw_force",)),
        Output("g_screw", "1", "screw-nut torque factor T_load/(F p/2pi): 1/eta driving, eta_inv back-driven",
               kind="aux"),
        Output("P_screw_nut", "W", "screw-nut efficiency loss", kind="loss"),
        Output("P_load", "W", "power delivered to the load, f_ext*v_rod", kind="power", roles=("load_power",)),
    )


_PARAMS = ("p", "J_m", "J_s", "M", "b_m", "c_v", "stroke", "v_max", "P_blend", "v_rod_max")


def _ratings(rod: str) -> tuple:
    """The stroke on the rod's mechanical position ``rod`` and the rated rod speed."""
    return (Rating("stroke", "stroke", (rod,), lambda P: P.stroke, "stroke", "m"),
            Rating("rod_speed", "rated rod speed", ("v_rod",), lambda P: P.v_rod_max, "v_rod_max", "m/s"))


class Elastic(Part):
    """Two-mass screw (docs: physics): nut and rod coupled by the dead-zone spring (eq. 2)
    with contact damping; the rod carries the friction contact."""

    family, value = "screw", "elastic"
    reads = (
        Port("F_load_rod", "N", "the load on the rod (the assembly's sum)"),
        Port("F_net", "N", "the force accelerating the contact, friction taken"),
        Port("M_load_rod", "kg", "masses moving with the rod (the assembly's sum)"),
        Port("T_m", "N*m", "the motor torque"),
        Port("eta_screw", "1", "the screw-nut direct efficiency"),
        Port("eta_inv_screw", "1", "the screw-nut inverse efficiency"),
        Port("stick", "1", "the friction's stuck flag"),
    )
    doc = "two-mass: dead-zone spring with contact damping between nut and rod"
    states = _shaft_states(contact=False) + (
        State("x_rod", "m", "rod position", roles=("rod_position",), scale=lambda P: P.stroke, travel=lambda P: 1.0,
              bound=_TRAVEL),
        State("v_rod", "m/s", "rod velocity", roles=("rod_velocity", "contact_velocity"), scale=lambda P: P.v_max,
              bound=_RINGING_ROD),
    )
    inputs = (F_EXT,)
    outputs = _outputs(_RINGING_ROD) + (Output("P_contact", "W", "contact-damping loss", kind="loss"),)
    params = _PARAMS + ("C", "c_c", "B")
    small_signal = _SMALL_SIGNAL
    ratings = _ratings("x_rod")
    # an optimiser's counterpart: the rigid screw. The screw mode (1.42 kHz on the reference
    # set) lies far above what a move excites, and with the friction on the rod (5e5 1/s at
    # rest) it makes explicit shooting steps of ~5 us; the rigid screw carries the friction on
    # the shaft inertia (565 1/s)
    smooth = {"screw": "rigid"}
    #: ``screw_lock``: ``blend`` (default) is the memoryless blend over ``P_blend`` alone;
    #: ``memory`` carries the self-locking memory z_lock (:func:`lock_rate`, parameter
    #: ``x_lock``): a held screw keeps its force. Opt-in for long holds (jams, held loads):
    #: its state is stiff at speed (about -8e4 1/s at 100 rad/s), which the default RK4
    #: steps of missions (1e-4 s) do not resolve, and periodic orbits' saltation does not
    #: carry its reset.
    options = {"screw_lock": ("blend", "memory")}

    def __init__(self, options: dict | None = None):
        """
        Parameters
        ----------
        options : dict, optional
            ``screw_lock``: ``"blend"`` (default) or ``"memory"``.
        """
        super().__init__(options)
        self.memory = self.opt.get("screw_lock", "blend") == "memory"
        if self.memory:
            self.states = type(self).states + (
                State("z_lock", "1", "screw-nut self-locking memory: -1 back-driven edge, +1 driving edge",
                      roles=("hysteresis",), scale=lambda P: 1.0),)
            self.params = type(self).params + ("x_lock",)
            self.small_signal = _SMALL_SIGNAL_LOCK
            self.smooth = {**type(self).smooth, "screw_lock": "blend"}  # the memory is stiff at speed
    stored = ("E_kin", "E_spring")
    loads = ("f_ext",)
    limits = _LIMITS
    heat = {"P_screw_nut": "screw", "P_contact": "screw"}

    def signals(self):
        def screw(b):
            F_in, delta, E_spring, P_contact, _ = elastic(b["phi"], b["omega"], b["x_rod"], b["v_rod"], b.P)
            return F_in, E_spring, P_contact

        def rod(b):
            return ca.if_else(b["stick"], 0, b["F_net"] / (b.P.M + b["M_load_rod"]))

        return {
            "x_in": lambda b: b["phi"] * lead_ratio(b.P),
            "v_in": lambda b: b["omega"] * lead_ratio(b.P),
            ("F_in", "E_spring", "P_contact"): screw,
            "v_contact": lambda b: b["v_rod"],
            "x_rod_mech": lambda b: b["x_rod"],
            "v_rod_mech": lambda b: b["v_rod"],
            "F_drive": lambda b: b["F_in"] - b["F_load_rod"],
            "g_screw": (lambda b: locked_factor(b["F_in"], b["omega"], b["z_lock"], b["eta_screw"], b.P,
                                                b["eta_inv_screw"])) if self.memory else
                       (lambda b: efficiency_factor(b["F_in"], b["omega"], b["eta_screw"], b.P, b["eta_inv_screw"])),
            "T_load": lambda b: lead_ratio(b.P) * b["F_in"] * b["g_screw"],
            der("phi"): lambda b: b["omega"],
            der("omega"): lambda b: _shaft(b, b.P.J_m + b.P.J_s),
            der("x_rod"): lambda b: b["v_rod"],
            der("v_rod"): rod,
            "P_screw_nut": lambda b: b["T_load"] * b["omega"] - b["F_in"] * b["v_in"],
            "E_kin": lambda b: 0.5 * (b.P.J_m + b.P.J_s) * b["omega"] ** 2 + 0.5 * b.P.M * b["v_rod"] ** 2,
            "P_load": lambda b: b["f_ext"] * b["v_rod"],
            **({der("z_lock"): lambda b: lock_rate(b["F_in"], b["omega"], b["z_lock"], b.P)} if self.memory else {}),
        }


def _shaft(b, J):
    return shaft(b["omega"], b["T_m"], b["T_load"], J, b.P)


class Rigid(Part):
    """One-mass screw (docs: physics, eq. 1): the rod follows the shaft; backlash acts on
    the position signal only, as a play operator; friction acts on the shaft."""

    family, value = "screw", "rigid"
    reads = (
        Port("F_friction", "N", "the friction force"),
        Port("F_load_rod", "N", "the load on the rod (the assembly's sum)"),
        Port("M_load_rod", "kg", "masses moving with the rod (the assembly's sum)"),
        Port("T_m", "N*m", "the motor torque"),
        Port("eta_screw", "1", "the screw-nut direct efficiency"),
        Port("eta_inv_screw", "1", "the screw-nut inverse efficiency"),
        Port("stick", "1", "the friction's stuck flag"),
    )
    doc = "one-mass: rod rigid on the shaft, backlash as a play on the position signal"
    states = _shaft_states(contact=True) + (
        # without backlash the play rests anywhere: held exactly at the nut, where both edges
        # act and the AD slope is 1 (a gap of -1e-17 at a shaft speed of +1e-16 selects 0)
        State("x_play", "m", "rod position after the backlash play", roles=("rod_position", "play"),
              scale=lambda P: P.stroke, travel=lambda P: 1.0, bound=_TRAVEL, rest="x_in",
              rest_when=lambda P: P.B == 0),
    )
    inputs = (F_EXT,)
    outputs = _outputs(_ROD_SPEED)
    params = _PARAMS + ("B",)
    small_signal = _SMALL_SIGNAL
    # the rod moves with the nut (x_in); its position signal x_rod is after the play
    ratings = _ratings("x_in")
    stored = ("E_kin",)
    loads = ("f_ext",)
    limits = _LIMITS
    heat = {"P_screw_nut": "screw"}

    def signals(self):
        def drive(b):
            # the force that holds the shaft (omega-dot = 0): the net motor torque
            # referred to the rod through the screw, minus the load
            T_net = b["T_m"] - b.P.b_m * b["omega"]
            g_hold = efficiency_factor(T_net / lead_ratio(b.P), b["omega"], b["eta_screw"], b.P, b["eta_inv_screw"])
            return T_net / (lead_ratio(b.P) * g_hold) - b["F_load_rod"]

        def shaft_rate(b):
            return ca.if_else(b["stick"], 0, _shaft(b, _J_eq(b.P, b["M_load_rod"])))

        return {
            "x_in": lambda b: b["phi"] * lead_ratio(b.P),
            "v_in": lambda b: b["omega"] * lead_ratio(b.P),
            "x_rod": lambda b: b["x_play"],
            "v_rod": lambda b: b["v_in"],
            "v_contact": lambda b: b["v_in"],
            # the rod itself moves with the nut; the play acts on the sensor signal only
            "x_rod_mech": lambda b: b["x_in"],
            "v_rod_mech": lambda b: b["v_in"],
            "F_drive": drive,
            "F_load": lambda b: b["F_load_rod"] + b["F_friction"],
            "g_screw": lambda b: efficiency_factor(b["F_load"], b["omega"], b["eta_screw"], b.P, b["eta_inv_screw"]),
            "T_load": lambda b: lead_ratio(b.P) * b["F_load"] * b["g_screw"],
            der("phi"): lambda b: b["omega"],
            der("omega"): shaft_rate,
            der("x_play"): lambda b: play_rate(b["x_in"], b["v_in"], b["x_play"], b.P.B),
            "F_in": lambda b: b["F_load"] + (b.P.M + b["M_load_rod"]) * lead_ratio(b.P) * b[der("omega")],
            "P_screw_nut": lambda b: b["T_load"] * b["omega"] - b["F_load"] * b["v_in"],
            "E_kin": lambda b: 0.5 * _J_eq(b.P) * b["omega"] ** 2,
            "P_load": lambda b: b["f_ext"] * b["v_rod"],
        }


def _J_eq(P, M_load=0):
    """Inertia referred to the shaft, J_rot + (M + M_load) (p/2pi)^2 (kg m^2); M_load the
    masses moving with the rod (a surface through its horn)."""
    return P.J_m + P.J_s + (P.M + M_load) * lead_ratio(P) ** 2
