"""``ema sweep`` as a real process: interrupted by SIGINT (or killed, a crash) after
some rows and resumed, the table equals the uninterrupted sweep's byte for byte, and
only the missing rows were run again; a pool of processes ends promptly on SIGINT too."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import pytest

from conftest import REFERENCE
from ema_casadi.sweeps import load_sweep, sweep

SPEC = """[sweep]
seed = 5
samples = 10
[variants]
friction = "hybrid"
[parameters]
B = { values = [2e-5, 1e-4, 3e-4] }
F_seal = { distribution = "uniform", low = 0.5, high = 1.5, relative = true }
[scenario]
duration = 1.0
x_cmd = "step:1mm@0.01"
solver = "rk4"
dt = 1e-5
dt_out = 1e-3
[metrics]
step = {}
hunting = {}
"""
#: rows of SPEC (3 values of B x 10 draws): with the compiled solvers a row takes
#: milliseconds (50 ms at dt = 1e-5 s), so the sweep must be long enough that an interrupt after 3 rows lands
#: before the last one (with 12 rows, all were done by then on an idle machine)
RUNS = 30


def _start(tmp_path, *args):
    return subprocess.Popen([sys.executable, "-m", "ema_casadi.cli", "sweep", str(REFERENCE), "s.toml",
                             "--out", "r.csv", "--no-progress", *args], cwd=tmp_path, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=dict(os.environ))


def _interrupt_after_rows(proc, journal, rows, limit=120.0):
    """SIGINT once the journal holds ``rows`` rows; (exit status, stderr, seconds to exit)."""
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < limit and proc.poll() is None:
        if journal.exists() and len(journal.read_text().splitlines()) - 1 >= rows:
            break
        time.sleep(0.05)
    assert proc.poll() is None, "the sweep ended before it could be interrupted"
    t_sig = time.perf_counter()
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=30)
    return proc.returncode, err, time.perf_counter() - t_sig


def test_interrupted_and_resumed_equals_the_uninterrupted_sweep(params, tmp_path):
    (tmp_path / "s.toml").write_text(SPEC)
    full = sweep(load_sweep(tmp_path / "s.toml", params), tmp_path / "full.csv", jobs=1)
    assert len(full) == RUNS and full.info["failed"] == 0
    journal = tmp_path / ".r.csv.journal"
    status, err, took = _interrupt_after_rows(_start(tmp_path, "--jobs", "1"), journal, 3)
    assert status == 130 and err.count("\n") == 1 and err.startswith("ema sweep: interrupted"), err
    assert "--resume" in err, err
    assert took < 2.0
    assert not (tmp_path / "r.csv").exists()
    kept = len(journal.read_text().splitlines()) - 1
    assert 3 <= kept < RUNS
    proc = subprocess.run([sys.executable, "-m", "ema_casadi.cli", "sweep", str(REFERENCE), "s.toml", "--out",
                           "r.csv", "--jobs", "1", "--resume", "--json"], cwd=tmp_path, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    result = json.loads(proc.stdout)
    assert result["resumed"] == kept and result["runs"] == RUNS
    assert (tmp_path / "r.csv").read_bytes() == (tmp_path / "full.csv").read_bytes()
    assert not journal.exists()


def test_killed_and_resumed_equals_the_uninterrupted_sweep(params, tmp_path):
    """SIGKILL (a crash: no cleanup at all) with a row cut short on disk: the journal's
    whole rows are kept, the cut one is run again."""
    (tmp_path / "s.toml").write_text(SPEC)
    sweep(load_sweep(tmp_path / "s.toml", params), tmp_path / "full.csv", jobs=1)
    journal = tmp_path / ".r.csv.journal"
    proc = _start(tmp_path, "--jobs", "1")
    t0 = time.perf_counter()
    while proc.poll() is None and not (journal.exists() and len(journal.read_text().splitlines()) > 3):
        assert time.perf_counter() - t0 < 120
        time.sleep(0.05)
    proc.kill()
    proc.communicate(timeout=30)
    kept = len(journal.read_text().splitlines()) - 1
    with journal.open("a") as fh:
        fh.write('{"run": 11, "B": 0.0003, "F_se')  # the crash came mid-line
    done = subprocess.run([sys.executable, "-m", "ema_casadi.cli", "sweep", str(REFERENCE), "s.toml", "--out",
                           "r.csv", "--jobs", "1", "--resume", "--json"], cwd=tmp_path, capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["resumed"] == kept
    assert (tmp_path / "r.csv").read_bytes() == (tmp_path / "full.csv").read_bytes()


def test_a_process_pool_ends_promptly_on_sigint(tmp_path):
    pytest.importorskip("multiprocessing")
    (tmp_path / "s.toml").write_text(SPEC.replace("duration = 1.0", "duration = 3.0"))
    journal = tmp_path / ".r.csv.journal"
    proc = _start(tmp_path, "--jobs", "2")
    status, err, took = _interrupt_after_rows(proc, journal, 1)
    assert status == 130 and err.count("\n") == 1 and err.startswith("ema sweep: interrupted"), err
    assert "--resume" in err, err
    assert took < 2.0
    assert not (tmp_path / "r.csv").exists()
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]
