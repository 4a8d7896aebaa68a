"""`ema faults` and `ema.run_faults`: a small fault table end to end (files, --json),
and its errors (exit 2, one line naming the file and key, nothing written)."""

import json
import subprocess
import sys

import pytest

import ema_casadi as ema
from conftest import DISCONNECT, REFERENCE, ROOT, assert_glance

SMALL = """
[scenario]
duration = 0.25
x_cmd = "ramp:40mm/s"
dt = 1e-5
sensor = "real"

[[fault]]
kind = "jam"
onset = 0.05

[[fault]]
kind = "stuck"
target = "x_s"
onset = [0.05, 0.1]
"""


def _write(tmp_path, text, name="f.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def _ema(*args):
    return subprocess.run([sys.executable, "-m", "ema_casadi.cli", "faults", *map(str, args)], capture_output=True,
                          text=True)


@pytest.mark.slow  # 21 s: the whole reference table through the CLI (test_run_faults_api_... is the fast one)
def test_faults_writes_table_summary_figure(tmp_path):
    out = tmp_path / "out"
    proc = _ema(REFERENCE, _write(tmp_path, SMALL), "--out", out, "--json", "--healthy-runs", "3", "--jobs", "1")
    assert proc.returncode == 0, proc.stderr
    r = json.loads(proc.stdout)
    h = r["healthy_runs"]  # three noisy runs with +-5 % tolerances through the sweep engine
    assert h["runs"] == 3 and h["failed"] == 0 and h["false_alarms"] == 0
    assert [row["case"] for row in r["rows"]] == ["none", "jam", "stuck x_s", "stuck x_s"]
    assert r["false_alarms_no_fault"] == []
    jam, stuck = r["rows"][1], r["rows"][2]
    assert jam["first_monitor"] == "latch_jam" and stuck["detected_latch_cross_s"] is not None
    assert 0 < stuck["detected_latch_cross_s"] < 0.05  # within a few confirmation times
    for ext in ("csv", "json", "png"):
        assert (out / f"f.{ext}").stat().st_size > 0
    rows = (out / "f.csv").read_text().splitlines()
    assert rows[0].startswith("case,kind,target,onset_s") and len(rows) == 1 + 4


def test_run_faults_api_returns_rows_and_a_figure(params):
    study = {"scenario": {"duration": 0.2, "x_cmd": "ramp:40mm/s", "sensor": "real"},
             "fault": [{"kind": "loss", "target": "x_s", "onset": 0.05}, {"kind": "jam", "onset": 0.05}]}
    res = ema.run_faults(params, study)
    again = ema.run_faults(params, study)  # the cases run on two threads: the same rows, bit for bit
    assert res.rows == again.rows
    assert len(res.rows) == 3 and res.rows[1]["kind"] == "loss"
    assert "cases=3" in assert_glance(res)
    # the rod sensor reads 0 while the rod is at 2 mm: the cross-check catches it
    assert res.rows[1]["detected_latch_cross_s"] is not None
    fig = res.plot()
    assert len(fig.axes) == 2


@pytest.mark.parametrize("text, says", [
    ('[[fault]]\nkind = "jamm"\n', "unknown fault kind 'jamm' (did you mean 'jam'?)"),
    ('[[fault]]\nkind = "stuck"\ntarget = "x_rodd"\n', "unknown target 'x_rodd' (did you mean 'x_s'?)"),
    ('[scenario]\nduration = 0.5\n[[fault]]\nkind = "jam"\nonset = 0.7\n', "onset: 0.7 s is outside the run"),
    ('[[fault]]\nkind = "supply"\nseverity = 1.5\n', "severity: 1.5 is outside the range"),
    ('[monitor]\nt_jam = { value = 20, unit = "m" }\n', "t_jam: unit 'm' is not the expected SI unit 's'"),
    ('[[fault]]\nkind = "jam"\nonst = 0.1\n', "unknown key 'onst' (did you mean 'onset'?)"),
    ('[scenario]\nairframe = "transport"\nx_cmd = "1mm"\n', "x_cmd: in the aircraft loop the flight-control law"),
    ('[scenario]\nairframe = "transport"\ncondition = "cruise"\n', "'cruise' unknown (did you mean 'cruise_sl'?)"),
    (f'[scenario]\nmission = "{ROOT / "models" / "mission_regional.toml"}"\nsegment = "cruize"\n',
     "segment: 'cruize' unknown (did you mean 'cruise'?)"),
])
def test_bad_fault_files_exit_2_in_one_line_and_write_nothing(tmp_path, text, says):
    out = tmp_path / "out"
    proc = _ema(REFERENCE, _write(tmp_path, text), "--out", out)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and says in lines[0] and "f.toml" in lines[0], proc.stderr
    assert not out.exists()


def test_a_threshold_in_the_wrong_unit_in_the_parameter_file_exits_2(tmp_path):
    # a length in seconds (a convertible unit, 1 mm, would be accepted and converted)
    text = (ROOT / "models" / "cesa_ema.toml").read_text() + '\n[monitor]\ne_track = { value = 1, unit = "s" }\n'
    model = _write(tmp_path, text, "m.toml")
    proc = _ema(model, _write(tmp_path, SMALL), "--out", tmp_path / "out")
    assert proc.returncode == 2
    assert len(proc.stderr.strip().splitlines()) == 1 and "[monitor] e_track: unit 's'" in proc.stderr
    assert not (tmp_path / "out").exists()


def test_list_names_every_kind_and_monitor():
    proc = _ema("--list", "--json")
    assert proc.returncode == 0, proc.stderr
    r = json.loads(proc.stdout)
    assert {"jam", "free_run", "short", "supply", "bias", "drift", "stuck", "loss", "noise", "wear_friction",
            "wear_backlash"} <= set(r["kinds"])
    assert set(r["kinds"]["stuck"]) == {"x_s", "omega_s", "i_q_s"}
    assert r["monitors"] == ["latch_track", "latch_jam", "latch_cross", "latch_oc", "latch_ot"]


def test_faults_in_the_aircraft_loop_report_pitch_and_load_factor(params):
    # a jam 0.3 s into a 1 deg attitude step at sea-level cruise: the surface freezes,
    # so the attitude falls behind the no-fault flight; the jam monitor catches it
    res = ema.run_faults(params, {"scenario": {"duration": 1.0, "airframe": "transport", "condition": "cruise_sl",
                                               "theta_cmd": "step:1deg@0.1", "dt": 2e-5},
                                  "fault": [{"kind": "jam", "onset": 0.3}]})
    none, jam = res.rows
    assert none["peak_theta_dev"] == 0.0 and none["first_monitor"] is None
    assert jam["peak_theta_dev"] > 1e-3 and jam["peak_n_z_dev"] > 0.01  # rad, g (measured 0.2 deg, 0.1 g)
    assert jam["detected_latch_jam_s"] is not None


def test_a_mission_segment_is_a_scenario(params):
    # the approach segment of the reference mission (its command and load: -6 mm, a
    # 3 mm 0.4 Hz sine, -10 kN), cut to 1.5 s, with the rod sensor stuck at 1 s while
    # the rod moves: the cross-check catches it
    res = ema.run_faults(params, {"scenario": {"mission": str(ROOT / "models" / "mission_regional.toml"),
                                               "segment": "approach", "duration": 1.5},
                                  "fault": [{"kind": "stuck", "target": "x_s", "onset": 1.0}]})
    assert res.spec.scenario["text"]["x_cmd"] != 0 and res.rows[0]["first_monitor"] is None
    assert res.rows[1]["detected_latch_cross_s"] is not None


@pytest.mark.parametrize("n", ["3", "0", "49"])  # 0 is no run (it was read as the default 1000)
def test_a_threshold_study_below_its_minimum_of_runs_is_refused(tmp_path, n):
    from ema_casadi.faults import MIN_STUDY_RUNS

    out = tmp_path / "out"
    proc = _ema("--thresholds", "--healthy-runs", n, "--out", out)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
    assert f"healthy runs {n}:" in proc.stderr and f"give at least {MIN_STUDY_RUNS}" in proc.stderr
    assert not out.exists()
    assert f"at least {MIN_STUDY_RUNS}: the study's minimum" in " ".join(_ema("--help").stdout.split())


@pytest.mark.parametrize("args, words", [
    # the rigid screw has no coupling to shear: its rod is the motor's (it ran as a row "disconnect ok")
    (("--variant", "screw=rigid"), "kind: a disconnect fault needs screw = elastic, the model has screw = rigid"),
    # the study reads the monitors: switched off by the user, refused (it was switched back on)
    (("--variant", "monitors=off"), "variant monitors=off: a fault study injects the faults and reads the monitors"),
    (("--variant", "faults=off"), "variant faults=off:"),
])
def test_a_case_that_would_mean_nothing_is_refused(tmp_path, args, words):
    from ema_casadi.faults import FaultError, parse_faults

    out = tmp_path / "out"
    proc = _ema("--faults", _write(tmp_path, DISCONNECT), *args, "--out", out)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1 and words in proc.stderr, proc.stderr
    assert not out.exists()
    import re
    import tomllib

    key, value = args[1].split("=")
    params = ema.load_parameters(REFERENCE)
    with pytest.raises(FaultError, match=re.escape(words)):  # the API: the same class and line
        parse_faults(tomllib.loads(DISCONNECT), params, "<f>", {key: value})
    own = tomllib.loads(DISCONNECT.replace("[scenario]", f"[scenario]\n{key} = \"{value}\""))
    with pytest.raises(FaultError, match=re.escape(words)):  # the fault file's own choice
        parse_faults(own, params, "<f>")
