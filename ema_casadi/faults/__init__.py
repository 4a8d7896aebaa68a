"""Fault studies (docs: faults): faults injected on a scenario, the ECU's detection.

Usage::

    import ema_casadi as ema
    params = ema.load_parameters("models/cesa_ema.toml")
    res = ema.run_faults(params)      # the packaged reference table; healthy=100 adds false alarms
    res.rows                 # per case: detection delay per monitor, peak deviation
    res.plot("coverage.png") # coverage matrix + transients (a Figure)

The model of every case is the one model with the fault-injection part
(``faults = on``), the monitors (``monitors = on``) and, for the PMSM, the
turn-to-turn short (``winding_short = on``); a case drives its fault's input from the
onset with the severity (:class:`FaultCase`), so one compiled model serves every case.
What a model can inject comes from its parts' :class:`~ema_casadi.model.components.Fault`
declarations (:func:`fault_kinds`); the monitors are its ``alarm`` outputs.

Layout: ``_spec`` reads and checks the fault file; ``_run`` runs the cases and the
healthy runs (through :mod:`ema_casadi.sweeps`); ``_result`` holds the table, the
coverage and the files; ``_thresholds`` the threshold study (detection time and
false-alarm rate per threshold, ``ema faults --thresholds``); the figures are drawn by
``plots._faults``.
"""

from ._result import FaultResult
from ._run import DEFAULT_FAULTS, HEALTHY_TOLERANCE, healthy_runs, run_faults
from ._spec import FaultCase, FaultError, FaultSpec, fault_kinds, fault_variants, load_faults, parse_faults
from ._thresholds import MIN_STUDY_RUNS, SCALES, ThresholdStudy, check_study_runs, detection_time, threshold_study

__all__ = [
    "run_faults", "healthy_runs", "load_faults", "parse_faults", "fault_kinds", "fault_variants", "FaultSpec",
    "FaultCase", "FaultResult", "FaultError", "DEFAULT_FAULTS", "HEALTHY_TOLERANCE",
    "threshold_study", "ThresholdStudy", "detection_time", "SCALES", "check_study_runs", "MIN_STUDY_RUNS",
]
