"""The reliability battery, second pass: the commands added since the first
battery (mission, sweep, aircraft, limit-cycle, the FMU exports, the new variants and
parameter tables) each given one mistake, one meaningless value, one size the machine
cannot do, one output that cannot be written, one flag that does not apply.

Every CLI case runs in-process through ``ema_casadi.cli.main`` and asserts its exit
status (2: a mistake, refused before any work; 3: a failed run), exactly one line on
stderr naming the offender (the flag, key or file), no traceback, nothing on stdout
for a refusal, and that nothing is left anywhere: the test's folder holds exactly the
files the case put there, and the system's temporary folder (``$TMPDIR``, pointed at
a private folder for the test) holds nothing new. Every refusal comes before any heavy
work (tiny runs and grids where a run would follow), so the battery is fast.
"""

from __future__ import annotations

import re
import tempfile
from dataclasses import dataclass, field

import pytest

from conftest import REFERENCE, SMALL_SWEEP
from ema_casadi.cli import main

REF = str(REFERENCE)
TEXT = REFERENCE.read_text(encoding="utf-8")


@dataclass
class Case:
    argv: list  # the whole command line; {tmp} is the case's folder, {model} the model file
    offender: str | list
    files: dict = field(default_factory=dict)  # name -> text; a name ending in / is a folder
    status: int = 2
    model: str = REF


def edit(old: str, new: str) -> str:
    assert old in TEXT, old
    return TEXT.replace(old, new, 1)


def param(table: str, key: str, value: str, unit: str) -> str:
    """The reference file with ``[table] key`` set to ``value`` (added if absent)."""
    line = f'{key} = {{ value = {value}, unit = "{unit}" }}'
    new, n = re.subn(rf"(?m)^{key} = \{{[^}}]*\}}", line, TEXT, count=1)
    return new if n else TEXT.replace(f"[{table}]\n", f"[{table}]\n{line}\n", 1)


CASES: dict[str, Case] = {}


def add(case_id: str, case: Case) -> None:
    assert case_id not in CASES, case_id
    CASES[case_id] = case


# -- the files the cases read -------------------------------------------------------------
def mission(*segments: str, head: str = '[mission]\nname = "m"\n') -> str:
    return head + "".join(f"[[segment]]\n{s}\n" for s in segments)


SEG = 'name = "{name}"\nduration = {duration}\nx_cmd = "0"\nf_ext = "0"\nT_amb = 20.0'
OK_MISSION = mission(SEG.format(name="a", duration=1.0))
SWEEP = SMALL_SWEEP
SPAN = "1um,2um"
LC = ["limit-cycle", "{model}", "--amplitudes", SPAN, "--freqs", "5,6", "--t-end", "0", "--periods", "4"]
MISSION = ["mission", "{model}", "{tmp}/m.toml", "--out", "{tmp}/out", "--no-progress", "--fast"]
SIM = ["simulate", "{model}", "--t-end", "0.001"]
FR = ["freqresp", "{model}", "--amplitudes", "1mm", "--freqs", "1", "--max-periods", "3"]
AC = ["aircraft", "{model}", "--condition", "cruise_sl"]
SW = ["sweep", "{model}", "{tmp}/s.toml", "--jobs", "1"]

# -- sizes: estimated and refused before anything is allocated ----------------------------
for dur, what in (("1e9", "1e+12 envelope samples"), ("2e5", "2e+08 envelope samples")):
    add(f"size-mission-segment-{dur}", Case(MISSION, ["segment 1 ('a') duration", what],
                                            {"m.toml": mission(SEG.format(name="a", duration=dur))}))
add("size-mission-steps", Case([*MISSION[:-1], "--dt", "1e-9"], ["mission's 2 s", "RK4 steps", "MAX_STEPS"],
                               {"m.toml": mission(SEG.format(name="a", duration=2.0))}))
for n in ("1000000000000", "2000000"):
    add(f"size-sweep-axis-{n}", Case(SW, ["[parameters] B points", "MAX_RUNS", "runs"],
                                     {"s.toml": SWEEP.replace("values = [2e-5, 1e-4]",
                                                              f"from = 1e-5, to = 1e-4, points = {n}")}))
for flag, value in (("--amplitudes", "1um-30um:1000000000000"), ("--freqs", "1-10:1000000000000"),
                    ("--amplitudes", "1um-30um:401")):
    argv = [*LC]
    argv[argv.index(flag) + 1] = value
    add(f"size-limit-cycle{flag}-{value.split(':')[1]}", Case(argv, [f"{flag} {value}", "points"]))
add("size-limit-cycle-grid", Case([*LC[:2], "--amplitudes", "1um-30um:30", "--freqs", "1-10:30", *LC[6:]],
                                  ["--amplitudes/--freqs", "30 x 30", "MAX_GRID"]))

# -- outputs: checked up front ---------------------------------------------------------------
for case_id, out, message in (("proc", "/proc/ema_out", "cannot write in /proc"),
                              ("below-a-file", "{tmp}/afile/out", "is not a folder"),
                              ("is-a-file", "{tmp}/afile", "exists and is not a folder"),
                              ("empty", "", "empty path"),
                              ("proc-below", "/proc/ema/out", "cannot write in /proc")):
    argv = [*MISSION]
    argv[argv.index("--out") + 1] = out
    add(f"out-mission-{case_id}", Case(argv, ["--out", message], {"m.toml": OK_MISSION, "afile": "x"}))
for fmt in ("json", "mat", "npz", "fmu-me", "fmu-cs", "c", "casadi"):
    add(f"out-export-{fmt}-empty", Case(["export", "{model}", "--format", fmt, "--out", ""], ["--out", "empty path"]))
EMPTY_OUTPUTS = {
    "simulate-out": [*SIM, "--out", ""], "simulate-plot": [*SIM, "--plot", ""],
    "sweep-out": [*SW, "--out", ""], "sweep-plot": [*SW, "--plot", ""],
    "freqresp-out": [*FR, "--out", ""], "freqresp-plot": [*FR, "--plot", ""],
    "limit-cycle-plot": [*LC, "--plot", ""], "margins-plot": ["margins", "{model}", "--plot", ""],
    "bode-plot": ["bode", "{model}", "--points", "5", "--plot", ""],
    "linearize-out": ["linearize", "{model}", "--out", ""],
    "aircraft-plot-dir": [*AC, "--no-responses", "--plot-dir", ""], "tune-out": ["tune", "{model}", "--out", ""],
}
for case_id, argv in EMPTY_OUTPUTS.items():
    flag = next(a for a in argv if a.startswith("--") and argv[argv.index(a) + 1] == "")
    add(f"out-{case_id}-empty", Case(argv, flag, {"s.toml": SWEEP}))
for cmd, argv, name in (("simulate", SIM, "x.csv"), ("sweep", SW, "s.csv"), ("freqresp", FR, "f.csv"),
                        ("export", ["export", "{model}", "--format", "json"], "l.json"),
                        ("linearize", ["linearize", "{model}"], "l.mat")):
    for case_id, where, message in (("proc", "/proc/" + name, "/proc"), ("below-a-file", "{tmp}/afile/" + name,
                                                                        "is a file")):
        add(f"out-{cmd}-{case_id}", Case([*argv, "--out", where], ["--out", message], {"s.toml": SWEEP, "afile": "x"}))

# -- values that mean nothing ------------------------------------------------------------------
for key, value in (("duration", "0"), ("dt", "0"), ("duration", "-1"), ("dt_out", "0"), ("event_tol", "0"),
                   ("rtol", "0")):
    text = re.sub(rf"(?m)^{key} = .*$", f"{key} = {value}", SWEEP) if f"\n{key} =" in SWEEP else \
        SWEEP.replace("[scenario]\n", f"[scenario]\n{key} = {value}\n")
    add(f"value-sweep-{key}-{value}", Case(SW, [f"[scenario] {key}", "must be positive"], {"s.toml": text}))
for level in ("10", "0"):
    add(f"value-sweep-bandwidth-level-{level}",
        Case(SW, ["[metrics] bandwidth level_db", "negative"],
             {"s.toml": SWEEP.replace("peak = {}", f"bandwidth = {{ level_db = {level} }}")}))
for flag, value, message in (("--k-i-x", "-3000", "must be non-negative"), ("--backlash", "-0.1", "must be non-neg"),
                             ("--k-i-x", "nan", "finite"), ("--backlash", "inf", "finite")):
    add(f"value-limit-cycle{flag}{value}", Case([*LC, "--variant", "controller=PI", f"{flag}={value}"],
                                                [f"{flag} {value}", message]))
for flag, value in (("--amplitudes", "30um-1um:7"), ("--freqs", "10-1:5"), ("--amplitudes", "1um-30um:1"),
                    ("--amplitudes", "0um-30um:5")):
    argv = [*LC]
    argv[argv.index(flag) + 1] = value
    add(f"value-limit-cycle-range{flag}-{value}", Case(argv, [f"{flag} {value}", "increasing"]))
for value in ("1e6", "-1e6", "sine:1e4@1", "400"):
    add(f"value-simulate-T_amb-{value}", Case([*SIM, "--variant", "thermal=lumped", "--input", f"T_amb={value}"],
                                              ["--input T_amb", "degC", "beyond"]))
RELATIONS = {
    "t_dead-1ms": (param("power", "t_dead", "1e-3", "s"), "[power] t_dead"),
    "t_dead-10us": (param("power", "t_dead", "1e-5", "s"), "[power] t_dead"),
    "a_pin-inside-horn": (param("airframe", "a_pin", "0.1", "m"), "[airframe] a_pin"),
    "a_pin-at-horn": (param("airframe", "a_pin", "0.15", "m"), "[airframe] a_pin"),
    "a_pin-stroke-unreachable": (param("airframe", "a_pin", "0.17", "m"), "[airframe] a_pin"),
}
for i, (case_id, (text, message)) in enumerate(RELATIONS.items()):
    cmd = (SIM, ["linearize", "{model}"], [*AC, "--no-responses"], ["margins", "{model}"], FR)[i]
    add(f"value-param-{case_id}", Case(cmd, ["bad.toml", message], {"bad.toml": text}, model="{tmp}/bad.toml"))
add("value-mission-duplicate-names", Case(MISSION, ["segment 2 ('a') name", "segment 1"],
                                          {"m.toml": mission(SEG.format(name="a", duration=1.0),
                                                             SEG.format(name="a", duration=1.0))}))
add("value-mission-duplicate-names-far", Case(MISSION, ["segment 3 ('a') name"], {"m.toml": mission(
    SEG.format(name="a", duration=1.0), SEG.format(name="b", duration=1.0), SEG.format(name="a", duration=1.0))}))
add("value-mission-segment-unresolved", Case(MISSION, ["segment 'a'", "dt_out"],
                                             {"m.toml": mission(SEG.format(name="a", duration=1e-6))}))
# flags that do not apply
NOT_APPLYING = {
    "export-fmi-version-fmu-me": (["export", "{model}", "--format", "fmu-me", "--fmi-version", "2.0"],
                                  ["--fmi-version", "only fmu-cs"]),
    "export-fmi-version-json": (["export", "{model}", "--format", "json", "--fmi-version", "3.0"], "--fmi-version"),
    "export-fmi-version-c": (["export", "{model}", "--format", "c", "--fmi-version", "2.0"],
                             ["--fmi-version", "only fmu-cs"]),
    "export-dt-json": (["export", "{model}", "--format", "json", "--dt", "1e-5"], "--dt"),
    "export-dt-mat": (["export", "{model}", "--format", "mat", "--dt", "1e-5"], "--dt"),
    "export-dt-npz": (["export", "{model}", "--format", "npz", "--dt", "1e-5"], "--dt"),
    "export-dt-fmu-me": (["export", "{model}", "--format", "fmu-me", "--dt", "1e-5"], ["--dt", "nothing of it steps"]),
    "export-open-fmu-cs": (["export", "{model}", "--format", "fmu-cs", "--open", "position"], "--open"),
    "export-open-casadi": (["export", "{model}", "--format", "casadi", "--open", "velocity"], "--open"),
    "limit-cycle-airframe-position": ([*LC, "--airframe", "b747"], "--airframe"),
    "limit-cycle-condition-position": ([*LC, "--condition", "landing"], "--condition"),
}
for flag in ("--dt", "--t-end", "--gust", "--gust-time", "--step-deg"):
    NOT_APPLYING[f"aircraft{flag}-no-responses"] = ([*AC, "--no-responses", flag, "1e-4" if flag == "--dt" else "3"],
                                                    flag)
NOT_APPLYING["aircraft-zoh-no-responses"] = ([*AC, "--no-responses", "--zoh"], "--zoh")
for case_id, (argv, flag) in NOT_APPLYING.items():
    add(f"unused-{case_id}", Case(argv, flag if isinstance(flag, list) else [flag, "has no effect"]))

# -- crashes on valid input, and values beyond any physical meaning ----------------------------
for af in ("b747", "transport"):
    add(f"crash-simulate-airframe-{af}-x-cmd", Case([*SIM, "--variant", f"airframe={af}", "--x-cmd", "1mm"],
                                                    ["--x-cmd", "theta_cmd"]))
for argv, message in (([*AC, "--no-responses", "--variant", "airframe=a320"], "--variant airframe=a320"),
                      ([*AC, "--no-responses", "--variant", "airframe=b747", "--airframe", "transport"], "disagree"),
                      ([*LC, "--loop", "aircraft", "--variant", "airframe=a320"], "--variant airframe=a320"),
                      ([*LC, "--loop", "aircraft", "--variant", "airframe=transport", "--airframe", "b747"],
                       "disagree")):
    add(f"crash-airframe-{argv[0]}-{message.split()[-1]}", Case(argv, message))
for cmd in ("margins", "linearize", "bode", "export"):
    extra = ["--format", "json", "--out", "{tmp}/l.json"] if cmd == "export" else []
    for flag, value in (("--f-ext", "1e300"), ("--f-ext", "-1e300"), ("--v-rod", "1e300")):
        add(f"crash-{cmd}{flag}{value}", Case([cmd, "{model}", *extra, f"{flag}={value}"],
                                              [flag, "physical envelope"]))  # the API's f_ext named by its flag
for value in ("step:1e300mm", "1e30", "sine:1e30mm@1", "step:300mm", "-250mm"):
    add(f"crash-simulate-x-cmd-{value}", Case([*SIM, "--x-cmd", value], ["--x-cmd", "beyond", "stroke"]))
add("crash-simulate-f-ext-huge", Case([*SIM, "--f-ext", "1e300"], ["f_ext", "force the motor holds"], status=3))
# a sine above the Nyquist rate of the sampling
for flag, value, extra in (("--x-cmd", "sine:1mm@1e9", []), ("--x-cmd", "sine:1mm@1e5", []),
                           ("--x-cmd", "chirp:1mm@1-1e6", []), ("--f-ext", "sine:1kN@1e6", []),
                           ("--input d_x", "sine:1um@1e6", []),
                           ("--x-cmd", "sine:1mm@6000", ["--solver", "cvodes", "--dt-out", "1e-4"]),
                           ("--x-cmd", "sine:1mm@20000", ["--solver", "rk4", "--dt", "2.5e-5"])):
    args = ["--input", value.join(("d_x=", ""))] if flag.startswith("--input") else [flag, value]
    add(f"nyquist-simulate{flag.replace(' ', '-')}-{value}-{len(extra)}",
        Case([*SIM, *extra, *args], [flag, "Nyquist"]))
# a load the actuator cannot hold: a failed point, exit 3
for loads in ("60kN", "-60kN", "0,55kN", "100kN"):
    add(f"failed-freqresp-load-{loads}", Case([*FR, "--loads", loads], ["above the", "kN the actuator holds"],
                                              status=3))

# -- messages that name the flags, not internals ---------------------------------------------------
add("names-limit-cycle-t-end", Case([*LC[:-4], "--t-end", "7000", "--periods", "4"], ["--t-end 7000 s", "MAX_"]))
add("names-limit-cycle-backlash", Case([*LC, "--backlash=-1"], "--backlash -1"))
add("names-limit-cycle-k-i-x", Case([*LC, "--variant", "controller=PI", "--k-i-x=-1"], "--k-i-x -1"))


# -- the harness ------------------------------------------------------------------------------------
def _files(root):
    return sorted(str(p.relative_to(root)) + ("/" if p.is_dir() else "") for p in root.rglob("*"))


@pytest.fixture
def private_tmpdir(tmp_path, monkeypatch):
    """$TMPDIR (and Python's tempfile) pointed at an empty folder of the test."""
    d = tmp_path / "TMPDIR"
    d.mkdir()
    monkeypatch.setenv("TMPDIR", str(d))
    monkeypatch.setattr(tempfile, "tempdir", str(d))
    return d


@pytest.mark.parametrize("case_id", list(CASES))
def test_cli(case_id, tmp_path, capsys, monkeypatch, private_tmpdir):
    case = CASES[case_id]
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    for name, content in case.files.items():
        (work / name).mkdir() if name.endswith("/") else (work / name).write_text(content, encoding="utf-8")
    before = _files(work)
    model = case.model.format(tmp=work)
    argv = [a.format(tmp=work, model=model) for a in case.argv]
    try:
        status = main(argv)
    except SystemExit as exc:
        status = exc.code
    out, err = capsys.readouterr()
    assert status == case.status, err
    assert err.endswith("\n") and err.count("\n") == 1, err
    for offender in case.offender if isinstance(case.offender, list) else [case.offender]:
        assert offender.format(tmp=work) in err, f"{offender!r} not in {err!r}"
    assert "Traceback" not in err
    if case.status == 2:
        assert out == ""
    assert _files(work) == before, "a file was left behind"
    assert _files(private_tmpdir) == [], "a temporary file was left in $TMPDIR"


def test_the_battery_covers_every_class():
    assert len(CASES) >= 120
    prefixes = {c.split("-")[0] for c in CASES}
    assert prefixes == {"size", "out", "value", "unused", "crash", "nyquist", "failed", "names"}


# -- the Python API: the same shared checks, the toolkit's own exception types ---------------------
@pytest.fixture(scope="module")
def api(params, model_cache):
    return {"params": params, "model": model_cache(), "thermal": model_cache(thermal="lumped")}


def _api_cases():
    import ema_casadi as E
    from ema_casadi import frequency, signals
    from ema_casadi._util import _checks
    from ema_casadi.model import checked
    from ema_casadi.simulation._inputs import check_inputs

    nan = float("nan")
    return {
        "checked-negative": (lambda c: checked("B", -1e-4), E.ParameterError, "B"),
        "checked-unknown": (lambda c: checked("Bx", 1.0), TypeError, "Bx"),
        "checked-where": (lambda c: checked("K_i_x", -1.0, "--k-i-x -1"), E.ParameterError, "--k-i-x"),
        "checked-table-entry": (lambda c: checked("eta_T_0", 1.5), E.ParameterError, "eta_T_0"),
        "p-override-nan": (lambda c: c["model"].p(B=nan), E.ParameterError, "B"),
        "replace-t-dead": (lambda c: c["params"].replace(t_dead=1e-3), E.ParameterError, "t_dead"),
        "replace-a-pin": (lambda c: c["params"].replace(a_pin=0.1), E.ParameterError, "a_pin"),
        "bandwidth-level-positive": (lambda c: frequency.bandwidth(E.closed_loop(c["model"]), level_db=10),
                                     E.LinearizationError, "level_db"),
        "op-f-ext-huge": (lambda c: E.operating_point(c["model"], f_ext=1e300), E.OperatingPointError, "f_ext"),
        "op-v-rod-huge": (lambda c: E.operating_point(c["model"], v_rod=-1e30), E.OperatingPointError, "v_rod"),
        "simulate-T-amb-huge": (lambda c: E.simulate(c["thermal"], 0.001, T_amb=1e6), E.RunFailed, "T_amb"),
        "simulate-f-ext-huge": (lambda c: E.simulate(c["model"], 0.001, f_ext=1e300), E.RunFailed, "f_ext"),
        "check-inputs-limit": (lambda c: check_inputs(c["model"], {"x_cmd": E.Signal.step(1.0)}, 0.1, {}, None,
                                                      E.SignalError, {"x_cmd": (0.225, "3 x the stroke")}),
                               E.SignalError, "3 x the stroke"),
        "simulate-aliasing": (lambda c: E.simulate(c["model"], 0.001, x_cmd=E.Signal.sine(1e-3, 1e9), dt=5e-6),
                              E.SignalError, "Nyquist"),
        "simulate-aliasing-cvodes": (lambda c: E.simulate(c["model"], 0.01, x_cmd=E.Signal.sine(1e-3, 1e4),
                                                          solver="cvodes", dt_out=1e-4), E.SignalError, "Nyquist"),
        "budget": (lambda c: _checks.budget(1e12, 1e6, "grid", E.SweepError), E.SweepError, "1e+12"),
        "budget-nan": (lambda c: _checks.budget(nan, 1e6, "grid", E.SweepError), E.SweepError, "grid"),
        "log-grid-reversed": (lambda c: signals.log_grid("30-1:5", "frequency", "Hz", "--freqs", E.SignalError, 10),
                              E.SignalError, "increasing"),
        "log-grid-huge": (lambda c: signals.log_grid("1-30:1000000000000", "frequency", "Hz", "--freqs",
                                                     E.SignalError, 10**5), E.SignalError, "1e+12"),
        "number-negative": (lambda c: _checks.number(0.0, "level", E.SweepError, negative=True), E.SweepError,
                            "negative"),
    }


API = list(_api_cases())


@pytest.mark.parametrize("case_id", API)
def test_api(case_id, api):
    call, error, offender = _api_cases()[case_id]
    with pytest.raises(error) as exc:
        call(api)
    msg = str(exc.value)
    assert "\n" not in msg and offender in msg, msg


def test_a_load_beyond_the_hold_force_is_a_failed_point_not_a_number(params):
    """60 kN is above the 54.5 kN the reference actuator holds at standstill: that
    point has no response to measure (status failed, NaN), the 0 kN point runs."""
    import numpy as np

    import ema_casadi as E

    r = E.sine_stream(params, [1e-3], [1.0], loads=[0.0, 60e3], max_periods=3)
    rows = r.rows()
    assert rows[0]["status"] != "failed" and rows[1]["status"] == "failed"
    assert "holds at standstill" in rows[1]["reason"]
    assert np.isnan(rows[1]["gain_db"]) and np.isfinite(rows[0]["gain_db"])


# -- valid input that used to crash: now a result --------------------------------------------------
VALID = {
    "simulate-airframe-b747": ["simulate", REF, "--variant", "airframe=b747", "--t-end", "0.01", "--json"],
    "simulate-airframe-transport": ["simulate", REF, "--variant", "airframe=transport", "--t-end", "0.01",
                                    "--input", "theta_cmd=step:0.01@0.001", "--json"],
    "aircraft-variant-airframe": ["aircraft", REF, "--variant", "airframe=b747", "--no-responses", "--json"],
}


@pytest.mark.parametrize("name", list(VALID))
def test_valid_input_that_crashed_gives_a_result(name, tmp_path, capsys, monkeypatch):
    import json
    import math

    monkeypatch.chdir(tmp_path)
    assert main(VALID[name]) == 0, capsys.readouterr().err
    out = json.loads(capsys.readouterr().out)
    if name.startswith("simulate"):
        assert out["variants"]["airframe"] == name.rsplit("-", 1)[1]
        assert all(math.isfinite(v) for v in out["final"].values())
    else:
        assert out["airframe"] == "b747", out.get("airframe")
