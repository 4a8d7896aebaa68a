"""The ``[sensor]``, ``[fault]`` and ``[monitor]`` parameter tables, SI inside.

Read by the real sensors (``sensor = "real"``), the fault-injection part (``faults =
"on"``) and the ECU monitors (``monitors = "on"``). Every key has its default, so
parameter files without these tables load unchanged; the defaults are the reference
values of the guide (estimates for a CESA-class actuator, stated there).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

__all__ = ["Sensor", "FaultModel", "Monitor", "FaultTables", "FAULT_GROUPS"]


def _d(unit: str, check: str, doc: str, default: float):
    return field(default=default, metadata={"unit": unit, "check": check, "doc": doc, "default": default})


_POS, _NONNEG, _FLAG, _TEMP, _REAL = "positive", "non-negative", "switch", "temperature", "real"
_WHOLE = "whole number"  # params.WHOLE (that module imports this one)


@dataclass(frozen=True)
class Sensor:
    """Rod position sensor (LVDT), motor angle sensor (resolver), phase-current sensors."""

    k_g_x: float = _d("1", _REAL, "LVDT gain error: x_s = (1 + k_g_x) x + ... (-)", 0.0)
    b_x: float = _d("m", _REAL, "LVDT bias (m)", 0.0)
    sigma_x: float = _d("m", _NONNEG, "LVDT white noise, standard deviation per position-loop sample (m)", 3e-7)
    q_x: float = _d("m", _NONNEG, "LVDT quantisation step (m); 0: none", 5e-7)
    tau_x: float = _d("s", _POS, "LVDT first-order lag (s); 1/(2 pi 1 kHz)", 1.0 / (2 * math.pi * 1000.0))
    N_theta: float = _d("1", _WHOLE, "resolver resolution, bits per mechanical revolution; 0: unquantised", 16.0)
    sigma_theta: float = _d("rad", _NONNEG, "resolver angle noise, standard deviation per speed-loop sample (rad)",
                            2e-4)
    k_g_i: float = _d("1", _REAL, "phase-current sensor gain error (-)", 0.0)
    b_i: float = _d("A", _REAL, "phase-current sensor offset, phase a (A)", 0.0)
    sigma_i: float = _d("A", _NONNEG, "phase-current noise, standard deviation per current-loop sample (A)", 0.05)
    q_i: float = _d("A", _NONNEG, "phase-current quantisation step (A): 12 bit over +-2 I_max", 4 * 24.0 / 4096)
    noise_seed: float = _d("1", _WHOLE, "seed of the sensor-noise sequences (a whole number)", 0.0)


@dataclass(frozen=True)
class FaultModel:
    """Models of the injected faults (the schedule itself is a fault file)."""

    k_jam: float = _d("N/m", _POS, "jam: stiffness of the lock at the onset position (N/m)", 2e8)
    d_jam: float = _d("N*s/m", _NONNEG, "jam: damping of the lock (N s/m)", 2e4)
    R_open: float = _d("Ohm", _POS, "bridge off: resistance the open windings see below the diode clamp (Ohm)",
                       100.0)
    tau_hold: float = _d("s", _POS, "time constant of the onset memories (jam anchor, stuck sensor) (s)", 1e-3)
    R_f: float = _d("Ohm", _POS, "winding short: resistance of the short across the shorted turns (Ohm)", 0.05)
    L_f: float = _d("H", _POS, "winding short: leakage inductance of the shorted loop per unit shorted fraction (H)",
                    5e-4)


@dataclass(frozen=True)
class Monitor:
    """ECU monitors: thresholds, confirmation times, reactions."""

    e_track: float = _d("m", _POS, "tracking monitor: |x_model - x_s| threshold (m)", 1.0e-3)
    t_track: float = _d("s", _POS, "tracking monitor: confirmation time (s)", 0.05)
    k_jam_i: float = _d("1", _POS, "jam monitor: |i_q| >= k_jam_i I_max (-)", 0.95)
    w_jam: float = _d("rad/s", _POS, "jam monitor: |omega_s| below this speed (rad/s)", 5.0)
    t_jam: float = _d("s", _POS, "jam monitor: confirmation time (s)", 0.02)
    e_cross: float = _d("m", _POS, "rod-motor cross-check: margin over B/2 + F/C (m)", 1.0e-4)
    t_cross: float = _d("s", _POS, "rod-motor cross-check: confirmation time (s)", 0.01)
    k_oc: float = _d("1", _POS, "over-current monitor: |i_dq| > k_oc I_max (-)", 1.25)
    t_oc: float = _d("s", _POS, "over-current monitor: confirmation time (s)", 0.005)
    T_ot: float = _d("degC", _TEMP, "over-temperature monitor: winding threshold (degC)", 170.0)
    t_ot: float = _d("s", _POS, "over-temperature monitor: confirmation time (s)", 1.0)
    react_track: float = _d("1", _FLAG, "1: a latched tracking monitor switches the bridge off", 0.0)
    react_jam: float = _d("1", _FLAG, "1: a latched jam monitor switches the bridge off", 0.0)
    react_cross: float = _d("1", _FLAG, "1: a latched cross-check switches the bridge off", 0.0)
    react_oc: float = _d("1", _FLAG, "1: a latched over-current monitor switches the bridge off", 0.0)
    react_ot: float = _d("1", _FLAG, "1: a latched over-temperature monitor switches the bridge off", 0.0)


#: The tables of this module by name (entries of ``params.GROUPS``).
FAULT_GROUPS = {"sensor": Sensor, "fault": FaultModel, "monitor": Monitor}


@dataclass(frozen=True, kw_only=True)
class FaultTables:
    """The groups of this module as fields of :class:`~ema_casadi.model.params.Parameters`
    (keyword-only, defaulted: a parameter file without the tables loads unchanged)."""

    sensor: Sensor = field(default_factory=Sensor)
    fault: FaultModel = field(default_factory=FaultModel)
    monitor: Monitor = field(default_factory=Monitor)
