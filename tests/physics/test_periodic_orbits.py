"""Periodic orbits by shooting (ema.periodic_orbit) against long simulations."""

from __future__ import annotations

import numpy as np
import pytest

import ema_casadi as ema
from ema_casadi import Signal
from ema_casadi.limitcycle import cycle_of


@pytest.fixture(scope="module")
def params():
    return ema.load_parameters("models/cesa_ema.toml")


@pytest.fixture(scope="module")
def hunting(params):
    # PI position loop K_i_x = 3000 1/s^2, smooth friction, the reference set otherwise
    # (elastic screw with B = 20 um): the hunting study's smooth case
    model = ema.build_model(params, {"controller": "PI", "friction": "smooth"})
    p = model.p(K_i_x=3000.0)
    return model, p, ema.periodic_orbit(model, "position", p=p)


def _long_run(model, p, t_end=4.0):
    """The hunting study's scenario (1 mm step held) by the variable-step RODAS4, its
    last 2 s measured (the cycle's slowest multiplier is ~0.06: settled within periods)."""
    res = ema.simulate(model, t_end, x_cmd=Signal.step(1e-3, 0.01), p=p, dt_out=2e-6, rtol=1e-9, atol=1e-12)
    return cycle_of(res.t, res["x_rod"], t_end / 2)


def test_hunting_orbit_matches_the_long_simulation(hunting):
    model, p, orb = hunting
    sim = _long_run(model, p)
    print(orb, orb.signals, sim)
    assert orb.freq_hz == pytest.approx(sim["freq_hz"], rel=0.005)
    assert orb.signals["x_rod"]["amplitude"] == pytest.approx(sim["amplitude"], rel=0.01)
    assert orb.residual < 1e-9
    assert abs(orb.trivial_multiplier - 1) < 1e-6
    assert orb.stable
