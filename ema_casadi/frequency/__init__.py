"""Frequency domain: Bode, closed-loop responses, dynamic stiffness, bandwidth, modes
and stability margins of the linearised model (``_response``), the margin arithmetic
(``_margins``) and the frequency grid (``_grid``)."""

from ._margins import margin_text
from ._response import (
    MAX_FREQ_POINTS,
    REQUIREMENT,
    LoopMargins,
    bandwidth,
    bode,
    check_points,
    closed_loop,
    compliance,
    dynamic_stiffness,
    freqresp,
    frequency_grid,
    loop_margins,
    margins,
    modes,
)

__all__ = [
    "LoopMargins", "frequency_grid", "freqresp", "bode", "margins", "loop_margins", "margin_text",
    "closed_loop", "compliance", "dynamic_stiffness", "bandwidth", "modes", "check_points", "MAX_FREQ_POINTS",
    "REQUIREMENT",
]
