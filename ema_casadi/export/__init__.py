"""Export: the linear model to ``.mat``/``.npz``/``.json`` and back, CasADi functions
as ``.casadi`` or C, and the whole model as FMU, C or CasADi folder (``fmu/``).

``_errors`` (the error type) is a leaf: ``_linear`` and ``fmu`` both import it and
``_linear`` dispatches to ``fmu``, never the other way round.
"""

from ._errors import ExportError
from ._linear import (
    FUNCTION_FORMATS,
    LINEAR_FORMATS,
    MODEL_FORMATS,
    export_function,
    export_model,
    load_linear,
    model_signature,
    save_linear,
    sidecar_path,
)

__all__ = ["LINEAR_FORMATS", "FUNCTION_FORMATS", "MODEL_FORMATS", "ExportError", "save_linear", "load_linear",
           "export_function", "export_model", "model_signature",
           "sidecar_path"]
