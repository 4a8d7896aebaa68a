"""The ``ema`` command line (docs: cli).

Each subcommand lives in its own module of this package and defines ``COMMAND``
(name), ``ORDER`` (position in ``--help``), ``HELP`` (one line), ``add_arguments(parser)``
and ``run(args) -> dict`` (the ``--json`` result) plus optionally ``report(result)``
(the human-readable text). Modules are discovered, so adding a command is adding a
file. Every command takes the model file as first argument, ``--variant KEY=VALUE``
(repeatable) and ``--json``.

Exit status and stderr (the reliability contract, docs: reliability), always one line, never a traceback:

- 0: done;
- 2: a mistake in a file, key, flag or value (checked before any work, outputs
  included: a path that cannot be written is refused up front);
- 3: a run failed (left the physical envelope, went non-finite, its integrator gave
  up: :class:`~ema_casadi.simulation.RunFailed`), or, for ``ema freqresp``, a
  requested point failed (the table is still written, with its status column);
- 130 / 143: interrupted by SIGINT (Ctrl-C) / SIGTERM, within about a second.

Outputs are written atomically and committed together at the end of the command
(:func:`ema_casadi._util._files.transaction`): an error, a failed run or an interrupt leaves
no output and no temporary file.

Importing this package costs next to nothing (``sys`` and the signal module): what
else the command line needs, the standard library's argparse included, loads after
:func:`main` has installed its signal handlers, so an interrupt during start-up is an
interrupt, not a traceback.
"""

from __future__ import annotations

import os
import sys
import threading
from typing import TYPE_CHECKING

from .._util import _interrupts

_interrupts.record_early()  # the ema process: a signal during the imports below is kept for main

from ._options import DEFAULT_MODEL, _holds_table, add_progress, model_path, progress_of, stage  # noqa: E402, F401

if TYPE_CHECKING:
    from pathlib import Path

__all__ = ["main", "UserError", "DEFAULT_MODEL", "check_output_path", "check_output_dir", "add_progress", "progress_of",
           "stage", "second_file", "model_path"]


#: Exit status of a failed run (and of ``ema freqresp`` with a failed point).
EXIT_FAILED = 3


class UserError(ValueError):
    """A mistake in the command line; reported as one line, exit status 2."""


def _user_errors() -> tuple:
    from .._util import _files
    from ..export import ExportError
    from ..linearisation import LinearizationError
    from ..model.params import ParameterError
    from ..signals import SignalError
    from ..simulation import SimulationError

    return (UserError, _files.OutputPathError, ParameterError, SignalError, SimulationError, LinearizationError,
            ExportError)


def _parser_class():
    import argparse

    class _Parser(argparse.ArgumentParser):
        def error(self, message):  # one line, not usage + message
            sys.stderr.write(f"{self.prog}: error: {message}\n")
            sys.exit(2)

    return _Parser


def _variant(text: str) -> tuple[str, str]:
    import argparse

    key, sep, value = text.partition("=")
    if not sep or not key or not value:
        raise argparse.ArgumentTypeError(f"--variant expects KEY=VALUE, got '{text}'")
    return key.strip(), value.strip()


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


class _VariantHelp:
    """The ``--variant`` help, generated from the registry when it is shown (importing
    the parts at every start-up would cost ~0.2 s): every key and option with its values."""

    def __str__(self) -> str:
        from ..model.components import OPTIONS, REGISTRY

        keys = ", ".join(f"{k}={'|'.join(v)}" for k, v in REGISTRY.items())
        opts = ", ".join(f"{k}={'|'.join(v)}" for k, v in OPTIONS.items())
        return f"variant choice, repeatable: {keys}; options {opts}"

    def __mod__(self, params) -> str:  # argparse expands %(default)s-style fields
        return str(self) % params

    def __contains__(self, text: str) -> bool:
        return text in str(self)

    def strip(self) -> str:
        return str(self).strip()


def add_common(p) -> None:
    p.add_argument("model", nargs="?", default=None, metavar="MODEL.toml",
                   help=f"parameter file (TOML, docs: physics); default: the packaged reference set {DEFAULT_MODEL}")
    p.add_argument("--variant", action="append", type=_variant, default=[], metavar="KEY=VALUE",
                   help=_VariantHelp())
    p.add_argument("--json", action="store_true", help="print a machine-readable result on stdout")


def load(args):
    """(Parameters, Model) from the common arguments."""
    from ..model.assembly import build_model
    from ..model.components import validate_variants
    from ..model.params import load_parameters

    variants = dict(args.variant)
    validate_variants(variants, "--variant")
    params = load_parameters(model_path(args), variants)
    return params, build_model(params)


def _jsonable(obj):
    from pathlib import Path

    import numpy as np

    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
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
    try:
        return _files.check_file(p, f"{flag} {path}")
    except _files.OutputPathError as exc:
        raise UserError(str(exc)) from None


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
    try:
        return _files.check_folder(path, names, f"{flag} {path}")
    except _files.OutputPathError as exc:
        raise UserError(str(exc)) from None


def _commands():
    import importlib
    import pkgutil

    mods = []
    for info in pkgutil.iter_modules(__path__):
        if info.name.startswith("_"):
            continue
        mod = importlib.import_module(f"{__name__}.{info.name}")
        if hasattr(mod, "COMMAND"):
            mods.append(mod)
    return sorted(mods, key=lambda m: (getattr(m, "ORDER", 100), m.COMMAND))


def build_parser():
    import argparse

    _Parser = _parser_class()
    parser = _Parser(prog="ema", description="Electromechanical actuator toolkit (CasADi). "
                     "Run 'ema COMMAND --help' for a command's options.")
    from .. import __version__

    parser.add_argument("--version", action="version", version=f"ema_casadi {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND", parser_class=_Parser)
    mods = {}
    for mod in _commands():
        p = sub.add_parser(mod.COMMAND, help=mod.HELP, description=(mod.__doc__ or mod.HELP).strip(),
                           formatter_class=argparse.RawDescriptionHelpFormatter)
        p.prog = f"ema {mod.COMMAND}"
        add_common(p)
        mod.add_arguments(p)
        mods[mod.COMMAND] = mod
    return parser, mods


def get_parser():
    """The ``ema`` argument parser with every subcommand (for the documentation's CLI
    reference, built by sphinx-argparse; :func:`main` parses with the same parser)."""
    return build_parser()[0]


def join_negative_values(argv: list[str], parser) -> list[str]:
    """``--f-ext -30kN`` -> ``--f-ext=-30kN``: a token that starts with '-' and a digit or
    '.' after a flag that takes a value is that flag's value (argparse alone reads
    ``-30kN`` as an unknown option). Long flags and their unambiguous prefixes are
    recognised; nothing after ``--`` is touched.

    Parameters
    ----------
    argv : list of str
        Arguments after the program name.
    parser : argparse.ArgumentParser
        The ``ema`` parser (its subcommands say which flags take a value).
    """
    import argparse
    import re

    negative = re.compile(r"-[0-9.]")
    subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    choices = subs[0].choices if subs else {}
    out, i, sub = [], 0, None
    while i < len(argv):
        tok = argv[i]
        if tok == "--":
            return out + argv[i:]
        if sub is None and tok in choices:
            sub = choices[tok]
        elif sub is not None and tok.startswith("--") and "=" not in tok and i + 1 < len(argv) \
                and negative.match(argv[i + 1]):
            flags = {o: a.nargs is None for a in sub._actions for o in a.option_strings if o.startswith("--")}
            match = [o for o in flags if o == tok] or [o for o in flags if o.startswith(tok)]
            if len(match) == 1 and flags[match[0]]:
                out.append(f"{tok}={argv[i + 1]}")
                i += 2
                continue
        out.append(tok)
        i += 1
    return out


def main(argv=None) -> int:
    """Run the ``ema`` command line and return its exit status.

    SIGINT and SIGTERM are handled from the first statement on (exit status 130 /
    143, one line on stderr, no output left). With ``argv`` None — the ``ema`` process
    itself — an interrupt ends the process at once after the cleanup (no wait for
    worker threads), and a run that cannot unwind within a second (IPOPT) is ended by
    a watchdog the same way.

    Parameters
    ----------
    argv : list of str, optional
        Arguments after the program name (default ``sys.argv[1:]``).
    """
    process = argv is None
    stop = _Stop(sys.argv[1:] if process else list(argv))
    with _interrupts.handling(stop.force_exit if process else None, on_signal=stop.silence):
        try:
            _interrupts.replay_early()  # a signal that came during start-up
            status = _run(argv, stop)
            if process:  # done and reported: a late signal must not kill the process silently
                _interrupts.finished()
        except _interrupts.Interrupted as exc:
            status = stop.report(exc.signum)
        except BrokenPipeError:
            status = _reader_gone()
        except KeyboardInterrupt:
            status = stop.report(2)
        except BaseException:
            if _interrupts.requested() is None:
                raise
            status = stop.report(_interrupts.requested())  # an interrupt CasADi turned into an error
        finally:
            stop.unsilence()
        if stop.reported and process:
            stop.exit(status)
        return status


def _reader_gone() -> int:
    """The reader of stdout went away (``ema ... --json | head``): end quietly with the
    shell's status for a broken pipe (128 + SIGPIPE), as other Unix tools do; stdout is
    pointed at the null device so that the interpreter's final flush does not fail again."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())
    os.close(devnull)
    return 128 + 13


class _Stop:
    """What an interrupt does: silence the unwinding, remove the temporaries, write the
    one line, end the process (the ``ema`` process itself)."""

    def __init__(self, words):
        self.command = words[0] if words and not words[0].startswith("-") else None
        self.reported = False
        self.stderr = None
        self._once = threading.Lock()  # the main thread and the watchdog may both report

    def silence(self, signum):
        # what the unwinding prints (CasADi's warnings, a worker's error) is not for the
        # user: the one line of report() is
        self.stderr = sys.stderr
        sys.stderr = _Silent()

    def unsilence(self):
        if isinstance(sys.stderr, _Silent):
            sys.stderr = self.stderr

    def report(self, signum) -> int:
        from .._util import _files

        with self._once:
            if not self.reported:
                self.reported = True
                _files.remove_temporaries()
                stream = self.stderr or sys.stderr
                stream.write(f"ema {self.command}: interrupted\n" if self.command else "ema: interrupted\n")
                stream.flush()
        return _interrupts.exit_status(signum)

    def exit(self, status):
        import os

        sys.stdout.flush()
        os._exit(status)

    def force_exit(self, signum):  # the watchdog: the run did not unwind in time
        self.exit(self.report(signum))


class _Silent:
    """A stream that drops what is written to it."""

    def write(self, s):
        return len(s)

    def flush(self):
        pass


def _run(argv, stop) -> int:
    """Parse, run the command in one output transaction, report; the exit status."""
    import json

    from .._util import _files
    from ..simulation import RunFailed

    parser, mods = build_parser()
    argv = join_negative_values(list(sys.argv[1:] if argv is None else argv), parser)
    args = parser.parse_args(argv)
    stop.command = args.command
    args.model_given = args.model is not None
    args.model = model_path(args)
    mod = mods[args.command]
    errors = _user_errors()
    try:
        with _files.transaction():
            result = mod.run(args)
            _interrupts.check()
    except errors as exc:
        _interrupts.check()
        sys.stderr.write(f"ema {args.command}: error: {exc}\n")
        return 2
    except RunFailed as exc:
        _interrupts.check()
        sys.stderr.write(f"ema {args.command}: failed: {exc}\n")
        return EXIT_FAILED
    if args.json:
        json.dump(_jsonable(result), sys.stdout, indent=1)
        sys.stdout.write("\n")
    else:
        report = getattr(mod, "report", None)
        if report:
            report(result)
        else:
            json.dump(_jsonable(result), sys.stdout, indent=1)
            sys.stdout.write("\n")
    failure = result.get("failure") if isinstance(result, dict) else None
    if failure:
        sys.stderr.write(f"ema {args.command}: failed: {failure}\n")
        return EXIT_FAILED
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
