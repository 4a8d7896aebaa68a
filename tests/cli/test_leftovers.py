"""Nothing left behind: no orphan workers after the sweep is killed, no sweep
journal after a scheduler out of reach, no compiler temporaries in $TMPDIR after an
interrupted build, no half-written mission folder, no silent death by a signal after a
complete run; and a heat balance beyond its tolerance is a failed mission, not a
result."""

from __future__ import annotations

import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import pytest

from conftest import REFERENCE
from ema_casadi._util import _compiled as compiled
from ema_casadi._util import _interrupts
from ema_casadi.cli import main

REF = str(REFERENCE)
MISSION = '[mission]\nname = "m"\n[[segment]]\nname = "a"\nduration = 2.0\nx_cmd = "sine:1mm@1"\nT_amb = 20.0\n'
SWEEP = """[sweep]
seed = 1
samples = 40
[variants]
friction = "hybrid"
[parameters]
B = { distribution = "uniform", low = 1e-5, high = 3e-5 }
[scenario]
duration = 0.5
x_cmd = "step:1mm@0.01"
solver = "rk4"
dt = 1e-5
[metrics]
peak = {}
"""


def _children(pid: int) -> list[int]:
    out = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                stat = (d / "stat").read_text()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                out.append(int(d.name))
    return out


def _alive(pid: int) -> bool:
    """Running (not gone, not a zombie waiting to be reaped)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_no_worker_outlives_a_killed_sweep_by_a_second(tmp_path):
    (tmp_path / "s.toml").write_text(SWEEP, encoding="utf-8")
    proc = subprocess.Popen([sys.executable, "-m", "ema_casadi.cli", "sweep", REF, "s.toml", "--jobs", "2",
                             "--out", "s.csv"], cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 120
        workers = []
        while time.monotonic() < deadline and len(workers) < 3:  # the two workers and the resource tracker
            time.sleep(0.2)
            workers = [p for p in _children(proc.pid) if _alive(p)]
            assert proc.poll() is None, "the sweep ended before its workers could be seen"
        assert len(workers) >= 2, workers
        time.sleep(1.0)  # the workers are computing
        proc.kill()
        proc.wait()
        time.sleep(1.0)
        assert [p for p in workers if _alive(p)] == []
    finally:
        if proc.poll() is None:
            proc.kill()


def test_a_scheduler_out_of_reach_leaves_no_journal(tmp_path, capsys, monkeypatch):
    pytest.importorskip("dask.distributed")
    (tmp_path / "s.toml").write_text(SWEEP, encoding="utf-8")
    monkeypatch.setenv("EMA_CASADI_SCHEDULER_TIMEOUT", "0.5")
    monkeypatch.chdir(tmp_path)
    args = ["sweep", REF, "s.toml", "--out", "s.csv", "--scheduler", "tcp://127.0.0.1:9"]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "tcp://127.0.0.1:9" in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.toml"]
    assert main(args) == 2  # again, not refused for a journal
    assert "journal" not in capsys.readouterr().err


def test_an_interrupted_build_leaves_nothing_in_tmpdir(tmp_path, monkeypatch):
    """A 'compiler' that writes its temporaries to $TMPDIR and hangs, interrupted: its
    process group is killed and its temporaries go with the private folder."""
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    pidfile = tmp_path / "pid"
    cmd = ["sh", "-c", f'echo $$ > {pidfile}; touch "$TMPDIR/ccTEMP.s"; sleep 30 & wait']
    # a real SIGINT to the main thread (as Ctrl-C sends): it wakes the blocked wait at once, where
    # _thread.interrupt_main only raised after the 30 s 'compiler' had ended
    timer = threading.Timer(1.0, signal.pthread_kill, (threading.main_thread().ident, signal.SIGINT))
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            compiled.run_compilers([cmd])
    finally:
        timer.cancel()
    pid = int(pidfile.read_text())
    pidfile.unlink()
    time.sleep(0.2)
    assert not _alive(pid)
    assert list(tmp_path.iterdir()) == []


def test_a_signal_after_a_complete_run_is_ignored_not_fatal():
    code = ("import os, signal, time\n"
            "from ema_casadi._util import _interrupts\n"
            "with _interrupts.handling():\n"
            "    _interrupts.finished()\n"
            "os.kill(os.getpid(), signal.SIGINT); os.kill(os.getpid(), signal.SIGTERM)\n"
            "time.sleep(0.2); print('done')\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0 and proc.stdout == "done\n", proc


def test_an_interrupted_mission_leaves_no_folder(tmp_path, capsys, monkeypatch):
    from ema_casadi.mission import MissionResult

    (tmp_path / "m.toml").write_text(MISSION, encoding="utf-8")

    def interrupted(self, path):
        Path(path).write_bytes(b"half a figure")
        raise _interrupts.Interrupted(signal.SIGINT)

    monkeypatch.setattr(MissionResult, "plot", interrupted)
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    status = main(["mission", REF, str(tmp_path / "m.toml"), "--out", str(tmp_path / "out"), "--fast", "--no-progress"])
    assert status == 130
    assert capsys.readouterr().err == "ema mission: interrupted\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.toml"]


def test_a_heat_balance_beyond_its_tolerance_is_a_failed_mission(tmp_path, capsys, monkeypatch):
    """The short mission closes its heat balance to 0.22 % (measured); with the
    tolerance set below that it is a failed run, exit 3, no output."""
    from ema_casadi.mission import _run

    (tmp_path / "m.toml").write_text(MISSION, encoding="utf-8")
    monkeypatch.setattr(_run, "HEAT_RESIDUAL_TOL", 1e-6)
    try:
        status = main(["mission", REF, str(tmp_path / "m.toml"), "--out", str(tmp_path / "out"), "--fast",
                       "--no-progress"])
    except SystemExit as exc:  # the mission command ends a failed run itself
        status = exc.code
    err = capsys.readouterr().err
    assert status == 3 and err.count("\n") == 1 and "heat balance" in err and "HEAT_RESIDUAL_TOL" in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.toml"]


def test_a_reader_that_goes_away_ends_the_command_quietly(tmp_path):
    """``ema bode --json --points 20000 | head -1``: the Bode table (1.35 MB) is larger
    than a pipe's buffer (64 KiB by default, 1 MiB at most on Linux), so the writer meets
    a closed pipe; it ends with the shell's broken-pipe status (141) and nothing on
    stderr (before: a BrokenPipeError traceback). The default table (28 kB) fits in the
    buffer and could be written whole before the reader closed: exit 0 (seen once)."""
    ema = Path(sys.executable).with_name("ema")
    proc = subprocess.Popen([str(ema), "bode", "--json", "--points", "20000"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, cwd=tmp_path)
    first = proc.stdout.read(1)
    proc.stdout.close()  # the reader goes away after one byte
    err = proc.stderr.read().decode()
    proc.stderr.close()
    assert proc.wait(timeout=120) == 141, err
    assert first == b"{" and err == ""
