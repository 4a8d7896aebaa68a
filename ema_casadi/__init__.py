"""ema_casadi: a direct-drive electromechanical actuator with ballscrew as one CasADi
model, at switchable fidelity, for simulation, linearisation, margins, nonlinear
frequency response, gain tuning and export.

Quick start::

    import ema_casadi as ema
    params = ema.load_parameters()              # the packaged reference set (or a path)
    model = ema.build_model(params, {"motor": "pmsm", "screw": "elastic"})
    res = ema.simulate(model, 0.2, x_cmd=ema.Signal.step(1e-3, 0.01))
    res["x_rod"]          # rod position (m), a sample every 1e-4 s
    res.info["solver"]    # "rosenbrock": solver="auto" picked the compiled RODAS4
    res.plot()            # a matplotlib Figure; res.to_pandas() a DataFrame
    lin = ema.linearize(model)                  # control.StateSpace, named signals
    ema.loop_margins(model)                     # GM/PM/disk margins per loop

Packages (``ema.simulation``, ``ema.linearisation``, ``ema.sinestream``, ...) are named
apart from their main functions (``ema.simulate``, ``ema.linearize``, ``ema.sine_stream``,
``ema.sweeps`` / ``ema.sweep``).
"""

from importlib import import_module
from importlib.util import find_spec

# Names are imported on first use (PEP 562): ``import ema_casadi.cli`` stays light, so
# the ``ema`` command installs its SIGINT/SIGTERM handlers before CasADi, SciPy and
# matplotlib load (the reliability contract, docs: reliability: Ctrl-C during start-up is an
# interrupt, not a traceback).
_EXPORTS = {
    ".model": ("AssemblyError", "Model", "build_model", "ParameterError", "Parameters", "load_parameters"),
    ".model.components": ("DEFAULT_VARIANTS", "REGISTRY", "VARIANTS"),
    ".export": ("ExportError", "export_function", "load_linear", "save_linear"),
    ".frequency": ("bode", "closed_loop", "dynamic_stiffness", "loop_margins", "margins"),
    ".linearisation": ("LinearizationError", "OperatingPointError", "linear_model", "linearize", "loop_transfer",
                       "operating_point"),
    "._util._resources": ("packaged_file", "packaged_files"),
    "._util._errors": ("EmaError", "InputError", "InfeasibleError", "RunError"),
    ".signals": ("Signal", "SignalError", "parse_signal"),
    ".simulation": ("RunFailed", "SimResult", "SimulationError", "simulate", "rk4_step_limit", "StepLimitWarning"),
    ".sinestream": ("FreqRespError", "FreqResponse", "sine_stream"),
    ".tuning": ("Requirements", "TuneError", "TuneResult", "tune"),
    ".sweeps": ("SweepError", "SweepResult", "load_sweep", "sweep"),
    ".identification": ("IdentificationError", "IdentResult", "identify"),
    ".faults": ("FaultError", "FaultResult", "load_faults", "run_faults", "threshold_study"),
    ".limitcycle": ("OrbitNotFound", "PeriodicOrbit", "periodic_orbit"),
    ".design": ("DesignError", "DesignResult", "design_experiment"),
    ".optimal": ("Infeasible", "OptimalError", "OptimalMove", "optimal_move"),
}
_WHERE = {name: mod for mod, names in _EXPORTS.items() for name in names}


def __getattr__(name):
    if name in _WHERE:
        value = getattr(import_module(_WHERE[name], __name__), name)
        globals()[name] = value
        return value
    if not name.startswith("_") and find_spec(f"{__name__}.{name}") is not None:
        return import_module(f".{name}", __name__)  # a subpackage: ema.tuning, ema.mission, ...
    raise AttributeError(f"module 'ema_casadi' has no attribute '{name}'")


def __dir__():
    return sorted(set(globals()) | set(_WHERE))


__version__ = "0.1.0"

__all__ = [
    "EmaError", "InputError", "InfeasibleError", "RunError",
    "AssemblyError", "Model", "build_model",
    "DEFAULT_VARIANTS", "REGISTRY", "VARIANTS", "ParameterError", "Parameters", "load_parameters",
    "packaged_file", "packaged_files",
    "Signal", "SignalError", "parse_signal",
    "RunFailed", "SimResult", "SimulationError", "simulate", "rk4_step_limit", "StepLimitWarning",
    "LinearizationError", "OperatingPointError", "linear_model", "linearize", "loop_transfer", "operating_point",
    "bode", "closed_loop", "dynamic_stiffness", "loop_margins", "margins",
    "ExportError", "export_function", "load_linear", "save_linear",
    "FreqResponse", "FreqRespError", "sine_stream",
    "Requirements", "TuneError", "TuneResult", "tune",
    "SweepError", "SweepResult", "load_sweep", "sweep",
    "IdentificationError", "IdentResult", "identify",
    "FaultError", "FaultResult", "load_faults", "run_faults", "threshold_study",
    "OrbitNotFound", "PeriodicOrbit", "periodic_orbit",
    "DesignError", "DesignResult", "design_experiment",
    "Infeasible", "OptimalError", "OptimalMove", "optimal_move",
]
