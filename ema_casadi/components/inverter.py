"""Power electronics (SPEC §2.2).

``ideal`` (averaged): the controller's voltage reaches the windings unchanged (the
voltage limit is applied by the current controller). Its losses are the averaged
conduction and switching losses of a two-level bridge carrying the same currents.
"""

from __future__ import annotations

import casadi as ca

from ._part import Output, Part

__all__ = ["ideal", "averaged_losses", "current_amplitude", "Ideal"]


def ideal(v):
    """Averaged inverter: winding voltage = commanded voltage.

    Parameters
    ----------
    v : SX
        Commanded voltage (V).
    """
    return v


def averaged_losses(I_hat, P, I_sq=None):
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
    """
    i_abs = 2 * I_hat / ca.pi
    i_sq = (I_hat**2 if I_sq is None else I_sq) / 2
    V0 = 0.5 * (P.V_CE0 + P.V_F0)
    r = 0.5 * (P.r_CE + P.r_F)
    P_cond = 3 * (V0 * i_abs + r * i_sq)
    P_sw = 3 * P.f_sw * P.E_sw * (P.V_dc / P.V_sw_ref) * (i_abs / P.I_sw_ref)
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


class Ideal(Part):
    """Averaged inverter: the controller's voltage reaches the windings; averaged
    conduction and switching losses of the bridge carrying the motor currents."""

    family, value = "inverter", "ideal"
    doc = "averaged bridge: winding voltage = controller voltage, averaged losses"
    outputs = (
        Output("v_d", "V", "d-axis winding voltage (0 for the dc motor)"),
        Output("v_q", "V", "q-axis winding voltage (dc motor: its voltage / 1.5)"),
        Output("P_inv_cond", "W", "inverter conduction loss", kind="loss"),
        Output("P_inv_sw", "W", "inverter switching loss", kind="loss"),
        Output("P_dc", "W", "power drawn at the DC-link input: winding power + inverter losses", kind="power"),
    )
    params = ("V_CE0", "V_F0", "r_CE", "r_F", "f_sw", "E_sw", "V_dc", "V_sw_ref", "I_sw_ref")
    heat = {"P_inv_cond": "inverter", "P_inv_sw": "inverter"}

    def signals(self):
        def losses(b):
            # I^2 passed as i_d^2 + i_q^2: what sqrt(.)^2 simplified to before the guard
            sq = b["i_d"] ** 2 + b["i_q"] ** 2
            return averaged_losses(current_amplitude(b["i_d"], b["i_q"]), b.P, sq)

        return {
            "v_d": lambda b: ideal(b["v_d_ref"]),
            "v_q": lambda b: ideal(b["v_q_ref"]),
            ("P_inv_cond", "P_inv_sw"): losses,
            "P_dc": lambda b: b["P_elec"] + b["P_inv_cond"] + b["P_inv_sw"],
        }
