"""Components: pure symbolic functions, one module per family (SPEC §2).

controller (ECU), inverter (power electronics), motor, ballscrew, friction.
Each function maps CasADi symbols (states, inputs, parameters) to derivatives and
outputs; none of them knows about the others. :mod:`ema_casadi.assembly` wires them.
"""

from . import ballscrew, controller, friction, inverter, motor

__all__ = ["ballscrew", "controller", "friction", "inverter", "motor"]
