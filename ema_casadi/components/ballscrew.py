"""Ballscrew / reductor (SPEC §2.4): ``rigid`` one-mass and ``elastic`` two-mass."""

from __future__ import annotations

import casadi as ca

__all__ = ["lead_ratio", "efficiency_factor", "dead_zone", "elastic", "play_rate", "P_BLEND"]

#: Width (W) over which the screw-nut efficiency switches between the direct and the
#: inverse value as the transmitted power changes sign. An exact switch makes a
#: sliding mode that stalls variable-step solvers while a load is held at standstill;
#: blending over ~0.1 W moves reference trajectories by < 0.25 um (STACK_NOTES).
P_BLEND = 0.1


def lead_ratio(P):
    """Rod travel per shaft radian, p / (2 pi) (m/rad)."""
    return P.p / (2 * ca.pi)


def efficiency_factor(F, omega, eta, P):
    """Factor g in T_load = (p/2 pi) F g: 1/eta when the motor drives the load
    (F omega > 0), eta_inv when the load back-drives; blended over P_BLEND watts."""
    w = 0.5 * (1 + ca.tanh(F * omega * lead_ratio(P) / P_BLEND))
    return w / eta + (1 - w) * P.eta_inv


def dead_zone(delta, B):
    """Dead zone of total width B (m): 0 inside |delta| <= B/2, delta -+ B/2 outside.

    Written as fmax(delta - B/2, 0) + fmin(delta + B/2, 0) so that with B = 0 the AD
    slope at delta = 0 is exactly 1 (two half-slopes), not 1/2.
    """
    return ca.fmax(delta - B / 2, 0) + ca.fmin(delta + B / 2, 0)


def elastic(phi, omega, x_rod, v_rod, P):
    """Two-mass screw: dead-zone spring (eq. 2) plus contact damping.

    Delta = x_in - x_rod with x_in = phi p/(2 pi);
    F_in = C dz(Delta) + c_c dDelta/dt while in contact (|Delta| >= B/2).
    Returns (F_in (N), Delta (m), E_spring (J), P_contact (W), in_contact).
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
    """Play (hysteresis) operator of width B as an ODE: the output x_play follows the
    input only while the input pushes on an edge of the gap (m/s)."""
    gap = x_in - x_play
    return ca.if_else(gap >= B / 2, ca.fmax(v_in, 0), 0) + ca.if_else(gap <= -B / 2, ca.fmin(v_in, 0), 0)
