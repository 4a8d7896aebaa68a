"""A mission with the switched bridge (``[model] inverter = "pwm"``): a 20 s segment
runs carrier-synchronously (it crashed with KeyError: 'steps'), its heat balance closes,
and its inverter losses agree with the averaged bridge's."""

import pytest

from ema_casadi.mission import run_mission

MISSION = """
[mission]
name = "20 s taxi"
T_start = 40.0

[model]
thermal = "lumped"
friction = "hybrid"
iron_loss = "on"
inverter = "{inverter}"

[limits]
T_w = 180.0
T_h = 120.0
T_s = 120.0
T_inv = 100.0

[[segment]]
name = "taxi"
duration = 20.0
x_cmd = "sine:2mm@0.2+sine:0.5mm@2"
f_ext = "10kN"
T_amb = [40.0, 35.0]
"""


@pytest.fixture(scope="module")
def runs(params, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("mission")
    out = {}
    for inverter in ("pwm", "ideal"):
        path = tmp / f"taxi_{inverter}.toml"
        path.write_text(MISSION.format(inverter=inverter))
        out[inverter] = run_mission(params, path)
    return out


def test_switched_mission_closes_its_heat_balance(runs):
    """Losses (from their carrier-period averages) = heat stored + heat to the ambient
    within 0.5 % (the issue's bound; +0.009 % measured), and the run really switched
    (16 kHz: 320 000 carrier periods in 20 s)."""
    r = runs["pwm"]
    hb = r.heat_balance()
    assert hb["losses_J"] > 100.0  # a real load (1.28 kJ)
    assert abs(hb["relative_residual"]) < 5e-3, hb
    assert r.info["switched"] and r.info["steps"] == 320_000


def test_switched_mission_losses_match_the_averaged_bridge(runs):
    """The inverter's and the motor's energy with the switched bridge within 2 % of the
    averaged bridge's (device losses from the same data; measured -0.21 % and +0.016 %:
    2 % is about ten times that, the averaged bridge's model error being the quantity)."""
    sw, av = runs["pwm"], runs["ideal"]
    parts_sw = sw.by_part(sw.energies()["total"])
    parts_av = av.by_part(av.energies()["total"])
    for family in ("inverter", "motor"):
        e_sw, e_av = parts_sw[family], parts_av[family]
        assert e_sw == pytest.approx(e_av, rel=0.02), (family, e_sw, e_av)
