"""The contract over the newest commands' inputs (docs: reliability): each mistake below
is refused before any work with one line naming the flag, key or file, exit status 2,
no traceback, nothing on stdout, nothing written; and the same value given to the
Python API raises the same kind of error (an :class:`~ema_casadi.InputError`, the
class named here) with a one-line message naming the argument.

The values: an input driven outside what it stands for (an efficiency above 1, a
temperature below absolute zero, a fault's severity outside its range) from
``--input``, a sweep file and a mission file, as the parameter and fault files refuse
them; an input the model does not read; a fitted prior that is not text or whose
numbers cannot be drawn from; a model without the rod command given to the commands
that command the rod; an empty channel list, a negative seed; a single-valued flag or
a NAME=VALUE name given twice; a bad --continue bound, an envelope distance no move
can make, the limit-cycle analyses on the switched bridge, an empty --out; a record
whose command lies beyond the rod's travel.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import pytest

import ema_casadi as E
from conftest import REFERENCE
from ema_casadi._util._errors import InputError
from ema_casadi.cli import main

REF = str(REFERENCE)
SIM = ["simulate", REF, "--t-end", "0.001"]
DESIGN = ["design-experiment", REF, "--free", "F_seal", "--duration", "2s", "--out", "{tmp}/out", "--no-progress"]


@dataclass
class Case:
    argv: list  # {tmp}: the case's folder
    offender: list  # words the one line holds (the flag, the key, the value)
    files: dict = field(default_factory=dict)  # name -> text or bytes


def _prior(estimate: str, lo: str, hi: str) -> str:
    """A fitted file's header line of F_seal as ``ema identify --out`` writes it."""
    return f"# F_seal: 100 -> {estimate} (95 %: {lo} .. {hi})\n[friction]\n"


def _record(x_cmd: str, unit_row: bool) -> str:
    """A short record (time, x_cmd, f_ext, x_rod, i_q) whose command stays at ``x_cmd``."""
    head = "time,x_cmd,f_ext,x_rod,i_q\nUnit:,m,N,m,A\n" if unit_row else "time,x_cmd [mm],f_ext,x_rod,i_q\n"
    return head + "".join(f"{k * 5e-4:g},{x_cmd},0,0,0\n" for k in range(40))


SWEEP = '[parameters]\nB = {{ values = [2e-5, 1e-4] }}\n[scenario]\nduration = 0.01\ninputs = {{ {inputs} }}\n' \
        '[metrics]\npeak = {{}}\n'
MISSION_SRC = (REFERENCE.parent / "mission_regional.toml").read_text(encoding="utf-8")
MISSION = MISSION_SRC.replace("T_amb = 40.0", 'T_amb = "step:-400@1"', 1)

CASES: dict[str, Case] = {}
# -- an input driven outside what it stands for: --input, a sweep file, a mission file ------------
for value in ("1.5", "-0.5", "0"):
    CASES[f"input-eta-{value}"] = Case([*SIM, "--input", f"eta={value}"], ["--input eta", "(0, 1]"])
CASES["input-T_amb-below-absolute-zero"] = Case([*SIM, "--variant", "thermal=lumped", "--input", "T_amb=-300"],
                                                ["--input T_amb", "-273.15"])
CASES["input-a_jam-2"] = Case([*SIM, "--variant", "faults=on", "--input", "a_jam=2"],
                              ["--input a_jam", "jam fault [0, 1]"])
CASES["input-a_shear-rigid"] = Case([*SIM, "--variant", "faults=on", "--variant", "screw=rigid", "--input",
                                     "a_shear=step:1@0.0005"], ["--input a_shear", "needs screw = elastic"])
CASES["input-a_shear-1.5"] = Case([*SIM, "--variant", "faults=on", "--input", "a_shear=1.5"],
                                  ["--input a_shear", "disconnect fault [0, 1]"])
CASES["input-eta-read-by-no-one"] = Case([*SIM, "--variant", "thermal=lumped", "--input", "eta=0.8"],
                                         ["--input eta", "has no effect", "thermal=lumped", "feedback_eta = 0"])
CASES["sweep-inputs-eta"] = Case(["sweep", REF, "{tmp}/s.toml", "--jobs", "1", "--out", "{tmp}/s.csv"],
                                 ["s.toml [scenario] inputs eta", "(0, 1]"],
                                 {"s.toml": SWEEP.format(inputs="eta = 1.5")})
CASES["sweep-inputs-a_jam"] = Case(["sweep", REF, "{tmp}/s.toml", "--jobs", "1", "--out", "{tmp}/s.csv"],
                                   ["inputs a_jam", "jam fault"],
                                   {"s.toml": '[variants]\nfaults = "on"\n' + SWEEP.format(inputs="a_jam = 2")})
CASES["sweep-inputs-eta-read-by-no-one"] = Case(
    ["sweep", REF, "{tmp}/s.toml", "--jobs", "1", "--out", "{tmp}/s.csv"], ["inputs eta", "has no effect"],
    {"s.toml": '[variants]\nthermal = "lumped"\n' + SWEEP.format(inputs="eta = 0.8")})
CASES["mission-T_amb-signal"] = Case(["mission", REF, "{tmp}/m.toml", "--out", "{tmp}/out"],
                                     ["m.toml", "T_amb 'step:-400@1'", "-400 degC"], {"m.toml": MISSION})
# -- design-experiment --prior ------------------------------------------------------------------
PRIORS = {"binary": (bytes(range(128, 256)) * 3, "not UTF-8"),
          "latin-1": ("# F_seal: 100 -> 150 (95 %: 120 .. 180) é\n".encode("latin-1"), "not UTF-8"),
          "estimate-0": (_prior("0", "-20", "20"), "F_seal estimate 0: must be positive"),
          "estimate-negative": (_prior("-150", "-200", "-100"), "F_seal estimate -150: must be positive"),
          "interval-inf": (_prior("150", "120", "inf"), "not finite")}
for name, (text, words) in PRIORS.items():
    CASES[f"prior-{name}"] = Case([*DESIGN, "--prior", "{tmp}/p.toml"], ["--prior", "p.toml", words],
                                  {"p.toml": text})
# -- a model without the rod command --------------------------------------------------------------
TRANSPORT = ["--variant", "airframe=transport"]
CASES["optimal-transport"] = Case(["optimal", REF, *TRANSPORT], ["--variant airframe=transport", "x_cmd"])
CASES["envelope-transport"] = Case(["optimal", REF, "--envelope", *TRANSPORT], ["--variant airframe=transport"])
CASES["design-transport"] = Case([*DESIGN, *TRANSPORT], ["--variant airframe=transport", "x_cmd"])
CASES["examples-transport"] = Case(["identify", REF, "--example-records", "{tmp}/ex", *TRANSPORT],
                                   ["airframe=transport", "x_cmd", "theta_cmd"])
# -- empty and negative ----------------------------------------------------------------------------
CASES["design-channels-empty"] = Case([*DESIGN, "--channels", ""], ["--channels", "at least one"])
CASES["design-channels-commas"] = Case([*DESIGN, "--channels", ",,"], ["--channels", "at least one"])
CASES["design-seed-negative"] = Case([*DESIGN, "--draws", "2", "--seed=-1"], ["--seed", "-1"])
CASES["faults-seed-negative"] = Case(["faults", REF, "--healthy-runs", "2", "--seed=-1", "--out", "{tmp}/out"],
                                     ["--seed", "-1"])
CASES["optimal-out-empty"] = Case(["optimal", REF, "--out", ""], ["--out ''"])
CASES["envelope-out-empty"] = Case(["optimal", REF, "--envelope", "--out", ""], ["--out ''"])
# -- a flag or a name given twice -------------------------------------------------------------------
TWICE = {"design-weights": [*DESIGN, "--weights", "F_seal=1", "--weights", "F_seal=2"],
         "limit-cycle-continue": ["limit-cycle", REF, "--method", "shooting", "--continue", "K_i_x=0:3000",
                                  "--continue", "K_i_x=0:5000"],
         "simulate-t-end": [*SIM, "--t-end", "0.002"],
         "simulate-progress": [*SIM, "--progress", "--no-progress"]}
for name, argv in TWICE.items():
    flag = {"design-weights": "--weights", "limit-cycle-continue": "--continue", "simulate-t-end": "--t-end",
            "simulate-progress": "--progress"}[name]
    CASES[f"twice-{name}"] = Case(argv, [flag, "given twice"])
FIT = ["identify", REF, "{tmp}/r.csv", "--free", "F_seal"]
NAME_TWICE = {"design-sigma": [*DESIGN, "--sigma", "x_rod=1um", "--sigma", "x_rod=8um"],
              "design-weights-list": [*DESIGN, "--weights", "F_seal=1,F_seal=2"],
              "identify-sigma": [*FIT, "--sigma", "x_rod=1um", "--sigma", "x_rod=8um"],
              "identify-structural": [*FIT, "--structural", "w_aw=0:1", "--structural", "w_aw=0:2"],
              "simulate-input": [*SIM, "--input", "eta=0.8", "--input", "eta=0.9"]}
for name, argv in NAME_TWICE.items():
    flag, key = {"design-sigma": ("--sigma", "x_rod"), "design-weights-list": ("--weights", "F_seal"),
                 "identify-sigma": ("--sigma", "x_rod"), "identify-structural": ("--structural", "w_aw"),
                 "simulate-input": ("--input", "eta")}[name]
    CASES[f"name-twice-{name}"] = Case(argv, [f"{flag} {key}", "given twice"], {"r.csv": _record("0", True)})
# -- messages in the user's terms ----------------------------------------------------------------
CASES["continue-bad-bound"] = Case(["limit-cycle", REF, "--method", "shooting", "--continue", "K_i_x=0:3000/s2"],
                                   ["--continue K_i_x=0:3000/s2", "'3000/s2'", "1/s^2"])
CASES["envelope-distances-overflow"] = Case(["optimal", REF, "--envelope", "--distances", "1e400"],
                                            ["--distances", "finite"])
CASES["envelope-distances-beyond-stroke"] = Case(["optimal", REF, "--envelope", "--distances", "500mm"],
                                                 ["--distances", "500 mm", "stroke"])
CASES["shooting-pwm"] = Case(["limit-cycle", REF, "--method", "shooting", "--variant", "inverter=pwm"],
                             ["inverter=pwm", "carrier periods", "inverter=ideal"])
CASES["describing-function-pwm"] = Case(["limit-cycle", REF, "--variant", "inverter=pwm"],
                                        ["--variant inverter=pwm", "inverter=ideal"])
# -- a record whose command lies beyond the rod's travel ----------------------------------------
for name, unit_row, value in (("unit-row", True, "0.5"), ("header-mm", False, "500")):
    CASES[f"record-command-500mm-{name}"] = Case(FIT,
                                                 ["r.csv", "x_cmd", "500 mm", "travel"],
                                                 {"r.csv": _record(value, unit_row)})


def _files(root):
    return sorted(str(p.relative_to(root)) for p in root.rglob("*"))


@pytest.mark.parametrize("case_id", list(CASES))
def test_refused_with_one_line(case_id, tmp_path, capsys, monkeypatch):
    case = CASES[case_id]
    monkeypatch.chdir(tmp_path)  # a default output would land here
    for name, content in case.files.items():
        (tmp_path / name).write_bytes(content if isinstance(content, bytes) else content.encode("utf-8"))
    before = _files(tmp_path)
    try:
        status = main([a.format(tmp=tmp_path) for a in case.argv])
    except SystemExit as exc:  # argparse's own errors
        status = exc.code
    out, err = capsys.readouterr()
    assert status == 2, err
    assert err.endswith("\n") and err.count("\n") == 1, err
    assert "Traceback" not in err and out == ""
    for word in case.offender:
        assert word in err, f"{word!r} not in {err!r}"
    assert _files(tmp_path) == before, "a file was left behind"


# -- the same values from the Python API -------------------------------------------------------
@pytest.fixture(scope="module")
def models(params):
    return {v: E.build_model(params, dict(kv.split("=") for kv in v.split(",")) if v else None)
            for v in ("", "thermal=lumped", "faults=on", "airframe=transport", "inverter=pwm",
                      "faults=on,screw=rigid")}


def _write(tmp, name, content) -> str:
    path = tmp / name
    path.write_bytes(content if isinstance(content, bytes) else content.encode("utf-8"))
    return str(path)


def _api_cases():
    from ema_casadi.faults import healthy_runs, load_faults
    from ema_casadi.identification import IdentificationError, read_record, synthetic_record
    from ema_casadi.limitcycle import describing_function, periodic_orbit
    from ema_casadi.mission import MissionError, load_mission
    from ema_casadi.optimal import performance_envelope
    from ema_casadi.simulation import SimulationError

    S, sim = E.signals.SignalError, E.simulate
    cases = {
        "eta-1.5": (lambda c: sim(c["m"][""], 0.001, eta=1.5), S, "eta"),
        "eta-0": (lambda c: sim(c["m"][""], 0.001, inputs={"eta": 0.0}), S, "eta"),
        "eta-signal": (lambda c: sim(c["m"][""], 0.001, eta="0.9+step:0.5@0.0005"), S, "(0, 1]"),
        "T_amb": (lambda c: sim(c["m"]["thermal=lumped"], 0.001, T_amb=-300.0), S, "-273.15"),
        "a_jam": (lambda c: sim(c["m"]["faults=on"], 0.001, a_jam=2.0), S, "jam fault"),
        "a_shear": (lambda c: sim(c["m"]["faults=on"], 0.001, a_shear="1.5"), S, "disconnect fault"),
        "a_shear-rigid": (lambda c: sim(c["m"]["faults=on,screw=rigid"], 0.001, a_shear="step:1@0.0005"), S,
                          "needs screw = elastic"),
        "eta-no-effect": (lambda c: sim(c["m"]["thermal=lumped"], 0.001, eta=0.8), S, "has no effect"),
        "sweep-eta": (lambda c: E.load_sweep(_write(c["tmp"], "s.toml", SWEEP.format(inputs="eta = 1.5")),
                                             c["params"]), E.SweepError, "inputs eta"),
        "sweep-eta-no-effect": (lambda c: E.load_sweep(_write(c["tmp"], "s.toml", '[variants]\nthermal = "lumped"\n'
                                                       + SWEEP.format(inputs="eta = 0.8")), c["params"]),
                                E.SweepError, "has no effect"),
        "mission-T_amb": (lambda c: load_mission(_write(c["tmp"], "m.toml", MISSION), c["params"]), MissionError,
                          "T_amb"),
        "prior-latin-1": (lambda c: E.design_experiment(c["params"], "F_seal", 2.0, prior=_write(
            c["tmp"], "p.toml", PRIORS["latin-1"][0])), E.DesignError, "--prior"),
        "prior-estimate-0": (lambda c: E.design_experiment(c["params"], "F_seal", 2.0,
                                                           prior={"F_seal": (0.0, -20.0, 20.0)}), E.DesignError,
                             "F_seal estimate 0"),
        "prior-inf": (lambda c: E.design_experiment(c["params"], "F_seal", 2.0,
                                                    prior={"F_seal": (150.0, 120.0, math.inf)}), E.DesignError,
                      "not finite"),
        "optimal-transport": (lambda c: E.optimal_move(c["m"]["airframe=transport"], 2e-3), E.OptimalError,
                              "airframe=transport"),
        "envelope-transport": (lambda c: performance_envelope(c["m"]["airframe=transport"]), E.OptimalError,
                               "airframe=transport"),
        "design-transport": (lambda c: E.design_experiment(c["params"], "F_seal", 2.0,
                                                           variants={"airframe": "transport"}), E.DesignError,
                             "airframe=transport"),
        "record-transport": (lambda c: synthetic_record(c["params"], c["tmp"] / "r.csv", t_end=0.01,
                                                        variants={"airframe": "transport"}), IdentificationError,
                             "x_cmd"),
        "design-channels": (lambda c: E.design_experiment(c["params"], "F_seal", 2.0, channels=[]), E.DesignError,
                            "--channels"),
        "design-seed": (lambda c: E.design_experiment(c["params"], "F_seal", 2.0, draws=2, seed=-1), E.DesignError,
                        "--seed"),
        "healthy-seed": (lambda c: healthy_runs(load_faults(REFERENCE.parent / "faults_reference.toml",
                                                            c["params"]), 2, seed=-1), E.FaultError, "seed"),
        "envelope-distance-inf": (lambda c: performance_envelope(c["m"][""], distances=[math.inf]), E.OptimalError,
                                  "distances"),
        "envelope-distance-stroke": (lambda c: performance_envelope(c["m"][""], distances=[0.5]), E.OptimalError,
                                     "stroke"),
        "orbit-pwm": (lambda c: periodic_orbit(c["m"]["inverter=pwm"]), SimulationError, "inverter=pwm"),
        "describing-function-pwm": (lambda c: describing_function(c["m"]["inverter=pwm"], "position", [1e-6], [5.0],
                                                                  p=c["m"]["inverter=pwm"].p(),
                                                                  x0=c["m"]["inverter=pwm"].x0()),
                                    SimulationError, "inverter=pwm"),
        "record-beyond-travel": (lambda c: read_record(_write(c["tmp"], "r.csv", _record("0.5", True)), c["m"][""]),
                                 IdentificationError, "travel"),
    }
    return cases


API = _api_cases()


@pytest.mark.parametrize("case_id", list(API))
def test_the_api_refuses_the_same_values(case_id, params, models, tmp_path):
    call, error, offender = API[case_id]
    with pytest.raises(error) as exc:
        call({"params": params, "m": models, "tmp": tmp_path})
    assert isinstance(exc.value, InputError), type(exc.value)  # exit status 2 from the command line
    msg = str(exc.value)
    assert "\n" not in msg and offender in msg, msg
    assert not any(p.name not in ("s.toml", "m.toml", "p.toml", "r.csv") for p in tmp_path.iterdir())


def test_a_refusal_as_a_process_prints_one_line(tmp_path):
    """As the ``ema`` process: the one line and nothing else reaches stderr (no
    traceback of a decoding error)."""
    import subprocess
    import sys

    case = CASES["prior-latin-1"]
    (tmp_path / "p.toml").write_bytes(case.files["p.toml"])
    proc = subprocess.run([sys.executable, "-m", "ema_casadi.cli", *(a.format(tmp=tmp_path) for a in case.argv)],
                          capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert proc.returncode == 2, proc.stderr
    assert len(proc.stderr.splitlines()) == 1 and "--prior" in proc.stderr, proc.stderr
    assert proc.stdout == "" and sorted(p.name for p in tmp_path.iterdir()) == ["p.toml"]
