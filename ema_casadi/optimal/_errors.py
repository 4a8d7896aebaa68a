"""The three ways an optimal move is refused."""

from __future__ import annotations

from .._util._errors import InfeasibleError, RunError
from ..simulation import SimulationError

__all__ = ["OptimalError", "Infeasible", "Unresolved"]


class OptimalError(SimulationError):
    """A request that cannot be a move (beyond the stroke, a load the screw does not hold,
    a duration below the minimum time, an unknown objective): one line naming it."""


class Infeasible(InfeasibleError, RuntimeError):
    """IPOPT found no move within the limits; the message names the limit that binds.

    Parameters
    ----------
    message : str
        One line: the status and the binding limit.
    solution : dict, optional
        The last iterate (``t``, ``X``, ``C``, ``margins``, ``status``).
    """

    def __init__(self, message: str, solution: dict | None = None):
        super().__init__(message)
        self.solution = solution


class Unresolved(RunError, RuntimeError):
    """An optimum that does not answer the question: a minimum time slower than the ECU's
    own step of the same move (a grid too coarse for it), or a move the closed loop does
    not resolve (neither the ECU's own step nor the replay enters the 2 % band). The
    message names the argument to change (``intervals``, ``move``) and by how much."""
