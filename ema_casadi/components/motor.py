"""Motors (SPEC §2.3): the 1-phase dc equivalent and the 3-phase PMSM in the rotor
dq frame (amplitude-invariant), and the shaft."""

from __future__ import annotations

from . import controller
from ._part import MARGIN, Bound, Hold, Input, Loop, Output, Part, State, der

__all__ = ["dc", "pmsm", "shaft", "no_load_speed", "Pmsm", "Dc", "CURRENT_LOOP", "CURRENT_BOUND"]


def dc(i, v, omega, P):
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
        Parameter symbols by flat name (uses ``pp``, ``psi``, ``R``, ``L_q``).
    """
    K_t = 1.5 * P.pp * P.psi
    R_dc, L_dc = 1.5 * P.R, 1.5 * P.L_q
    di = (v - R_dc * i - K_t * omega) / L_dc
    return di, K_t * i, v * i, R_dc * i**2, 0.5 * L_dc * i**2


def pmsm(i_d, i_q, v_d, v_q, omega, P):
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
        Parameter symbols by flat name (uses ``pp``, ``psi``, ``R``, ``L_d``, ``L_q``).
    """
    omega_e = P.pp * omega
    di_d = (v_d - P.R * i_d + omega_e * P.L_q * i_q) / P.L_d
    di_q = (v_q - P.R * i_q - omega_e * (P.L_d * i_d + P.psi)) / P.L_q
    T = 1.5 * P.pp * (P.psi * i_q + (P.L_d - P.L_q) * i_d * i_q)
    P_elec = 1.5 * (v_d * i_d + v_q * i_q)
    P_cu = 1.5 * P.R * (i_d**2 + i_q**2)
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
    Output("T_m", "N*m", "motor torque"),
    Output("P_elec", "W", "electrical power into the windings", kind="power"),
    Output("P_cu", "W", "copper loss", kind="loss"),
)
_D_I = Input("d_i", "A", "current", "injection at the q-current feedback (loop break)", injection=True)


def _volts(P):
    return P.V_dc


def _amps(P):
    return P.I_max


class Pmsm(Part):
    """3-phase PMSM in the rotor dq frame with FOC current control (SPEC §2.1, §2.3)."""

    family, value = "motor", "pmsm"
    doc = "3-phase PMSM, rotor dq frame, FOC current loop"
    inputs = (_D_I,)
    outputs = _COMMON_OUT
    params = ("pp", "psi", "R", "L_d", "L_q", "K_p_i", "K_i_i", "k_v", "V_dc", "loop_i", "f_s_i")
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
                b["i_cmd"], i_d, b.feedback(CURRENT_LOOP), i_d, i_q, b["omega"], b["z_d"], b["z_q"], b.P
            )

        def plant(b):
            return pmsm(b["i_d"], b["i_q"], b["v_d"], b["v_q"], b["omega"], b.P)

        return {
            ("v_d_ref", "v_q_ref", der("z_d"), der("z_q")): current_law,
            (der("i_d"), der("i_q"), "T_m", "P_elec", "P_cu", "E_mag"): plant,
        }


class Dc(Part):
    """1-phase dc-equivalent motor with a simple current PI (SPEC §2.3)."""

    family, value = "motor", "dc"
    doc = "1-phase dc equivalent of the PMSM q axis, simple current PI"
    inputs = (_D_I,)
    outputs = _COMMON_OUT
    params = ("pp", "psi", "R", "L_q", "K_p_i", "K_i_i", "k_v", "V_dc", "loop_i", "f_s_i")
    loops = (CURRENT_LOOP,)
    holds = Pmsm.holds
    states = (
        State("z_i", "V", "current integral part", roles=("controller_integral",), scale=_volts, loop="current"),
        State("i", "A", "winding current", roles=("current",), scale=_amps, bound=CURRENT_BOUND),
    )
    stored = ("E_mag",)

    def signals(self):
        def current_law(b):
            v, z_dot = controller.current_law_simple(b["i_cmd"], b.feedback(CURRENT_LOOP), b["omega"], b["z_i"], b.P)
            return 0, v / 1.5, z_dot

        def plant(b):
            return dc(b["i"], 1.5 * b["v_q"], b["omega"], b.P)

        return {
            ("v_d_ref", "v_q_ref", der("z_i")): current_law,
            (der("i"), "T_m", "P_elec", "P_cu", "E_mag"): plant,
            "i_d": lambda b: 0,
            "i_q": lambda b: b["i"],
        }
