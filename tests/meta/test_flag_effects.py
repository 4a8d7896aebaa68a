"""Every command x every flag it accepts: the flag has an effect, or, in the combinations
that disable it, it is refused in one line naming it (exit status 2, nothing written, no
traceback) - generated from the argparse parsers and the ``NO_EFFECT`` table each
command declares beside its arguments (:class:`ema_casadi.cli._flags.NoEffect`), so a
new flag without a declaration fails here, as does a declared combination that runs.

Parse-level and cheap: a combination the dispatcher refuses is checked on the parse (and
one per command end to end); the few that need the model (the solver ``auto`` picks, the
loops a model has) run through ``main`` and build it.
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


def _refusal(command, example):
    """What the dispatcher says of a command line before any work: the UserError's
    text, or None (parse, the flags given, the NO_EFFECT table)."""
    from ema_casadi.cli import UserError
    from ema_casadi.cli._flags import refuse_no_effect

    args = SUBS[command].parse_args(list(example))
    args._given = given_flags(SUBS[command], list(example))
    try:
        refuse_no_effect(args, {**COMMON, **MODS[command].NO_EFFECT})
    except UserError as exc:
        return str(exc)
    return None


def _refused_by_main(command, example, flag, tmp_path, monkeypatch, capsys):
    """The whole command line through ``main``: exit status 2, one line naming the flag,
    nothing written (the outputs would land in the working folder), no traceback."""
    monkeypatch.chdir(tmp_path)
    status = main([command, *example, "--json"])
    cap = capsys.readouterr()
    lines = cap.err.strip().splitlines()
    assert status == 2 and len(lines) == 1 and "Traceback" not in cap.err, cap.err
    assert lines[0].startswith(f"ema {command}: error: {flag}"), lines[0]
    assert cap.out == "" and not any(tmp_path.iterdir()), (cap.out, list(tmp_path.iterdir()))


@pytest.mark.parametrize(("command", "flag", "k", "rule"), CASES, ids=[f"{c}{f}-{k}" for c, f, k, _ in CASES])
def test_a_flag_without_effect_is_refused(command, flag, k, rule, tmp_path, monkeypatch, capsys):
    """The declared combination is refused naming the flag: by the dispatcher before any
    work where the rule is parse-level (checked here on the parse, a millisecond), by the
    command once the model is built where it needs the model (run through ``main``)."""
    assert flag in rule.example, f"the example of ema {command} {flag} does not give {flag}"
    if rule.when is None:
        _refused_by_main(command, rule.example, flag, tmp_path, monkeypatch, capsys)
        return
    args = SUBS[command].parse_args(list(rule.example))
    assert rule.when(args), f"ema {command} {' '.join(rule.example)}: its rule does not hold on it"
    text = _refusal(command, rule.example)
    assert text is not None and text.startswith(f"{flag} has no effect") and "\n" not in text, text


#: One parse-level refusal per command, end to end (the dispatcher's line, status, outputs).
END_TO_END = {c: next((f, r) for f, rules in MODS[c].NO_EFFECT.items() for r in rules if r.when is not None)
              for c in COMMANDS if any(r.when is not None for rules in MODS[c].NO_EFFECT.values() for r in rules)}


@pytest.mark.parametrize("command", list(END_TO_END))
def test_the_dispatcher_refuses_in_one_line_before_any_work(command, tmp_path, monkeypatch, capsys):
    flag, rule = END_TO_END[command]
    _refused_by_main(command, rule.example, flag, tmp_path, monkeypatch, capsys)


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
