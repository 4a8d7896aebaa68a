"""A full disk: every command that writes, with its output on a filesystem
that has no space left, ends with exit status 2, one line naming the output and the
reason, no traceback, and leaves nothing on that filesystem (nor in $TMPDIR).

The full filesystem is real: a small tmpfs mounted for the test and filled up (root and
a kernel that lets the test mount are needed; the tests are skipped otherwise).
"""

from __future__ import annotations

import os
import subprocess
import tempfile
from pathlib import Path

import pytest

from conftest import REFERENCE, SMALL_SWEEP
from ema_casadi.cli import main

REF = str(REFERENCE)
MISSION = '[mission]\nname = "m"\n[[segment]]\nname = "a"\nduration = 2.0\nx_cmd = "sine:1mm@1"\nT_amb = 20.0\n'
SWEEP = SMALL_SWEEP


@pytest.fixture(scope="module")
def full(tmp_path_factory):
    """A mounted tmpfs of 256 kB filled to the last byte; yields its folder."""
    where = tmp_path_factory.mktemp("full")
    try:
        subprocess.run(["mount", "-t", "tmpfs", "-o", "size=256k", "tmpfs", str(where)], check=True,
                       capture_output=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        pytest.skip("cannot mount a small tmpfs here (needs root and mount rights): no full filesystem to test on")
    try:
        fd = os.open(where / "filler", os.O_WRONLY | os.O_CREAT)
        try:
            while True:
                os.write(fd, b"\0" * 4096)
        except OSError:
            pass
        finally:
            os.close(fd)
        yield where
    finally:
        subprocess.run(["umount", "-l", str(where)], capture_output=True, timeout=10)


def _inputs(tmp_path: Path) -> dict:
    (tmp_path / "m.toml").write_text(MISSION, encoding="utf-8")
    (tmp_path / "s.toml").write_text(SWEEP, encoding="utf-8")
    return {"tmp": tmp_path}


SIM = ["simulate", REF, "--t-end", "0.05"]
COMMANDS = {
    "simulate-csv": [*SIM, "--out", "{full}/run.csv"],
    "simulate-npz": [*SIM, "--out", "{full}/run.npz"],
    "simulate-mat": [*SIM, "--out", "{full}/run.mat"],
    "simulate-plot": [*SIM, "--plot", "{full}/run.png"],
    "linearize-mat": ["linearize", REF, "--out", "{full}/lin.mat"],
    "export-json": ["export", REF, "--format", "json", "--out", "{full}/lin.json"],
    "export-npz": ["export", REF, "--format", "npz", "--out", "{full}/lin.npz"],
    "export-casadi": ["export", REF, "--format", "casadi", "--out", "{full}/f.casadi"],
    "export-c": ["export", REF, "--format", "c", "--out", "{full}/ema_f.c"],
    "mission-new-folder": ["mission", REF, "{tmp}/m.toml", "--out", "{full}/out", "--fast", "--no-progress"],
    "mission-existing-folder": ["mission", REF, "{tmp}/m.toml", "--out", "{full}", "--fast", "--no-progress"],
    "sweep-out": ["sweep", REF, "{tmp}/s.toml", "--jobs", "1", "--out", "{full}/s.csv"],
    "sweep-plot": ["sweep", REF, "{tmp}/s.toml", "--jobs", "1", "--out", "{tmp}/s.csv", "--plot", "{full}/s.png"],
    "freqresp-out": ["freqresp", REF, "--amplitudes", "1mm", "--freqs", "1", "--max-periods", "3", "--out",
                     "{full}/fr.csv"],
    "freqresp-plot": ["freqresp", REF, "--amplitudes", "1mm", "--freqs", "1,2", "--max-periods", "3", "--plot",
                      "{full}/fr.png"],
    "bode-plot": ["bode", REF, "--points", "20", "--plot", "{full}/b.png"],
    "margins-plot": ["margins", REF, "--plot", "{full}/m.png"],
    "limit-cycle-plot": ["limit-cycle", REF, "--amplitudes", "1um,2um", "--freqs", "5,6", "--t-end", "0",
                         "--periods", "4", "--no-refine", "--plot", "{full}/lc.png"],
    "aircraft-plot-dir": ["aircraft", REF, "--no-responses", "--condition", "cruise_sl", "--plot-dir", "{full}/ac"],
    "tune-out": ["tune", REF, "--max-iter", "1", "--out", "{full}/tuned.toml"],
}


#: Longer commands (tens of seconds): run with -m slow.
SLOW = {"demo": ["demo", REF, "--out", "{full}/demo", "--no-progress"],
        "export-fmu-cs": ["export", REF, "--format", "fmu-cs", "--out", "{full}/x.fmu"]}


@pytest.mark.parametrize("name", [*COMMANDS, *(pytest.param(n, marks=pytest.mark.slow) for n in SLOW)])
def test_a_full_disk_is_one_line_and_leaves_nothing(name, full, tmp_path, capsys, monkeypatch):
    ctx = _inputs(tmp_path)
    tmpdir = tmp_path / "TMPDIR"
    tmpdir.mkdir()
    monkeypatch.setenv("TMPDIR", str(tmpdir))
    monkeypatch.setattr(tempfile, "tempdir", str(tmpdir))
    monkeypatch.chdir(tmp_path)
    before = sorted(p.name for p in full.iterdir())
    argv = [a.format(full=full, **ctx) for a in {**COMMANDS, **SLOW}[name]]
    status = main(argv)
    out, err = capsys.readouterr()
    assert status == 2, err
    assert err.count("\n") == 1 and "No space left on device" in err, err
    assert str(full) in err  # names the output
    assert "Traceback" not in err
    assert sorted(p.name for p in full.iterdir()) == before, "something was left on the full filesystem"
    assert list(tmpdir.iterdir()) == []
    assert not (tmp_path / ".s.csv.journal").exists()
