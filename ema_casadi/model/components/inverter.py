"""Power electronics (docs: physics).

``ideal`` (averaged): the controller's voltage reaches the windings unchanged (the
voltage limit is applied by the current controller). Its losses are the averaged
conduction and switching losses of a two-level bridge carrying the same currents.
"""

from __future__ import annotations

import casadi as ca

from ._part import Output, Part
from ._ports import Port

__all__ = ["ideal", "averaged_losses", "current_amplitude", "open_bridge", "Ideal"]


def ideal(v):
    """Averaged inverter: winding voltage = commanded voltage.

    Parameters
    ----------
    v : SX
        Commanded voltage (V).
    """
    return v


def averaged_losses(I_hat, P, I_sq=None, v_dc=None):
    """Averaged losses of a 3-leg two-level bridge (W).

    Each leg conducts its phase current through an IGBT or a diode at every instant,
    so with sinusoidal phase currents of amplitude I_hat: mean|i| = 2 I_hat/pi,
    mean i^2 = I_hat^2/2. Conduction: 3 (V_0 mean|i| + r mean i^2) with the IGBT and
    diode data averaged; switching: 3 f_sw E_sw (V_dc/V_sw_ref)(mean|i|/I_sw_ref).
    At standstill the phase currents are DC; the same formula is used (documented
    approximation). Returns (P_cond, P_sw).

    Parameters
    ----------
    I_hat : SX
        Phase-current amplitude (A).
    P : SimpleNamespace
        Parameter symbols by flat name (uses ``V_CE0``, ``V_F0``, ``r_CE``, ``r_F``, ``f_sw``,
        ``E_sw``, ``V_dc``, ``V_sw_ref``, ``I_sw_ref``).
    I_sq : SX, optional
        I_hat^2 (A^2), when the caller has it (default: I_hat squared).
    v_dc : SX, optional
        DC-link voltage (V); default ``P.V_dc``.
    """
    i_abs = 2 * I_hat / ca.pi
    i_sq = (I_hat**2 if I_sq is None else I_sq) / 2
    V0 = 0.5 * (P.V_CE0 + P.V_F0)
    r = 0.5 * (P.r_CE + P.r_F)
    P_cond = 3 * (V0 * i_abs + r * i_sq)
    P_sw = 3 * P.f_sw * P.E_sw * ((P.V_dc if v_dc is None else v_dc) / P.V_sw_ref) * (i_abs / P.I_sw_ref)
    return P_cond, P_sw


def current_amplitude(i_d, i_q):
    """|i_dq| = sqrt(i_d^2 + i_q^2) (A), written so that its derivative at zero current
    is 0 rather than NaN (sqrt'(0) times 0): sqrt(s + [s = 0]) - [s = 0], the same value
    bit for bit. A thermal network integrates the losses, and CVODES then needs a finite
    Jacobian at rest.

    Parameters
    ----------
    i_d, i_q : SX
        d and q currents (A).
    """
    s = i_d**2 + i_q**2
    zero = s == 0
    return ca.sqrt(s + zero) - zero


def open_bridge(b):
    """Winding voltages (v_d, v_q) (V) with the bridge switched off (all gates off).

    Below the diode clamp the windings are open: the voltage is the one that lets the
    currents decay through the resistance ``R_open`` alone,
    ``v = R i + (motional and cross-coupling terms) - R_open i``, so
    ``L di/dt = -R_open i`` (an open circuit, made a fast decay for the integrator).
    When that voltage would exceed what the freewheeling diodes allow, the circle
    ``|v_dq| <= v_dc/sqrt(3)`` (the line-to-line back-EMF above the DC link), it is
    clamped there and the diodes carry current back into the link: the motor brakes
    above the speed where its back-EMF reaches the link. Works for both motors (the dc
    equivalent is the q axis with i_d = 0).

    Parameters
    ----------
    b : Bus
        The signals (reads ``i_d``, ``i_q``, ``omega``, ``R_w``, ``psi_m``, ``v_dc``;
        parameters ``pp``, ``L_d``, ``L_q``, ``R_open``).
    """
    P = b.P
    i_d, i_q, w_e = b["i_d"], b["i_q"], P.pp * b["omega"]
    v_d = (b["R_w"] - P.R_open) * i_d - w_e * P.L_q * i_q
    v_q = (b["R_w"] - P.R_open) * i_q + w_e * (P.L_d * i_d + b["psi_m"])
    scale = ca.fmin(1, (b["v_dc"] / 3**0.5) / ca.sqrt(v_d**2 + v_q**2 + 1e-12))
    return scale * v_d, scale * v_q


_P_BRIDGE = Output("P_bridge", "W", "power the bridge draws from the DC link: winding power + inverter losses",
                   kind="power")


#: What both bridges read: the controller's voltages, the DC link, the currents, the speed and
#: the winding's constants (the losses' and the power balance's inputs).
_BRIDGE_READS = (
        Port("v_d_ref", "V", "the controller's d voltage"),
        Port("v_q_ref", "V", "the controller's q voltage"),
        Port("v_dc", "V", "the DC-link voltage"),
        Port("i_d", "A", "the d current"),
        Port("i_q", "A", "the q current"),
        Port("omega", "rad/s", "the motor speed"),
        Port("R_w", "Ohm", "the winding resistance"),
        Port("psi_m", "Wb", "the magnet flux linkage"),
        Port("P_elec", "W", "the electrical power into the windings"),
    )

class Ideal(Part):
    """Averaged inverter: the controller's voltage reaches the windings; averaged
    conduction and switching losses of the bridge carrying the motor currents."""

    family, value = "inverter", "ideal"
    reads = _BRIDGE_READS
    doc = "averaged bridge: winding voltage = controller voltage, averaged losses"
    outputs = (
        Output("v_d", "V", "d-axis winding voltage (0 for the dc motor)", roles=("d_voltage",)),
        Output("v_q", "V", "q-axis winding voltage (dc motor: its voltage / 1.5)", roles=("q_voltage",)),
        Output("P_inv_cond", "W", "inverter conduction loss", kind="loss"),
        Output("P_inv_sw", "W", "inverter switching loss", kind="loss"),
        _P_BRIDGE,
    )
    params = ("V_CE0", "V_F0", "r_CE", "r_F", "f_sw", "E_sw", "V_dc", "V_sw_ref", "I_sw_ref", "R_open", "pp", "L_d",
              "L_q")
    heat = {"P_inv_cond": "inverter", "P_inv_sw": "inverter"}

    def signals(self):
        def losses(b):
            # I^2 passed as i_d^2 + i_q^2: what sqrt(.)^2 simplified to before the guard
            sq = b["i_d"] ** 2 + b["i_q"] ** 2
            # the link voltage the supply provides (the parameter V_dc for the ideal supply)
            return averaged_losses(current_amplitude(b["i_d"], b["i_q"]), b.P, sq, b["v_dc"])

        return {
            ("v_d_open", "v_q_open"): open_bridge,
            "v_d": lambda b: ideal(b["v_d_ref"]),
            "v_q": lambda b: ideal(b["v_q_ref"]),
            ("P_inv_cond", "P_inv_sw"): losses,
            "P_bridge": lambda b: b["P_elec"] + b["P_inv_cond"] + b["P_inv_sw"],
        }


# ---- the switched bridge -------------------------------------------------
SQRT3 = 3**0.5
LEGS = ("a", "b", "c")


def inverse_park(x_d, x_q, theta):
    """Phase quantities (a, b, c) of a dq vector at the electrical angle ``theta``
    (amplitude-invariant, no zero sequence).

    Parameters
    ----------
    x_d, x_q : SX
        d and q components.
    theta : SX
        Electrical angle (rad).
    """
    c, s = ca.cos(theta), ca.sin(theta)
    x_al, x_be = x_d * c - x_q * s, x_d * s + x_q * c
    return x_al, -0.5 * x_al + 0.5 * SQRT3 * x_be, -0.5 * x_al - 0.5 * SQRT3 * x_be


def park(x_a, x_b, x_c, theta):
    """dq components of phase quantities (amplitude-invariant; the zero sequence drops out).

    Parameters
    ----------
    x_a, x_b, x_c : SX
        Phase quantities.
    theta : SX
        Electrical angle (rad).
    """
    x_al = (2 * x_a - x_b - x_c) / 3
    x_be = (x_b - x_c) / SQRT3
    c, s = ca.cos(theta), ca.sin(theta)
    return x_al * c + x_be * s, -x_al * s + x_be * c


def svpwm_duties(v_a, v_b, v_c, v_dc):
    """Carrier-based SVPWM: the min-max zero sequence v_0 = -(max + min)/2 added to
    the phase references, duty d_k = 1/2 + (v_k + v_0)/v_dc, clipped to [0, 1]. Within
    the hexagon (|v_dq| <= v_dc/sqrt(3), which the FOC limit k_v < 1 keeps) the
    clip is inactive and the average leg voltages reproduce the reference exactly.

    Parameters
    ----------
    v_a, v_b, v_c : SX
        Phase voltage references (V).
    v_dc : SX
        DC-link voltage (V).
    """
    v0 = -0.5 * (ca.fmax(ca.fmax(v_a, v_b), v_c) + ca.fmin(ca.fmin(v_a, v_b), v_c))
    return tuple(ca.fmin(ca.fmax(0.5 + (v + v0) / v_dc, 0), 1) for v in (v_a, v_b, v_c))


def leg_losses(s, i, P):
    """Conduction loss of one leg in state ``s`` (1: upper device, 0: lower; a duty
    between them gives the carrier-period average) carrying the phase current ``i``
    (positive out of the leg): the upper IGBT or the lower diode carry i > 0, the
    lower IGBT or the upper diode i < 0. Returns (IGBT loss, diode loss) (W):
    IGBT V_CE0 |i| + r_CE i^2, diode V_F0 |i| + r_F i^2, each times its share.

    Parameters
    ----------
    s : SX
        Leg state or duty (-).
    i : SX
        Phase current (A).
    P : SimpleNamespace
        Parameter symbols (uses ``V_CE0``, ``r_CE``, ``V_F0``, ``r_F``).
    """
    a = ca.fabs(i)
    share_T = ca.if_else(i > 0, s, 1 - s)
    return share_T * (P.V_CE0 * a + P.r_CE * i**2), (1 - share_T) * (P.V_F0 * a + P.r_F * i**2)


def averaged_device_losses(i_d, i_q, v_d, v_q, v_dc, P):
    """Conduction losses of the six IGBTs and of the six diodes (W), averaged over the
    carrier and over an electrical period of sinusoidal currents of amplitude
    I = |i_dq| (the classic modulation-dependent formulas of a PWM leg):
    IGBT V_CE0 I (1/(2 pi) + m/8) + r_CE I^2 (1/8 + m/(3 pi)), diode V_F0 I (1/(2 pi) - m/8)
    + r_F I^2 (1/8 - m/(3 pi)) per device, m = M cos(phi) = 2 (v . i)/(v_dc |i|)
    (the SVPWM zero sequence moves the split by well under 1 %; at standstill the
    currents are DC and this is the documented approximation of the ideal bridge).

    Parameters
    ----------
    i_d, i_q, v_d, v_q : SX
        Currents (A) and voltages (V) in the dq frame.
    v_dc : SX
        DC-link voltage (V).
    P : SimpleNamespace
        Parameter symbols (uses ``V_CE0``, ``r_CE``, ``V_F0``, ``r_F``).
    """
    I = current_amplitude(i_d, i_q)
    m = 2 * (v_d * i_d + v_q * i_q) / (v_dc * (I + (I == 0)))
    P_T = 6 * (P.V_CE0 * I * (1 / (2 * ca.pi) + m / 8) + P.r_CE * I**2 * (1 / 8 + m / (3 * ca.pi)))
    P_D = 6 * (P.V_F0 * I * (1 / (2 * ca.pi) - m / 8) + P.r_F * I**2 * (1 / 8 - m / (3 * ca.pi)))
    return P_T, P_D


def _sort3(a, b, c):
    lo, hi = ca.fmin(a, b), ca.fmax(a, b)
    lo, mid = ca.fmin(lo, c), ca.fmax(lo, c)
    mid, hi = ca.fmin(mid, hi), ca.fmax(mid, hi)
    return lo, mid, hi


def half_period(edges, rising, T_half):
    """The four sub-intervals of half a carrier period in which each leg switches once
    at its instant ``edges[k]`` (from the start of the half, within [0, T_half]):
    off -> on for the ``rising`` half (carrier falling from its peak), on -> off
    otherwise. Returns (durations, leg states per sub-interval)."""
    e = [ca.fmin(ca.fmax(t, 0), T_half) for t in edges]
    t1, t2, t3 = _sort3(*e)
    bounds = (0, t1, t2, t3, T_half)
    durations = [bounds[j + 1] - bounds[j] for j in range(4)]
    states = []
    for j in range(4):
        mid = 0.5 * (bounds[j] + bounds[j + 1])
        states.append([*((mid > t) if rising else (mid < t) for t in e), 1])
    return durations, states


class Pwm(Part):
    """Three-phase two-level bridge, carrier-based SVPWM, regular-sampled symmetric PWM
    (docs: pwm). 3-phase motor only.

    The leg states ``s_a, s_b, s_c`` (1: upper device on) are *switched* signals: in
    the continuous model (trim, linearisation, CVODES) they are the duty cycles, i.e.
    the carrier-period average of the bridge; the carrier-synchronous simulator
    (:mod:`ema_casadi.simulation`) sets them per sub-interval from :meth:`schedule`.
    The carrier is a triangle with its peak at the ECU sample: each leg switches on once
    in the first half period at (1 - d_k) T/2 and off once in the second at d_k T/2 after
    the valley. Dead time t_dead delays the turn-on of the upper device (i > 0: the leg
    stays at 0 through the lower diode) or of the lower one (i < 0): the edge moves by
    t_dead by the sign of the phase current at the sample; an edge that would pass the
    half period is held at its end (only at duties within 2 t_dead f_sw of 0 or 1).
    Switching energy E_sw (v_dc/V_sw_ref)(|i|/I_sw_ref) per leg per period (one on-off
    pair), as the power f_sw E_sw ...: the carrier-period average of the impulses.
    """

    family, value = "inverter", "pwm"
    reads = (*_BRIDGE_READS, Port("phi", "rad", "the shaft angle"))
    smooth = {"inverter": "ideal"}
    doc = "switched 2-level bridge, SVPWM at f_sw, exact switching instants"
    requires = {"motor": ("pmsm",)}
    outputs = (
        Output("v_d", "V", "d-axis winding voltage (Park of the phase voltages)", roles=("d_voltage",)),
        Output("v_q", "V", "q-axis winding voltage", roles=("q_voltage",)),
        Output("v_d_avg", "V", "d-axis voltage of the averaged bridge: the held reference within v_dc/sqrt(3)"),
        Output("v_q_avg", "V", "q-axis voltage of the averaged bridge"),
        Output("P_inv_cond", "W", "inverter conduction loss (IGBTs and diodes)", kind="loss"),
        Output("P_inv_sw", "W", "inverter switching loss (carrier-period average)", kind="loss"),
        _P_BRIDGE,
        Output("P_cond_T", "W", "conduction loss of the six IGBTs (part of P_inv_cond)", kind="aux"),
        Output("P_cond_D", "W", "conduction loss of the six diodes (part of P_inv_cond)", kind="aux"),
        *(Output(f"i_{k}", "A", f"phase-{k} current") for k in LEGS),
        *(Output(f"s_{k}", "1", f"leg {k} state (1 upper device on; continuous model: its duty)") for k in LEGS),
        *(Output(f"d_{k}", "1", f"leg {k} duty cycle of the SVPWM") for k in LEGS),
        *(Output(f"v_{k}n", "V", f"phase-{k} voltage (to the star point)") for k in LEGS),
        Output("v_ab", "V", "line voltage a-b"),
        Output("v_bc", "V", "line voltage b-c"),
        Output("i_sw", "A", "current through the ideal switches into the legs, sum s_k i_k (v_dc i_sw: the "
                            "winding power, without the inverter losses)"),
        Output("i_dc", "A", "DC-link current the bridge draws, P_bridge / v_dc: v_dc i_dc is the winding power "
                            "plus the inverter losses (with the ideal supply, V_dc i_dc = P_dc)"),
    )
    params = ("V_CE0", "V_F0", "r_CE", "r_F", "f_sw", "E_sw", "V_sw_ref", "I_sw_ref", "t_dead", "pp", "R_open", "L_d",
              "L_q")
    heat = {"P_inv_cond": "inverter", "P_inv_sw": "inverter"}
    #: the leg states, and ``sw``: 1 in the switched simulation, 0 in the continuous model
    switched = (*(f"s_{k}" for k in LEGS), "sw")
    carrier = "f_sw"

    def signals(self):
        def theta(b):
            return b.P.pp * b.state("shaft_angle")

        def reference(b):
            # the held reference within the hexagon's inscribed circle v_dc/sqrt(3) (the FOC
            # limit k_v <= 1 keeps it there; a lifted trim or a link dip may not), where the
            # min-max SVPWM is linear and its average leg voltages reproduce it exactly
            v_d, v_q = b["v_d_ref"], b["v_q_ref"]
            scale = ca.fmin(1, (b["v_dc"] / SQRT3) / ca.sqrt(v_d**2 + v_q**2 + 1e-12))
            return scale * v_d, scale * v_q

        def duties(b):
            return svpwm_duties(*inverse_park(b["v_d_avg"], b["v_q_avg"], b["theta_e"]), b["v_dc"])

        def phase_voltages(b):
            s = [b[f"s_{k}"] for k in LEGS]
            mean = (s[0] + s[1] + s[2]) / 3
            return tuple(b["v_dc"] * (sk - mean) for sk in s)

        def winding_voltages(b):
            # Park of the phase voltages, written as the reference plus the Park of the
            # switching error v_dc ((s - d) - mean): the same value (the duties reproduce
            # the reference), and exactly the reference, independent of the shaft angle,
            # in the continuous model where s = d (trim and linearisation see no round-off)
            e = [b["sw"] * (b[f"s_{k}"] - b[f"d_{k}"]) for k in LEGS]
            mean = (e[0] + e[1] + e[2]) / 3
            e_d, e_q = park(*(b["v_dc"] * (ek - mean) for ek in e), b["theta_e"])
            return b["v_d_avg"] + e_d, b["v_q_avg"] + e_q

        def losses(b):
            # switched (sw = 1): each device's instantaneous conduction loss; continuous
            # (sw = 0): the electrical-period average of its carrier-period average
            # (averaged_device_losses), independent of the rotor angle like the ideal bridge's
            parts = [leg_losses(b[f"s_{k}"], b[f"i_{k}"], b.P) for k in LEGS]
            sw = b["sw"]
            P_T0, P_D0 = averaged_device_losses(b["i_d"], b["i_q"], b["v_d_avg"], b["v_q_avg"], b["v_dc"], b.P)
            P_T = sw * (parts[0][0] + parts[1][0] + parts[2][0]) + (1 - sw) * P_T0
            P_D = sw * (parts[0][1] + parts[1][1] + parts[2][1]) + (1 - sw) * P_D0
            i_abs = ca.fabs(b["i_a"]) + ca.fabs(b["i_b"]) + ca.fabs(b["i_c"])
            i_abs = sw * i_abs + (1 - sw) * 6 / ca.pi * current_amplitude(b["i_d"], b["i_q"])
            P_sw = b.P.f_sw * b.P.E_sw * (b["v_dc"] / b.P.V_sw_ref) * (i_abs / b.P.I_sw_ref)
            return P_T, P_D, P_T + P_D, P_sw

        return {
            ("v_d_open", "v_q_open"): open_bridge,
            "theta_e": theta,
            ("d_a", "d_b", "d_c"): duties,
            **{f"s_{k}": (lambda b, k=k: b[f"d_{k}"]) for k in LEGS},
            ("i_a", "i_b", "i_c"): lambda b: inverse_park(b["i_d"], b["i_q"], b["theta_e"]),
            ("v_an", "v_bn", "v_cn"): phase_voltages,
            ("v_d_avg", "v_q_avg"): reference,
            ("v_d", "v_q"): winding_voltages,
            "v_ab": lambda b: b["v_an"] - b["v_bn"],
            "v_bc": lambda b: b["v_bn"] - b["v_cn"],
            "i_sw": lambda b: b["s_a"] * b["i_a"] + b["s_b"] * b["i_b"] + b["s_c"] * b["i_c"],
            "i_dc": lambda b: b["P_bridge"] / b["v_dc"],
            ("P_cond_T", "P_cond_D", "P_inv_cond", "P_inv_sw"): losses,
            "sw": lambda b: 0,
            # the continuous model draws the winding power itself (v_dc i_sw equals it but
            # for round-off that would depend on the rotor angle)
            "P_bridge": lambda b: (b["sw"] * b["v_dc"] * b["i_sw"] + (1 - b["sw"]) * b["P_elec"] + b["P_inv_cond"]
                                   + b["P_inv_sw"]),
        }

    def schedule(self, b):
        """One carrier period as two halves of four sub-intervals each, from the held
        references at the sample (bus ``b``): ``[(durations, leg states), (..., ...)]``.
        Each leg's edge in closed form from its duty and the sign of its current."""
        T_half = 0.5 / b.P.f_sw
        td = b.P.t_dead
        on, off = [], []
        for k in LEGS:
            d, i = b[f"d_{k}"], b[f"i_{k}"]
            on.append((1 - d) * T_half + td * (i > 0))
            off.append(d * T_half + td * (i < 0))
        return [half_period(on, True, T_half), half_period(off, False, T_half)]
