"""The CLI's help stays true to the registry and its defaults work."""

import argparse

from ema_casadi.cli import add_common, build_parser
from ema_casadi.model.components import VARIANTS


def test_the_variant_help_names_every_key_and_value():
    p = argparse.ArgumentParser()
    add_common(p)
    text = next(a.help for a in p._actions if "--variant" in a.option_strings)
    for key, values in VARIANTS.items():
        assert f"{key}={'|'.join(values)}" in text, key


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
