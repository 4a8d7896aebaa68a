"""Parameter sets: TOML file -> typed, validated, SI-unit objects (docs: physics).

A parameter file holds one table per group (``[screw]``, ``[friction]``, ``[motor]``,
``[power]``, ``[control]``, ``[thermal]``, ``[actuator]``) and an optional ``[model]``
table with the default variants. Every value carries its unit, which must be the SI
unit the schema names::

    [screw]
    p = { value = 5.0e-3, unit = "m" }   # lead per revolution

Names are the physics reference's symbols. Inside the toolkit the parameters travel as one flat
numeric vector (:meth:`Parameters.vector`) so that the assembled CasADi Function takes
them as an input: changing a value never rebuilds a model.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from .._util._checks import describe, number, read_toml
from .._util._checks import nearest as _nearest
from .._util._errors import InputError
from .._util._files import write_text
from .._util._notebook import Summarised
from ._param_units import absent as _absent
from ._param_units import raw_value
from ._relations import check_relations

__all__ = ["ParameterError", "UnknownParameterError", "Parameters", "load_parameters", "GROUPS", "checked",
           "checked_rule", "TEMP", "FLAG"]


class ParameterError(InputError, ValueError):
    """A parameter file or variant choice is invalid (one line: the file, the key, what was expected)."""


class UnknownParameterError(ParameterError, TypeError):
    """A keyword naming no parameter (:meth:`Parameters.vector`, :meth:`Parameters.replace`):
    a ParameterError like any bad parameter, a TypeError like any unexpected keyword."""


# Value checks ---------------------------------------------------------------------
POS = "positive"  # > 0
NONNEG = "non-negative"  # >= 0
FRAC = "fraction"  # 0 < x <= 1
SFRAC = "signed fraction"  # -1 <= x <= 1, not 0
INT = "positive integer"
WHOLE = "whole number"  # 0, 1, 2, ... (a seed, a count of bits)
NONPOS = "non-positive"  # <= 0
FLAG = "switch"  # 0 or 1 (false or true)
TEMP = "temperature"  # degC, above absolute zero
REAL = "real"  # any finite number (a signed coefficient)

#: Length of a table parameter in the flat vector (2..TABLE_MAX points, padded: :func:`_pad`).
TABLE_MAX = 6


def _p(unit: str, check: str, doc: str, default=None, table: bool = False):
    """A parameter field. ``default``: the value taken when a file lacks the key (keys added
    after files were written); ``table``: a list of 2 to TABLE_MAX values, each checked."""
    meta = {"unit": unit, "check": check, "doc": doc, **({} if default is None else {"default": default})}
    return field(metadata={**meta, "table": True} if table else meta)


@dataclass(frozen=True)
class Actuator:
    """Actuator envelope (paper Table 1)."""

    stroke: float = _p("m", POS, "half stroke: the rod travels +-stroke (m)")
    v_rod_max: float = _p("m/s", POS, "rated rod speed, the ball screw's speed limit (2400 rpm of a 5 mm lead) (m/s)",
                          default=0.2)


@dataclass(frozen=True)
class Screw:
    """Ballscrew (docs: physics)."""

    p: float = _p("m", POS, "lead, rod travel per screw revolution (m)")
    eta: float = _p("1", FRAC, "direct efficiency, motor drives the load (-)")
    eta_inv: float = _p("1", FRAC, "inverse efficiency, load back-drives the motor (-)")
    J_s: float = _p("kg*m^2", NONNEG, "screw rotating inertia (kg m^2)")
    M: float = _p("kg", POS, "rod + nut mass (kg)")
    C: float = _p("N/m", POS, "drive-train axial stiffness (N/m)")
    c_c: float = _p("N*s/m", NONNEG, "contact damping, acts only in contact (N s/m)")
    B: float = _p("m", NONNEG, "backlash, total gap (m)")
    P_blend: float = _p("W", NONNEG, "width of the efficiency switch in transmitted power; 0: the exact switch (W)",
                        default=0.1)
    x_lock: float = _p("m", NONNEG, "self-locking memory: pre-sliding travel at the rod; 0: blend (m)", default=1e-6)


@dataclass(frozen=True)
class Friction:
    """Friction (docs: physics)."""

    F_seal: float = _p("N", NONNEG, "seal friction force (N)")
    C_bear: float = _p("m", NONNEG, "thrust-bearing torque per axial load (m)")
    c_v: float = _p("N*s/m", NONNEG, "rod viscous friction (N s/m)")
    b_m: float = _p("N*m*s/rad", NONNEG, "motor-shaft viscous friction (N m s/rad)")
    r_start: float = _p("1", POS, "breakaway ratio F_start/F_r (-)")
    v_s: float = _p("m/s", POS, "smoothing velocity of the smooth variant (m/s)")
    eps: float = _p("m/s", POS, "stick dead band of the hybrid variant (m/s)")
    v_st: float = _p("m/s", POS, "Stribeck velocity of the optional hump and of the LuGre curve (m/s)")
    delta_st: float = _p("1", POS, "Stribeck shape exponent: the hump decays as exp(-(|v|/v_st)^delta_st); 2 Gaussian, "
                         "1 exponential (-)", default=2.0)
    sigma_0: float = _p("N/m", POS, "LuGre bristle stiffness: pre-sliding deflection F/sigma_0 (N/m)", default=1.0e7)
    sigma_1: float = _p("N*s/m", NONNEG, "LuGre bristle damping (N s/m)", default=5.0e3)


@dataclass(frozen=True)
class Motor:
    """PMSM, rotor dq frame, amplitude-invariant (docs: physics)."""

    pp: float = _p("1", INT, "pole pairs (-)")
    psi: float = _p("Wb", POS, "permanent-magnet flux linkage (Wb)")
    R: float = _p("Ohm", POS, "phase resistance at T_ref (Ohm)")
    alpha_Cu: float = _p("1/K", NONNEG, "copper temperature coefficient (1/K)")
    L_d: float = _p("H", POS, "d-axis inductance (H)")
    L_q: float = _p("H", POS, "q-axis inductance (H)")
    J_m: float = _p("kg*m^2", POS, "rotor inertia (kg m^2)")
    I_max: float = _p("A", POS, "current limit, peak (A)")
    k_h: float = _p("W/(Hz*Wb^2)", NONNEG, "iron loss, hysteresis coefficient: k_h f_e psi^2 (W/(Hz Wb^2))",
                    default=1.6)
    k_e: float = _p("W/(Hz*Wb)^2", NONNEG, "iron loss, eddy-current coefficient: k_e (f_e psi)^2 (W/(Hz Wb)^2)",
                    default=0.016)


@dataclass(frozen=True)
class Power:
    """Inverter and supply (docs: physics)."""

    V_dc: float = _p("V", POS, "DC-link (supply) voltage (V); MIL-STD-704F normal range 250-280 V")
    k_v: float = _p("1", FRAC, "voltage-limit factor on V_dc/sqrt(3) (-)")
    f_sw: float = _p("Hz", POS, "switching frequency (Hz)")
    V_CE0: float = _p("V", NONNEG, "IGBT threshold voltage (V)")
    r_CE: float = _p("Ohm", NONNEG, "IGBT slope resistance (Ohm)")
    V_F0: float = _p("V", NONNEG, "diode threshold voltage (V)")
    r_F: float = _p("Ohm", NONNEG, "diode slope resistance (Ohm)")
    E_sw: float = _p("J", NONNEG, "E_on + E_off at the reference point (J)")
    V_sw_ref: float = _p("V", POS, "reference voltage of E_sw (V)")
    I_sw_ref: float = _p("A", POS, "reference current of E_sw (A)")
    t_dead: float = _p("s", NONNEG, "dead time (s)")
    R_line: float = _p("Ohm", POS, "supply = line: resistance, source to DC link (Ohm)", default=0.1)
    L_line: float = _p("H", POS, "supply-line inductance, source to DC link (H)", default=20e-6)
    C_dc: float = _p("F", POS, "DC-link capacitance (F)", default=200e-6)


@dataclass(frozen=True)
class Control:
    """Cascade controller (docs: physics)."""

    K_p_i: float = _p("V/A", POS, "current-loop proportional gain (V/A)")
    K_i_i: float = _p("V/(A*s)", POS, "current-loop integral gain (V/(A s))")
    K_p_w: float = _p("A*s/rad", POS, "speed-loop proportional gain (A/(rad/s))")
    T_i_w: float = _p("s", POS, "speed-loop integral time (s)")
    K_x: float = _p("1/s", POS, "position-loop gain: rod-speed command per error (1/s)")
    K_i_x: float = _p("1/s^2", NONNEG, "position-loop integral gain, PI variant (1/s^2)")
    v_max: float = _p("m/s", POS, "rod rate limit (m/s)")
    f_s_i: float = _p("Hz", POS, "current-loop sample rate (Hz)")
    f_s_w: float = _p("Hz", POS, "speed-loop sample rate (Hz)")
    f_s_x: float = _p("Hz", POS, "position-loop sample rate (Hz)")
    w_aw: float = _p("1", SFRAC, "clamping anti-windup band, fraction of the output limit: > 0 above the limit, "
                                 "< 0 below it (-)", default=0.01)
    k_bc: float = _p("1", POS, "back-calculation tracking rate in units of K_i/K_p (-)", default=1.0)
    w_knee: float = _p("1", FRAC, "smooth limit's knee half-width, fraction of the limit (-)", default=0.05)


@dataclass(frozen=True)
class Thermal:
    """Lumped thermal network (docs: physics)."""

    C_th_w: float = _p("J/K", POS, "winding heat capacity (J/K)")
    R_th_ws: float = _p("K/W", POS, "winding-to-stator thermal resistance (K/W)")
    C_th_h: float = _p("J/K", POS, "housing heat capacity (J/K)")
    R_th_ha: float = _p("K/W", POS, "housing-to-ambient thermal resistance (K/W)")
    C_th_s: float = _p("J/K", POS, "screw heat capacity (J/K)")
    R_th_sh: float = _p("K/W", POS, "screw-to-housing thermal resistance (K/W)")
    C_th_inv: float = _p("J/K", POS, "inverter heat-sink heat capacity (J/K)", default=400.0)
    R_th_inv: float = _p("K/W", POS, "inverter heat-sink-to-ambient thermal resistance (K/W)", default=0.25)
    alpha_psi: float = _p("1/K", NONPOS, "magnet-flux temperature coefficient (1/K), rotor at T_h", default=-1.2e-3)
    T_ref: float = _p("degC", TEMP, "reference temperature of R and psi (degC)", default=20.0)
    T_eta: tuple = _p("degC", TEMP, "temperatures of the screw-efficiency table, increasing (degC)",
                      default=(-55.0, -20.0, 20.0, 80.0), table=True)
    eta_T: tuple = _p("1", FRAC, "screw direct efficiency at T_eta (-); eta_inv follows shifted by eta_inv - eta",
                      default=(0.80, 0.86, 0.90, 0.91), table=True)
    feedback_R: float = _p("1", FLAG, "1: winding resistance R(T_w) (alpha_Cu); 0: R at T_ref", default=1.0)
    feedback_psi: float = _p("1", FLAG, "1: magnet flux psi(T_h) (alpha_psi); 0: psi at T_ref", default=1.0)
    feedback_eta: float = _p("1", FLAG, "1: screw efficiency from the table at T_s; 0: the eta input", default=1.0)
    T_max_w: float = _p("degC", TEMP, "winding insulation limit, e.g. class H 180 degC (degC)", default=180.0)


@dataclass(frozen=True)
class EndStop:
    """Stroke end stops (docs: physics), used by ``endstop = "elastic"``."""

    k_stop: float = _p("N/m", POS, "end-stop stiffness (N/m)")
    d_stop: float = _p("N*s/m", NONNEG, "end-stop damping, in contact only (N s/m)")


@dataclass(frozen=True)
class Load:
    """The load on the rod besides f_ext, used by ``load = "aero_spring"``."""

    k_aero: float = _p("N/m", NONNEG, "surface hinge-moment stiffness referred to the rod (N/m)", default=1.0e5)


# The optional tables --------------------------------------------------------------
def _opt(unit: str, check: str, doc: str, default: float):
    """A field of an optional table: its default a dataclass default too (the table may be absent)."""
    return field(default=default, metadata={"unit": unit, "check": check, "doc": doc, "default": default})


# [sensor], [fault], [monitor]: read by the real sensors (sensor = "real"), the
# fault-injection part (faults = "on") and the ECU monitors (monitors = "on"); the
# defaults are the reference values of the guide (estimates for a CESA-class actuator).
@dataclass(frozen=True)
class Sensor:
    """Rod position sensor (LVDT), motor angle sensor (resolver), phase-current sensors."""

    k_g_x: float = _opt("1", REAL, "LVDT gain error: x_s = (1 + k_g_x) x + ... (-)", 0.0)
    b_x: float = _opt("m", REAL, "LVDT bias (m)", 0.0)
    sigma_x: float = _opt("m", NONNEG, "LVDT white noise, standard deviation per position-loop sample (m)", 3e-7)
    q_x: float = _opt("m", NONNEG, "LVDT quantisation step (m); 0: none", 5e-7)
    tau_x: float = _opt("s", POS, "LVDT first-order lag (s); 1/(2 pi 1 kHz)", 1.0 / (2 * math.pi * 1000.0))
    N_theta: float = _opt("1", WHOLE, "resolver resolution, bits per mechanical revolution; 0: unquantised", 16.0)
    sigma_theta: float = _opt("rad", NONNEG, "resolver angle noise, standard deviation per speed-loop sample (rad)",
                            2e-4)
    k_g_i: float = _opt("1", REAL, "phase-current sensor gain error (-)", 0.0)
    b_i: float = _opt("A", REAL, "phase-current sensor offset, phase a (A)", 0.0)
    sigma_i: float = _opt("A", NONNEG, "phase-current noise, standard deviation per current-loop sample (A)", 0.05)
    q_i: float = _opt("A", NONNEG, "phase-current quantisation step (A): 12 bit over +-2 I_max", 4 * 24.0 / 4096)
    noise_seed: float = _opt("1", WHOLE, "seed of the sensor-noise sequences (a whole number)", 0.0)


@dataclass(frozen=True)
class FaultModel:
    """Models of the injected faults (the schedule itself is a fault file)."""

    k_jam: float = _opt("N/m", POS, "jam: stiffness of the lock at the onset position (N/m)", 2e8)
    d_jam: float = _opt("N*s/m", NONNEG, "jam: damping of the lock (N s/m)", 2e4)
    R_open: float = _opt("Ohm", POS, "bridge off: resistance the open windings see below the diode clamp (Ohm)",
                       100.0)
    tau_hold: float = _opt("s", POS, "time constant of the onset memories (jam anchor, stuck sensor) (s)", 1e-3)
    R_f: float = _opt("Ohm", POS, "winding short: resistance of the short across the shorted turns (Ohm)", 0.05)
    L_f: float = _opt("H", POS, "winding short: leakage inductance of the shorted loop per unit shorted fraction (H)",
                    5e-4)


@dataclass(frozen=True)
class Monitor:
    """ECU monitors: thresholds, confirmation times, reactions."""

    e_track: float = _opt("m", POS, "tracking monitor: |x_model - x_s| threshold (m)", 1.0e-3)
    t_track: float = _opt("s", POS, "tracking monitor: confirmation time (s)", 0.05)
    k_jam_i: float = _opt("1", POS, "jam monitor: |i_q| >= k_jam_i I_max (-)", 0.95)
    w_jam: float = _opt("rad/s", POS, "jam monitor: |omega_s| below this speed (rad/s)", 5.0)
    t_jam: float = _opt("s", POS, "jam monitor: confirmation time (s)", 0.02)
    e_cross: float = _opt("m", POS, "rod-motor cross-check: margin over B/2 + F/C (m)", 1.0e-4)
    t_cross: float = _opt("s", POS, "rod-motor cross-check: confirmation time (s)", 0.01)
    k_oc: float = _opt("1", POS, "over-current monitor: |i_dq| > k_oc I_max (-)", 1.25)
    t_oc: float = _opt("s", POS, "over-current monitor: confirmation time (s)", 0.005)
    T_ot: float = _opt("degC", TEMP, "over-temperature monitor: winding threshold (degC)", 170.0)
    t_ot: float = _opt("s", POS, "over-temperature monitor: confirmation time (s)", 1.0)
    react_track: float = _opt("1", FLAG, "1: a latched tracking monitor switches the bridge off", 0.0)
    react_jam: float = _opt("1", FLAG, "1: a latched jam monitor switches the bridge off", 0.0)
    react_cross: float = _opt("1", FLAG, "1: a latched cross-check switches the bridge off", 0.0)
    react_oc: float = _opt("1", FLAG, "1: a latched over-current monitor switches the bridge off", 0.0)
    react_ot: float = _opt("1", FLAG, "1: a latched over-temperature monitor switches the bridge off", 0.0)


#: The sensor, fault and monitor tables by name (entries of :data:`GROUPS`).
FAULT_GROUPS = {"sensor": Sensor, "fault": FaultModel, "monitor": Monitor}


@dataclass(frozen=True, kw_only=True)
class FaultTables:
    """The sensor, fault and monitor groups as fields of :class:`Parameters` (keyword-only,
    defaulted: a parameter file without the tables loads unchanged)."""

    sensor: Sensor = field(default_factory=Sensor)
    fault: FaultModel = field(default_factory=FaultModel)
    monitor: Monitor = field(default_factory=Monitor)


# [airframe] (docs: physics): read by the airframe parts (airframe = "transport" | "b747"):
# the Stevens & Lewis medium transport (Aircraft Control and Simulation, 2nd ed., §3.6,
# converted from US units with ft = 0.3048 m, slug = 14.5939 kg, lbf = 4.44822 N,
# coefficients per rad), the elevator surface and horn (§3), the pitch flight-control law
# (§4) and the flight condition trimmed for. Every key has its default.
@dataclass(frozen=True)
class Airframe:
    """Aircraft, surface and flight-control law (used by ``airframe != "none"``)."""

    S_w: float = _opt("m^2", "positive", "wing area (2170 ft^2)", 201.5995968)
    c_w: float = _opt("m", "positive", "mean aerodynamic chord (17.5 ft)", 5.334)
    m_ac: float = _opt("kg", "positive", "aircraft mass (5000 slug)", 72969.51468603182)
    I_yy: float = _opt("kg*m^2", "positive", "pitch inertia (4.1e6 slug ft^2)", 5558853.588158742)
    T_stat: float = _opt("N", "positive", "static thrust (6e4 lbf)", 266893.29691563)
    dT_dV: float = _opt("N*s/m", "non-positive", "thrust lapse with airspeed (-38 lbf/(ft/s))", -554.5683116138417)
    z_E: float = _opt("m", REAL, "thrust moment arm (2 ft)", 0.6096)
    C_L_a: float = _opt("1/rad", "positive", "lift slope (0.085 /deg)", 4.870141258611998)
    C_m_a: float = _opt("1/rad", REAL, "pitch stiffness (-0.022 /deg)", -1.260507149287811)
    C_m_de: float = _opt("1/rad", REAL, "elevator power (-0.016 /deg)", -0.9167324722093172)
    C_m_q: float = _opt("1/rad", REAL, "pitch damping", -16.0)
    C_m_ad: float = _opt("1/rad", REAL, "alpha-dot damping", -6.0)
    C_L_ad: float = _opt("1/rad", REAL, "alpha-dot lift", 0.0)
    C_D_cls: float = _opt("1", "non-negative", "induced-drag factor", 0.042)
    x_cg: float = _opt("1", "fraction", "centre of gravity, fraction of the chord", 0.25)
    C_L0: float = _opt("1", REAL, "lift at zero alpha (clean 0.20, landing 1.0)", 0.20)
    C_D0: float = _opt("1", "non-negative", "zero-lift drag (clean 0.016, landing 0.08)", 0.016)
    C_m0: float = _opt("1", REAL, "pitch moment at zero alpha (clean 0.05, landing -0.20)", 0.05)
    dC_D: float = _opt("1", "non-negative", "gear drag increment (landing 0.02)", 0.0)
    dC_m: float = _opt("1", REAL, "gear pitch-moment increment (landing -0.05)", 0.0)
    g_0: float = _opt("m/s^2", "positive", "gravity (32.17 ft/s^2)", 9.805416)
    r_horn: float = _opt("m", "positive", "elevator horn length r", 0.15)
    a_pin: float = _opt("m", "positive", "hinge to actuator pin distance a (rod perpendicular to the horn at neutral)",
                      1.0)
    S_c_e: float = _opt("m^3", "positive", "elevator area x chord S_e c_e", 3.5)
    C_h0: float = _opt("1", REAL, "hinge moment at zero alpha and deflection", 0.0)
    C_h_a: float = _opt("1/rad", REAL, "hinge-moment slope with alpha", -0.3)
    C_h_d: float = _opt("1/rad", REAL, "hinge-moment slope with deflection", -0.5)
    J_e: float = _opt("kg*m^2", "non-negative", "surface inertia about the hinge", 15.0)
    K_q: float = _opt("s", "non-negative", "pitch-rate gain of the flight-control law", 1.0)
    K_th: float = _opt("1", "non-negative", "pitch-attitude gain", 2.0)
    K_ith: float = _opt("1/s", "non-negative", "pitch-attitude integral gain", 0.5)
    f_s_a: float = _opt("Hz", "positive", "flight-control computer rate (sampled law)", 80.0)
    V_0: float = _opt("m/s", "positive", "trim airspeed (500 ft/s)", 152.4)
    h_0: float = _opt("m", "non-negative", "trim altitude", 0.0)


GROUPS: dict[str, type] = {
    "actuator": Actuator,
    "screw": Screw,
    "friction": Friction,
    "motor": Motor,
    "power": Power,
    "control": Control,
    "thermal": Thermal,
    "endstop": EndStop,
    "load": Load,
    "airframe": Airframe, **FAULT_GROUPS,  # the aircraft loop, sensors, faults, monitors: optional tables
}

#: Loop-closure flags (the paper's "Gain = 1" block), appended to the numeric
#: parameter vector: 1 closes the loop, 0 opens it at the feedback signal.
LOOP_FLAGS = ("loop_x", "loop_w", "loop_i", "loop_a")


def _unknown(func: str, key: str, names) -> str:
    return f"{func}() got an unexpected keyword argument '{key}': no parameter of that name{_nearest(key, names)}"


def _variant_table(model, src: str) -> dict[str, str]:
    """The [model] table: variant key -> value names (checked against the registry of
    parts when a model is built)."""
    if not isinstance(model, dict):
        raise ParameterError(f"{src}: [model] must be a table of variant names")
    for k, v in model.items():
        if not isinstance(v, str):
            raise ParameterError(f"{src}: [model] {k} must be a variant name (a string), got {v!r}")
    return dict(model)


@dataclass(frozen=True, repr=False)
class Parameters(Summarised, FaultTables):
    """A complete, validated parameter set in SI units.

    Attributes are the groups (``params.screw.p``); :meth:`vector` flattens them in
    :meth:`names` order for the CasADi model's parameter input.

    Attributes
    ----------
    actuator, screw, friction, motor, power, control, thermal, endstop, load, airframe, sensor, fault, monitor : object
        The parameter groups of :data:`GROUPS`, each value in the SI unit its field
        declares (:meth:`units`).
    variants : dict
        The default variant choice of the set (its ``[model]`` table).
    source : str
        Where the set came from (a file path), named in error messages.
    overrides : tuple of str
        Variant keys given by ``load_parameters(variants=...)`` (a wrong one is blamed there).
    missing : tuple of str
        Tables the file lacks (NaN values): ``build_model`` names one its variants read.
    system : dict
        The ``[instances]``, ``[surface]`` and ``[equaliser]`` tables of a model of several
        actuators on one surface, as read ({} for one actuator): checked by ``build_model``.
    """

    actuator: Actuator
    screw: Screw
    friction: Friction
    motor: Motor
    power: Power
    control: Control
    thermal: Thermal
    endstop: EndStop
    airframe: Airframe = Airframe()
    load: Load = Load(k_aero=1.0e5)
    variants: dict[str, str] = field(default_factory=dict)
    source: str = "<memory>"
    missing: tuple = ()
    overrides: tuple = ()
    #: The tables of a model of several actuators (``[instances]``, ``[surface]``,
    #: ``[equaliser]``), as read: checked when the model is built (docs: dual actuators).
    system: dict = field(default_factory=dict)

    def _facts(self) -> dict:
        return {"source": Path(self.source).name, "parameters": len(self.names()),
                "variants": ", ".join(f"{k}={v}" for k, v in self.variants.items()) or None,
                "missing": ", ".join(self.missing) or None}

    # -- flat view ---------------------------------------------------------------
    @staticmethod
    def names() -> list[str]:
        """Flat parameter names (the physics reference's symbols), then the loop-closure flags. A table
        parameter ``T_eta`` is ``T_eta_0`` ... ``T_eta_5`` (:data:`TABLE_MAX` entries)."""
        out = [n for cls in GROUPS.values() for f in fields(cls) for n in _flat_names(f)]
        return out + list(LOOP_FLAGS)

    @staticmethod
    def group_of() -> dict[str, str]:
        """Flat parameter name -> the table it belongs to (``"B"`` -> ``"screw"``)."""
        return {n: g for g, cls in GROUPS.items() for f in fields(cls) for n in _flat_names(f)}

    @staticmethod
    def units() -> dict[str, str]:
        """SI unit of every flat parameter."""
        out = {n: f.metadata["unit"] for cls in GROUPS.values() for f in fields(cls) for n in _flat_names(f)}
        out.update({k: "1" for k in LOOP_FLAGS})
        return out

    def as_dict(self) -> dict[str, float]:
        """Flat name -> value (SI), loop flags closed (1.0); tables padded (:func:`_pad`)."""
        out = {}
        for g in GROUPS:
            grp = getattr(self, g)
            for f in fields(grp):
                val = getattr(grp, f.name)
                if f.metadata.get("table"):
                    out.update(zip(_flat_names(f), _pad(val, f.metadata["check"] == TEMP), strict=True))
                else:
                    out[f.name] = float(val)
        out.update({k: 1.0 for k in LOOP_FLAGS})
        return out

    def vector(self, **overrides: float) -> np.ndarray:
        """Flat numeric vector for the model's ``p`` input (with ``[instances]``: the model
        of several actuators' vector, each instance's copies after the shared names).

        Parameters
        ----------
        **overrides : float
            Values by flat name (SI); an unknown name raises :class:`UnknownParameterError`.
        """
        if self.system:  # several actuator instances: the model's whole vector
            return SYSTEM_HOOKS["vector"](self, **overrides)
        d = self.as_dict()
        for k, v in overrides.items():
            if k not in d:
                raise UnknownParameterError(_unknown("Parameters.vector", k, d))
            d[k] = number(v, f"Parameters.vector: {k}", ParameterError, unit=self.units()[k])
        return np.array([d[n] for n in self.names()], dtype=float)

    def scalars(self) -> dict[str, tuple]:
        """Every scalar entry of the parameter vector of the model this set builds ->
        (nominal value (SI), unit, check): the groups' fields, and with ``[instances]``
        each instance's copies (``A.C``, ``B.x_rig``) and the surface's and equaliser's."""
        if self.system:
            return SYSTEM_HOOKS["scalars"](self)
        d = self.as_dict()
        return {f.name: (d[f.name], f.metadata["unit"], f.metadata["check"]) for cls in GROUPS.values()
                for f in fields(cls) if not f.metadata.get("table")}

    def replace(self, **values: float) -> Parameters:
        """A copy with some flat parameters changed (validated like a file).

        Parameters
        ----------
        **values : float
            New values by flat name (SI); an unknown name raises :class:`UnknownParameterError`.
        """
        raw = {g: {f.name: getattr(getattr(self, g), f.name) for f in fields(cls)} for g, cls in GROUPS.items()
               if g not in self.missing}
        flat_group = {f.name: g for g, cls in GROUPS.items() for f in fields(cls)}
        system = self.system
        if system:  # an instance's (A.C) or the surface's value goes into its table
            system = SYSTEM_HOOKS["replace"](self, {k: v for k, v in values.items() if k not in flat_group})
            values = {k: v for k, v in values.items() if k in flat_group}
        for k, v in values.items():
            if k not in flat_group:
                raise UnknownParameterError(_unknown("Parameters.replace", k, flat_group))
            raw[flat_group[k]][k] = v
        return replace(_build(raw, self.variants, self.source, plain=True), system=system)

    def to_toml(self, path: str | Path, header: str = "") -> Path:
        """Write the set as a parameter file (atomically: no half-written file).

        Parameters
        ----------
        path : str or Path
            The TOML file to write.
        header : str
            Text written as comment lines at the top.
        """
        lines = [f"# {line}" for line in header.splitlines()] if header else []
        lines += ["[model]"] + [f'{k} = "{v}"' for k, v in self.variants.items()]
        for g, cls in GROUPS.items():
            lines += ["", f"[{g}]"]
            for f in fields(cls):
                val = getattr(getattr(self, g), f.name)
                val = f"[{', '.join(repr(float(v)) for v in val)}]" if f.metadata.get("table") else repr(val)
                lines.append(f'{f.name} = {{ value = {val}, unit = "{f.metadata["unit"]}" }}'
                             f'  # {f.metadata["doc"]}')
        return write_text(path, "\n".join(lines) + "\n")

    # -- derived quantities used across the toolkit --------------------------------
    @property
    def K_t(self) -> float:
        """Torque constant 1.5*pp*psi (N m/A)."""
        return 1.5 * self.motor.pp * self.motor.psi


def _flat_names(f) -> list[str]:
    return [f"{f.name}_{i}" for i in range(TABLE_MAX)] if f.metadata.get("table") else [f.name]


def _pad(values, temperature: bool) -> list[float]:
    """A table padded to TABLE_MAX entries: values hold the last one; temperatures go
    on in 1 K steps past the last (so every padded interval has width 1 and adds nothing
    to a piecewise-linear interpolation)."""
    vals = [float(v) for v in values]
    last = vals[-1]
    return vals + [last + (k + 1 if temperature else 0.0) for k in range(TABLE_MAX - len(vals))]


def _check_table(where: str, meta: dict, value: Any) -> tuple:
    if not isinstance(value, (list, tuple)) or not 2 <= len(value) <= TABLE_MAX:
        raise ParameterError(f"{where}: expected a list of 2 to {TABLE_MAX} numbers, got {value!r}")
    item = {k: v for k, v in meta.items() if k != "table"}
    vals = tuple(_check_value(where, "", "", item, v, plain=True, bare=True) for v in value)
    if meta["check"] == TEMP and any(b <= a for a, b in zip(vals, vals[1:], strict=False)):
        raise ParameterError(f"{where}: temperatures must increase strictly, got {list(vals)}")
    return vals


def _check_value(src: str, group: str, name: str, meta: dict, raw: Any, plain: bool, bare: bool = False):
    where = src if bare else f"{src}: [{group}] {name}"
    unit = meta["unit"]
    value = raw if plain else raw_value(where, raw, unit, ParameterError)  # convertible units (_param_units)
    if meta.get("table"):
        return _check_table(where, meta, value)
    check = meta["check"]
    if check == FLAG and isinstance(value, bool):
        value = float(value)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ParameterError(f"{where}: expected a number, got {type(value).__name__} {value!r}")
    try:
        value = float(value)
    except OverflowError:
        raise ParameterError(f"{where}: expected a finite number, got an integer of {len(str(value))} digits") from None
    if not math.isfinite(value):
        raise ParameterError(f"{where}: expected a finite number, got {value}")
    if check == POS and not value > 0:
        raise ParameterError(f"{where}: must be positive, got {value}")
    if check == NONNEG and value < 0:
        raise ParameterError(f"{where}: must be non-negative, got {value}")
    if check == FRAC and not 0 < value <= 1:
        raise ParameterError(f"{where}: must be in (0, 1], got {value}")
    if check == SFRAC and not (-1 <= value <= 1 and value != 0):
        raise ParameterError(f"{where}: must be in [-1, 1] and not 0, got {value}")
    if check == INT and not (value >= 1 and value == int(value)):
        raise ParameterError(f"{where}: must be a positive integer, got {value}")
    if check == WHOLE and not (value >= 0 and value == int(value)):
        raise ParameterError(f"{where}: must be a whole number (0, 1, 2, ...), got {value:g}")
    if check == NONPOS and value > 0:
        raise ParameterError(f"{where}: must be zero or negative, got {value}")
    if check == FLAG and value not in (0.0, 1.0):
        raise ParameterError(f"{where}: must be 0 or 1 (false or true), got {value}")
    if check == TEMP and not value > -273.15:
        raise ParameterError(f"{where}: must be a temperature in degC above -273.15, got {value}")
    return value


#: Tables of a model of several actuators, read by the assembly (not flat parameters).
SYSTEM_TABLES = ("instances", "surface", "equaliser")
#: What a set with those tables delegates to the model layer's ``_system`` (which
#: registers ``vector``, ``scalars``, ``replace`` when it loads, with the assembly).
SYSTEM_HOOKS: dict = {}


def _build(data: dict, variants: dict | None, src: str, plain: bool = False) -> Parameters:
    unknown = set(data) - set(GROUPS) - {"model", *SYSTEM_TABLES}
    for g in sorted(unknown):
        raise ParameterError(f"{src}: unknown table [{g}]{_nearest(g, GROUPS)}; expected {', '.join(GROUPS)}")
    groups, missing = {}, []
    for g, cls in GROUPS.items():
        table = data.get(g, {} if all("default" in f.metadata for f in fields(cls)) else None)
        if table is None:  # only the variants that read it need it: named when one does (build_model)
            missing.append(g)
            groups[g] = cls(**{f.name: _absent(f) for f in fields(cls)})
            continue
        if not isinstance(table, dict):
            raise ParameterError(f"{src}: [{g}] must be a table")
        names = [f.name for f in fields(cls)]
        for key in table:
            if key not in names:
                raise ParameterError(f"{src}: [{g}] unknown key '{key}'{_nearest(key, names)}")
        values = {}
        for f in fields(cls):
            if f.name not in table and "default" in f.metadata:
                values[f.name] = f.metadata["default"]  # a key newer than the file
            elif f.name not in table:
                raise ParameterError(
                    f"{src}: [{g}] missing key '{f.name}' ({f.metadata['doc']}, unit {f.metadata['unit']})"
                )
            else:
                values[f.name] = _check_value(src, g, f.name, dict(f.metadata), table[f.name], plain)
        groups[g] = cls(**values)
    model = data.get("model", {}) if variants is None else variants
    merged = _variant_table(model, src)
    s = groups["screw"]
    if s.eta * s.eta_inv > 1:
        raise ParameterError(f"{src}: [screw] eta*eta_inv must not exceed 1 (got {s.eta * s.eta_inv:.3g})")
    if "thermal" not in missing:
        _check_eta_table(src, groups["thermal"], s)
    check_relations(src, groups, ParameterError, missing)
    return Parameters(**groups, variants=merged, source=src, missing=tuple(missing))


def _check_eta_table(src: str, th: Thermal, s: Screw) -> None:
    """The efficiency table: one efficiency per temperature, and the inverse efficiency
    it implies (shifted by eta_inv - eta) in (0, 1] at every point."""
    if len(th.eta_T) != len(th.T_eta):
        raise ParameterError(f"{src}: [thermal] eta_T has {len(th.eta_T)} values, T_eta {len(th.T_eta)}: "
                             "expected one efficiency per temperature")
    inv = [e + s.eta_inv - s.eta for e in th.eta_T]
    if not all(0 < v <= 1 for v in inv):
        raise ParameterError(f"{src}: [thermal] eta_T shifted by eta_inv - eta ({s.eta_inv - s.eta:+.3g}) "
                             f"gives inverse efficiencies {[round(v, 4) for v in inv]}, outside (0, 1]")


def load_parameters(path: str | Path | None = None, variants: dict[str, str] | None = None) -> Parameters:
    """Load and validate a parameter file.

    Parameters
    ----------
    path : str or Path, optional
        TOML parameter file (the layout of models/cesa_ema.toml), read as given (relative
        to the working folder); default the packaged reference set ``cesa_ema.toml``.
    variants : dict, optional
        Variant overrides on top of the file's ``[model]`` table.

    Raises
    ------
    ParameterError
        One-line message naming the file and key: unreadable file or not UTF-8 text (a
        UTF-8 byte-order mark is accepted), not TOML, missing or unknown table or key
        (with the nearest valid name), wrong type or unit, non-finite or out-of-range
        value, unknown variant.
    """
    if path is None:
        from .._util._resources import packaged_file

        path = packaged_file()
    if not isinstance(path, (str, Path)):
        raise ParameterError(f"path: expected a parameter file path (str or Path), got {describe(path)}")
    if variants is not None and not isinstance(variants, dict):
        raise ParameterError(f"variants: expected a dict of variant names, got {describe(variants)}")
    src = str(path)
    data = read_toml(path, "parameter file", ParameterError)
    merged = _variant_table(data.get("model", {}), src)
    given = _variant_table(variants or {}, "variants")
    merged.update(given)
    # the registry checks the names when a model is built, blaming the file or `variants`
    system = {k: data[k] for k in SYSTEM_TABLES if k in data}
    return replace(_build(data, merged, src), overrides=tuple(given), system=system)


# -- one flat value set from outside a file (a command-line flag) -----------------------
def checked(name: str, value, where: str | None = None) -> float:
    """``value`` (SI) for the flat parameter ``name``, checked as a parameter file's
    value is (a finite number in the field's range), else :class:`ParameterError`
    naming ``where``; a loop flag only as a finite number.

    Parameters
    ----------
    name : str
        Flat parameter name (``B``, ``K_i_x``, ``T_eta_2``); an unknown one raises
        :class:`UnknownParameterError`.
    value : float
        The value (SI).
    where : str, optional
        How to name it in the message (default the name; the command line passes its flag).
    """
    where = where or name
    rules = _rules()
    if name in LOOP_FLAGS:
        return number(value, where, ParameterError)
    if name not in rules:
        raise UnknownParameterError(_unknown("checked", name, rules))
    value = value.item() if isinstance(value, np.generic) else value
    return _check_value(where, "", "", rules[name], value, plain=True, bare=True)


@functools.cache
def _rules() -> dict:
    """Flat parameter name -> its field's rule (its metadata but the table), built once."""
    return {n: {k: v for k, v in f.metadata.items() if k != "table"}
            for cls in GROUPS.values() for f in fields(cls) for n in _flat_names(f)}


def is_parameter(name: str) -> bool:
    """Whether :func:`checked` knows ``name`` (a flat parameter or a loop flag)."""
    return name in LOOP_FLAGS or name in _rules()


def checked_rule(rule: str, value, where: str) -> float:
    """``value`` checked by a parameter rule as a file's value is, else ParameterError.

    Parameters
    ----------
    rule : str
        The rule (:data:`TEMP`: a temperature above absolute zero, :data:`FRAC` ...).
    value : float
        The value (SI).
    where : str
        How to name it in the message.
    """
    return _check_value(where, "", "", {"unit": "", "check": rule}, value, plain=True, bare=True)
