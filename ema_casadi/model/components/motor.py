"""Motors (docs: physics): the 1-phase dc equivalent and the 3-phase PMSM in the rotor
dq frame (amplitude-invariant), and the shaft.

The winding resistance and the magnet flux are the signals ``R_w`` and ``psi_m`` of
the bus: the thermal part provides them (the parameters R and psi with ``thermal =
"off"``, functions of the winding and housing temperatures with ``"lumped"``). The
controller keeps the nominal R and psi (the ECU does not know the temperature).

Iron loss (docs: physics, option ``iron_loss = "on"``) is a drag torque on the shaft,
T_fe = P_fe / omega, folded into the shaft torque ``T_m``, so the energy balance
closes with P_fe as one more loss; with ``"off"`` (the reference file's default) P_fe
is 0 and the equations are those without iron loss.
"""

from __future__ import annotations

import math

import casadi as ca

from ._part import MARGIN, Bound, Fault, Input, Output, Part, Rating, State, der
from ._ports import Port
from .controller import CURRENT_LOOP, FocCurrent, PiCurrent

__all__ = ["dc", "pmsm", "shaft", "no_load_speed", "iron_loss", "winding_short", "OMEGA_FE", "MU_MIN", "Pmsm",
           "ShortedPmsm", "Dc", "CURRENT_LOOP", "CURRENT_BOUND"]

#: Speed (rad/s, ~1 rpm) over which the hysteresis drag, k_h pp psi^2/(2 pi) sign(omega),
#: is smoothed at standstill (sign -> omega/sqrt(omega^2 + OMEGA_FE^2)). RK4 at 1e-4 s
#: sees its slope as an eigenvalue near -550 1/s (h lambda = 0.05); a linearisation at
#: rest with iron loss on sees it as ~0.9 N m s/rad of extra shaft damping.
OMEGA_FE = 0.1


def iron_loss(omega, psi, P):
    """Iron loss as a drag torque: P_fe = k_h f_e psi^2 + k_e (f_e psi)^2 with the
    electrical frequency f_e = pp |omega|/(2 pi), |omega| smoothed to
    omega^2/sqrt(omega^2 + OMEGA_FE^2) (a square root compiles to one instruction, tanh
    to a library call). The torque T_fe is written first and P_fe = T_fe omega (>= 0),
    so the loss is exactly the drag's power. Returns (T_fe (N m), P_fe (W)).

    Parameters
    ----------
    omega : SX
        Shaft speed (rad/s).
    psi : SX
        Magnet flux linkage (Wb).
    P : SimpleNamespace
        Parameter symbols by flat name (uses ``pp``, ``k_h``, ``k_e``).
    """
    c = P.pp / (2 * ca.pi)  # f_e per rad/s
    T_fe = P.k_h * c * psi**2 * omega / ca.sqrt(omega**2 + OMEGA_FE**2) + P.k_e * c**2 * psi**2 * omega
    return T_fe, T_fe * omega


#: Smallest shorted fraction modelled (-): below it the shorted loop is healthy and its
#: current decays with TAU_NO_SHORT (a loop of so few turns is too stiff for RK4).
MU_MIN = 0.02
TAU_NO_SHORT = 1e-3


def winding_short(mu, i_f, i_d, i_q, di_d, di_q, theta_e, omega_e, R, psi, P):
    """Turn-to-turn short of a fraction ``mu`` of phase a's turns through ``R_f``.

    The shorted sub-winding is a circuit of its own (after Vaseghi, Takorabet and
    Meibody-Tabar, IEEE Trans. Magn. 45(2), 2009, for L_d = L_q): it carries
    ``i_a - i_f``, the short ``i_f``. Its MMF ``-mu i_f`` on the a axis adds
    ``-(2/3) mu i_f c`` to the dq currents' flux, ``c = (cos theta_e, -sin theta_e)``;
    the sub-winding links ``mu`` of phase a's flux plus its leakage ``mu L_f``. With
    ``a_h`` the healthy dq current derivatives and ``u_a = R i_a + c.(L a_h + omega_e J
    psi_dq)`` the healthy phase-a voltage:

    ``mu L_f di_f/dt = mu u_a - (mu R (1 - 2 mu/3) + R_f) i_f``,
    ``di_dq/dt = a_h + (2/3) mu c (R i_f + L di_f/dt)/L``,
    ``T_em += pp psi mu i_f sin theta_e``,
    ``P_short = mu R (i_f^2 - 2 i_a i_f) + R_f i_f^2`` (the extra copper loss, in the
    winding). With the currents held by the controller the loop is a series circuit:
    ``mu (L_f + 2 mu L/3) di_f/dt = mu (R i_a + e_a) - (mu R + R_f) i_f``.

    Returns (di_f/dt (A/s), di_d/dt, di_q/dt (A/s), dT (N m), P_short (W)).

    Parameters
    ----------
    mu : SX
        Shorted fraction of phase a's turns (-); below MU_MIN the loop is healthy.
    i_f : SX
        Current in the short (A).
    i_d, i_q, di_d, di_q : SX
        dq currents (A) and their healthy derivatives (A/s).
    theta_e, omega_e : SX
        Electrical angle (rad) and speed (rad/s).
    R, psi : SX
        Phase resistance (Ohm), magnet flux (Wb).
    P : SimpleNamespace
        Parameter symbols (uses ``L_d``, ``L_q``, ``pp``, ``R_f``, ``L_f``).
    """
    c, s = ca.cos(theta_e), ca.sin(theta_e)
    i_a = i_d * c - i_q * s
    psi_d, psi_q = P.L_d * i_d + psi, P.L_q * i_q
    u_a = R * i_a + c * (P.L_d * di_d - omega_e * psi_q) - s * (P.L_q * di_q + omega_e * psi_d)
    on = mu >= MU_MIN
    mu_safe = ca.if_else(on, mu, 1)
    faulty = (mu * u_a - (mu * R * (1 - 2 * mu / 3) + P.R_f) * i_f) / (mu_safe * P.L_f)
    di_f = ca.if_else(on, faulty, -i_f / TAU_NO_SHORT)
    mu_on = ca.if_else(on, mu, 0)
    k = 2 / 3 * mu_on
    d_d = di_d + k * c * (R * i_f + P.L_d * di_f) / P.L_d
    d_q = di_q - k * s * (R * i_f + P.L_q * di_f) / P.L_q
    dT = P.pp * psi * mu_on * i_f * s
    P_short = mu_on * R * (i_f**2 - 2 * i_a * i_f) + ca.if_else(on, P.R_f * i_f**2, 0)
    return di_f, d_d, d_q, dT, P_short


def dc(i, v, omega, P, R=None, psi=None):
    """DC-equivalent motor: L_dc di/dt = v - R_dc i - K_e omega; T = K_t i.

    Power-invariant equivalent of the PMSM q axis (i = i_q, v = 1.5 v_q):
    K_t = K_e = 1.5 pp psi, R_dc = 1.5 R, L_dc = 1.5 L_q.
    Returns (di/dt (A/s), T (N m), P_elec (W), P_cu (W), E_mag (J)).

    Parameters
    ----------
    i : SX
        Winding current (A).
    v : SX
        Winding voltage (V).
    omega : SX
        Motor speed (rad/s).
    P : SimpleNamespace
        Parameter symbols by flat name (uses ``pp``, ``L_q``, and ``psi``, ``R`` unless given).
    R : SX, optional
        Phase resistance (Ohm); default ``P.R``.
    psi : SX, optional
        Magnet flux linkage (Wb); default ``P.psi``.
    """
    R = P.R if R is None else R
    psi = P.psi if psi is None else psi
    K_t = 1.5 * P.pp * psi
    R_dc, L_dc = 1.5 * R, 1.5 * P.L_q
    di = (v - R_dc * i - K_t * omega) / L_dc
    return di, K_t * i, v * i, R_dc * i**2, 0.5 * L_dc * i**2


def pmsm(i_d, i_q, v_d, v_q, omega, P, R=None, psi=None):
    """PMSM in the rotor dq frame (amplitude-invariant).

    L_d di_d/dt = v_d - R i_d + omega_e L_q i_q
    L_q di_q/dt = v_q - R i_q - omega_e (L_d i_d + psi)
    T = 1.5 pp (psi i_q + (L_d - L_q) i_d i_q),  omega_e = pp omega.
    Returns (di_d/dt, di_q/dt (A/s), T (N m), P_elec (W), P_cu (W), E_mag (J)).

    Parameters
    ----------
    i_d, i_q : SX
        d and q currents (A).
    v_d, v_q : SX
        d and q voltages (V).
    omega : SX
        Motor (mechanical) speed (rad/s).
    P : SimpleNamespace
        Parameter symbols by flat name (uses ``pp``, ``L_d``, ``L_q``, and ``psi``, ``R``
        unless given).
    R : SX, optional
        Phase resistance (Ohm); default ``P.R``.
    psi : SX, optional
        Magnet flux linkage (Wb); default ``P.psi``.
    """
    R = P.R if R is None else R
    psi = P.psi if psi is None else psi
    omega_e = P.pp * omega
    di_d = (v_d - R * i_d + omega_e * P.L_q * i_q) / P.L_d
    di_q = (v_q - R * i_q - omega_e * (P.L_d * i_d + psi)) / P.L_q
    T = 1.5 * P.pp * (psi * i_q + (P.L_d - P.L_q) * i_d * i_q)
    P_elec = 1.5 * (v_d * i_d + v_q * i_q)
    P_cu = 1.5 * R * (i_d**2 + i_q**2)
    E_mag = 0.75 * (P.L_d * i_d**2 + P.L_q * i_q**2)
    return di_d, di_q, T, P_elec, P_cu, E_mag


def shaft(omega, T, T_load, J, P):
    """J d omega/dt = T - b_m omega - T_load. Returns d omega/dt (rad/s^2).

    Parameters
    ----------
    omega : SX
        Shaft speed (rad/s).
    T : SX
        Motor torque (N m).
    T_load : SX
        Load torque on the shaft (N m).
    J : SX
        Inertia on the shaft (kg m^2).
    P : SimpleNamespace
        Parameter symbols by flat name (uses ``b_m``).
    """
    return (T - P.b_m * omega - T_load) / J


def no_load_speed(P):
    """Speed at which the back-EMF equals the DC link, V_dc / K_e with K_e = 1.5 pp psi
    (rad/s): the motor cannot drive itself faster, and a load that back-drives it
    beyond a few times this speed overdrives the inverter's diodes.

    Parameters
    ----------
    P : SimpleNamespace
        Parameter values by flat name (uses ``V_dc``, ``pp``, ``psi``).
    """
    return P.V_dc / (1.5 * P.pp * P.psi)


# ---- parts: the windings and the shaft torque; each motor brings its current controller
# (controller.FocCurrent, controller.PiCurrent: assembled just before it)
#: Envelope of the winding currents: the speed loop commands at most I_max; a few
#: times that only flows when the back-EMF runs away from the voltage limit.
CURRENT_BOUND = Bound(lambda E: MARGIN * E.I_max, f"{MARGIN:g} x I_max")

_COMMON_OUT = (
    Output("i_d", "A", "d-axis current (0 for the dc motor)", bound=CURRENT_BOUND),
    Output("i_q", "A", "q-axis current (the dc motor's current)", bound=CURRENT_BOUND, roles=("motor_current",)),
    Output("T_m", "N*m", "motor torque on the shaft (electromagnetic, less the iron-loss drag)"),
    Output("P_elec", "W", "electrical power into the windings", kind="power"),
    Output("P_cu", "W", "copper loss", kind="loss"),
    Output("P_fe", "W", "iron loss, a drag torque on the shaft (0 unless iron_loss = on)", kind="loss"),
)
_HEAT = {"P_cu": "winding", "P_fe": "housing"}
_IRON = {"iron_loss": ("off", "on")}


def _amps(P):
    return P.I_max


def _iron(opt):
    """Providers of the shaft torque T_m and the iron loss P_fe, from T_em."""
    if opt.get("iron_loss", "off") == "off":
        return {"T_m": lambda b: b["T_em"], "P_fe": lambda b: 0}

    def iron(b):
        return iron_loss(b["omega"], b["psi_m"], b.P)

    return {("T_fe", "P_fe"): iron, "T_m": lambda b: b["T_em"] - b["T_fe"]}


_PMSM_KEYS = (der("i_d"), der("i_q"), "T_em", "P_elec", "P_cu", "E_mag")
#: Operating limits (:class:`~ema_casadi.model.components.Rating`): the current vector within
#: I_max, the voltage vector within the linear-SVPWM circle k_v V_dc/sqrt(3).
_RATINGS = (
    Rating("current", "current limit", ("i_d", "i_q"), lambda P: P.I_max, "I_max", "A"),
    Rating("voltage", "voltage circle", ("v_d", "v_q"), lambda P: P.k_v * P.V_dc / math.sqrt(3), "k_v V_dc/sqrt(3)",
           "V"),
)
#: The FOC commands i_d = 0: a negative i_d (field weakening) would raise the top speed
#: beyond the voltage circle's psi-limited one; the drive as commissioned does not use it.
_NO_FIELD_WEAKENING = Rating("field_weakening", "no field weakening (the FOC commands i_d = 0)", ("i_d",),
                             lambda P: 0.0, "i_d >= 0", "A", sense="min", role="strategy")


class Pmsm(Part):
    """3-phase PMSM in the rotor dq frame (docs: physics), with its FOC current
    controller (:class:`~ema_casadi.model.components.controller.FocCurrent`, brought).

    With the option ``winding_short = "on"`` the part is :class:`ShortedPmsm`.

    Parameters
    ----------
    options : dict, optional
        ``iron_loss`` and ``winding_short`` (default ``"off"`` each).
    """

    family, value = "motor", "pmsm"
    reads = (
        Port("v_d", "V", "the winding d voltage"),
        Port("v_q", "V", "the winding q voltage"),
        Port("omega", "rad/s", "the motor speed"),
        Port("R_w", "Ohm", "the winding resistance"),
        Port("psi_m", "Wb", "the magnet flux linkage"),
    )
    doc = "3-phase PMSM, rotor dq frame, FOC current loop"
    brings = (FocCurrent,)
    outputs = _COMMON_OUT
    params = ("pp", "psi", "L_d", "L_q", "k_h", "k_e")
    ratings = (*_RATINGS, _NO_FIELD_WEAKENING)
    options = {**_IRON, "winding_short": ("off", "on")}
    heat = _HEAT
    states = (
        State("i_d", "A", "d-axis current", roles=("current",), scale=_amps, bound=CURRENT_BOUND),
        State("i_q", "A", "q-axis current", roles=("current",), scale=_amps, bound=CURRENT_BOUND),
    )
    stored = ("E_mag",)

    @classmethod
    def form(cls, options: dict) -> type:
        """:class:`ShortedPmsm` with ``winding_short = "on"``, else the healthy PMSM.

        Parameters
        ----------
        options : dict
            The values of the options the part reads.
        """
        return ShortedPmsm if options.get("winding_short", "off") == "on" else cls

    def signals(self):
        def plant(b):
            return pmsm(b["i_d"], b["i_q"], b["v_d"], b["v_q"], b["omega"], b.P, b["R_w"], b["psi_m"])

        return {_PMSM_KEYS: plant, **_iron(self.opt)}


class ShortedPmsm(Pmsm):
    """The PMSM with the turn-to-turn short of phase a (:func:`winding_short`; option
    ``winding_short = "on"``): the state ``i_f``, the fault input ``mu_short`` and the
    loss ``P_short`` into the winding node."""

    reads = Pmsm.reads + (Port("phi", "rad", "the shaft angle"),)
    states = Pmsm.states + (State("i_f", "A", "current in the shorted turns' short", scale=_amps),)
    inputs = (Input("mu_short", "1", "dimensionless", "fault: shorted fraction of phase a's turns (0 healthy)"),)
    outputs = Pmsm.outputs + (Output("P_short", "W", "extra copper loss of the turn-to-turn short", kind="loss"),)
    params = Pmsm.params + ("R_f", "L_f")
    heat = {**Pmsm.heat, "P_short": "winding"}
    faults = (Fault("short", "mu_short", "1", MU_MIN, 0.5,
                    "a fraction of phase a's turns shorted through R_f (winding_short = on)"),)

    def signals(self):
        plant = super().signals()

        def shorted(b):
            di_d, di_q, T, P_elec, P_cu, E_mag = plant[_PMSM_KEYS](b)
            P = b.P
            di_f, di_d, di_q, dT, P_short = winding_short(
                b["mu_short"], b["i_f"], b["i_d"], b["i_q"], di_d, di_q, P.pp * b.state("shaft_angle"),
                P.pp * b["omega"], b["R_w"], b["psi_m"], P)
            return di_d, di_q, T + dT, P_elec, P_cu, E_mag, di_f, P_short

        return {(*_PMSM_KEYS, der("i_f"), "P_short"): shorted, **_iron(self.opt)}


class Dc(Part):
    """1-phase dc-equivalent motor (docs: physics), with its current PI
    (:class:`~ema_casadi.model.components.controller.PiCurrent`, brought)."""

    family, value = "motor", "dc"
    reads = (
        Port("v_q", "V", "the winding q voltage"),
        Port("omega", "rad/s", "the motor speed"),
        Port("R_w", "Ohm", "the winding resistance"),
        Port("psi_m", "Wb", "the magnet flux linkage"),
    )
    doc = "1-phase dc equivalent of the PMSM q axis, simple current PI"
    brings = (PiCurrent,)
    outputs = _COMMON_OUT
    params = ("pp", "psi", "L_q", "k_h", "k_e")
    ratings = _RATINGS
    options = _IRON
    heat = _HEAT
    states = (State("i", "A", "winding current", roles=("current",), scale=_amps, bound=CURRENT_BOUND),)
    stored = ("E_mag",)

    def signals(self):
        def plant(b):
            return dc(b["i"], 1.5 * b["v_q"], b["omega"], b.P, b["R_w"], b["psi_m"])

        return {
            (der("i"), "T_em", "P_elec", "P_cu", "E_mag"): plant,
            **_iron(self.opt),
            "i_d": lambda b: 0,
            "i_q": lambda b: b["i"],
        }
