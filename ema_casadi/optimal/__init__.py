"""Optimal control of the actuator itself (docs: optimal-control).

:func:`optimal_move` solves a minimum-time, minimum-energy (from the DC link) or
minimum-heat (in the winding) move of the rod by direct multiple shooting on the model's
smooth variant (:meth:`~ema_casadi.model.assembly.Model.smooth`) - or by direct
collocation (Radau IIA) where the model is too stiff for RK4 substeps (under load) -
with the model's
operating limits (:meth:`~ema_casadi.model.assembly.Model.operating_limits`) as the
constraints, and replays the resulting command profile in the full model beside the
ECU's own step. Two levels of control: ``through="drive"``, the motor voltages (the
drive's capability: the physical bound of the commissioned drive), and
``through="ecu"``, the rod command with the cascade in the loop (a command profile for
the real ECU). :func:`performance_envelope` tabulates the top rod speed against load,
the largest force held and the minimum move time over distance, at soak temperatures.
"""

from ._api import optimal_move, replay_window, settling_time
from ._envelope import Envelope, performance_envelope
from ._errors import Infeasible, OptimalError, Unresolved
from ._problem import INTERVALS, LEVELS, METHODS, OBJECTIVES, Problem, check_request, initial_guess, rk4_substeps, solve
from ._result import STAIR, OptimalMove

__all__ = ["optimal_move", "performance_envelope", "Envelope", "OptimalMove", "OptimalError", "Infeasible",
           "Unresolved", "OBJECTIVES", "LEVELS", "METHODS", "INTERVALS", "STAIR", "Problem", "check_request", "solve",
           "rk4_substeps", "initial_guess", "replay_window", "settling_time"]
