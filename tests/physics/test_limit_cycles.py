"""Limit cycles by describing function against long simulations."""

from __future__ import annotations

import numpy as np
import pytest

import ema_casadi as ema
from ema_casadi import Signal
from ema_casadi.limitcycle import cycle_of, describing_function, harmonic_balance, refine


@pytest.fixture(scope="module")
def params():
    return ema.load_parameters("models/cesa_ema.toml")


def test_no_cycle_predicted_and_the_simulation_decays(params):
    # P position loop (no integrator), rigid screw, hybrid friction: L_N never reaches -1
    # on the grid (measured: the phase stays above -160 deg where |L_N| > 1; at 2 um the
    # rod does not answer at all), and the 1 mm step settles: the rod stands still over
    # the second half of the run (peak-to-peak exactly 0, measured)
    model = ema.build_model(params, {"friction": "hybrid", "screw": "rigid"})
    df = describing_function(model, "position", [5e-6, 1e-5, 3e-5], [5.0, 10.0, 20.0], p=model.p(),
                             x0=model.x0(), dt=1e-4, periods=10, settle=5)
    assert df.cycles == []
    res = ema.simulate(model, 3.0, x_cmd=Signal.step(1e-3, 0.01), dt=1e-4, dt_out=1e-4, solver="rk4")
    late = res.t > 1.5
    assert np.ptp(res["x_rod"][late]) < 1e-9  # m
    assert cycle_of(res.t, res["x_rod"], 1.5)["amplitude"] == 0.0


def _hunting(params, screw):
    model = ema.build_model(params, {"controller": "PI", "friction": "hybrid", "screw": screw})
    p = model.p(K_i_x=3000.0)
    res = ema.simulate(model, 6.0, x_cmd=Signal.step(1e-3, 0.01), dt=1e-4, dt_out=1e-4, p=p, solver="rk4")
    return model, dict(p=p, x0=model.x0(), dt=1e-4), cycle_of(res.t, res["x_rod"], 3.0)


def test_harmonic_balance_finds_the_simulated_hunting_cycle(params):
    # PI position loop K_i_x = 3000 1/s^2, rigid screw, hybrid friction, started where the
    # describing function's first-harmonic balance puts the root (8.0 um, 6.9 Hz, measured by
    # the slow test below), 23 % / 11 % from the simulated cycle. With the 3rd, 5th and 7th
    # harmonics balanced too, measured: 6.513 um, 6.226 Hz against the 6 s run's 6.512 um,
    # 6.231 Hz (+0.04 %, -0.06 %); adding the 9th moves the answer by 0.4 %, the truncation
    # error. Asserted at 2 % (5 x that) and a converged residual
    model, kw, sim = _hunting(params, "rigid")
    hb = harmonic_balance(model, "position", {"amplitude": 8.0e-6, "freq_hz": 6.9, "stable": True}, **kw)
    assert hb["harmonic_balance"]["converged"] and hb["harmonic_balance"]["residual"] < 1e-2
    assert hb["method"] == "harmonic balance"
    assert hb["amplitude"] == pytest.approx(sim["amplitude"], rel=0.02)
    assert hb["freq_hz"] == pytest.approx(sim["freq_hz"], rel=0.02)
    assert 0.2 < hb["harmonic_balance"]["harmonics"][3] < 0.4  # stick-slip: far from a sine (measured 0.29)


def test_harmonic_balance_rejects_bad_orders(params):
    model = ema.build_model(params, {"controller": "PI"})
    for bad in [(1, 3), (3, 3), (32,)]:
        with pytest.raises(ValueError, match="harmonics"):
            harmonic_balance(model, "position", {"amplitude": 1e-5, "freq_hz": 5.0}, p=model.p(), x0=model.x0(),
                             harmonics=bad)


@pytest.mark.slow
@pytest.mark.parametrize("screw, df_err", [("rigid", (0.23, 0.11)), ("elastic", (0.50, 0.26))])
def test_pi_hunting_prediction_vs_simulation(params, screw, df_err):
    # PI position loop K_i_x = 3000 1/s^2, hybrid friction (studies/hunting_df.py), the
    # whole chain: the grid, its stable root, Newton, the harmonic balance (1, 3, 5, 7).
    # Measured against the 6 s runs (first harmonic of x_rod over 3-6 s):
    #   rigid:   DF 8.03 um, 6.93 Hz (+23 %, +11 %); balanced 6.51 um, 6.23 Hz (-0.0 %, -0.1 %)
    #   elastic: DF 6.24 um, 6.02 Hz (+50 %, +26 %); balanced 4.20 um, 4.81 Hz (+1.0 %, +0.8 %)
    # Asserted: the balanced cycle within 3 % (3 x the largest error measured; the requirement is
    # 25 % / 10 %), and the first-harmonic root as far off as measured (within 5 points): the
    # single-harmonic balance is what the higher harmonics correct
    model, kw, sim = _hunting(params, screw)
    df = describing_function(model, "position", np.geomspace(1e-6, 3e-5, 7), np.geomspace(1.5, 15, 10), **kw)
    (c,) = [c for c in df.cycles if c["stable"]]
    hb = harmonic_balance(model, "position", refine(model, "position", c, **kw), **kw)
    assert hb["method"] == "harmonic balance"
    assert hb["amplitude"] == pytest.approx(sim["amplitude"], rel=0.03)
    assert hb["freq_hz"] == pytest.approx(sim["freq_hz"], rel=0.03)
    assert hb["df_amplitude"] / sim["amplitude"] - 1 == pytest.approx(df_err[0], abs=0.05)
    assert hb["df_freq_hz"] / sim["freq_hz"] - 1 == pytest.approx(df_err[1], abs=0.05)


@pytest.mark.slow
@pytest.mark.parametrize("B, amp_sim, f_sim", [(1e-4, 5.84e-6, 1.76), (3e-4, 16.7e-6, 1.75), (5e-4, 27.6e-6, 1.75)])
def test_aircraft_backlash_prediction_vs_simulation(params, B, amp_sim, f_sim):
    # studies/aircraft_backlash.py: 747, rigid screw, hybrid friction, at the actuator-command
    # break, grid 0.01 B..B x 0.3..5 Hz. Measured: predicted 5.37 / 14.9 / 24.8 um at 1.48 / 1.51 /
    # 1.51 Hz against the 300 s runs' 5.84 / 16.7 / 27.6 um at 1.76 / 1.75 / 1.75 Hz (the simulated
    # values are checked here against their own run below): amplitude -8 / -11 / -10 % (asserted
    # at the required 25 %), frequency -16 / -14 / -14 % (asserted at 18 %; the required 10 % is
    # not met: the forced open loop has several periodic answers to one sine, see docs: aircraft)
    from ema_casadi.limitcycle import setup

    model = ema.build_model(params, {"airframe": "b747", "friction": "hybrid", "screw": "rigid"})
    s = setup(model, "aircraft", model.p(B=B))
    kw = dict(p=s["p"], x0=s["x0"], inputs=s["inputs"], meas0=s["meas0"], dt=1e-4)
    df = describing_function(model, "aircraft", np.geomspace(0.01, 1.0, 7) * B, np.geomspace(0.3, 5.0, 8), **kw)
    (c,) = [c for c in df.cycles if c["stable"]]
    res = s["confirm"](300.0, 1e-4)
    sim = cycle_of(res.t, res["x_cmd"], 150.0)
    assert sim["amplitude"] == pytest.approx(amp_sim, rel=0.05) and sim["freq_hz"] == pytest.approx(f_sim, rel=0.02)
    assert c["amplitude"] == pytest.approx(sim["amplitude"], rel=0.25)
    assert c["freq_hz"] == pytest.approx(sim["freq_hz"], rel=0.18)
    if B == 3e-4:
        # the harmonic balance cannot balance this cycle (residual 0.19 after 6 steps, measured)
        # and says so: the prediction stays the describing function's, flagged
        hb = harmonic_balance(model, "aircraft", c, iterations=6, **kw)
        assert not hb["harmonic_balance"]["converged"] and hb["method"] == "describing function"
        assert (hb["amplitude"], hb["freq_hz"]) == (c["amplitude"], c["freq_hz"])
