"""Every command in ``ema --help`` runs on the reference model with no arguments but its
required ones and exits 0, with no warning: the commands are taken from the parser,
so a new command is in this test the day it is added.

The default suite runs each command on its defaults where that takes a few seconds;
:data:`SHORT` names the few whose defaults are long studies, with the flag that makes
them short and why. ``test_every_command_on_its_own_defaults`` (slow) runs those on
their defaults too."""

import pytest

from ema_casadi.cli import main
from ema_casadi.cli._parser import _subparsers, build_parser

#: The required arguments of a command (argparse refuses it without them).
REQUIRED = {"export": ["--format", "json", "--out", "lin.json"]}
#: Commands whose defaults are long studies -> (flags that shorten them, why).
SHORT = {
    "demo": (None, "the whole demo (every figure and the sine-stream maps, ~20 s): make demo runs it"),
    "mission": (None, "the packaged regional mission (~30 s): test_mission runs it through the API"),
    "freqresp": (["--amplitudes", "1%", "--freqs", "1"], "the default 5 x 12 point map (~12 s)"),
    "tune": (["--max-iter", "2"], "the default IPOPT run to convergence (~6 s)"),
    "design-experiment": (["--free", "F_seal", "--duration", "2s"], "its default: every identifiable parameter over "
                                                                      "10 s (~14 s)"),
}


def _commands():
    parser, _ = build_parser()
    return list(_subparsers(parser).choices)


def _run(command, extra, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    parser, _ = build_parser()
    quiet = any("--no-progress" in a.option_strings for a in _subparsers(parser).choices[command]._actions)
    code = main([command, *REQUIRED.get(command, []), *extra, *(["--no-progress"] if quiet else [])])
    err = capsys.readouterr().err
    assert code == 0, err
    assert "warning" not in err.lower(), err


@pytest.mark.parametrize("command", _commands())
def test_every_command_runs_on_its_defaults(command, tmp_path, monkeypatch, capsys):
    flags, why = SHORT.get(command, ([], None))
    if flags is None:
        pytest.skip(f"{command}: {why}")
    _run(command, flags, tmp_path, monkeypatch, capsys)


@pytest.mark.slow
@pytest.mark.parametrize("command", sorted(SHORT))
def test_every_command_on_its_own_defaults(command, tmp_path, monkeypatch, capsys):
    _run(command, [], tmp_path, monkeypatch, capsys)


def test_shooting_on_its_defaults_takes_the_hunting_scenario_and_says_so(tmp_path, monkeypatch, capsys):
    """The reference P loop settles (no orbit): --method shooting alone takes controller=PI,
    K_i_x 3000 and names it on its first line; --variant controller=P keeps the P loop
    (exit 3: nothing to shoot)."""
    monkeypatch.chdir(tmp_path)
    assert main(["limit-cycle", "--method", "shooting", "--no-df", "--t-end", "0", "--no-progress"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("scenario:") and "--variant controller=PI --k-i-x 3000" in out[0]
    assert "periodic orbit of the position loop" in out[1] and "stable" in out[1]
    assert main(["limit-cycle", "--method", "shooting", "--no-df", "--t-end", "0", "--no-progress",
                 "--variant", "controller=P"]) == 3
    assert "scenario" not in capsys.readouterr().out
