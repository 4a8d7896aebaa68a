"""ema_casadi: a direct-drive electromechanical actuator with ballscrew as one CasADi
model, at switchable fidelity, for simulation, linearisation, margins, nonlinear
frequency response, gain tuning and export.

Quick start::

    import ema_casadi as ema
    params = ema.load_parameters("models/cesa_ema.toml")
    model = ema.build_model(params, {"motor": "pmsm", "screw": "elastic"})
    res = ema.simulate(model, 0.2, x_cmd=ema.Signal.step(1e-3, 0.01))
    res["x_rod"]          # rod position (m)
    lin = ema.linearize.linearize(model)       # control.StateSpace, named signals
    ema.loop_margins(model)                     # GM/PM/disk margins per loop

``ema.linearize`` is a module (its function of the same name is not re-exported, so
that ``from ema_casadi import linearize`` keeps giving the module); ``ema.tune`` is the
tuning function (its package is :mod:`ema_casadi.tuning`).
"""

from .assembly import INPUTS, OUTPUTS, Model, build_model
from .params import DEFAULT_VARIANTS, VARIANTS, ParameterError, Parameters, load_parameters
from .signals import Signal, SignalError, parse_signal
from .simulate import SimResult, SimulationError, simulate
from .linearize import LinearizationError, OperatingPointError, linear_model, loop_transfer, operating_point
from .frequency import bode, closed_loop, dynamic_stiffness, loop_margins, margins
from .export import ExportError, export_function, load_linear, save_linear
from .freqresp import FreqResponse, FreqRespError, sine_stream
from .tuning import Requirements, TuneError, TuneResult, tune

__version__ = "0.1.0"

__all__ = [
    "INPUTS", "OUTPUTS", "Model", "build_model",
    "DEFAULT_VARIANTS", "VARIANTS", "ParameterError", "Parameters", "load_parameters",
    "Signal", "SignalError", "parse_signal",
    "SimResult", "SimulationError", "simulate",
    "LinearizationError", "OperatingPointError", "linear_model", "loop_transfer", "operating_point",
    "bode", "closed_loop", "dynamic_stiffness", "loop_margins", "margins",
    "ExportError", "export_function", "load_linear", "save_linear",
    "FreqResponse", "FreqRespError", "sine_stream",
    "Requirements", "TuneError", "TuneResult", "tune",
]
