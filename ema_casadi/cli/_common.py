"""What the commands share: the one-line user error, the model of a command (read and
assembled once, :func:`load`), the checks of output paths before any work, the second
file of a command, JSON conversion. Light: nothing heavy is imported here."""

from __future__ import annotations

from typing import TYPE_CHECKING

from .._util._errors import InputError
from ._options import _holds_table, model_path

if TYPE_CHECKING:
    from pathlib import Path

__all__ = ["EXIT_FAILED", "UserError", "second_file", "load", "jsonable", "check_output_path",
           "check_output_dir", "key_values"]


#: Exit status of a failed run (and of ``ema freqresp`` with a failed point).
EXIT_FAILED = 3


class UserError(InputError, ValueError):
    """A mistake in the command line; reported as one line, exit status 2."""


def second_file(args, positional: str | None, flag_value: str | None, *, flag: str, what: str, key: str,
                default: str) -> str:
    """The second file of ``ema COMMAND [MODEL] [FILE]`` (a mission, a sweep), unambiguous:
    the first positional is always the parameter file, the second file comes second or
    by its flag; without either it is the packaged ``default``. A single positional that
    is a ``what`` file (it holds ``[key]``) is refused with one line saying how to name it.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line (``args.model_given``: a MODEL.toml was named).
    positional, flag_value : str or None
        The file as the second positional and as ``flag``.
    flag : str
        The named flag (``"--mission"``).
    what : str
        The kind of file, for the message (``"mission"``).
    key : str
        A table only that kind of file has (``"segment"``).
    default : str
        The packaged file used when none is given.
    """
    from .._util._resources import packaged_file

    if positional is not None and flag_value is not None:
        raise UserError(f"{flag} {flag_value}: the {what} file is already given as the second argument "
                        f"({positional}); give one of them")
    named = positional if positional is not None else flag_value
    if named is None and getattr(args, "model_given", True) and _holds_table(args.model, key):
        raise UserError(f"{args.model}: a {what} file ([{key}] tables), given where the parameter file goes; "
                        f"give MODEL.toml {what.upper()}.toml, or {flag} {args.model}")
    return named if named is not None else str(packaged_file(default))


def load(args):
    """(Parameters, Model) of the command: the parameter file with the ``--variant``
    choices, read and assembled once per command; a later call with the same file and
    choices returns the same pair (pass the model down rather than build it again).

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line (``args.model``, ``args.variant``).
    """
    key = (model_path(args), tuple(args.variant))
    done = getattr(args, "_loaded", None)
    if done is not None and done[0] == key:
        return done[1]
    from ..model.assembly import build_model
    from ..model.components import validate_variants
    from ..model.params import load_parameters

    variants = dict(args.variant)
    validate_variants(variants, "--variant")
    params = load_parameters(key[0], variants)
    args._loaded = (key, (params, build_model(params)))
    return args._loaded[1]


def jsonable(obj):
    """``obj`` as JSON can hold it: arrays as lists, paths as text, a non-finite number as
    null / "inf" / "-inf".

    Parameters
    ----------
    obj : object
        A result: dicts, lists, arrays, numbers, paths, text.
    """
    from pathlib import Path

    import numpy as np

    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, (np.floating, float)):
        v = float(obj)
        return v if np.isfinite(v) else (None if np.isnan(v) else ("inf" if v > 0 else "-inf"))
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, Path):
        return str(obj)
    return obj


def check_output_path(path: str | None, suffixes: tuple[str, ...], flag: str) -> Path | None:
    """Validate an output file before any work: its suffix, and that it can be written
    (its folder exists, is a folder and takes a file; the path is not a folder).

    Parameters
    ----------
    path : str or None
        The path given (None: the flag was not used).
    suffixes : tuple of str
        Allowed endings, lower case (``(".csv", ".npz")``).
    flag : str
        The flag, for the message (``"--out"``).
    """
    from pathlib import Path

    from .._util import _files

    if path is None:
        return None
    p = Path(path)
    if p.suffix.lower() not in suffixes:
        raise UserError(f"{flag} {path}: expected a file ending in {' or '.join(suffixes)}")
    return _files.check_file(p, f"{flag} {path}")


def check_output_dir(path: str | None, names, flag: str) -> Path | None:
    """Validate an output folder before any work: it can be assembled beside its place
    and moved in; an existing folder is replaced whole, so it may hold only ``names``.

    Parameters
    ----------
    path : str or None
        The folder given (None: the flag was not used).
    names : iterable of str
        The files the command writes into it.
    flag : str
        The flag, for the message (``"--out"``).
    """
    from .._util import _files

    if path is None:
        return None
    return _files.check_folder(path, names, f"{flag} {path}")


def key_values(items, flag: str, form: str = "NAME=VALUE") -> dict:
    """``NAME=VALUE`` items of a repeatable flag (``--sigma x_rod=1um --sigma i_q=0.05A``)
    or of a list (``--weights a=1,b=2``) as name -> value text, in order; UserError
    naming ``flag`` for an item without a name or a value, and for a name given twice
    (the last would silently win).

    Parameters
    ----------
    items : iterable of str
        The items as given.
    flag : str
        The flag, for the messages (``"--sigma"``).
    form : str
        The item's form, for the message (``"CHANNEL=VALUE"``).
    """
    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        key, value = key.strip(), value.strip()
        if not sep or not key or not value:
            raise UserError(f"{flag} '{item}': expected {form}")
        if key in out:
            raise UserError(f"{flag} {key}: given twice ({key}={out[key]}, then {key}={value}); give it once")
        out[key] = value
    return out
