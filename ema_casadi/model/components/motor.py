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

from . import controller
from ._part import MARGIN, Bound, Gain, Hold, Input, Limit, Loop, Output, Part, State, der

__all__ = ["dc", "pmsm", "shaft", "no_load_speed", "iron_loss", "OMEGA_FE", "Pmsm", "Dc", "CURRENT_LOOP",
           "CURRENT_BOUND"]

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


# ---- parts: each motor brings its own current controller (FOC or simple PI) ----------
CURRENT_LOOP = Loop("current", flag="loop_i", injection="d_i", measured="i_q", rate="f_s_i")
#: Envelope of the winding currents: the speed loop commands at most I_max; a few
#: times that only flows when the back-EMF runs away from the voltage limit.
CURRENT_BOUND = Bound(lambda E: MARGIN * E.I_max, f"{MARGIN:g} x I_max")

_COMMON_OUT = (
    Output("i_d", "A", "d-axis current (0 for the dc motor)", bound=CURRENT_BOUND),
    Output("i_q", "A", "q-axis current (the dc motor's current)", bound=CURRENT_BOUND),
    Output("T_m", "N*m", "motor torque on the shaft (electromagnetic, less the iron-loss drag)"),
    Output("P_elec", "W", "electrical power into the windings", kind="power"),
    Output("P_cu", "W", "copper loss", kind="loss"),
    Output("P_fe", "W", "iron loss, a drag torque on the shaft (0 unless iron_loss = on)", kind="loss"),
)
_HEAT = {"P_cu": "winding", "P_fe": "housing"}
_OPTIONS = {"iron_loss": ("off", "on"), **controller.AW_OPTION}
_D_I = Input("d_i", "A", "current", "injection at the q-current feedback (loop break)", injection=True)


def _volts(P):
    return P.V_dc


def _amps(P):
    return P.I_max


def _iron(opt):
    """Providers of the shaft torque T_m and the iron loss P_fe, from T_em."""
    if opt.get("iron_loss", "off") == "off":
        return {"T_m": lambda b: b["T_em"], "P_fe": lambda b: 0}

    def iron(b):
        return iron_loss(b["omega"], b["psi_m"], b.P)

    return {("T_fe", "P_fe"): iron, "T_m": lambda b: b["T_em"] - b["T_fe"]}


#: The voltage limit of the current controller (the linear-SVPWM circle), which a trim
#: keeps inactive; lifted through k_v, not V_dc (V_dc also sets the switching losses,
#: which heat the inverter node of a thermal network).
_LIMITS = (Limit("voltage", "voltage limit", "|v_dq|", lambda y, P: math.hypot(y["v_d"], y["v_q"]),
                 lambda P: P.k_v * P.V_dc / math.sqrt(3), "k_v V_dc/sqrt(3)", lift=("k_v",), unit="V"),)
_GAINS = (Gain("K_p_i", "current"), Gain("K_i_i", "current"))


class Pmsm(Part):
    """3-phase PMSM in the rotor dq frame with FOC current control (docs: physics)."""

    family, value = "motor", "pmsm"
    doc = "3-phase PMSM, rotor dq frame, FOC current loop"
    inputs = (_D_I,)
    outputs = _COMMON_OUT
    params = ("pp", "psi", "L_d", "L_q", "K_p_i", "K_i_i", "k_v", "V_dc", "loop_i", "f_s_i", "k_h", "k_e")
    trim_limits = _LIMITS
    gains = _GAINS
    options = _OPTIONS
    heat = _HEAT
    loops = (CURRENT_LOOP,)
    holds = (Hold("v_d_ref", "V", "current"), Hold("v_q_ref", "V", "current"))
    states = (
        State("z_d", "V", "d-current integral part", roles=("controller_integral",), scale=_volts, loop="current"),
        State("z_q", "V", "q-current integral part", roles=("controller_integral",), scale=_volts, loop="current"),
        State("i_d", "A", "d-axis current", roles=("current",), scale=_amps, bound=CURRENT_BOUND),
        State("i_q", "A", "q-axis current", roles=("current",), scale=_amps, bound=CURRENT_BOUND),
    )
    stored = ("E_mag",)

    def signals(self):
        def current_law(b):
            i_d, i_q = b["i_d"], b["i_q"]
            return controller.current_law_foc(
                b["i_cmd"], i_d, b.feedback(CURRENT_LOOP), i_d, i_q, b["omega"], b["z_d"], b["z_q"], b.P, b["v_dc"],
                self.opt.get("anti_windup", controller.ANTI_WINDUP[0]),
            )

        def plant(b):
            return pmsm(b["i_d"], b["i_q"], b["v_d"], b["v_q"], b["omega"], b.P, b["R_w"], b["psi_m"])

        return {
            ("v_d_ref", "v_q_ref", der("z_d"), der("z_q")): current_law,
            (der("i_d"), der("i_q"), "T_em", "P_elec", "P_cu", "E_mag"): plant,
            **_iron(self.opt),
        }


class Dc(Part):
    """1-phase dc-equivalent motor with a simple current PI (docs: physics)."""

    family, value = "motor", "dc"
    doc = "1-phase dc equivalent of the PMSM q axis, simple current PI"
    inputs = (_D_I,)
    outputs = _COMMON_OUT
    params = ("pp", "psi", "L_q", "K_p_i", "K_i_i", "k_v", "V_dc", "loop_i", "f_s_i", "k_h", "k_e")
    trim_limits = _LIMITS
    gains = _GAINS
    options = _OPTIONS
    heat = _HEAT
    loops = (CURRENT_LOOP,)
    holds = Pmsm.holds
    states = (
        State("z_i", "V", "current integral part", roles=("controller_integral",), scale=_volts, loop="current"),
        State("i", "A", "winding current", roles=("current",), scale=_amps, bound=CURRENT_BOUND),
    )
    stored = ("E_mag",)

    def signals(self):
        def current_law(b):
            v, z_dot = controller.current_law_simple(b["i_cmd"], b.feedback(CURRENT_LOOP), b["omega"], b["z_i"], b.P,
                                                     b["v_dc"], self.opt.get("anti_windup", controller.ANTI_WINDUP[0]))
            return 0, v / 1.5, z_dot

        def plant(b):
            return dc(b["i"], 1.5 * b["v_q"], b["omega"], b.P, b["R_w"], b["psi_m"])

        return {
            ("v_d_ref", "v_q_ref", der("z_i")): current_law,
            (der("i"), "T_em", "P_elec", "P_cu", "E_mag"): plant,
            **_iron(self.opt),
            "i_d": lambda b: 0,
            "i_q": lambda b: b["i"],
        }
