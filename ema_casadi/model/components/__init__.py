"""Components: one module per family, each variant a *part* (docs: physics).

controller (the ECU's loops: the outer loops and the current controllers the motors bring), sensor
(what the ECU reads), motor (windings and torque),
inverter (power electronics), ballscrew (drive-train mechanics), friction, endstop,
thermal, supply, faults (fault injection), monitors (the ECU's fault detection). A part declares its
states, inputs, outputs, parameters and loops next to its equations
(:mod:`~ema_casadi.model.components._part`); :data:`REGISTRY` maps every variant key and value
to its part; :mod:`ema_casadi.model.assembly` composes the chosen parts by signal name.
"""

from . import (
    airframe,
    ballscrew,
    controller,
    endstop,
    faults,
    friction,
    inverter,
    load,
    monitors,
    motor,
    sensor,
    supply,
    thermal,
)
from ._part import (
    HEAT_NODES,
    INPUT_KINDS,
    INPUT_ROLES,
    MARGIN,
    OUTPUT_KINDS,
    OUTPUT_ROLES,
    POLICIES,
    RATING_SENSES,
    SIGNAL_KEYS,
    AssemblyError,
    Bound,
    Bus,
    Fault,
    Freeze,
    Gain,
    Hold,
    Input,
    Limit,
    Loop,
    Node,
    Output,
    Part,
    Rating,
    Seed,
    State,
    der,
    heat_signal,
    node_outflow,
)
from ._ports import Connection, Port
from ._registry import (
    DEFAULT_VARIANTS,
    OPTIONS,
    PART_CLASSES,
    REGISTRY,
    VARIANTS,
    VariantError,
    parts_for,
    served_by,
    validate_variants,
)
from .monitors import TAU_LATCH, TAU_RESET

__all__ = [
    "airframe", "ballscrew", "controller", "endstop", "faults", "friction", "inverter", "load", "monitors", "motor",
    "sensor", "supply", "thermal",
    "INPUT_KINDS", "OUTPUT_KINDS", "INPUT_ROLES", "OUTPUT_ROLES", "SIGNAL_KEYS",
    "MARGIN", "POLICIES", "AssemblyError", "Bound", "Fault", "Freeze", "Gain", "Limit", "Rating", "RATING_SENSES",
    "Seed", "Bus", "Hold", "Input", "Loop", "Output",
    "Part", "State", "der", "Port", "Connection",
    "HEAT_NODES", "heat_signal", "Node", "node_outflow",
    "DEFAULT_VARIANTS", "OPTIONS", "REGISTRY", "VARIANTS", "VariantError", "parts_for", "validate_variants",
    "PART_CLASSES", "served_by",
    # the monitors' timer reset and latch time constants (s): what a statistic's detection obeys
    "TAU_RESET", "TAU_LATCH",
]
