"""The model: typed parameters (``params``), the parts by family (``components/``) and
the one assembly that composes them (``assembly``, with its private helpers
``_derived``). Everything above this layer asks the assembled
:class:`Model` (signals by name and role), never a part's module."""

from ._param_units import raw_value
from ._steady import has_hump, nut_force, steady_friction
from .assembly import AssemblyError, Model, build_model
from .params import GROUPS, ParameterError, Parameters, UnknownParameterError, checked, load_parameters

__all__ = ["Model", "build_model", "AssemblyError", "ParameterError", "UnknownParameterError", "Parameters",
           "load_parameters", "GROUPS", "checked", "raw_value",
           # the steady-state relations an analysis reads from records (identification's friction start)
           "steady_friction", "has_hump", "nut_force"]
