"""The two ways an optimal move is refused."""

from __future__ import annotations

from .._util._errors import InfeasibleError
from ..simulation import SimulationError

__all__ = ["OptimalError", "Infeasible"]


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
