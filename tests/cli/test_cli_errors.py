"""Bad input: exit status 2, one line on stderr naming file and key, no output file."""

import re
import subprocess
import sys

import pytest

from conftest import REFERENCE
from ema_casadi.cli import main

TEXT = REFERENCE.read_text()


def edited(tmp_path, old, new):
    assert old in TEXT
    path = tmp_path / "bad.toml"
    path.write_text(TEXT.replace(old, new, 1))
    return path


CASES = {
    "missing key": (('M = { value = 3.0, unit = "kg" }', ""), r"\[screw\] missing key 'M'"),
    "unknown key": (('M = { value', 'Mass = { value'), r"\[screw\] unknown key 'Mass' \(did you mean 'M'\?\)"),
    "wrong type": (('value = 3.0, unit = "kg"', 'value = "3.0", unit = "kg"'), r"\[screw\] M: expected a number"),
    "non-finite": (('value = 3.0, unit = "kg"', 'value = nan, unit = "kg"'), r"\[screw\] M: expected a finite number"),
    "non-positive": (('value = 3.0, unit = "kg"', 'value = -3.0, unit = "kg"'), r"\[screw\] M: must be positive"),
    "wrong unit": (('value = 3.0, unit = "kg"', 'value = 3.0, unit = "g"'),
                   r"\[screw\] M: unit 'g' is not the expected SI unit 'kg'"),
    "unknown variant": (('motor = "pmsm"', 'motor = "bldc"'), r"unknown motor variant 'bldc'; allowed: pmsm, dc"),
}


@pytest.mark.parametrize("case", list(CASES))
def test_bad_parameter_file(tmp_path, capsys, case):
    (old, new), pattern = CASES[case]
    path = edited(tmp_path, old, new)
    out = tmp_path / "run.csv"
    status = main(["simulate", str(path), "--t-end", "0.01", "--out", str(out)])
    err = capsys.readouterr().err
    assert status == 2
    assert err.count("\n") == 1, err
    assert str(path) in err
    assert re.search(pattern, err), err
    assert not out.exists()
    assert not list(tmp_path.glob("run.csv*"))


@pytest.mark.parametrize(
    "argv, pattern",
    [
        (["--variant", "screw=spring"], r"unknown screw variant 'spring'; allowed: elastic, rigid"),
        (["--variant", "motr=dc"], r"unknown variant key 'motr' \(did you mean 'motor'\?\)"),
        (["--x-cmd", "stp:1mm"], r"--x-cmd 'stp:1mm': expected step:AMP"),
        (["--f-ext", "10kg"], r"--f-ext '10kg': unknown force unit 'kg'"),
        (["--t-end", "-1"], r"--t-end must be a positive number of seconds"),
        (["--out", "x.txt"], r"--out x.txt: expected a file ending in .csv or .npz"),
        (["--input", "eta=900mm"], r"--input eta: '900mm': unknown dimensionless unit 'mm'"),
        (["--input", "T_cab=20"], r"--input 'T_cab': unknown input; the model's inputs are x_cmd, f_ext, eta"),
        (["--input", "eta"], r"--input 'eta': expected NAME=SIGNAL"),
        (["--variant", "endstop=hard"], r"unknown endstop variant 'hard'; allowed: off, elastic"),
    ],
)
def test_bad_flags(tmp_path, capsys, argv, pattern):
    base = [] if "--t-end" in argv else ["--t-end", "0.01"]  # a flag given once (twice is refused)
    status = main(["simulate", str(REFERENCE), *base, *argv])
    err = capsys.readouterr().err
    assert status == 2
    assert err.count("\n") == 1, err
    assert re.search(pattern, err), err


def test_missing_model_file_as_a_process(tmp_path):
    out = tmp_path / "run.csv"
    missing = tmp_path / "none.toml"
    proc = subprocess.run([sys.executable, "-m", "ema_casadi.cli", "simulate", str(missing), "--out", str(out)],
                          capture_output=True, text=True)
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [f"ema simulate: error: {missing}: no such parameter file"]
    assert "Traceback" not in proc.stderr
    assert not out.exists()


def test_simulate_writes_csv_with_named_columns(tmp_path, capsys):
    out = tmp_path / "run.csv"
    assert main(["simulate", str(REFERENCE), "--t-end", "0.02", "--out", str(out), "--json"]) == 0
    lines = out.read_text().splitlines()
    header, units = lines[0].split(","), lines[1].split(",")
    # the file layout (docs: simulate): a time column named 'time', then a 'Unit:' row (MATLAB's SDI layout)
    assert header[:4] == ["time", "x_cmd", "f_ext", "eta"]
    assert units[:4] == ["Unit:", "m", "N", "1"] and len(units) == len(header)
    assert "x_rod" in header and "i_q" in header and "P_cu" in header
    assert len(header) == len(set(header))


def test_simulate_drives_named_inputs(tmp_path):
    out = tmp_path / "run.csv"
    assert main(["simulate", str(REFERENCE), "--t-end", "0.01", "--input", "eta=0.8", "--out", str(out)]) == 0
    lines = out.read_text().splitlines()
    eta = lines[0].split(",").index("eta")
    assert float(lines[-1].split(",")[eta]) == 0.8
