"""The command line on a model of two actuators on one surface (``elevator_dual.toml``):
its wiring and per-channel results, and bad instance tables refused in one line naming
the table or the port (exit status 2, nothing written)."""

from __future__ import annotations

import json

import pytest

from ema_casadi import packaged_file
from ema_casadi.cli import main

DUAL = packaged_file("elevator_dual.toml")


def _run(argv, capsys):
    status = main(argv)
    cap = capsys.readouterr()
    return status, cap.out, cap.err


def test_ema_model_prints_each_channels_wiring(capsys):
    status, out, err = _run(["model", str(DUAL), "--connections", "--json"], capsys)
    assert status == 0, err
    rows = {(r["reader"], r["port"]): r for r in json.loads(out)["connections"]}
    assert rows[("A.friction = smooth", "v_contact")]["provider"] == "A.screw = elastic"
    assert rows[("A.friction = smooth", "v_contact")]["source"] == "A.v_contact"
    # the surface reads each channel's rod; each controller its command from the equaliser
    assert rows[("surface = hinge", "B.x_rod_mech")]["provider"] == "B.screw = elastic"
    assert rows[("controller = equaliser_integral", "A.F_att")]["provider"] == "surface = hinge"


def test_ema_simulate_writes_each_channels_columns(tmp_path, capsys):
    out = tmp_path / "run.csv"
    status, text, err = _run(["simulate", str(DUAL), "--x-cmd", "step:5mm@0.01", "--t-end", "0.05",
                              "--out", str(out)], capsys)
    assert status == 0, err
    header = out.read_text().splitlines()[0].split(",")
    assert {"A.x_rod", "B.x_rod", "A.i_q", "B.i_q", "A.F_att", "B.F_att", "F_fight", "x_surf"} <= set(header)
    assert "F_fight = " in text


BAD = {
    "unknown-port": ('[instances.B]\nmode = "active"', '[instances.B]\nmode = "active"\n[instances.B.connect]\n'
                     'x_nowhere = "x_cmd"', "[instances.B.connect] x_nowhere: no port of that name in instance B"),
    "unknown-signal": ('[instances.B]\nmode = "active"', '[instances.B]\nmode = "active"\n[instances.B.connect]\n'
                       'eta = "A.nothing"', "[instances.B.connect] eta = 'A.nothing': no signal of that name"),
    "two-instances-of-one-name": ('[instances.B]\nmode = "active"', '[instances.A]\nmode = "active"',
                                  "instances"),
    "table-of-a-part-not-in-the-model": ('[instances.B]\nmode = "active"', '[instances.B]\nmode = "active"\n'
                                         '[instances.B.endstop]\nk_stop = { value = 1e8, unit = "N/m" }',
                                         "[instances.B.endstop] no part of the model reads the table [endstop]"),
    "mode-it-does-not-have": ('[instances.B]\nmode = "active"', '[instances.B]\nmode = "backup"',
                              "[instances.B] mode = 'backup': a channel has the modes active, standby, off"),
    "unknown-table": ('[instances.B]\nmode = "active"', '[instances.B]\nmode = "active"\n[instances.B.gearbox]\n'
                      'x = 1', "[instances.B.gearbox] unknown table"),
}


@pytest.mark.parametrize("case", list(BAD))
def test_a_bad_instance_table_is_refused_in_one_line(case, tmp_path, capsys, monkeypatch):
    old, new, message = BAD[case]
    text = DUAL.read_text()
    assert old in text
    path = tmp_path / "dual.toml"
    path.write_text(text.replace(old, new, 1))
    monkeypatch.chdir(tmp_path)
    status, out, err = _run(["simulate", str(path), "--t-end", "0.01", "--out", "run.csv"], capsys)
    lines = err.strip().splitlines()
    assert status == 2 and len(lines) == 1 and "Traceback" not in err, err
    assert message in lines[0], lines[0]
    assert out == "" and sorted(p.name for p in tmp_path.iterdir()) == ["dual.toml"]


def test_ema_sweep_draws_an_instances_parameter(tmp_path, capsys):
    """A sweep over channel B's rigging offset (``B.x_rig``, an instance's parameter): the
    largest fight of each run is the one at t = 0, where both rods and the surface start at
    0 and B's attachment alone is stretched by the offset: k_att,B x_rig / 2 (5 kN); none
    with the channels matched."""
    spec = tmp_path / "fight.toml"
    spec.write_text('[sweep]\nname = "fight over the rigging offset"\n[parameters]\n'
                    '"B.x_rig" = { values = [-1e-4, 0.0, 1e-4], unit = "m" }\n'
                    '[scenario]\nduration = 0.2\nx_cmd = "step:5mm@0.01"\n'
                    '[metrics]\npeak = { signals = ["F_fight"] }\n')
    out = tmp_path / "fight.csv"
    status, _, err = _run(["sweep", str(DUAL), str(spec), "--jobs", "1", "--out", str(out)], capsys)
    assert status == 0, err
    rows = [line.split(",") for line in out.read_text().splitlines()[1:]]
    peaks = {float(r[1]): float(r[2]) for r in rows}
    assert peaks[0.0] <= 1.0
    assert peaks[1e-4] == pytest.approx(1e8 * 1e-4 / 2, rel=1e-6) and peaks[-1e-4] == pytest.approx(peaks[1e-4])


def test_ema_faults_strikes_one_channel(tmp_path, capsys):
    """A fault names its channel as its target (``jam`` of B, ``disconnect`` of B): the
    surface's transient (``x_surf``, the model's rod position) and B's own monitors."""
    spec = tmp_path / "faults.toml"
    spec.write_text('[scenario]\nduration = 0.25\nx_cmd = "step:5mm@0.02"\nf_ext = "15kN"\n'
                    '[[fault]]\nkind = "jam"\ntarget = "B"\nonset = 0.1\n'
                    '[[fault]]\nkind = "disconnect"\ntarget = "B"\nonset = 0.1\n')
    status, out, err = _run(["faults", str(DUAL), str(spec), "--out", str(tmp_path / "out"), "--json"], capsys)
    assert status == 0, err
    rows = {r["case"]: r for r in json.loads(out)["rows"]}
    assert set(rows) == {"none", "jam B", "disconnect B"}
    assert all(r["status"] == "ok" for r in rows.values())
    # B's rod-motor cross-check sees its drive train break; A's monitors see nothing
    cut = rows["disconnect B"]
    assert cut["first_monitor"] == "B.latch_cross" and 0 < cut["detected_B.latch_cross_s"] < 0.05  # 11 ms
    assert all(cut[k] is None for k in cut if k.startswith("detected_A."))
    assert cut["peak_deviation_m"] > rows["jam B"]["peak_deviation_m"]  # 0.38 mm against 0.04 mm
    spec.write_text(spec.read_text().replace('target = "B"', 'target = "C"', 1))
    status, _, err = _run(["faults", str(DUAL), str(spec), "--out", str(tmp_path / "bad")], capsys)
    assert status == 2 and "unknown target 'C'" in err and len(err.strip().splitlines()) == 1, err
