"""The request of an optimal move checked before any work (:func:`check_request`) and
the names it is checked against."""

from __future__ import annotations

from .._util._checks import integer, number
from ..model.assembly import Model
from ._errors import OptimalError

__all__ = ["OBJECTIVES", "LEVELS", "METHODS", "MAX_INTERVALS", "check_method", "check_request"]

#: Most intervals of a move's NLP, checked before it is built: the NLP's memory grows
#: about linearly with the intervals (16 GB were reached at 100000 intervals, about
#: 160 kB an interval), so this bound keeps it under about 1 GB; the default is 40 and
#: 2000 already resolves a move far finer than the ECU's sampling.
MAX_INTERVALS = 5000
#: Memory of the NLP per interval (bytes), for the refusal's estimate.
_BYTES_PER_INTERVAL = 160e3

#: What a move minimises: its duration, the energy drawn from the DC link, the heat in the winding.
OBJECTIVES = ("time", "energy", "heat")
#: The control: ``drive`` (the innermost loop's held outputs, the motor voltages: the
#: drive's capability) or ``ecu`` (the rod command through the cascade).
LEVELS = ("drive", "ecu")
#: The transcriptions: ``auto`` (multiple shooting where its RK4 chain, intervals x
#: substeps, is at most :data:`~ema_casadi.optimal._problem.EXPAND_LIMIT`, else collocation), ``shooting`` (RK4
#: substeps in every interval), ``collocation`` (Radau IIA, :mod:`._collocation`).
METHODS = ("auto", "shooting", "collocation")


def check_method(method) -> str:
    """``method`` if it is one of :data:`METHODS` (else :class:`OptimalError`)."""
    if method not in METHODS:
        raise OptimalError(f"method '{method}' unknown; choose one of {', '.join(METHODS)}")
    return method


def check_request(model: Model, move, load, objective, duration, start, through, intervals,
                  method: str = "auto") -> tuple:
    """Every argument checked before any work (:class:`OptimalError`, one line naming it);
    the checked values but ``method`` returned.

    Parameters
    ----------
    model, move, load, objective, duration, start, through, intervals, method
        As :func:`~ema_casadi.optimal.optimal_move` takes them.
    """
    if check_method(method) != "auto" and through == "ecu":
        raise OptimalError(f"method {method}: command shaping (through ecu) searches a command by runs, "
                           "it has no transcription")
    if not isinstance(model, Model):
        raise OptimalError(f"model: expected a Model (from build_model), got {type(model).__name__}")
    for role in ("command", "load"):  # the move commands the rod and holds its load
        model.needs_input(role, "an optimal move of the rod", OptimalError)
    move = number(move, "move", OptimalError)
    load = number(load, "load", OptimalError)
    start = number(start, "start", OptimalError)
    if objective not in OBJECTIVES:
        raise OptimalError(f"objective '{objective}' unknown; choose one of {', '.join(OBJECTIVES)}")
    if through not in LEVELS:
        raise OptimalError(f"through '{through}' unknown; choose one of {', '.join(LEVELS)}")
    intervals = integer(intervals, "intervals", OptimalError, minimum=4)
    if intervals > MAX_INTERVALS:  # before any NLP is built: its memory grows with them
        raise OptimalError(f"intervals {intervals}: above the limit of {MAX_INTERVALS} (an NLP of about "
                           f"{intervals * _BYTES_PER_INTERVAL / 1e9:.3g} GB); give at most {MAX_INTERVALS}")
    if through == "ecu" and objective != "time":
        raise OptimalError(f"through ecu: command shaping minimises the time to the 2 % band (objective time), "
                           f"not '{objective}'")
    if objective == "time":
        if duration is not None:
            raise OptimalError("duration: a minimum-time move has no given duration (objective energy or heat)")
    else:
        if duration is None:
            raise OptimalError(f"duration: an objective '{objective}' move needs its duration (s)")
        duration = number(duration, "duration", OptimalError)
        if not duration > 0:
            raise OptimalError(f"duration {duration:g} s: must be positive")
    if move == 0:
        raise OptimalError("move: 0 m is no move")
    limits = model.operating_limits()
    stroke = limits.get("stroke")
    if stroke is not None and not (abs(start) <= stroke and abs(start + move) <= stroke):
        raise OptimalError(f"move {move * 1e3:g} mm from {start * 1e3:g} mm ends at {(start + move) * 1e3:g} mm, "
                           f"beyond the stroke +-{stroke * 1e3:g} mm")
    held = model.envelope_limits().get("held_load")
    if held is not None and abs(load) > held:
        raise OptimalError(f"load {load / 1e3:g} kN: above the {held / 1e3:.4g} kN the screw holds at the "
                           "current limit")
    speed = limits.get("rod_speed")
    if duration is not None and speed and duration < abs(move) / speed:
        raise OptimalError(f"duration {duration:g} s: below the minimum time of {abs(move) * 1e3:g} mm even at "
                           f"the rated rod speed {speed * 1e3:g} mm/s ({abs(move) / speed:.4g} s)")
    return move, load, objective, duration, start, through, intervals
