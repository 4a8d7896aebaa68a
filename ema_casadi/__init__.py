"""ema_casadi: a direct-drive electromechanical actuator with ballscrew as one CasADi
model, at switchable fidelity, for simulation, linearisation, margins, nonlinear
frequency response, gain tuning and export.

Quick start::

    import ema_casadi as ema
    params = ema.load_parameters("models/cesa_ema.toml")
    model = ema.build_model(params, {"motor": "pmsm", "screw": "elastic"})
    res = ema.simulate(model, 0.2, x_cmd=ema.Signal.step(1e-3, 0.01))
    res["x_rod"]          # rod position (m)
    lin = ema.linearize(model)                  # control.StateSpace, named signals
    ema.loop_margins(model)                     # GM/PM/disk margins per loop

Packages (``ema.simulation``, ``ema.linearisation``, ``ema.sinestream``, ...) are named
apart from their main functions (``ema.simulate``, ``ema.linearize``, ``ema.sine_stream``).
"""

from .assembly import AssemblyError, Model, build_model
from .components import DEFAULT_VARIANTS, REGISTRY, VARIANTS
from .export import ExportError, export_function, load_linear, save_linear
from .frequency import bode, closed_loop, dynamic_stiffness, loop_margins, margins
from .linearisation import (
    LinearizationError,
    OperatingPointError,
    linear_model,
    linearize,
    loop_transfer,
    operating_point,
)
from .params import ParameterError, Parameters, load_parameters
from .signals import Signal, SignalError, parse_signal
from .simulation import SimResult, SimulationError, simulate
from .sinestream import FreqRespError, FreqResponse, sine_stream
from .tuning import Requirements, TuneError, TuneResult, tune

__version__ = "0.1.0"

__all__ = [
    "AssemblyError", "Model", "build_model",
    "DEFAULT_VARIANTS", "REGISTRY", "VARIANTS", "ParameterError", "Parameters", "load_parameters",
    "Signal", "SignalError", "parse_signal",
    "SimResult", "SimulationError", "simulate",
    "LinearizationError", "OperatingPointError", "linear_model", "linearize", "loop_transfer", "operating_point",
    "bode", "closed_loop", "dynamic_stiffness", "loop_margins", "margins",
    "ExportError", "export_function", "load_linear", "save_linear",
    "FreqResponse", "FreqRespError", "sine_stream",
    "Requirements", "TuneError", "TuneResult", "tune",
]
