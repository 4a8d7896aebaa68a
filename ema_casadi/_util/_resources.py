"""The reference files shipped with the package (``models/*.toml``): the defaults of the
API and the command line, found through :mod:`importlib.resources` wherever the
program runs. A path given by the user is read as given (relative to the working
folder); only an omitted file falls back to the packaged one."""

from __future__ import annotations

from importlib.resources import files
from pathlib import Path

__all__ = ["REFERENCE_MODEL", "REFERENCE_MISSION", "REFERENCE_SWEEP", "REFERENCE_FAULTS", "packaged_file",
           "packaged_files"]

#: The reference parameter set (CESA elevator EMA).
REFERENCE_MODEL = "cesa_ema.toml"
#: The reference mission (about 20 minutes of a regional-jet flight).
REFERENCE_MISSION = "mission_regional.toml"
#: The reference sweep (the default of ``ema sweep``).
REFERENCE_SWEEP = "sweep_reference.toml"
#: The reference fault table (the default of ``ema faults``).
REFERENCE_FAULTS = "faults_reference.toml"


def packaged_files() -> list[str]:
    """The names of the shipped files (``cesa_ema.toml``, ...), sorted."""
    return sorted(p.name for p in files("ema_casadi").joinpath("models").iterdir() if p.name.endswith(".toml"))


def packaged_file(name: str = REFERENCE_MODEL) -> Path:
    """The path of a shipped file, e.g. ``packaged_file("mission_regional.toml")``.

    Parameters
    ----------
    name : str
        A name from :func:`packaged_files` (default: the reference parameter set).

    Raises
    ------
    FileNotFoundError
        ``name`` is not shipped (the message lists what is).
    """
    path = files("ema_casadi").joinpath("models", name)
    if not path.is_file():
        raise FileNotFoundError(f"{name}: not a packaged file; the package ships {', '.join(packaged_files())}")
    return Path(str(path))
