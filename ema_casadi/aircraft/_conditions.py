"""Flight conditions of the aircraft loop (docs: aircraft): airspeed, altitude, configuration, gains."""

from __future__ import annotations

from ..linearisation import LinearizationError
from ..model.components import PART_CLASSES

__all__ = ["CONDITIONS", "condition_overrides"]

#: Condition name -> flat parameter values (SI), as the airframe parts declare them
#: (their ``conditions``: trim airspeed and altitude, configuration, flight-control gains).
CONDITIONS = {name: dict(values) for cls in PART_CLASSES for name, values in cls.conditions.items()}


def condition_overrides(condition: str) -> dict:
    """The flat parameter values of a flight condition (a copy).

    Parameters
    ----------
    condition : str
        One of :data:`CONDITIONS`.
    """
    if condition not in CONDITIONS:
        raise LinearizationError(f"condition '{condition}' unknown; choose one of {', '.join(CONDITIONS)}")
    return dict(CONDITIONS[condition])
