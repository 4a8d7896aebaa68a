"""Options every command shares: the parameter file (MODEL.toml, the packaged reference
by default) and the progress convention (``--progress/--no-progress``, on by default
only when stderr is a terminal). Light: nothing heavy is imported here (the ``ema``
process installs its signal handlers first)."""

from __future__ import annotations

import sys

__all__ = ["add_progress", "progress_of", "stage", "model_path"]

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
