"""Experiment design: the rig test that pins the parameters down (docs: experiment-design).

``design_experiment()`` chooses a command and load profile of a given length, within
the test's stroke, the rig's load capability and the limits the parts declare, that
makes the 95 % intervals of named parameters smallest by a D-, A- or E-optimal (or
weighted) criterion, from the Fisher information of the exact forward sensitivities
``identify`` fits with (:mod:`._fisher`); over a library of segments (multisines, slews,
stop-and-go steps, load levels: :mod:`._excitation`, :mod:`._library`) by IPOPT on the convex
approximate-design problem (:mod:`._optimise`); compares it with the standard tests
(chirp, steps, loaded slews) of the same length; ``DesignResult.verify()`` simulates
and fits it (:mod:`._verify`).
"""

from ._design import DEFAULT_FREE, SPREAD, DesignError, DesignFailed, design_experiment, read_prior
from ._excitation import (
           RAMP,
           STANDARD_PARTS,
           STANDARD_SPEED,
           TAPER,
           Segment,
           Test,
           output_names,
           realise,
           segment_command,
           standard_test,
)
from ._fisher import PHYSICAL, Information, information, intervals, limit_usage
from ._library import (
           AIM,
           AMPLITUDES,
           BANDS,
           LEAD_IN,
           LIMIT_TOLERANCE,
           LOAD_LEVELS,
           SLEWS,
           STEPS,
           STROKE_MARGIN,
           admissible,
           at_limits,
           candidates,
)
from ._optimise import CRITERIA, criterion, efficient_rounding, optimal_weights
from ._result import DesignResult
from ._verify import START_SPREAD

__all__ = ["design_experiment", "DesignResult", "DesignError", "DesignFailed", "read_prior", "DEFAULT_FREE", "SPREAD",
           "Segment", "Test", "STANDARD_PARTS", "STANDARD_SPEED", "output_names", "realise", "segment_command",
           "standard_test", "RAMP", "TAPER",
           "Information", "information", "intervals", "limit_usage", "PHYSICAL",
           "candidates", "admissible", "at_limits", "AIM", "BANDS", "SLEWS", "STEPS", "LEAD_IN", "LOAD_LEVELS",
           "AMPLITUDES",
           "STROKE_MARGIN", "LIMIT_TOLERANCE", "CRITERIA", "criterion", "optimal_weights", "efficient_rounding",
           "START_SPREAD"]
