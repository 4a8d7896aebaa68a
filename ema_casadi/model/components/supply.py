"""The 270 V supply (docs: physics, the power rows of the parameter table).

The inverters draw the power ``P_bridge`` (winding power + their own losses) from the
DC link; the supply provides the DC-link voltage ``v_dc`` the controller measures (its
voltage limit follows it) and ``P_dc``, the power drawn at the 270 V input.

- ``ideal``: the source itself is the DC link, ``v_dc = V_dc`` (the parameter) and
  ``P_dc = P_bridge`` (the expressions of the model before the supply family existed).
- ``line``: the source V_dc behind the line resistance R_line and inductance L_line
  feeds the DC-link capacitor C_dc:
  L_line di_line/dt = V_dc - R_line i_line - v_dc,  C_dc dv_dc/dt = i_line - P_bridge / v_dc.
  The bridge's current is its power over the link voltage, so its losses (not a part of
  the circuit equations) are drawn from the link too and the energy balance at the input
  closes. The states are the line current and the deviation ``dv_dc = v_dc - V_dc`` (0 at
  rest). Its resonance, 1/(2 pi sqrt(L_line C_dc)) = 2.5 kHz with damping
  zeta = (R_line/2) sqrt(C_dc/L_line) = 0.16 for the reference values, is an eigenvalue of
  magnitude ~1.6e4 1/s: h lambda = 0.08 for RK4 at 5 us (no step-size constraint beyond
  the rod's), CVODES takes it in its stride.

MIL-STD-704F: the normal range of a 270 V DC bus is 250-280 V; ``V_dc`` may be set
anywhere in it (tests run 250 V).
"""

from __future__ import annotations

from ._part import Bound, Output, Part, State, der
from ._ports import Port

__all__ = ["Ideal", "Line"]

_V_DC = Output("v_dc", "V", "DC-link voltage (the controller's measured supply voltage)")
_P_DC = Output("P_dc", "W", "power drawn at the 270 V input", kind="power", roles=("electrical_power",))


class Ideal(Part):
    """The ideal 270 V source: the DC link at the parameter V_dc."""

    family, value = "supply", "ideal"
    reads = (Port("P_bridge", "W", "the power the bridge draws"),)
    doc = "ideal source: DC-link voltage = V_dc"
    outputs = (_P_DC, _V_DC)
    params = ("V_dc",)

    def signals(self):
        return {"v_dc": lambda b: b.P.V_dc, "P_dc": lambda b: b["P_bridge"]}


def _volts(P):
    return P.V_dc


def _amps(P):
    return P.I_max


class Line(Part):
    """Source V_dc behind R_line, L_line feeding the DC-link capacitor C_dc."""

    family, value = "supply", "line"
    reads = (Port("P_bridge", "W", "the power the bridge draws"),)
    doc = "source behind R_line, L_line feeding the DC-link capacitor C_dc"
    states = (
        State("i_line", "A", "supply-line current (source to DC link)", roles=("current",), scale=_amps,
              bound=Bound(lambda E: 10 * E.I_max, "10 x I_max")),
        State("dv_dc", "V", "DC-link voltage less the source voltage", scale=_volts,
              bound=Bound(lambda E: E.V_dc, "V_dc (the link at 0 or twice the source)")),
    )
    outputs = (
        _P_DC, _V_DC,
        Output("i_line", "A", "supply-line current"),
        Output("P_line", "W", "supply-line resistive loss", kind="loss"),
    )
    params = ("V_dc", "R_line", "L_line", "C_dc")
    # the line and DC-link filter sit on the inverter's board and harness: its heat is counted there
    heat = {"P_line": "inverter"}
    stored = ("E_link",)

    def signals(self):
        def link(b):
            i, v = b["i_line"], b["v_dc"]
            return (b.P.V_dc - b.P.R_line * i - v) / b.P.L_line, (i - b["P_bridge"] / v) / b.P.C_dc

        return {
            "v_dc": lambda b: b.P.V_dc + b["dv_dc"],
            (der("i_line"), der("dv_dc")): link,
            "P_dc": lambda b: b.P.V_dc * b["i_line"],
            "P_line": lambda b: b.P.R_line * b["i_line"] ** 2,
            "E_link": lambda b: 0.5 * b.P.L_line * b["i_line"] ** 2 + 0.5 * b.P.C_dc * b["v_dc"] ** 2,
        }
