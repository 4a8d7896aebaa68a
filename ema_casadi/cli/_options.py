"""Options every command shares: the parameter file (MODEL.toml, the packaged reference
by default) and the progress convention (``--progress/--no-progress``, on by default
only when stderr is a terminal). Light: nothing heavy is imported here (the ``ema``
process installs its signal handlers first)."""

from __future__ import annotations

import sys

__all__ = ["add_progress", "progress_of", "stage", "model_path", "seconds"]

#: The packaged reference parameter set: the model of every command run without a MODEL.toml.
DEFAULT_MODEL = "cesa_ema.toml"


def _holds_table(path: str, key: str) -> bool:
    """True when ``path`` is a readable TOML file with a top-level ``key``."""
    import tomllib

    try:
        with open(path, "rb") as f:
            return key in tomllib.load(f)
    except (OSError, ValueError):
        return False


def add_progress(p) -> None:
    """The progress convention of every long command: ``--progress/--no-progress``, by
    default on only when stderr is a terminal (read it with :func:`progress_of`).

    Parameters
    ----------
    p : argparse.ArgumentParser
        The command's parser.
    """
    import argparse

    p.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                   help="progress on stderr (--no-progress: none); default: on when stderr is a terminal (a log "
                        "gets whole lines, no carriage returns)")


def progress_of(args) -> bool:
    """Whether to show progress: the flag of :func:`add_progress`, else stderr is a terminal.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line.
    """
    return sys.stderr.isatty() if args.progress is None else bool(args.progress)


def stage(args, label: str, frac: float, note: str = "") -> None:
    """Progress of a command made of stages (``ema tune``, ``ema aircraft``, ...): the
    fraction done and what runs now, by the one progress bar (whole lines into a log).

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line (its ``--progress`` flag).
    label : str
        The command, before the bar.
    frac : float
        Fraction done, 0..1.
    note : str
        What runs now.
    """
    from ..simulation import progress_bar

    progress_bar(frac, progress_of(args), label, note)


def model_path(args) -> str:
    """The parameter file of the command: MODEL.toml as given, else the packaged reference.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line (``args.model`` None when no MODEL.toml was named).
    """
    from .._util._resources import packaged_file

    return args.model if args.model is not None else str(packaged_file(DEFAULT_MODEL))


#: Time units a time flag takes (factor to s); a bare number is seconds.
TIME_UNITS = {"us": 1e-6, "ms": 1e-3, "s": 1.0, "min": 60.0, "h": 3600.0}


def seconds(text: str) -> float:
    """A time flag's value in s: ``0.5``, ``0.5s``, ``500ms``, ``2min``, ``20us``, ``1h``
    (argparse ``type``: a value it cannot read is refused naming the flag).

    Parameters
    ----------
    text : str
        The value as given.
    """
    import argparse
    import re

    m = re.fullmatch(r"\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?|[-+]?(?:inf|nan))\s*([a-z]*)\s*", text,
                     re.IGNORECASE)
    if not m or (m.group(2) and m.group(2) not in TIME_UNITS):
        raise argparse.ArgumentTypeError(f"'{text}' is not a time: give seconds, or a number with a unit "
                                         f"({', '.join(TIME_UNITS)}), e.g. 0.5, 500ms, 2min")
    return float(m.group(1)) * TIME_UNITS[m.group(2) or "s"]

