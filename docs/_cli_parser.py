"""The ``ema`` parser as the CLI reference shows it (sphinx-argparse reads the help
texts as reStructuredText): the command line's own parser, with ``|x|`` (an absolute
value in a help text) escaped so that docutils does not take it for a substitution."""

from __future__ import annotations

import argparse
import re

_BARS = re.compile(r"(?<![\\|])\|(?=[^\s|])([^|\n]*?[^\s\\|])\|(?!\|)")


def _escape(text):
    return _BARS.sub(r"\\|\1\\|", text) if isinstance(text, str) else text


def _walk(parser: argparse.ArgumentParser) -> None:
    parser.description = _escape(parser.description)
    parser.epilog = _escape(parser.epilog)
    for action in parser._actions:
        action.help = _escape(action.help)
        if isinstance(action, argparse._SubParsersAction):
            for choice in action._choices_actions:
                choice.help = _escape(choice.help)
            for sub in action.choices.values():
                _walk(sub)


def get_parser() -> argparse.ArgumentParser:
    """The ``ema`` parser, help texts escaped for reStructuredText."""
    from ema_casadi.cli import get_parser as ema_parser

    parser = ema_parser()
    _walk(parser)
    return parser
