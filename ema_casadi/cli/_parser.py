"""The ``ema`` argument parser: the commands discovered in this package, the arguments
every command shares, the ``--variant`` help from the registry (a help formatter fills
it in when the help is shown: importing the parts at every start-up would cost ~0.2 s)."""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys

from ._options import DEFAULT_MODEL

__all__ = ["VariantHelpFormatter", "variant_help", "add_common", "build_parser", "get_parser",
           "join_values", "unknown_flag", "given_flags", "flag_name", "once_only"]

#: The ``--variant`` help as declared; :class:`VariantHelpFormatter` shows the registry's keys and
#: values in its place (another formatter shows this sentence).
VARIANT_FIELD = "variant choice, repeatable (KEY=VALUE: a part of the model or an option)"


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, not usage + message
        sys.stderr.write(f"{self.prog}: error: {message}\n")
        sys.exit(2)

    def parse_known_args(self, args=None, namespace=None):
        ns, rest = super().parse_known_args(args, namespace)
        ns.__dict__.pop(_SEEN, None)  # what once_only() kept while parsing
        return ns, rest


#: The namespace attribute in which :func:`once_only` keeps the flags seen while parsing.
_SEEN = "_ema_flags_seen"


def once_only(p) -> None:
    """Make every single-valued flag of the parser ``p`` refuse a second occurrence
    (``--weights a=1 --weights b=2``: argparse keeps the last one silently): a flag that
    takes one value, and a ``--x/--no-x`` switch. Flags meant to repeat (``append``:
    ``--variant``, ``--input``, ``--sigma``), plain switches (``--json`` twice means
    the same) and help are left as they are.

    Parameters
    ----------
    p : argparse.ArgumentParser
        A command's parser, its arguments added.
    """
    for action in p._actions:
        kind = type(action)
        if not action.option_strings or not (kind is argparse._StoreAction
                                             or kind is argparse.BooleanOptionalAction):
            continue

        class Once(kind):
            def __call__(self, parser, namespace, values, option_string=None):
                seen = namespace.__dict__.setdefault(_SEEN, {})
                given = option_string if values is None or values == [] else f"{option_string} {values}"
                if self.dest in seen:
                    raise argparse.ArgumentError(self, f"given twice ({seen[self.dest]}, then {given}); it takes "
                                                       "one value: give it once")
                seen[self.dest] = given
                super().__call__(parser, namespace, values, option_string)

        Once.__name__ = Once.__qualname__ = f"Once{kind.__name__}"
        action.__class__ = Once


def variant_help() -> str:
    """The ``--variant`` help: every variant key and option with its values, from the registry."""
    from ..model.components import OPTIONS, REGISTRY

    keys = ", ".join(f"{k}={'|'.join(v)}" for k, v in REGISTRY.items())
    opts = ", ".join(f"{k}={'|'.join(v)}" for k, v in OPTIONS.items())
    return f"variant choice, repeatable: {keys}; options {opts}"


class VariantHelpFormatter(argparse.RawDescriptionHelpFormatter):
    """The commands' help formatter: descriptions as written, and the help of an argument
    declared as :data:`VARIANT_FIELD` (``--variant``) generated from the registry when shown."""

    def _get_help_string(self, action):
        text = super()._get_help_string(action)
        return variant_help().replace("%", "%%") if text == VARIANT_FIELD else text


def _variant(text: str) -> tuple[str, str]:
    key, sep, value = text.partition("=")
    if not sep or not key or not value:
        raise argparse.ArgumentTypeError(f"--variant expects KEY=VALUE, got '{text}'")
    return key.strip(), value.strip()


def add_common(p) -> None:
    """The arguments of every command: MODEL.toml (optional), ``--variant`` and ``--json``.

    Parameters
    ----------
    p : argparse.ArgumentParser
        The command's parser (its help formatter :class:`VariantHelpFormatter`).
    """
    p.add_argument("model", nargs="?", default=None, metavar="MODEL.toml",
                   help=f"parameter file (TOML, docs: physics); default: the packaged reference set {DEFAULT_MODEL}")
    p.add_argument("--variant", action="append", type=_variant, default=[], metavar="KEY=VALUE",
                   help=VARIANT_FIELD)
    p.add_argument("--json", action="store_true", help="print a machine-readable result on stdout")


def _commands():
    """The command modules of this package (each defines ``COMMAND``), in ``--help`` order."""
    mods = []
    for info in pkgutil.iter_modules(importlib.import_module(__package__).__path__):
        if info.name.startswith("_"):
            continue
        mod = importlib.import_module(f"{__package__}.{info.name}")
        if hasattr(mod, "COMMAND"):
            mods.append(mod)
    return sorted(mods, key=lambda m: (getattr(m, "ORDER", 100), m.COMMAND))


def build_parser():
    """(the ``ema`` parser, command name -> module): every command discovered, its
    parser with the common arguments and its own."""
    parser = _Parser(prog="ema", description="Electromechanical actuator toolkit (CasADi). "
                     "Run 'ema COMMAND --help' for a command's options.")
    from .. import __version__

    parser.add_argument("--version", action="version", version=f"ema_casadi {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND", parser_class=_Parser)
    mods = {}
    for mod in _commands():
        p = sub.add_parser(mod.COMMAND, help=mod.HELP, description=(mod.__doc__ or mod.HELP).strip(),
                           formatter_class=VariantHelpFormatter)
        p.prog = f"ema {mod.COMMAND}"
        add_common(p)
        mod.add_arguments(p)
        once_only(p)
        mods[mod.COMMAND] = mod
    return parser, mods


def get_parser():
    """The ``ema`` argument parser with every subcommand (for the documentation's CLI
    reference, built by sphinx-argparse; :func:`main` parses with the same parser)."""
    parser = build_parser()[0]
    text = variant_help()
    for sub in _subparsers(parser).choices.values():  # the reference shows the text, not the field
        for action in sub._actions:
            if "--variant" in action.option_strings:
                action.help = text
    return parser


def flag_name(action) -> str:
    """The name a flag goes by in messages and ``NO_EFFECT`` tables: its first long option
    (``--progress`` for ``--progress/--no-progress``)."""
    return next(o for o in action.option_strings if o.startswith("--"))


def given_flags(sub, words: list[str]) -> set[str]:
    """The flags on a command's line (by :func:`flag_name`), also those given at their
    default value: ``words`` parsed again by the command's parser ``sub`` with every
    default suppressed, so that only what was given is set.

    Parameters
    ----------
    sub : argparse.ArgumentParser
        The command's parser.
    words : list of str
        The arguments after the command's name (already parsed once, so valid).
    """
    flags = {a.dest: flag_name(a) for a in sub._actions if any(o.startswith("--") for o in a.option_strings)}
    saved = [(a, a.default) for a in sub._actions]
    try:
        for a, _ in saved:
            a.default = argparse.SUPPRESS
        ns, _ = sub.parse_known_args(words)
    finally:
        for a, d in saved:
            a.default = d
    return {flags[d] for d in vars(ns) if d in flags}


def _subparsers(parser) -> argparse._SubParsersAction:
    return next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))


def unknown_flag(argv: list[str], parser) -> str | None:
    """The one-line error for the first flag no parser knows (before argparse, whose
    message for ``ema --versoin`` is "arguments are required: COMMAND" and for
    ``ema simulate --tend 1`` has no suggestion), with the nearest flag, or for a
    command that does not exist (``ema simulat``), with the nearest command; None when
    every flag is known. A flag is known by its name or an unambiguous prefix (as
    argparse abbreviates); nothing after ``--`` is looked at.

    Parameters
    ----------
    argv : list of str
        Arguments after the program name.
    parser : argparse.ArgumentParser
        The ``ema`` parser.
    """
    from .._util._checks import nearest

    choices = _subparsers(parser).choices
    prog, sub = "ema", parser
    for tok in argv:
        if tok == "--":
            return None
        if sub is parser and tok in choices:
            prog, sub = f"ema {tok}", choices[tok]
            continue
        if sub is parser and not tok.startswith("-"):  # the command's place: a mistyped command
            return f"ema: error: unknown command {tok!r}{nearest(tok, choices, 0.6)} (ema --help lists the commands)"
        if not tok.startswith("--") or len(tok) < 3:
            continue
        name = tok.split("=", 1)[0]
        known = [o for a in sub._actions for o in a.option_strings if o.startswith("--")]
        if name in known or sum(o.startswith(name) for o in known) == 1:
            continue
        hint = nearest(name, known)
        if sum(o.startswith(name) for o in known) > 1:
            hint = f" (ambiguous: {', '.join(o for o in known if o.startswith(name))})"
        return f"{prog}: error: unknown flag {name}{hint}"
    return None


#: Unit words a flag's value may be followed by, apart (``--f-ext 30 kN``).
UNIT_WORDS = ("N", "kN", "MN", "m", "mm", "um", "%", "m/s", "mm/s", "us", "ms", "s", "min", "h", "deg", "rad",
              "Hz", "kHz", "V", "A", "K", "degC")


def join_values(argv: list[str], parser) -> list[str]:
    """A flag's value as argparse must see it, in one pass over the arguments:

    - ``--f-ext -30kN`` -> ``--f-ext=-30kN``: a token that starts with '-' and a digit or
      '.' after a flag that takes a value is that flag's value (argparse alone reads
      ``-30kN`` as an unknown option);
    - ``--f-ext 30 kN`` -> ``--f-ext 30kN`` (and ``--f-ext=-30 kN`` -> ``--f-ext=-30kN``):
      a number followed by a unit word of :data:`UNIT_WORDS` is one value (argparse
      alone reads ``kN`` as the parameter file).

    Long flags and their unambiguous prefixes are recognised; nothing after ``--`` is touched.

    Parameters
    ----------
    argv : list of str
        Arguments after the program name.
    parser : argparse.ArgumentParser
        The ``ema`` parser (its subcommands say which flags take a value).
    """
    import re

    negative = re.compile(r"-[0-9.]")
    number = re.compile(r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?")
    choices = _subparsers(parser).choices
    out, i, takes = [], 0, None

    def unit_after(j: int) -> bool:
        return j < len(argv) and argv[j] in UNIT_WORDS

    while i < len(argv):
        tok = argv[i]
        if tok == "--":
            return out + argv[i:]
        if takes is None and tok in choices:  # the subcommand: which of its flags take a value
            flags = {o: a.nargs is None for a in choices[tok]._actions for o in a.option_strings if o.startswith("--")}
            takes = {o for o, value in flags.items() if value}
            known = list(flags)
        elif takes and tok.startswith("--") and i + 1 < len(argv):
            flag, eq, value = tok.partition("=")
            match = [o for o in known if o == flag] or [o for o in known if o.startswith(flag)]
            if len(match) == 1 and match[0] in takes:
                if eq and number.fullmatch(value) and unit_after(i + 1):
                    out.append(tok + argv[i + 1])
                    i += 2
                    continue
                nxt = argv[i + 1]
                if not eq and (negative.match(nxt) or number.fullmatch(nxt)):
                    k = i + 2
                    if number.fullmatch(nxt) and unit_after(k):
                        nxt, k = nxt + argv[k], k + 1
                    out += [f"{tok}={nxt}"] if nxt.startswith("-") else [tok, nxt]
                    i = k
                    continue
        out.append(tok)
        i += 1
    return out
