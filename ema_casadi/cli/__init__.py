"""The ``ema`` command line (SPEC §6).

Each subcommand lives in its own module of this package and defines ``COMMAND``
(name), ``ORDER`` (position in ``--help``), ``HELP`` (one line), ``add_arguments(parser)``
and ``run(args) -> dict`` (the ``--json`` result) plus optionally ``report(result)``
(the human-readable text). Modules are discovered, so adding a command is adding a
file. Every command takes the model file as first argument, ``--variant KEY=VALUE``
(repeatable) and ``--json``.

User mistakes (bad file, key, flag or value) end with exit status 2 and one line on
stderr naming what was wrong; no traceback, no half-written output file.
"""

from __future__ import annotations

import argparse
import importlib
import json
import pkgutil
import re
import sys
from pathlib import Path

import numpy as np

from ..export import ExportError
from ..linearisation import LinearizationError
from ..params import ParameterError
from ..signals import SignalError
from ..simulation import SimulationError

__all__ = ["main", "UserError", "DEFAULT_MODEL"]

DEFAULT_MODEL = "models/cesa_ema.toml"


class UserError(ValueError):
    """A mistake in the command line; reported as one line, exit status 2."""


USER_ERRORS = (UserError, ParameterError, SignalError, SimulationError, LinearizationError, ExportError)


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, not usage + message
        sys.stderr.write(f"{self.prog}: error: {message}\n")
        sys.exit(2)


def _variant(text: str) -> tuple[str, str]:
    key, sep, value = text.partition("=")
    if not sep or not key or not value:
        raise argparse.ArgumentTypeError(f"--variant expects KEY=VALUE, got '{text}'")
    return key.strip(), value.strip()


def add_common(p: argparse.ArgumentParser) -> None:
    p.add_argument("model", nargs="?", default=DEFAULT_MODEL,
                   help=f"parameter file (TOML, SPEC §3); default {DEFAULT_MODEL}")
    p.add_argument("--variant", action="append", type=_variant, default=[], metavar="KEY=VALUE",
                   help="variant choice, repeatable: motor=pmsm|dc, screw=elastic|rigid, "
                        "friction=smooth|hybrid, friction_shape=tanh|fermi, stribeck=off|on, "
                        "inverter=ideal, controller=P|PI")
    p.add_argument("--json", action="store_true", help="print a machine-readable result on stdout")


def load(args):
    """(Parameters, Model) from the common arguments."""
    from ..assembly import build_model
    from ..params import load_parameters

    variants = dict(args.variant)
    params = load_parameters(args.model, variants)
    return params, build_model(params)


def _jsonable(obj):
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
    """Validate an output path before any work: suffix and an existing folder."""
    if path is None:
        return None
    p = Path(path)
    if p.suffix.lower() not in suffixes:
        raise UserError(f"{flag} {path}: expected a file ending in {' or '.join(suffixes)}")
    if not p.parent.exists():
        raise UserError(f"{flag} {path}: folder {p.parent} does not exist")
    return p


def _commands():
    mods = []
    for info in pkgutil.iter_modules(__path__):
        if info.name.startswith("_"):
            continue
        mod = importlib.import_module(f"{__name__}.{info.name}")
        if hasattr(mod, "COMMAND"):
            mods.append(mod)
    return sorted(mods, key=lambda m: (getattr(m, "ORDER", 100), m.COMMAND))


def build_parser():
    parser = _Parser(prog="ema", description="Electromechanical actuator toolkit (CasADi). "
                     "Run 'ema COMMAND --help' for a command's options.")
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


_NEGATIVE = re.compile(r"-[0-9.]")


def join_negative_values(argv: list[str], parser: argparse.ArgumentParser) -> list[str]:
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
                and _NEGATIVE.match(argv[i + 1]):
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

    Parameters
    ----------
    argv : list of str, optional
        Arguments after the program name (default ``sys.argv[1:]``).
    """
    parser, mods = build_parser()
    argv = join_negative_values(list(sys.argv[1:] if argv is None else argv), parser)
    args = parser.parse_args(argv)
    mod = mods[args.command]
    try:
        result = mod.run(args)
    except USER_ERRORS as exc:
        sys.stderr.write(f"ema {args.command}: error: {exc}\n")
        return 2
    except KeyboardInterrupt:
        sys.stderr.write(f"ema {args.command}: interrupted\n")
        return 130
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
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
