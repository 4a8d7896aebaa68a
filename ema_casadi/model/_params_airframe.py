"""The ``[airframe]`` parameter table (docs: physics), SI inside.

Read by the airframe parts (``airframe = "transport" | "b747"``): the Stevens & Lewis
medium transport (Stevens & Lewis, Aircraft Control and Simulation, 2nd ed., §3.6,
converted from US units with ft = 0.3048 m,
slug = 14.5939 kg, lbf = 4.44822 N, coefficients per rad), the elevator surface and horn
(§3), the pitch flight-control law (§4) and the flight condition trimmed for. Every
key has its default, so parameter files without the table load unchanged.
"""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["Airframe"]

_REAL = "real"  # any finite number (a signed coefficient)


def _a(unit: str, check: str, doc: str, default: float):
    return field(default=default, metadata={"unit": unit, "check": check, "doc": doc, "default": default})


@dataclass(frozen=True)
class Airframe:
    """Aircraft, surface and flight-control law (used by ``airframe != "none"``)."""

    S_w: float = _a("m^2", "positive", "wing area (2170 ft^2)", 201.5995968)
    c_w: float = _a("m", "positive", "mean aerodynamic chord (17.5 ft)", 5.334)
    m_ac: float = _a("kg", "positive", "aircraft mass (5000 slug)", 72969.51468603182)
    I_yy: float = _a("kg*m^2", "positive", "pitch inertia (4.1e6 slug ft^2)", 5558853.588158742)
    T_stat: float = _a("N", "positive", "static thrust (6e4 lbf)", 266893.29691563)
    dT_dV: float = _a("N*s/m", "non-positive", "thrust lapse with airspeed (-38 lbf/(ft/s))", -554.5683116138417)
    z_E: float = _a("m", _REAL, "thrust moment arm (2 ft)", 0.6096)
    C_L_a: float = _a("1/rad", "positive", "lift slope (0.085 /deg)", 4.870141258611998)
    C_m_a: float = _a("1/rad", _REAL, "pitch stiffness (-0.022 /deg)", -1.260507149287811)
    C_m_de: float = _a("1/rad", _REAL, "elevator power (-0.016 /deg)", -0.9167324722093172)
    C_m_q: float = _a("1/rad", _REAL, "pitch damping", -16.0)
    C_m_ad: float = _a("1/rad", _REAL, "alpha-dot damping", -6.0)
    C_L_ad: float = _a("1/rad", _REAL, "alpha-dot lift", 0.0)
    C_D_cls: float = _a("1", "non-negative", "induced-drag factor", 0.042)
    x_cg: float = _a("1", "fraction", "centre of gravity, fraction of the chord", 0.25)
    C_L0: float = _a("1", _REAL, "lift at zero alpha (clean 0.20, landing 1.0)", 0.20)
    C_D0: float = _a("1", "non-negative", "zero-lift drag (clean 0.016, landing 0.08)", 0.016)
    C_m0: float = _a("1", _REAL, "pitch moment at zero alpha (clean 0.05, landing -0.20)", 0.05)
    dC_D: float = _a("1", "non-negative", "gear drag increment (landing 0.02)", 0.0)
    dC_m: float = _a("1", _REAL, "gear pitch-moment increment (landing -0.05)", 0.0)
    g_0: float = _a("m/s^2", "positive", "gravity (32.17 ft/s^2)", 9.805416)
    r_horn: float = _a("m", "positive", "elevator horn length r", 0.15)
    a_pin: float = _a("m", "positive", "hinge to actuator pin distance a (rod perpendicular to the horn at neutral)",
                      1.0)
    S_c_e: float = _a("m^3", "positive", "elevator area x chord S_e c_e", 3.5)
    C_h0: float = _a("1", _REAL, "hinge moment at zero alpha and deflection", 0.0)
    C_h_a: float = _a("1/rad", _REAL, "hinge-moment slope with alpha", -0.3)
    C_h_d: float = _a("1/rad", _REAL, "hinge-moment slope with deflection", -0.5)
    J_e: float = _a("kg*m^2", "non-negative", "surface inertia about the hinge", 15.0)
    K_q: float = _a("s", "non-negative", "pitch-rate gain of the flight-control law", 1.0)
    K_th: float = _a("1", "non-negative", "pitch-attitude gain", 2.0)
    K_ith: float = _a("1/s", "non-negative", "pitch-attitude integral gain", 0.5)
    f_s_a: float = _a("Hz", "positive", "flight-control computer rate (sampled law)", 80.0)
    V_0: float = _a("m/s", "positive", "trim airspeed (500 ft/s)", 152.4)
    h_0: float = _a("m", "non-negative", "trim altitude", 0.0)
