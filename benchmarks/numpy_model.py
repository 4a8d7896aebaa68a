"""NumPy transcription of the reference configuration (pmsm + elastic + smooth tanh
friction + ideal inverter + P position loop, continuous ECU), written from the physics reference (docs: physics)
independently of the CasADi assembly. It is the right-hand side handed to the peers
(scipy ``solve_ivp``, python-control ``nlsys``) in the benchmarks, and
``tests/test_numpy_model.py`` checks it against ``model.f`` at random states.

State order: z_w, z_d, z_q, i_d, i_q, phi, omega, x_rod, v_rod (as ``model.states``).
"""

from __future__ import annotations

import math

import numpy as np

STATES = ("z_w", "z_d", "z_q", "i_d", "i_q", "phi", "omega", "x_rod", "v_rod")
P_BLEND = 0.1  # W, efficiency blend width (same modelling choice as the toolkit)


def _clamp(u, lim):
    return min(max(u, -lim), lim)


def rhs(t, x, x_cmd, f_ext, eta, P):
    """dx/dt for inputs x_cmd (m), f_ext (N), eta (-) and parameter dict P (SI)."""
    z_w, z_d, z_q, i_d, i_q, phi, omega, x_rod, v_rod = x
    r = P["p"] / (2 * math.pi)
    # position loop (P): speed command clamped to the rate limit
    w_max = P["v_max"] / r
    w_cmd = _clamp(P["K_x"] / r * (x_cmd - x_rod), w_max)
    # speed PI with back-calculation anti-windup
    K_i_w = P["K_p_w"] / P["T_i_w"]
    e_w = w_cmd - omega
    i_u = P["K_p_w"] * e_w + z_w
    i_cmd = _clamp(i_u, P["I_max"])
    dz_w = K_i_w * e_w + (K_i_w / P["K_p_w"]) * (i_cmd - i_u)
    # FOC current loop with decoupling, circle voltage limit
    w_e = P["pp"] * omega
    e_d, e_q = -i_d, i_cmd - i_q
    vd_u = P["K_p_i"] * e_d + z_d - w_e * P["L_q"] * i_q
    vq_u = P["K_p_i"] * e_q + z_q + w_e * (P["L_d"] * i_d + P["psi"])
    v_lim = P["k_v"] * P["V_dc"] / math.sqrt(3)
    s = min(1.0, v_lim / math.sqrt(vd_u**2 + vq_u**2 + 1e-12))
    v_d, v_q = s * vd_u, s * vq_u
    k_aw = P["K_i_i"] / P["K_p_i"]
    dz_d = P["K_i_i"] * e_d + k_aw * (v_d - vd_u)
    dz_q = P["K_i_i"] * e_q + k_aw * (v_q - vq_u)
    # PMSM
    di_d = (v_d - P["R"] * i_d + w_e * P["L_q"] * i_q) / P["L_d"]
    di_q = (v_q - P["R"] * i_q - w_e * (P["L_d"] * i_d + P["psi"])) / P["L_q"]
    T = 1.5 * P["pp"] * (P["psi"] * i_q + (P["L_d"] - P["L_q"]) * i_d * i_q)
    # elastic screw: dead-zone spring + contact damping
    delta = phi * r - x_rod
    half = P["B"] / 2
    dz = max(delta - half, 0.0) + min(delta + half, 0.0)
    d_delta = omega * r - v_rod
    F_in = P["C"] * dz + (P["c_c"] * d_delta if abs(delta) >= half else 0.0)
    w = 0.5 * (1 + math.tanh(F_in * omega * r / P_BLEND))
    T_load = r * F_in * (w / eta + (1 - w) * P["eta_inv"])
    domega = (T - P["b_m"] * omega - T_load) / (P["J_m"] + P["J_s"])
    # smooth friction on the rod
    F_r = P["F_seal"] + abs(f_ext) / r * P["C_bear"]
    F_fr = F_r * math.tanh(v_rod / P["v_s"]) + P["c_v"] * v_rod
    dv = (F_in - f_ext - F_fr) / P["M"]
    return np.array([dz_w, dz_d, dz_q, di_d, di_q, omega, domega, v_rod, dv])
