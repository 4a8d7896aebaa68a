"""Motors (SPEC §2.3): the 1-phase dc equivalent and the 3-phase PMSM in the rotor
dq frame (amplitude-invariant), and the shaft."""

from __future__ import annotations

__all__ = ["dc", "pmsm", "shaft"]


def dc(i, v, omega, P):
    """DC-equivalent motor: L_dc di/dt = v - R_dc i - K_e omega; T = K_t i.

    Power-invariant equivalent of the PMSM q axis (i = i_q, v = 1.5 v_q):
    K_t = K_e = 1.5 pp psi, R_dc = 1.5 R, L_dc = 1.5 L_q.
    Returns (di/dt (A/s), T (N m), P_elec (W), P_cu (W), E_mag (J)).
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
    """J d omega/dt = T - b_m omega - T_load. Returns d omega/dt (rad/s^2)."""
    return (T - P.b_m * omega - T_load) / J
