"""The public API of ``import ema_casadi as ema`` stays: every documented name is there
and resolves (new names may come; none of these goes), and the calls scripts make keep
their positional parameters."""

from __future__ import annotations

import inspect

import pytest

import ema_casadi as ema

#: The names of ``ema`` (its ``__all__`` and the API reference) as documented.
DOCUMENTED = (
    "AssemblyError", "Model", "build_model", "DEFAULT_VARIANTS", "REGISTRY", "VARIANTS", "ParameterError",
    "Parameters", "load_parameters", "packaged_file", "packaged_files", "Signal", "SignalError", "parse_signal",
    "RunFailed", "SimResult", "SimulationError", "simulate", "LinearizationError", "OperatingPointError",
    "linear_model", "linearize", "loop_transfer", "operating_point", "bode", "closed_loop", "dynamic_stiffness",
    "loop_margins", "margins", "ExportError", "export_function", "load_linear", "save_linear", "FreqResponse",
    "FreqRespError", "sine_stream", "Requirements", "TuneError", "TuneResult", "tune", "SweepError", "SweepResult",
    "load_sweep", "sweep", "IdentificationError", "IdentResult", "identify", "FaultError", "FaultResult",
    "load_faults", "run_faults",
)
#: Positional parameters of the calls a script makes, in order.
POSITIONAL = {
    "simulate": ("model", "t_end", "x_cmd", "f_ext", "eta"),
    "operating_point": ("model", "x_cmd", "f_ext", "v_rod"),
    "build_model": ("params", "variants"),
}


def test_every_documented_name_is_public_and_resolves():
    missing = [n for n in DOCUMENTED if n not in ema.__all__]
    assert not missing, missing
    for name in DOCUMENTED:
        obj = getattr(ema, name)
        assert getattr(obj, "__module__", "ema_casadi").startswith("ema_casadi") or isinstance(obj, dict), name


@pytest.mark.parametrize("name, params", POSITIONAL.items())
def test_the_calls_keep_their_positional_parameters(name, params):
    sig = inspect.signature(getattr(ema, name))
    positional = tuple(p.name for p in sig.parameters.values()
                       if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD))
    assert positional == params
