"""The export error type, in a leaf module: the linear export and the FMU/C/CasADi
exports below it (``fmu/``) both raise it without importing each other."""

__all__ = ["ExportError"]


class ExportError(ValueError):
    """Bad export request or unreadable file (one line, names the file)."""
