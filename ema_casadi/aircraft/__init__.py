"""The aircraft - flight control - actuator loop (docs: aircraft): trim at a flight
condition, loop transfers at the actuator-command break (ideal and linearised EMA),
margins, the equivalent delay the EMA adds, and pitch responses with the nonlinear EMA."""

from ._conditions import CONDITIONS, condition_overrides
from ._loop import (
    DELAY_BAND_RAD_S,
    AircraftMargins,
    aircraft_margins,
    aircraft_point,
    ema_loop,
    equivalent_delay,
    ideal_loop,
)
from ._responses import RESPONSE_SIGNALS, gust_response, one_minus_cosine, pitch_step

__all__ = [
    "CONDITIONS", "condition_overrides", "DELAY_BAND_RAD_S", "AircraftMargins", "aircraft_margins",
    "aircraft_point", "ema_loop", "equivalent_delay", "ideal_loop",
    "RESPONSE_SIGNALS", "gust_response", "one_minus_cosine", "pitch_step",
]
