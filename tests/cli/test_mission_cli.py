"""`ema mission`: a short mission end to end (files, --json, progress), and its errors
(exit 2, one line naming the file and key, nothing written)."""

import json
import subprocess
import sys

import pytest

from conftest import REFERENCE
from ema_casadi.cli import main

SHORT = """
[mission]
name = "short"
T_start = 30.0

[limits]
T_w = 150.0

[[segment]]
name = "check"
duration = 3.0
x_cmd = "step:20mm@0.2+step:-20mm@1.5"
f_ext = "2kN"
T_amb = 30.0

[[segment]]
name = "hold"
duration = 2.0
x_cmd = "-1mm+sine:0.5mm@2"
f_ext = "-15kN"
T_amb = [30, 0]
"""


@pytest.fixture
def short(tmp_path):
    path = tmp_path / "short.toml"
    path.write_text(SHORT)
    return path


def test_mission_writes_csv_figure_summary_and_json(tmp_path, short):
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "-m", "ema_casadi.cli", "mission", str(REFERENCE), str(short),
                           "--out", str(out), "--json"], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    r = json.loads(proc.stdout)
    assert r["mission"] == "short" and r["duration_s"] == 5.0
    assert [s["name"] for s in r["segments"]] == ["check", "hold"]
    assert r["peaks"]["T_w"]["limit_degC"] == 150.0 and r["limits_ok"] is True
    assert r["energy_J"]["P_cu"] > 0 and r["energy_by_part_J"]["motor"] >= r["energy_J"]["P_cu"]
    assert "mission [" in proc.stderr and "100.0%" in proc.stderr  # progress on the terminal
    for name in ("short.csv", "short.png", "short_summary.json"):
        assert (out / name).stat().st_size > 0
    assert json.loads((out / "short_summary.json").read_text())["mission"] == "short"
    rows = (out / "short.csv").read_text().splitlines()
    assert rows[0].split(",")[:4] == ["time", "segment", "T_amb", "T_w"] and len(rows) == 2 + 6


def test_mission_report_and_quiet(tmp_path, short, capsys):
    assert main(["mission", str(short), "--out", str(tmp_path), "--quiet"]) == 0
    captured = capsys.readouterr()
    assert captured.err == ""
    assert "peak temperatures (degC):" in captured.out and "limit 150: ok" in captured.out
    assert "total" in captured.out and "wrote" in captured.out


@pytest.mark.parametrize(
    "edit, pattern",
    [
        (('duration = 3.0', 'duraton = 3.0'),
         r"segment 1 \('check'\): unknown key 'duraton' \(did you mean 'duration'"),
        (('f_ext = "2kN"', 'f_ext = "2kg"'), r"segment 1 \('check'\) f_ext: '2kg': unknown force unit 'kg'"),
        (('x_cmd = "step:20mm@0.2', 'x_cmd = "step:90mm@0.2'), r"x_cmd: reaches 90 mm .* beyond the stroke"),
        (('T_amb = [30, 0]', 'T_amb = [30, 0, 1]'), r"segment 2 \('hold'\) T_amb: expected \[start, end\]"),
    ],
)
def test_bad_mission_exits_2_with_one_line(tmp_path, short, capsys, edit, pattern):
    import re

    short.write_text(SHORT.replace(*edit))
    out = tmp_path / "out"
    assert main(["mission", str(short), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(short) in err and re.search(pattern, err), err
    assert not out.exists()


@pytest.mark.parametrize(
    "argv, pattern",
    [
        (["none.toml"], r"none.toml: no such mission file"),
        (["--dt", "0"], r"--dt must be a positive number of seconds"),
        (["--fast", "--dt", "1e-4"], r"--fast sets the step; give --fast or --dt, not both"),
        (["--csv-dt", "0.001"], r"--csv-dt \(0.001 s\) must not be shorter than --dt-out"),
        (["--variant", "thermal=off"], r"a mission needs the thermal network: variant thermal = lumped"),
        (["--variant", "termal=off"], r"unknown variant key 'termal' \(did you mean 'thermal'\?\)"),
    ],
)
def test_bad_flags_exit_2(tmp_path, short, capsys, argv, pattern):
    import re

    args = ["mission", str(REFERENCE)] + ([] if argv[0].endswith(".toml") else [str(short)]) + argv
    assert main([*args, "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and re.search(pattern, err), err


def test_a_failed_run_exits_3(tmp_path, short, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["mission", str(short), "--out", str(tmp_path / "o"), "--dt", "2e-3", "--dt-out", "2e-3", "--quiet"])
    assert exc.value.code == 3
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "the run failed" in err
    assert not (tmp_path / "o").exists()
