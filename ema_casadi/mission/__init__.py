"""Flight missions through the thermal network (docs: missions): temperatures, losses and
energy per part and per segment, peaks against limits.

A mission is a TOML file of segments run back to back on the full model (thermal =
lumped, hybrid friction, iron loss on, compiled RK4 at 1e-4 s)::

    [mission]
    name = "Regional jet, one flight"
    T_start = 40.0                 # degC: every thermal node soaked at it
                                   # (default: the first segment's cavity temperature)
    [model]                        # variants (defaults thermal = "lumped",
    friction = "hybrid"            # friction = "hybrid", iron_loss = "on")

    [limits]                       # peak temperatures judged against (degC)
    T_w = 180.0                    # winding insulation class (default: T_max_w of the
    T_h = 120.0                    # parameter file); T_h, T_s, T_inv default 120, 120, 100

    [[segment]]
    name = "pre-flight check"
    duration = 90.0                # s (or "90s")
    x_cmd = "step:70mm@2+step:-140mm@8+step:70mm@14"   # signal syntax (docs: simulate), bare numbers mm
    f_ext = "1kN"                  # signal syntax (docs: simulate), bare numbers N; positive pushes the rod in
    T_amb = 40.0                   # cavity, degC: a number, a signal, or [start, end]
                                   # for a linear change over the segment

Times inside a segment's signals count from the segment's start. Before anything runs,
every segment is checked: known keys, signals that parse with their quantity's units,
the command within the stroke, the load within what the current limit holds, the
cavity within -100...300 degC (:class:`MissionError`, one line naming file, segment and
key). A run that leaves the envelope (rod beyond the stroke, current beyond the limit,
non-finite state) ends with :class:`MissionFailed`, never with a result.

:func:`run_mission` simulates the mission in blocks of ~60 s of mission time (each
continuing from the previous end, so one trajectory), keeping every ``dt_out`` = 10 ms
sample of the temperatures, losses and heat flows; :class:`MissionResult` integrates
them per segment (:meth:`~MissionResult.energies`), finds the peaks
(:meth:`~MissionResult.peaks`), checks the heat balance and writes the
CSV (1 s rows, temperatures in degC, mean powers per row), the figure and the summary.
"""

from ._demo import SHORT_MISSION, demo_mission
from ._profile import (
    MISSION_VARIANTS,
    Mission,
    MissionError,
    Piecewise,
    Ramp,
    Segment,
    load_mission,
    node_limits,
    parse_mission,
)
from ._result import MissionResult
from ._run import FAST_DT, FULL_DT, MissionFailed, run_mission

__all__ = [
    "Mission", "Segment", "Piecewise", "Ramp", "MissionError", "MissionFailed", "MissionResult",
    "load_mission", "parse_mission", "run_mission", "MISSION_VARIANTS", "node_limits", "FULL_DT", "FAST_DT",
    "SHORT_MISSION", "demo_mission",
]
