"""The CLI's help stays true to the registry and its defaults work."""

import argparse

from ema_casadi.cli import add_common, build_parser, get_parser
from ema_casadi.model.components import VARIANTS


def _commands(parser):
    return next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices


def test_the_variant_help_names_every_key_and_value():
    """What ``ema COMMAND --help`` shows (every command) and what the CLI reference shows."""
    for name, sub in _commands(build_parser()[0]).items():
        shown = "".join(sub.format_help().split())  # the wrapping's line breaks and indents out
        for key, values in VARIANTS.items():
            assert f"{key}={'|'.join(values)}" in shown, (name, key)
    for name, sub in _commands(get_parser()).items():
        text = next(a.help for a in sub._actions if "--variant" in a.option_strings)
        assert type(text) is str, name  # a plain string, no look-alike
        for key, values in VARIANTS.items():
            assert f"{key}={'|'.join(values)}" in text, (name, key)


def test_add_common_alone_gives_a_parser_whose_help_formats():
    """A parser of another formatter still shows a sentence (no unexpanded field)."""
    p = argparse.ArgumentParser()
    add_common(p)
    assert "--variant KEY=VALUE" in p.format_help() and "%(" not in p.format_help()


def test_every_long_command_takes_the_one_progress_convention():
    """--progress/--no-progress (default: on a terminal only) on every long command."""
    _, mods = build_parser()
    parser, _ = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    for name in ("simulate", "mission", "sweep", "freqresp", "tune", "aircraft", "limit-cycle", "demo"):
        flags = {o for a in sub.choices[name]._actions for o in a.option_strings}
        assert {"--progress", "--no-progress"} <= flags and "--quiet" not in flags, name
        action = next(a for a in sub.choices[name]._actions if "--progress" in a.option_strings)
        assert action.default is None, name  # None: decided by whether stderr is a terminal
