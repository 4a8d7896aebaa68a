"""The export error type, in a leaf module: the linear export and the FMU/C/CasADi
exports below it (``fmu/``) both raise it without importing each other."""

from .._util._errors import InputError

__all__ = ["ExportError"]


class ExportError(InputError, ValueError):
    """Bad export request or unreadable file (one line, names the file)."""
