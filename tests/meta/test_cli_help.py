"""The CLI's help stays true to the registry and its defaults work."""

import argparse

from ema_casadi.cli import DEFAULT_MODEL, add_common, positionals
from ema_casadi.model.components import VARIANTS


def test_the_variant_help_names_every_key_and_value():
    p = argparse.ArgumentParser()
    add_common(p)
    text = next(a.help for a in p._actions if "--variant" in a.option_strings)
    for key, values in VARIANTS.items():
        assert f"{key}={'|'.join(values)}" in text, key


def test_a_single_file_named_is_the_commands_own_file():
    assert positionals(DEFAULT_MODEL, None, "d.toml") == (DEFAULT_MODEL, "d.toml")
    assert positionals("mission.toml", None, "d.toml") == (DEFAULT_MODEL, "mission.toml")
    assert positionals("m.toml", "mission.toml", "d.toml") == ("m.toml", "mission.toml")
