"""Fault injection (variant ``faults = off | on``).

With ``on`` the model carries every fault kind below, each activated by one model
input that is 0 when healthy (:class:`~ema_casadi.model.components.Fault`); a fault schedule
(:mod:`ema_casadi.faults`) drives those inputs from the onset on with the severity, so
one compiled model serves every case. The part acts on the signals of the others
through modifiers (:meth:`~ema_casadi.model.components.Part.modify`) and a rod load; the
parts it acts on do not know of it. With every input 0 the model's trajectories are
those of the healthy actuator.

- **jam** (``a_jam``, 0..1): the rod-nut assembly locks at its position at the onset:
  a stop of stiffness ``a k_jam`` and damping ``a d_jam`` anchored at ``x_jam``,
  ``F_jam = a (k_jam (x_rod - x_jam) + d_jam v_rod)``, a load on the rod. The anchor
  follows the rod while healthy, ``dx_jam/dt = (1 - a)(v_rod + (x_rod - x_jam)/tau_hold)``
  (exactly the rod's own motion, plus a correction that keeps the linearisation
  stable), and stands still from the onset (a = 1). The lock stores
  ``E_jam = a k_jam (x_rod - x_jam)^2 / 2`` (in ``E_stored``) and dissipates
  ``P_jam = F_jam v_rod - dE_jam/dt = a d_jam v_rod^2 + a k_jam (x_rod - x_jam) dx_jam/dt``
  at constant severity (the damping, and the slip of a partial lock's anchor), a loss of
  its own that heats the screw node, so the energy balance closes through a jam. A
  severity that changes while the lock is stretched exchanges ``da/dt k_jam (x_rod -
  x_jam)^2 / 2`` more, which no output carries; a step from healthy does not (the
  anchor is at the rod then: the stretch is 0).
- **free_run** (``a_open``, 0..1): the bridge is switched off, the winding voltages
  become those of the open bridge with its freewheeling diodes
  (``v_d_open``, ``v_q_open``: :func:`~ema_casadi.model.components.inverter.open_bridge`):
  ``v = (1 - a) v_bridge + a v_open``. The surface then moves under its load against
  friction and the screw's back-driving efficiency.
- **disconnect** (``a_shear``, 0..1): the mechanical link between motor and rod breaks
  (a sheared coupling or a lost nut): the force the screw transmits becomes
  ``(1 - a) F_in`` on both sides, so the rod moves under its load against its own
  friction and the motor side (shaft and screw) turns free as the loop drives it. It
  needs the two-mass screw (``screw = elastic``), where the rod is a body of its own;
  the rigid screw has no coupling force to cut (a fault file's disconnect case is
  refused there: :attr:`~ema_casadi.model.components.Fault.requires`). The coupling
  breaks over :data:`TAU_SHEAR` (its sheared fraction ``a_sh`` follows ``a``): the
  sheared part holds no spring energy (``E_cut = -a_sh E_spring`` in ``E_stored``) and
  damps nothing, and what it held is released as ``P_shear = da_sh/dt E_spring -
  a_sh P_contact``, a loss of its own (the screw node), so the balance closes through
  a shear.
- **supply** (``a_supply``, 0..1): the DC link loses the fraction ``a`` of its voltage,
  ``v_dc -> (1 - a) v_dc`` (undervoltage; 1 is a supply loss).
- **wear** (``wear_f``, ``wear_b``, relative growth, driven as a ramp from the onset at
  the severity per second): ``F_seal``, ``C_bear`` grow as ``(1 + wear_f)``, the
  backlash ``B`` as ``(1 + wear_b)`` (:meth:`~ema_casadi.model.components.Part.adjust`).
- **sensor faults** on each sensed signal ``x_s`` (rod position), ``omega_s`` (speed
  estimate), ``i_q_s`` (q current): ``bias`` (a step of the reading, in its unit),
  ``drift`` (the same input, ramping at the severity per second), ``stuck`` (the reading
  freezes at its value at the onset, a memory like the jam anchor), ``loss`` (the
  reading drops to 0) and ``noise`` (extra white noise of the severity's standard
  deviation, a seeded sequence at the signal's loop rate):
  ``y -> (1 - l)((1 - s) y + s m) + bias + sigma_f n_f``.
"""

from __future__ import annotations

import casadi as ca

from ._part import Fault, Input, Output, Part, State, der
from ._ports import Port

__all__ = ["On", "SENSOR_TARGETS"]

#: Sensed signal -> (tag of its fault inputs, input kind, unit, loop, bias range (SI)).
SENSOR_TARGETS = {
    "x_s": ("x", "length", "m", "position", 0.075),
    "omega_s": ("w", "angular_velocity", "rad/s", "velocity", 500.0),
    "i_q_s": ("i", "current", "A", "current", 100.0),
}


def _sensor_faults() -> tuple:
    out = []
    for target, (tag, _, unit, _, span) in SENSOR_TARGETS.items():
        out += [
            Fault("bias", f"bias_{tag}", unit, -span, span, f"{target} reads the severity more (a step)", target),
            Fault("drift", f"bias_{tag}", f"{unit}/s", -span, span, f"{target} drifts at the severity per second",
                  target, rate=True),
            Fault("stuck", f"stuck_{tag}", "1", 0.0, 1.0, f"{target} freezes at its onset value (1)", target),
            Fault("loss", f"loss_{tag}", "1", 0.0, 1.0, f"{target} reads 0 (1: signal lost)", target),
            Fault("noise", f"noise_{tag}", unit, 0.0, span / 10, f"{target} gets extra white noise of this sigma",
                  target),
        ]
    return tuple(out)


def _sensor_inputs() -> tuple:
    out = []
    for target, (tag, kind, unit, loop, _) in SENSOR_TARGETS.items():
        out += [
            Input(f"bias_{tag}", unit, kind, f"fault: bias (or drift) added to {target}"),
            Input(f"stuck_{tag}", "1", "dimensionless", f"fault: {target} stuck at its onset value (0..1)"),
            Input(f"loss_{tag}", "1", "dimensionless", f"fault: {target} lost, reads 0 (0..1)"),
            Input(f"noise_{tag}", unit, kind, f"fault: standard deviation of extra noise on {target}"),
            Input(f"n_fault_{tag}", "1", "dimensionless", f"unit white noise of the {target} noise fault",
                  noise=loop, seed="noise_seed"),
        ]
    return tuple(out)


def _sensor_states() -> tuple:
    scales = {"x_s": lambda P: P.stroke, "omega_s": lambda P: P.v_max * 2 * ca.pi / P.p, "i_q_s": lambda P: P.I_max}
    return tuple(
        State(f"m_{tag}", unit, f"memory of {target} for the stuck fault (its value at the onset)",
              scale=scales[target], travel=(lambda P: 1.0) if target == "x_s" else None)
        for target, (tag, _, unit, _, _) in SENSOR_TARGETS.items()
    )


def _unit(v):
    return ca.fmin(ca.fmax(v, 0), 1)


#: The time constant over which a disconnect's coupling breaks (s): the sheared fraction
#: ``a_sh`` follows ``a_shear`` with it, so that the spring energy the coupling held is
#: released as a power of its own (``P_shear``); 20 time constants (1 ms) after the
#: onset it is gone to 2e-9.
TAU_SHEAR = 5e-5


class On(Part):
    """Every fault kind, each behind its own input (module docstring)."""

    family, value = "faults", "on"
    reads = (
        Port("x_rod_mech", "m", "the rod's mechanical position"),
        Port("v_rod_mech", "m/s", "the rod's mechanical velocity"),
        Port("x_s", "m", "the measured rod position"),
        Port("E_spring", "J", "the coupling's spring energy (the elastic screw), released by a shear", optional=True),
        Port("P_contact", "W", "the coupling's contact damping (the elastic screw), cut by a shear", optional=True),
        Port("omega_s", "rad/s", "the measured motor speed"),
        Port("i_q_s", "A", "the measured q current"),
        Port("v_d_open", "V", "the winding d voltage with the bridge on"),
        Port("v_q_open", "V", "the winding q voltage with the bridge on"),
    )
    doc = "fault injection: jam, free-run (bridge off), disconnect, supply loss, sensor bias/drift/stuck/loss/noise"
    states = (
        State("x_jam", "m", "jam anchor: follows the rod while healthy, stands at the onset position",
              scale=lambda P: P.stroke, travel=lambda P: 1.0),
        State("a_sh", "1", "the coupling's sheared fraction: follows a_shear within TAU_SHEAR", scale=lambda P: 1.0),
        *_sensor_states(),
    )
    inputs = (
        Input("a_jam", "1", "dimensionless", "fault: jam, fraction of the lock stiffness (0 healthy, 1 locked)"),
        Input("a_open", "1", "dimensionless", "fault: bridge off / drive loss (0 healthy, 1 off)"),
        Input("a_shear", "1", "dimensionless", "fault: motor-rod link broken (0 healthy, 1 disconnected)"),
        Input("a_supply", "1", "dimensionless", "fault: fraction of the DC-link voltage lost (0 healthy, 1 lost)"),
        Input("wear_f", "1", "dimensionless", "fault: relative growth of F_seal and C_bear (0 healthy)"),
        Input("wear_b", "1", "dimensionless", "fault: relative growth of the backlash B (0 healthy)"),
        *_sensor_inputs(),
    )
    outputs = (Output("F_jam", "N", "force of the jam lock on the rod (positive pushes the rod in)"),
               Output("P_jam", "W", "jam lock loss: its damping and its anchor's slip", kind="loss"),
               Output("P_shear", "W", "a shearing coupling: the spring energy it releases, less the contact "
                      "damping (P_contact) its sheared part no longer does", kind="loss"))
    params = ("k_jam", "d_jam", "tau_hold", "p", "stroke", "v_max", "I_max", "F_seal", "C_bear", "B")
    loads = ("F_jam",)
    stored = ("E_jam", "E_cut")  # E_cut = -a_sh E_spring: the sheared part of the coupling holds none
    heat = {"P_jam": "screw", "P_shear": "screw"}  # the locked rod and nut, the coupling: with the rod and screw
    faults = (
        Fault("jam", "a_jam", "1", 0.0, 1.0, "the rod locks at its onset position (1: fully)"),
        Fault("free_run", "a_open", "1", 0.0, 1.0, "the bridge is switched off (1): no drive, diodes only"),
        Fault("disconnect", "a_shear", "1", 0.0, 1.0,
              "the coupling shears (1): motor side free of the nut and rod (screw = elastic)",
              requires=(("screw", ("elastic",)),)),  # the rigid screw has no coupling: its rod is the motor's
        Fault("supply", "a_supply", "1", 0.0, 1.0, "the DC link loses this fraction of its voltage"),
        Fault("wear_friction", "wear_f", "1/s", 0.0, 10.0, "F_seal and C_bear grow by this fraction per second",
              rate=True),
        Fault("wear_backlash", "wear_b", "1/s", 0.0, 100.0, "the backlash B grows by this fraction per second",
              rate=True),
        *_sensor_faults(),
    )

    def signals(self):
        def jam(b):
            a, v = _unit(b["a_jam"]), b["v_rod_mech"]
            stretch = b["x_rod_mech"] - b["x_jam"]
            anchor = (1 - a) * (v + stretch / b.P.tau_hold)
            spring = a * b.P.k_jam * stretch
            return (spring + a * b.P.d_jam * v, anchor, 0.5 * spring * stretch,
                    a * b.P.d_jam * v**2 + spring * anchor)

        def shear(b):  # the sheared part of the coupling holds no energy and damps nothing
            rate = (_unit(b["a_shear"]) - b["a_sh"]) / TAU_SHEAR
            spring, damping = (b[n] if n in b else 0.0 for n in ("E_spring", "P_contact"))
            return rate, -b["a_sh"] * spring, rate * spring - b["a_sh"] * damping

        out = {("F_jam", der("x_jam"), "E_jam", "P_jam"): jam, (der("a_sh"), "E_cut", "P_shear"): shear}
        for target, (tag, *_rest) in SENSOR_TARGETS.items():
            out[der(f"m_{tag}")] = (lambda b, target=target, tag=tag:
                                    (1 - _unit(b[f"stuck_{tag}"])) * (b[target] - b[f"m_{tag}"]) / b.P.tau_hold)
        return out

    def adjust(self):
        def grown(name, by):
            return lambda P, u: getattr(P, name) * (1 + ca.fmax(u[by], 0))

        return {"F_seal": grown("F_seal", "wear_f"), "C_bear": grown("C_bear", "wear_f"), "B": grown("B", "wear_b")}

    def modify(self):
        def voltages(b, v, k):
            a = _unit(b["a_open"])
            return (1 - a) * v + a * b[("v_d_open", "v_q_open")[k]]

        out = {
            "v_d": lambda b, v: voltages(b, v, 0),
            "v_q": lambda b, v: voltages(b, v, 1),
            "v_dc": lambda b, v: (1 - _unit(b["a_supply"])) * v,
            "F_in": lambda b, F: (1 - b["a_sh"]) * F,
        }
        for target, (tag, *_rest) in SENSOR_TARGETS.items():
            out[target] = lambda b, y, tag=tag: _sensed(b, y, tag)
        return out


def _sensed(b, y, tag):
    s, lost = _unit(b[f"stuck_{tag}"]), _unit(b[f"loss_{tag}"])
    return (1 - lost) * ((1 - s) * y + s * b[f"m_{tag}"]) + b[f"bias_{tag}"] + b[f"noise_{tag}"] * b[f"n_fault_{tag}"]
