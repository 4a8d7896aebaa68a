"""`ema optimal`: the minimum-time move on the reference model end to end (files, --json,
the command profile read back by `ema simulate`), and its refusals (exit 2, one line,
nothing written)."""

import json

import pytest

from conftest import REFERENCE
from ema_casadi.cli import main


def _run(capsys, *args):
    status = main(["optimal", str(REFERENCE), *map(str, args)])
    out, err = capsys.readouterr()
    return status, out, err


@pytest.mark.parametrize("args, words", [
    (("--move", "100mm"), "beyond the stroke"),
    (("--load", "80kN"), "the screw holds"),
    (("--objective", "speed"), "objective 'speed' unknown"),
    (("--objective", "energy", "--duration", "0.01"), "below the minimum time"),
    (("--through", "cascade"), "through 'cascade' unknown"),
    (("--method", "euler"), "method 'euler' unknown"),
    (("--through", "ecu", "--objective", "energy", "--duration", "0.3"), "command shaping minimises the time"),
    (("--move", "2mm", "--intervals", "100000"), "intervals 100000: above the limit of 5000"),  # before any NLP
    (("--envelope", "--distances", "0"), "distances: finite and above 0"),
    (("--envelope", "--intervals", "0"), "intervals: expected an integer >= 4, got 0"),  # not the default 30
    (("--envelope", "--variant", "thermal=lumped", "--temperatures", "-300"), "above absolute zero"),
    (("--envelope", "--variant", "thermal=lumped", "--temperatures", "nan"), "above absolute zero"),
])
def test_bad_requests_exit_2_with_one_line(capsys, tmp_path, args, words):
    out = tmp_path / "out"
    status, _, err = _run(capsys, *args, "--out", out)
    assert status == 2 and words in err and err.count("\n") == 1, err
    assert not out.exists()


def test_a_load_the_drive_cannot_move_against_is_infeasible_exit_3(capsys, tmp_path):
    # 49 kN against an outward move: within the 54.5 kN the screw holds (not bad input), above the
    # K_t I_max eta 2 pi/p = 48.9 kN the motor drives at the current limit (computed from the parameters here):
    # the largest steady speed is the smooth lock's creep (3.9 um/s), named infeasible with the current limit
    import math

    import ema_casadi as ema

    P = ema.build_model(ema.load_parameters(REFERENCE)).pdict()
    drives = 1.5 * P.pp * P.psi * P.I_max * P.eta * 2 * math.pi / P.p
    assert 48e3 < drives < 49e3
    out = tmp_path / "out"
    status, _, err = _run(capsys, "--move", "5mm", "--load", "49kN", "--out", out)
    assert status == 3 and err.count("\n") == 1, err
    assert "infeasible" in err and "the binding limit is the current limit (I_max = 24 A)" in err, err
    assert not out.exists()


# the solve, the replay and the ECU step on the elastic model: 5 s (it took 53 s with IPOPT's adaptive barrier)
def test_minimum_time_move_writes_a_command_simulate_reads(capsys, tmp_path):
    out = tmp_path / "opt"
    status, text, err = _run(capsys, "--move", "10mm", "--json", "--out", out)
    assert status == 0, err
    r = json.loads(text)
    assert r["ipopt"]["status"] == "Solve_Succeeded" and {"current", "voltage"} <= set(r["binding"])
    assert sorted(p.name for p in out.iterdir()) == ["command.csv", "move.png", "optimum.csv", "replay.csv"]
    assert r["replay"]["ratings"]["current"]["ratio"] <= 1.01  # I_max within 1 % in the full model
    status = main(["simulate", str(REFERENCE), "--x-cmd", f"{out / 'command.csv'}:x_cmd", "--t-end", "0.2", "--json"])
    sim = json.loads(capsys.readouterr().out)
    assert status == 0 and abs(sim["final"]["x_rod"] - 0.01) < 2e-4, sim.get("final")


def test_shaped_command_through_the_ecu_read_back_by_simulate(capsys, tmp_path):
    # the shaped command written as command.csv and run by `ema simulate --x-cmd FILE.csv:x_cmd` in the full
    # model: its 2 % settling time from the run's own CSV sooner than the ECU's step (measured 0.1228 s, 0.1307 s)
    import numpy as np

    from ema_casadi.simulation import step_response_metrics

    out = tmp_path / "opt"
    status, text, err = _run(capsys, "--move", "10mm", "--through", "ecu", "--json", "--out", out)
    assert status == 0, err
    r = json.loads(text)
    step = r["ecu_step_settling_time_s"]
    run = tmp_path / "run.csv"
    status = main(["simulate", str(REFERENCE), "--x-cmd", f"{out / 'command.csv'}:x_cmd", "--t-end", "0.2",
                   "--out", str(run)])
    capsys.readouterr()
    assert status == 0
    head = run.read_text().splitlines()[0].split(",")
    data = np.loadtxt(run, delimiter=",", skiprows=2)
    t, x = data[:, 0], data[:, head.index("x_rod")]
    settle = step_response_metrics(t, x / 0.01)["settling_time_s"]
    assert settle < 0.98 * step and settle == pytest.approx(r["replay"]["settling_time_s"], abs=2e-4), (settle, step)


def test_envelope_table(capsys, tmp_path):
    out = tmp_path / "env"
    status, text, err = _run(capsys, "--envelope", "--loads", "0,20kN", "--distances", "2mm", "--intervals", "16",
                             "--json", "--out", out)
    assert status == 0, err
    r = json.loads(text)
    v0, v20 = r["top_speed_m_s"]["None"]
    assert 0.085 < v20 < v0 < 0.1  # the voltage circle's top speed (98 mm/s), 89.5 mm/s against 20 kN and friction
    assert (out / "envelope.csv").read_text().startswith("load_N,v_top_m_s_at_ref\n")
    assert (out / "envelope.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert r["written"] == [str(out / "envelope.csv"), str(out / "envelope.png")]


# the solve, the ECU's step and the replay, about 2 s each: the answers that would mean nothing
@pytest.mark.parametrize("args, words", [
    # 8 intervals: 1.524 s against the ECU's own step's 0.919 s (40 intervals: 0.775 s), Solve_Succeeded
    (("--move", "75mm", "--intervals", "8"), "intervals 8: too coarse for a 75 mm move"),
    # 1 um: the 2 % band (20 nm) within the LVDT's 0.5 um step; the ECU's step never moves the rod
    (("--move", "1um",), "rests 1 µm from the target, outside its 2 % band (0.02 µm); give a move of at least 100 µm"),
])
def test_an_optimum_that_means_nothing_is_refused_exit_3(capsys, tmp_path, args, words):
    out = tmp_path / "out"
    status, _, err = _run(capsys, *args, "--out", out)
    assert status == 3 and words in err and err.count("\n") == 1, err
    assert not out.exists()
