"""Stroke end stops (docs: physics): the rod is limited to |x_rod| <= stroke.

The stop touches the rod's mechanical motion (``x_rod_mech``, ``v_rod_mech`` of the
screw part: the rod itself for the elastic screw, the nut for the rigid one, whose
``x_rod`` is the position signal after the backlash play).

``elastic``: beyond the stroke an elastic stop with damping in contact only and no
pulling force (the Modelica ElastoGap law). With the penetration
d = max(|x_rod| - stroke, 0) and the outward rod velocity v_out = sign(x_rod) v_rod::

    F_stop = max(0, k_stop d + d_stop v_out)   while d > 0, else 0   (N, pushes the rod back)

With the stops, the rod's envelope (``overtravel`` beyond the stroke) widens by the
stops' deflection under three times the largest force the motor holds (0.93 mm on the
reference set).

The stop stores E_stop = k_stop d^2 / 2 and dissipates
P_stop = (F_stop - k_stop d) v_out >= 0 (the damping d_stop v_out^2 while it pushes,
and the spring energy it releases while the clip holds the force at 0), so the energy
balance closes exactly.
"""

from __future__ import annotations

import casadi as ca

from ._part import MARGIN, Output, Part
from ._ports import Port
from .ballscrew import OVERTRAVEL, held_force

__all__ = ["stop_force", "Elastic"]


def stop_force(x, v, stroke, k_stop, d_stop):
    """ElastoGap stop at +-stroke.

    Returns (F_stop (N, magnitude, >= 0), F on the rod as a load (N, positive pushes the
    rod in, like f_ext), penetration (m), E_stop (J), P_stop (W)).

    Parameters
    ----------
    x : SX
        Rod position (m).
    v : SX
        Rod velocity (m/s).
    stroke : SX
        Stroke from the centre to either stop (m).
    k_stop : SX
        Stop stiffness (N/m).
    d_stop : SX
        Stop damping (N s/m).
    """
    s = ca.sign(x)
    pen = ca.fmax(ca.fabs(x) - stroke, 0)
    v_out = s * v
    F = ca.if_else(pen > 0, ca.fmax(0, k_stop * pen + d_stop * v_out), 0)
    return F, s * F, pen, 0.5 * k_stop * pen**2, (F - k_stop * pen) * v_out


class Elastic(Part):
    """Elastic, damped, non-pulling stops at both ends of the stroke."""

    family, value = "endstop", "elastic"
    reads = (
        Port("x_rod_mech", "m", "the rod's mechanical position"),
        Port("v_rod_mech", "m/s", "the rod's mechanical velocity"),
    )
    doc = "ElastoGap stops at +-stroke: k_stop, d_stop, no pulling force"
    outputs = (
        Output("F_stop", "N", "end-stop force on the rod (>= 0, pushes it back into the stroke)"),
        Output("P_stop", "W", "end-stop loss (damping, and spring energy released while clipped)", kind="loss"),
    )
    params = ("stroke", "k_stop", "d_stop")
    stored = ("E_stop",)
    heat = {"P_stop": "screw"}  # the rod's collar and the stop: counted with the rod and screw
    loads = ("F_stop_rod",)
    # the rod may pass the stroke by the stops' deflection under a few times the
    # largest force the motor holds (measured: 0.31 mm held, < 1 mm on impact)
    limits = {"overtravel": lambda P: OVERTRAVEL + MARGIN * held_force(P) / P.k_stop}

    def signals(self):
        def stop(b):
            F, F_rod, _pen, E, P_loss = stop_force(b["x_rod_mech"], b["v_rod_mech"], b.P.stroke, b.P.k_stop, b.P.d_stop)
            return F, F_rod, E, P_loss

        return {("F_stop", "F_stop_rod", "E_stop", "P_stop"): stop}
