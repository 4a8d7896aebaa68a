"""Friction on the rod (SPEC §2.5). Forces in N, velocities in m/s; positive friction
opposes positive velocity. With the rigid screw the same laws act on the shaft, with
the rod velocity v = omega p/(2 pi) and the force referred back through p/(2 pi)."""

from __future__ import annotations

import casadi as ca

__all__ = ["sliding_level", "smooth", "SHAPES"]

SHAPES = ("tanh", "fermi")


def sliding_level(f_ext, P):
    """Resistive force level while sliding (eq. 7): F_r = F_seal + |F_ext| (2 pi/p) C_bear (N)."""
    return P.F_seal + ca.fabs(f_ext) * (2 * ca.pi / P.p) * P.C_bear


def _s(v, v_s, shape):
    if shape == "tanh":
        return ca.tanh(v / v_s)
    if shape == "fermi":
        return 2 / (1 + ca.exp(-v / v_s)) - 1
    raise ValueError(f"friction shape '{shape}' not one of {SHAPES}")


def smooth(v, F_r, P, shape="tanh", stribeck=False):
    """Simplified friction (eq. 3): F_r s(v) [+ (F_start - F_r) e^-(v/v_st)^2 s(v)] + c_v v.

    Returns (F_friction (N), its Coulomb part without the viscous term (N))."""
    s = _s(v, P.v_s, shape)
    F_c = F_r * s
    if stribeck:
        F_c = F_c + (P.r_start - 1) * F_r * ca.exp(-((v / P.v_st) ** 2)) * s
    return F_c + P.c_v * v, F_c
