"""Signals by name and role: the model answers what the parts declare."""

import numpy as np
import pytest

import ema_casadi as ema
from ema_casadi import Signal


def test_one_unit_table_for_states_inputs_outputs(model_cache):
    model = model_cache()
    units = model.units
    assert units["t"] == "s"
    assert units["x_rod"] == "m" and units["f_ext"] == "N" and units["eta"] == "1"
    assert units["d_w"] == "rad/s" and units["i_q"] == "A" and units["P_cu"] == "W"
    assert set(model.states) | set(model.inputs) | set(model.outputs) <= set(units)
    r = ema.simulate(model, 0.002, dt=2.5e-6, solver="rk4", decimate=1)  # inside RK4's 5.57 us limit
    assert r.units() == {c: units[c] for c in r.columns()}


def test_roles_find_the_rod_and_the_shaft(model_cache):
    elastic, rigid = model_cache(), model_cache(screw="rigid")
    assert elastic.state_with("rod_position") == "x_rod"
    assert elastic.state_with("contact_velocity") == "v_rod"
    assert rigid.state_with("contact_velocity") == "omega"
    assert rigid.states_with("play") == ("x_play",)
    P = elastic.pdict()
    assert elastic.travel()["phi"] == pytest.approx(P.p / (2 * np.pi), rel=1e-15)


def test_simulate_drives_any_input_by_name(model_cache):
    """A 1 um step injected at the position feedback (d_x) acts like a -1 um command."""
    model = model_cache()
    a = ema.simulate(model, 0.05, d_x=Signal.step(1e-6, 0.01), solver="cvodes", dt_out=1e-3)
    b = ema.simulate(model, 0.05, x_cmd=Signal.step(-1e-6, 0.01), solver="cvodes", dt_out=1e-3)
    assert np.abs(a["x_rod"] - b["x_rod"]).max() < 1e-15
    assert a["t"] is a.t


def test_inputs_are_parsed_with_their_quantity_kind(model_cache):
    model = model_cache()
    with pytest.raises(ema.SignalError, match="unknown dimensionless unit 'mm'"):
        ema.simulate(model, 0.01, eta="900mm")
    r = ema.simulate(model, 0.002, eta="0.85", f_ext="2kN", x_cmd="1mm")
    assert r["eta"][-1] == 0.85 and r["f_ext"][-1] == 2e3 and r["x_cmd"][-1] == 1e-3
    with pytest.raises(TypeError, match="unexpected keyword argument 'x_cmdd'; did you mean 'x_cmd'"):
        ema.simulate(model, 0.01, x_cmdd=1e-3)


def test_options_no_part_reads_are_listed_as_ignored(model_cache):
    assert model_cache(friction="hybrid", friction_shape="fermi").ignored == ("friction_shape", "stribeck")
    assert model_cache().ignored == ()


def test_losses_and_stored_energy_come_from_the_parts(model_cache):
    model = model_cache(endstop="elastic")
    owners = {n: part.family for part in model.parts for n in (o.name for o in part.outputs)}
    assert owners["P_stop"] == "endstop" and owners["P_contact"] == "screw" and owners["P_cu"] == "motor"
    assert set(model.outputs_of("loss")) == {
        "P_cu", "P_fe", "P_inv_cond", "P_inv_sw", "P_screw_nut", "P_contact", "P_friction", "P_viscous", "P_stop"}
    assert "P_contact" not in model_cache(screw="rigid").outputs
