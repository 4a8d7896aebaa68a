"""What a user and a script see when a command's check trips: for each case below (a
command, the flag and bad value that trip one of its checks, and the API call that takes
the same value), the command line ends with the family's exit status (2 for a mistake
in the input) and one line on stderr that names the offender, writes nothing in its
folder, and the error it raised is the very class the API raises for the same value.

The cases are data; what is asserted is behaviour - the status, the line, the folder,
the class a script catches - measured by running both paths, never a table compared
with itself. Every check here trips before any work (well under a second each).
"""

from __future__ import annotations

import tomllib
from collections.abc import Callable
from dataclasses import dataclass

import pytest

import ema_casadi as ema
from conftest import DISCONNECT, REFERENCE
from ema_casadi.cli import _run as run_module
from ema_casadi.cli import main

SWEEP = """
[sweep]
seed = 1

[parameters]
w_aw = { values = [0.005, 0.02] }

[scenario]
duration = 0.05
x_cmd = "step:1mm@0.01"

[metrics]
step = {}
"""


@dataclass(frozen=True)
class Case:
    """One check: ``argv`` after the command (``{rec}``, ``{faults}``, ``{sweep}`` are
    the fixtures' files), the words the refusal must hold (the offender named), and the
    API call with the same value (``api(ctx)``)."""

    command: str
    argv: tuple
    words: tuple
    api: Callable


def _spec(ctx, variants=None):
    return ema.faults.parse_faults(tomllib.loads(ctx["faults_text"]), ctx["params"], "<faults>", variants)


CASES = {
    "optimal-move-beyond-stroke": Case(
        "optimal", ("--move", "100mm"), ("move 100 mm", "beyond the stroke"),
        lambda c: ema.optimal_move(c["model"], 0.1)),
    "optimal-intervals-above-limit": Case(
        "optimal", ("--move", "2mm", "--intervals", "100000"), ("intervals 100000", "above the limit"),
        lambda c: ema.optimal_move(c["model"], 2e-3, intervals=100000)),
    "optimal-intervals-below-4": Case(
        "optimal", ("--move", "2mm", "--intervals", "3"), ("intervals", ">= 4"),
        lambda c: ema.optimal_move(c["model"], 2e-3, intervals=3)),
    "optimal-objective-unknown": Case(
        "optimal", ("--objective", "speed"), ("objective 'speed' unknown",),
        lambda c: ema.optimal_move(c["model"], 1e-2, objective="speed")),
    "optimal-method-unknown": Case(
        "optimal", ("--method", "euler"), ("method 'euler' unknown",),
        lambda c: ema.optimal_move(c["model"], 1e-2, method="euler")),
    "faults-study-runs-below-minimum": Case(
        "faults", ("--faults", "{faults}", "--thresholds", "--healthy-runs", "3"), ("healthy runs 3", "at least 50"),
        lambda c: ema.faults.threshold_study(_spec(c), healthy=3)),
    "faults-study-runs-zero": Case(
        "faults", ("--faults", "{faults}", "--thresholds", "--healthy-runs", "0"), ("healthy runs 0",),
        lambda c: ema.faults.threshold_study(_spec(c), healthy=0)),
    "faults-monitors-off": Case(
        "faults", ("--faults", "{faults}", "--variant", "monitors=off"), ("monitors=off",),
        lambda c: _spec(c, {"monitors": "off"})),
    "faults-disconnect-rigid-screw": Case(
        "faults", ("--faults", "{faults}", "--variant", "screw=rigid"), ("disconnect", "screw = elastic"),
        lambda c: _spec(c, {"screw": "rigid"})),
    "identify-free-unused-by-the-law": Case(
        "identify", ("{rec}", "--free", "w_aw"), ("'w_aw'", "anti_windup = backcalc"),
        lambda c: ema.identify(c["params"], [c["rec"]], ["w_aw"])),
    "identify-free-unused-by-the-shape": Case(
        "identify", ("{rec}", "--free", "w_knee"), ("'w_knee'", "limit_shape = clip"),
        lambda c: ema.identify(c["params"], [c["rec"]], ["w_knee"])),
    "identify-structural-unused": Case(
        "identify", ("{rec}", "--free", "F_seal", "--structural", "w_aw=0.005:0.02"), ("'w_aw'", "backcalc"),
        lambda c: ema.identify(c["params"], [c["rec"]], ["F_seal"], structural={"w_aw": (0.005, 0.02)})),
    "identify-model-error-above-ceiling": Case(
        "identify", ("{rec}", "--free", "F_seal", "--model-error", "1e6"), ("model error 1e+06", "--allow-misfit"),
        lambda c: ema.identify(c["params"], [c["rec"]], ["F_seal"], model_error=1e6)),
    "sweep-parameter-unused-by-the-law": Case(
        "sweep", ("--spec", "{sweep}"), ("w_aw", "anti_windup = backcalc"),
        lambda c: ema.sweeps.parse_sweep(tomllib.loads(SWEEP), c["params"])),
}


@pytest.fixture(scope="module")
def ctx(params, tmp_path_factory):
    d = tmp_path_factory.mktemp("inputs")
    (d / "faults.toml").write_text(DISCONNECT)
    (d / "sweep.toml").write_text(SWEEP)
    rec = ema.identification.synthetic_record(params, d / "step.csv", t_end=0.3, x_cmd="step:1mm@0.02")
    return {"params": params, "model": ema.build_model(params), "rec": rec, "faults": d / "faults.toml",
            "faults_text": DISCONNECT, "sweep": d / "sweep.toml"}


@pytest.mark.parametrize("name", sorted(CASES))
def test_a_tripped_check_is_one_line_its_status_nothing_written_and_the_apis_class(name, ctx, tmp_path, capsys,
                                                                                 monkeypatch):
    case = CASES[name]
    files = {k: str(ctx[k]) for k in ("rec", "faults", "sweep")}
    argv = [case.command, str(REFERENCE), *(a.format(**files) for a in case.argv)]
    out = {"identify": "fit.toml", "sweep": "sweep.csv"}.get(case.command, "out")  # a file, or a folder
    argv += ["--out", str(tmp_path / out)]
    raised = []
    refused = run_module._refused
    monkeypatch.setattr(run_module, "_refused",
                        lambda command, exc, flags=None: raised.append(exc) or refused(command, exc, flags))
    monkeypatch.chdir(tmp_path)
    status = main(argv)
    _, err = capsys.readouterr()
    assert len(raised) == 1, (status, err)
    exc = raised[0]
    assert status == exc.exit_status == (2 if isinstance(exc, ema.InputError) else 3), err
    assert err.count("\n") == 1 and err.startswith(f"ema {case.command}: "), err
    assert "Traceback" not in err
    for w in case.words:
        assert w in err, (w, err)
    assert not list(tmp_path.iterdir()), sorted(p.name for p in tmp_path.iterdir())
    with pytest.raises(ema.EmaError) as api:
        case.api(ctx)
    assert type(api.value) is type(exc), (type(api.value), type(exc))
    for w in case.words:
        if not w.startswith("--"):  # the API names its argument; the flag is the command line's word
            assert w in str(api.value) or w.replace("'", "") in str(api.value), (w, str(api.value))
