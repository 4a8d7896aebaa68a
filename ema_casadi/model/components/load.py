"""The load on the rod besides the external force ``f_ext`` (docs: physics).

``constant``: none; the rod carries ``f_ext`` alone (the reference).

``aero_spring``: the hinge moment of a control surface as a spring in rod position, the
surface's aerodynamic stiffness referred to the rod, on top of ``f_ext``::

    F_aero = k_aero x_rod      (N, positive pushes the rod in, like f_ext)

so the rod carries f_ext + k_aero x_rod and the spring stores E_aero = k_aero x_rod^2 / 2.
The spring acts on the rod's mechanical motion (``x_rod_mech`` of the screw part). In the
linearisation it adds k_aero to the dynamic stiffness -f_ext/x_rod at every frequency:
K_aero(jw) = K(jw) + k_aero.
"""

from __future__ import annotations

from ._part import Output, Part
from ._ports import Port

__all__ = ["Constant", "AeroSpring"]


class Constant(Part):
    """No load besides ``f_ext``."""

    family, value = "load", "constant"
    doc = "the external force f_ext alone"


class AeroSpring(Part):
    """The surface's hinge moment as a spring in rod position, plus ``f_ext``."""

    family, value = "load", "aero_spring"
    reads = (Port("x_rod_mech", "m", "the rod's mechanical position"),)
    doc = "hinge-moment spring k_aero x_rod on the rod, plus f_ext"
    outputs = (Output("F_aero", "N", "hinge-moment spring on the rod, k_aero x_rod (positive pushes it in)"),)
    params = ("k_aero",)
    stored = ("E_aero",)
    loads = ("F_aero",)

    def signals(self):
        def spring(b):
            x = b["x_rod_mech"]
            return b.P.k_aero * x, 0.5 * b.P.k_aero * x**2

        return {("F_aero", "E_aero"): spring}
