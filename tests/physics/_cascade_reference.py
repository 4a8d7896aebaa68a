"""NumPy transcription of the ECU cascade with the anti-windup laws of
``docs/guide/ecu-structure.md``, written from those equations independently of the
CasADi parts: the PI position loop (output the motor-speed command, limited to the
rate limit), the PI speed loop (the current command, limited to I_max) and the PI
current loop of the dc-equivalent motor (the winding voltage with back-EMF
feed-forward, limited to 1.5 k_v V_dc/sqrt(3)), on a rigid one-mass drive train without
friction, backlash or efficiency loss (J_eq omega' = K_t i - (p/2 pi) f_ext).

Anti-windup laws (``law``): ``backcalc`` z' = K_i e + (K_i/K_p)(u_sat - u); ``band``
the toolkit's clamping z' = K_i [e - g(d) max(e, 0) - g(-d) min(e, 0)] with the gate
g(d) = s^2 (3 - 2 s), s = min(max(d, 0)/w, 1), w = band u_lim and d = u - u_sat;
``exact`` the textbook conditional integration: z' = 0 while e d > 0, else K_i e.

Continuous ECU: every state by classical RK4 with step ``dt``. Sampled ECU (``zoh``):
at each step whose interval [t, t + dt) holds a sampling instant n/f_s of a loop, that
loop (outer to inner, each seeing the outer loop's new output) recomputes its held
output and advances its integrator by forward Euler over 1/f_s; the plant then takes
an RK4 step with the held voltage.
"""

from __future__ import annotations

import math

import numpy as np

LAWS = ("backcalc", "band", "exact")


def _gate(d: float, w: float) -> float:
    s = min(max(d, 0.0) / w, 1.0)
    return s * s * (3 - 2 * s)


def _rate(law: str, e: float, u: float, u_sat: float, K_p: float, K_i: float, w: float) -> float:
    d = u - u_sat
    if law == "backcalc":
        return K_i * e + (K_i / K_p) * (u_sat - u)
    if law == "exact":
        return 0.0 if e * d > 0 else K_i * e
    return K_i * (e - _gate(d, w) * max(e, 0.0) - _gate(-d, w) * min(e, 0.0))


def simulate_cascade(P: dict, x_cmd: float, f_ext: float, t_end: float, dt: float, law: str,
                     band: float = 0.01, zoh: bool = False) -> np.ndarray:
    """Rod position (m) and motor speed (rad/s) at 0, dt, ..., t_end (one row each)
    after a step of the command to ``x_cmd`` (m) at t = 0 under the constant load
    ``f_ext`` (N), from rest. ``P``: flat parameter values (SI)."""
    if law not in LAWS:
        raise ValueError(f"law {law!r} not one of {LAWS}")
    r = P["p"] / (2 * math.pi)
    K_t = 1.5 * P["pp"] * P["psi"]
    R_dc, L_dc = 1.5 * P["R"], 1.5 * P["L_q"]
    J = P["J_m"] + P["J_s"] + P["M"] * r**2
    loops = (  # K_p, K_i, limit, sample rate
        (P["K_x"] / r, P["K_i_x"] / r, P["v_max"] / r, P["f_s_x"]),
        (P["K_p_w"], P["K_p_w"] / P["T_i_w"], P["I_max"], P["f_s_w"]),
        (1.5 * P["K_p_i"], 1.5 * P["K_i_i"], 1.5 * P["k_v"] * P["V_dc"] / math.sqrt(3), P["f_s_i"]),
    )

    def ecu(z, s, k, outer):
        i, om, phi = s
        e, ff = ((x_cmd - phi * r, 0.0), (outer - om, 0.0), (outer - i, K_t * om))[k]
        K_p, K_i, lim, _ = loops[k]
        u = K_p * e + z[k] + ff
        u_sat = min(max(u, -lim), lim)
        return u_sat, _rate(law, e, u, u_sat, K_p, K_i, band * lim)

    def plant(s, v):
        i, om, _ = s
        return np.array([(v - R_dc * i - K_t * om) / L_dc, (K_t * i - r * f_ext) / J, om])

    def f(y, held):
        if held is not None:
            return np.concatenate([np.zeros(3), plant(y[3:], held)])
        out, dz = 0.0, np.empty(3)
        for k in range(3):
            out, dz[k] = ecu(y[:3], y[3:], k, out)
        return np.concatenate([dz, plant(y[3:], out)])

    n = int(round(t_end / dt))
    y = np.zeros(6)  # z_x, z_w, z_i, i, omega, phi
    held, v = [0.0, 0.0, 0.0], None
    out = np.zeros((n + 1, 2))
    for j in range(n):
        t = j * dt
        if zoh:
            for k in range(3):
                fs = loops[k][3]
                if math.ceil((t + dt) * fs - 1e-9) > math.ceil(t * fs - 1e-9):
                    held[k], dz = ecu(y[:3], y[3:], k, held[k - 1] if k else 0.0)
                    y[k] += dz / fs
            v = held[2]
        k1 = f(y, v)
        k2 = f(y + dt / 2 * k1, v)
        k3 = f(y + dt / 2 * k2, v)
        k4 = f(y + dt * k3, v)
        y = y + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        out[j + 1] = [y[5] * r, y[4]]
    return out
