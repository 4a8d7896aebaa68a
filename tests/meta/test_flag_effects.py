"""Every command x every flag it accepts: the flag has an effect, or, in the combinations
that disable it, it is refused in one line naming it (exit status 2, nothing written, no
traceback) - generated from the argparse parsers and the ``NO_EFFECT`` table each
command declares beside its arguments (:class:`ema_casadi.cli._flags.NoEffect`), so a
new flag without a declaration fails here, as does a declared combination that runs.

Parse-level and cheap: a combination the dispatcher refuses costs the parse; the few
that need the model (the solver ``auto`` picks, the loops a model has) build it once.
"""

from __future__ import annotations

import argparse
import importlib
import re
from pathlib import Path

import pytest

from ema_casadi.cli import main
from ema_casadi.cli._flags import COMMON
from ema_casadi.cli._parser import _subparsers, build_parser, flag_name, given_flags

PARSER, MODS = build_parser()
SUBS = _subparsers(PARSER).choices


def _flags(command: str) -> dict:
    """The command's flags by name (:func:`flag_name`) -> their argparse action."""
    return {flag_name(a): a for a in SUBS[command]._actions
            if any(o.startswith("--") for o in a.option_strings) and not isinstance(a, argparse._HelpAction)}


COMMANDS = sorted(SUBS)
CASES = [(c, f, k, rule) for c in COMMANDS for f, rules in getattr(MODS[c], "NO_EFFECT", {}).items()
         for k, rule in enumerate(rules)]


@pytest.mark.parametrize("command", COMMANDS)
def test_every_flag_is_declared(command):
    """The table names exactly the command's own flags (the common ones are in COMMON):
    a flag added without saying where it has no effect is caught here."""
    table = getattr(MODS[command], "NO_EFFECT", None)
    assert table is not None, f"ema {command}: no NO_EFFECT table beside its arguments"
    flags = set(_flags(command))
    assert set(table) <= flags, f"ema {command}: declared but not a flag: {sorted(set(table) - flags)}"
    missing = sorted(flags - set(COMMON) - set(table))
    assert not missing, f"ema {command}: flags without a declaration: {missing}"


def _sources(mod) -> str:
    """The command module's source and that of the command-line modules it imports from."""
    text = Path(mod.__file__).read_text()
    names = set(re.findall(r"^from \.(\w+) import", text, re.M))
    return text + "".join(Path(importlib.import_module(f"ema_casadi.cli.{n}").__file__).read_text() for n in names)


@pytest.mark.parametrize("command", COMMANDS)
def test_every_flag_is_read(command):
    """Every flag's value is read by the command (``args.<dest>``, or its name in a table
    of flags): a flag the command never looks at has no effect anywhere."""
    text = _sources(MODS[command])
    unread = [f for f, a in _flags(command).items() if f not in COMMON
              and f"args.{a.dest}" not in text and f'"{a.dest}"' not in text]
    assert not unread, f"ema {command}: flags never read: {unread}"


@pytest.mark.parametrize(("command", "flag", "k", "rule"), CASES, ids=[f"{c}{f}-{k}" for c, f, k, _ in CASES])
def test_a_flag_without_effect_is_refused(command, flag, k, rule, tmp_path, monkeypatch, capsys):
    """The declared combination: exit status 2, one line naming the flag, nothing written
    (the outputs would land in the working folder), no traceback."""
    assert flag in rule.example, f"the example of ema {command} {flag} does not give {flag}"
    if rule.when is not None:  # the predicate the dispatcher checks holds on the example itself
        args = SUBS[command].parse_args(list(rule.example))
        assert rule.when(args), f"ema {command} {' '.join(rule.example)}: its rule does not hold on it"
    monkeypatch.chdir(tmp_path)
    status = main([command, *rule.example, "--json"])
    cap = capsys.readouterr()
    lines = cap.err.strip().splitlines()
    assert status == 2 and len(lines) == 1 and "Traceback" not in cap.err, cap.err
    assert lines[0].startswith(f"ema {command}: error: {flag}"), lines[0]
    assert cap.out == "" and not any(tmp_path.iterdir()), (cap.out, list(tmp_path.iterdir()))


def test_given_flags_are_what_the_line_names():
    """Given at the default value, abbreviated, with '=', as --no-X: each counts as given;
    nothing else does."""
    sub = SUBS["simulate"]
    assert given_flags(sub, ["--t-end", "0.2", "--no-prog", "--solver=auto", "--zo"]) == \
        {"--t-end", "--progress", "--solver", "--zoh"}
    assert given_flags(sub, []) == set()
    assert sub.parse_args([]).t_end == 0.2  # the defaults are back after the second parse


def test_a_declared_rule_leaves_the_flag_alone_elsewhere(tmp_path, monkeypatch, capsys):
    """The same flag outside its disabling combination is not refused: ``--loop`` of
    ``ema bode`` acts with ``--kind open`` (one cheap run on the linear model)."""
    monkeypatch.chdir(tmp_path)
    assert main(["bode", "--kind", "open", "--loop", "velocity", "--points", "5", "--json"]) == 0, \
        capsys.readouterr().err
