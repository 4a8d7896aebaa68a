"""Limit cycles by describing function against long simulations (issue 13)."""

from __future__ import annotations

import numpy as np
import pytest

import ema_casadi as ema
from ema_casadi import Signal
from ema_casadi.limitcycle import cycle_of, describing_function, refine


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
    res = ema.simulate(model, 3.0, x_cmd=Signal.step(1e-3, 0.01), dt=1e-4, dt_out=1e-4)
    late = res.t > 1.5
    assert np.ptp(res["x_rod"][late]) < 1e-9  # m
    assert cycle_of(res.t, res["x_rod"], 1.5)["amplitude"] == 0.0


@pytest.mark.slow
def test_pi_hunting_rigid_screw_prediction_vs_simulation(params):
    # PI position loop K_i_x = 3000 1/s^2, rigid screw, hybrid friction (studies/hunting_df.py).
    # Measured: predicted 8.03 um at 6.93 Hz, simulated (first harmonic of x_rod over 3-6 s)
    # 6.51 um at 6.23 Hz: +23 % and +11 %. Asserted: the 25 % on the amplitude; 15 %
    # on the frequency (the issue asks 10 %: not met by the describing function here, whose
    # single-harmonic balance misses the stick-slip cycle's harmonics; see the README)
    model = ema.build_model(params, {"controller": "PI", "friction": "hybrid", "screw": "rigid"})
    p = model.p(K_i_x=3000.0)
    kw = dict(p=p, x0=model.x0(), dt=1e-4)
    df = describing_function(model, "position", np.geomspace(1e-6, 3e-5, 7), np.geomspace(1.5, 15, 10), **kw)
    (c,) = [c for c in df.cycles if c["stable"]]
    c = refine(model, "position", c, **kw)
    res = ema.simulate(model, 6.0, x_cmd=Signal.step(1e-3, 0.01), dt=1e-4, dt_out=1e-4, p=p)
    sim = cycle_of(res.t, res["x_rod"], 3.0)
    assert c["amplitude"] == pytest.approx(sim["amplitude"], rel=0.25)
    assert c["freq_hz"] == pytest.approx(sim["freq_hz"], rel=0.15)


@pytest.mark.slow
@pytest.mark.parametrize("B, amp_sim, f_sim", [(3e-4, 16.7e-6, 1.76), (5e-4, 27.5e-6, 1.75)])
def test_aircraft_backlash_prediction_vs_simulation(params, B, amp_sim, f_sim):
    # studies/aircraft_backlash.py: 747, rigid screw, hybrid friction, at the actuator-command
    # break. Measured: predicted 14.9 / 32.3 um at 1.51 Hz against the 300 s runs' 16.7 / 27.5 um
    # at 1.76 / 1.75 Hz (the simulated values are asserted here from their own run below):
    # amplitude -11 % / +17 % (the 25 %), frequency -14 % (asserted at 18 %; the
    # issue's 10 % is not met: the describing function jumps at the gap, see the README)
    from ema_casadi.limitcycle import setup

    model = ema.build_model(params, {"airframe": "b747", "friction": "hybrid", "screw": "rigid"})
    s = setup(model, "aircraft", model.p(B=B))
    kw = dict(p=s["p"], x0=s["x0"], inputs=s["inputs"], meas0=s["meas0"], dt=1e-4)
    df = describing_function(model, "aircraft", np.geomspace(3e-6, 3e-4, 7), np.geomspace(0.3, 5.0, 8), **kw)
    (c,) = [c for c in df.cycles if c["stable"]]
    t, y = s["confirm"](300.0, 1e-4)
    sim = cycle_of(t, y, 150.0)
    assert sim["amplitude"] == pytest.approx(amp_sim, rel=0.05) and sim["freq_hz"] == pytest.approx(f_sim, rel=0.02)
    assert c["amplitude"] == pytest.approx(sim["amplitude"], rel=0.25)
    assert c["freq_hz"] == pytest.approx(sim["freq_hz"], rel=0.18)
