"""Steady-state relations of the model's parts for analyses that read them from
records (the friction start of identification): the steady-state friction law of the
friction variant, and the nut force that a net motor torque transmits. The variant
values are known here, in the model layer; the analyses ask by the model's variants.
"""

from __future__ import annotations

import casadi as ca

from .components.ballscrew import efficiency_factor
from .components.friction import sliding_level, smooth, stribeck_curve

__all__ = ["steady_friction", "has_hump", "nut_force"]


def steady_friction(variants: dict, v, f_ext, P):
    """The friction force at steady sliding speed ``v`` (m/s) under the load ``f_ext``
    (N) of the model with ``variants`` (N): the smooth law (its shape and optional
    hump) for ``smooth`` and ``lugre_smooth`` (whose steady state it is), the Stribeck
    curve with sign(v) plus the viscous term for ``lugre``, the sliding level with
    sign(v) plus the viscous term for ``hybrid``.

    Parameters
    ----------
    variants : dict
        The model's variants (``Model.variants``).
    v, f_ext : SX or float
        Speed (m/s) and load (N).
    P : object
        Parameters by attribute (flat names; symbols or floats).
    """
    F_r = sliding_level(f_ext, P)
    friction = variants.get("friction", "smooth")
    if friction == "lugre":
        return stribeck_curve(v, F_r, P) * ca.sign(v) + P.c_v * v
    if friction == "hybrid":
        return F_r * ca.sign(v) + P.c_v * v
    return smooth(v, F_r, P, variants.get("friction_shape", "tanh"), variants.get("stribeck", "off") == "on")[0]


def has_hump(variants: dict) -> bool:
    """Whether the steady-state friction law has a breakaway hump (r_start, v_st).

    Parameters
    ----------
    variants : dict
        The model's variants (``Model.variants``).
    """
    return variants.get("friction") == "lugre" or (variants.get("friction") in ("smooth", "lugre_smooth", None)
                                                    and variants.get("stribeck") == "on")


def nut_force(T_net: float, omega: float, eta: float, P) -> float:
    """The axial force (N) the nut transmits when the net motor torque ``T_net`` (N m,
    after the inertia and the shaft's viscous friction) drives the screw at ``omega``
    (rad/s): T_net = (p/2 pi) F g with the efficiency factor g of the power's direction.

    Parameters
    ----------
    T_net, omega, eta : float
        Net torque (N m), shaft speed (rad/s), direct efficiency (-).
    P : object
        Parameters by attribute (uses ``p``, ``eta_inv``, ``P_blend``).
    """
    r = P.p / (2 * ca.pi)
    return T_net / (r * float(efficiency_factor(T_net / r, omega, eta, P)))
