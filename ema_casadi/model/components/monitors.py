"""ECU monitors (variant ``monitors = off | on``): fault detection on what the ECU reads.

Each monitor ``k`` watches a condition ``c_k`` on the sensed signals, confirms it over
its confirmation time and latches:

- a confirmation timer ``tc_k`` (s): ``dtc/dt = 1`` while ``c_k`` holds, otherwise it
  decays back to 0 with ``TAU_RESET`` (a counter reset, kept continuous so the model
  trims and linearises); the monitor *trips* when ``tc_k >= t_conf``;
- a latch ``L_k`` (an ``alarm`` output): ``dL/dt = (1 - L)/TAU_LATCH`` while tripped or
  once ``L > 1/2``, else ``-L/TAU_LATCH``: bistable, so once set it stays set. The
  detection time is the first instant with ``L >= 1/2``, ``TAU_LATCH ln 2`` (0.07 ms)
  after the trip, well within one position-loop sample.

The conditions (thresholds and confirmation times from the ``[monitor]`` table):

- ``track``: ``|x_ref - x_s| > e_track``; ``x_ref`` is the command through the nominal
  closed loop, a first order ``1/K_x`` with the rate limit:
  ``dx_ref/dt = clamp(K_x (x_cmd - x_ref), -v_max, v_max)``;
- ``jam``: ``|i_q_s| >= k_jam_i I_max`` and ``|omega_s| < w_jam``;
- ``cross`` (rod vs motor): ``|x_in_s - x_s| > B/2 + |F_est|/C + e_cross``, the nut
  position from the resolver against the rod sensor, with the drive train's deflection
  under the force the current makes, ``F_est = K_t i_q_s 2 pi/p``;
- ``oc`` (over-current): ``|i_dq,s| > k_oc I_max``;
- ``ot`` (over-temperature): ``T_w > T_ot`` (with the thermal network; never without).

Each monitor also outputs its statistic (kind ``statistic``, ``stat_<monitor>``): the
quantity its condition compares with its threshold, in the threshold's unit, so that
the condition holds at ``stat >= threshold`` - ``|x_ref - x_s|`` (m, against
``e_track``); ``|i_q_s| / I_max`` while ``|omega_s| < w_jam``, else 0 (against
``k_jam_i``); ``|x_in_s - x_s| - B/2 - |F_est|/C`` (m, against ``e_cross``);
``|i_dq,s| / I_max`` (against ``k_oc``); ``T_w`` (degC, against ``T_ot``; 0 without
the thermal network). Their largest healthy values are the monitors' margins.

A latched monitor with its reaction flag ``react_k = 1`` switches the bridge off (the
open-bridge winding voltages, as the free-run fault), so fault accommodation runs in
the same model.
"""

from __future__ import annotations

import math

import casadi as ca

from ._part import Output, Part, State, der
from ._ports import Port

__all__ = ["On", "MONITORS", "THRESHOLDS", "TAU_RESET", "TAU_LATCH"]

#: Decay time of a confirmation timer when its condition clears (s).
TAU_RESET = 1e-3
#: Time constant of a latch (s): it reaches 1/2 TAU_LATCH ln 2 after the trip.
TAU_LATCH = 1e-4

#: Monitor -> (confirmation-time parameter, reaction flag, one-line meaning).
MONITORS = {
    "track": ("t_track", "react_track", "position tracking error against the nominal closed loop"),
    "jam": ("t_jam", "react_jam", "current at the limit with the motor at rest"),
    "cross": ("t_cross", "react_cross", "rod sensor against the motor angle"),
    "oc": ("t_oc", "react_oc", "over-current"),
    "ot": ("t_ot", "react_ot", "winding over-temperature"),
}


#: Monitor -> (threshold parameter, statistic unit).
THRESHOLDS = {"track": ("e_track", "m"), "jam": ("k_jam_i", "1"), "cross": ("e_cross", "m"), "oc": ("k_oc", "1"),
              "ot": ("T_ot", "degC")}


def _estimates(b):
    """The sampled current magnitude |i_dq| (A) and the screw force estimated from the
    sampled i_q (N), which the over-current and cross-check monitors judge."""
    P = b.P
    k = 2 * math.pi / P.p
    i_dq = ca.sqrt(b["i_d_s"] ** 2 + b["i_q_s"] ** 2 + 1e-30)
    F_est = 1.5 * P.pp * P.psi * b["i_q_s"] * k
    return i_dq, F_est


def _statistics(b):
    """Each monitor's statistic, in its threshold's unit (module docstring)."""
    P = b.P
    i_dq, F_est = _estimates(b)
    stat = {
        "track": ca.fabs(b["x_ref"] - b["x_s"]),
        "jam": ca.if_else(ca.fabs(b["omega_s"]) < P.w_jam, ca.fabs(b["i_q_s"]) / P.I_max, 0),
        "cross": ca.fabs(b["x_in_s"] - b["x_s"]) - P.B / 2 - ca.fabs(F_est) / P.C,
        "oc": i_dq / P.I_max,
        "ot": b["T_w"] if "T_w" in b else ca.SX(0),
    }
    return tuple(stat[name] for name in MONITORS)


def _conditions(b):
    P = b.P
    i_dq, F_est = _estimates(b)
    cond = {
        "track": ca.fabs(b["x_ref"] - b["x_s"]) > P.e_track,
        "jam": ca.logic_and(ca.fabs(b["i_q_s"]) >= P.k_jam_i * P.I_max, ca.fabs(b["omega_s"]) < P.w_jam),
        "cross": ca.fabs(b["x_in_s"] - b["x_s"]) > P.B / 2 + ca.fabs(F_est) / P.C + P.e_cross,
        "oc": i_dq > P.k_oc * P.I_max,
        "ot": (b["T_w"] > P.T_ot) if "T_w" in b else ca.SX(0),
    }
    return tuple(cond[name] for name in MONITORS)


class On(Part):
    """The ECU's monitors, each a confirmation timer and a latch (module docstring)."""

    family, value = "monitors", "on"
    reads = (
        Port("x_cmd", "m", "the rod command"),
        Port("x_s", "m", "the measured rod position"),
        Port("x_in_s", "m", "the measured nut position"),
        Port("omega_s", "rad/s", "the measured motor speed"),
        Port("i_d_s", "A", "the measured d current"),
        Port("i_q_s", "A", "the measured q current"),
        Port("v_d_open", "V", "the winding d voltage with the bridge on"),
        Port("v_q_open", "V", "the winding q voltage with the bridge on"),
        Port("T_w", "degC", "the winding temperature", optional=True),
    )
    doc = "ECU monitors: tracking, jam, rod-motor cross-check, over-current, over-temperature; latched"
    states = (
        State("x_ref", "m", "monitor: the command through the nominal closed loop", scale=lambda P: P.stroke,
              travel=lambda P: 1.0),
        *(State(f"tc_{n}", "s", f"monitor {n}: confirmation timer", scale=lambda P, t=t: getattr(P, t))
          for n, (t, _, _) in MONITORS.items()),
        *(State(f"L_{n}", "1", f"monitor {n}: latch") for n in MONITORS),
    )
    outputs = (
        *(Output(f"latch_{n}", "1", f"latched monitor: {doc}", kind="alarm") for n, (_, _, doc) in MONITORS.items()),
        Output("bridge_off", "1", "the monitors' reaction: 1 switches the bridge off", kind="flag"),
        *(Output(f"stat_{n}", THRESHOLDS[n][1], f"monitor {n}'s statistic: holds at >= {THRESHOLDS[n][0]}",
                 kind="statistic", threshold=THRESHOLDS[n][0], confirm=t, alarm=f"latch_{n}")
          for n, (t, _, _) in MONITORS.items()),
    )
    params = ("e_track", "t_track", "k_jam_i", "w_jam", "t_jam", "e_cross", "t_cross", "k_oc", "t_oc", "T_ot", "t_ot",
              "react_track", "react_jam", "react_cross", "react_oc", "react_ot", "K_x", "v_max", "I_max", "B", "C",
              "pp", "psi", "p", "stroke")

    def signals(self):
        def x_ref(b):
            P = b.P
            return ca.fmin(ca.fmax(P.K_x * (b["x_cmd"] - b["x_ref"]), -P.v_max), P.v_max)

        def monitors(b):
            out = []
            for (name, (t_conf, _, _)), c in zip(MONITORS.items(), _conditions(b), strict=True):
                tc, L = b[f"tc_{name}"], b[f"L_{name}"]
                trip = tc >= getattr(b.P, t_conf)
                on = ca.logic_or(trip, L > 0.5)
                out += [ca.if_else(c, 1, -tc / TAU_RESET), ca.if_else(on, 1 - L, -L) / TAU_LATCH]
            return tuple(out)

        def bridge_off(b):
            off = 0
            for name, (_, react, _) in MONITORS.items():
                off = ca.fmax(off, getattr(b.P, react) * (b[f"L_{name}"] > 0.5))
            return off

        keys = tuple(k for n in MONITORS for k in (der(f"tc_{n}"), der(f"L_{n}")))
        return {
            der("x_ref"): x_ref,
            keys: monitors,
            **{f"latch_{n}": (lambda b, n=n: b[f"L_{n}"]) for n in MONITORS},
            "bridge_off": bridge_off,
            tuple(f"stat_{n}" for n in MONITORS): _statistics,
        }

    def modify(self):
        def voltages(b, v, k):
            off = b["bridge_off"]
            return (1 - off) * v + off * b[("v_d_open", "v_q_open")[k]]

        return {"v_d": lambda b, v: voltages(b, v, 0), "v_q": lambda b, v: voltages(b, v, 1)}
