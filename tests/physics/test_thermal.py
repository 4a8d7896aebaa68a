"""The thermal network (docs: physics, thermal = lumped): single node, feedbacks R(T),
psi(T), eta(T), and the electrical energy balance with iron loss.

Held-load tests use the smooth friction with CVODES and eta_inv = 1/eta, so that the
screw-nut factor g = 1/eta whatever the blend between driving and back-driven says: the
held current is then constant once the load step has settled (by ~5 s; measured
constant to 1e-7 from 10 s on), and the feedback alone changes it. Each tolerance is
the stated acceptance value; the measured deviation is stated beside it.
"""

import numpy as np
import pytest

import ema_casadi as ema
from ema_casadi import Signal

T_SETTLED = 10.0  # s: the 30 kN load step has settled (current constant to 1e-7)


@pytest.fixture(scope="module")
def lumped(params):
    return ema.build_model(params, {"thermal": "lumped"})


def _hold(model, params, t_end, **overrides):
    """30 kN held at standstill from t = 0; feedbacks as given (others off)."""
    flags = {"feedback_R": 0.0, "feedback_psi": 0.0, "feedback_eta": 0.0, **overrides}
    p = model.p(eta_inv=1 / params.screw.eta, **flags)
    return ema.simulate(model, t_end, x_cmd=0.0, f_ext=30e3, solver="cvodes", dt_out=1.0, p=p)


def test_single_node_time_constant_and_final_rise(lumped, params):
    """The inverter node (one capacity to the ambient) under a constant loss: the rise
    reaches 63.2 % of its final value at tau = R_th C_th = 100 s (within 1 %; measured
    99.996 s), and the final rise is P R_th (within 0.5 %; measured 4.5e-5 short of it
    after 10 tau, e^-10)."""
    r = _hold(lumped, params, 1000.0)
    th = params.thermal
    P_inv = r["P_inv_cond"] + r["P_inv_sw"]
    sel = r.t >= T_SETTLED
    assert np.ptp(P_inv[sel]) < 1e-6 * P_inv[-1]  # a constant loss step
    rise = r["T_inv"] - 20.0
    final = P_inv[-1] * th.R_th_inv
    tau = th.R_th_inv * th.C_th_inv
    assert tau == pytest.approx(100.0)
    assert rise[-1] == pytest.approx(final, rel=5e-3)
    t63 = np.interp((1 - np.exp(-1)) * final, rise, r.t)
    assert t63 == pytest.approx(tau, rel=1e-2)


def test_winding_resistance_feedback(lumped, params):
    """R(T_w) on: a held 30 kN load heats the winding (75 K in 300 s) and the copper loss
    grows by (1 + alpha_Cu dT_w) (x1.29 here) within 1 % at every sample (measured
    5e-11); with R(T) off it stays constant."""
    r = _hold(lumped, params, 300.0, feedback_R=1.0)
    sel = r.t >= T_SETTLED
    T_w, P_cu = r["T_w"][sel], r["P_cu"][sel]
    assert T_w[-1] - T_w[0] > 50.0
    a = params.motor.alpha_Cu
    factor = (1 + a * (T_w - 20.0)) / (1 + a * (T_w[0] - 20.0))
    np.testing.assert_allclose(P_cu / P_cu[0], factor, rtol=1e-2)
    off = _hold(lumped, params, 300.0)
    assert np.ptp(off["P_cu"][off.t >= T_SETTLED]) < 1e-6 * off["P_cu"][-1]


def test_magnet_flux_feedback(lumped, params):
    """psi(T_h) on: the current holding 30 kN grows by 1/(1 + alpha_psi dT_h) within 1 %
    (measured 6e-9; factor 1.025) as the housing warms (20 K in 300 s)."""
    r = _hold(lumped, params, 300.0, feedback_psi=1.0)
    sel = r.t >= T_SETTLED
    i, T_h = np.hypot(r["i_d"], r["i_q"])[sel], r["T_h"][sel]
    assert T_h[-1] - T_h[0] > 15.0
    ap = params.thermal.alpha_psi
    factor = (1 + ap * (T_h[0] - 20.0)) / (1 + ap * (T_h - 20.0))
    assert factor[-1] > 1.02
    np.testing.assert_allclose(i / i[0], factor, rtol=1e-2)


def test_cold_screw_needs_the_analytic_extra_current(params):
    """eta(T_s) on, soaked at -40 degC (eta = 0.8257 from the table): a steady 40 mm/s
    against 20 kN draws the analytic extra current over the same motion at 20 degC
    (eta = 0.90) within 2 % (measured 0.92 A, 0.11 % below the analytic 0.924 A)."""
    model = ema.build_model(params, {"thermal": "lumped"})
    p = model.p(feedback_R=0.0, feedback_psi=0.0, feedback_eta=1.0)
    v, F = 0.040, 20e3
    i = {}
    for T in (-40.0, 20.0):
        x0 = model.x0()
        for n in model.states_with("temperature"):
            x0[model.index(n)] = T
        r = ema.simulate(model, 0.6, Signal.ramp(v), F, T_amb=T, x0=x0, p=p, solver="cvodes", dt_out=1e-3)
        sel = r.t > 0.3
        np.testing.assert_allclose(r["v_rod"][sel], v, rtol=1e-3)
        i[T] = float(np.mean(r["i_q"][sel]))
        eta = float(np.mean(r["eta_screw"][sel]))
        assert eta == pytest.approx(np.interp(T, params.thermal.T_eta, params.thermal.eta_T), abs=2e-4)
    s, fr = params.screw, params.friction
    F_r = fr.F_seal + F * (2 * np.pi / s.p) * fr.C_bear
    eta_cold = np.interp(-40.0, params.thermal.T_eta, params.thermal.eta_T)
    extra = (F + F_r + fr.c_v * v) * s.p / (2 * np.pi) * (1 / eta_cold - 1 / s.eta) / params.K_t
    assert extra > 0.8  # A
    assert i[-40.0] - i[20.0] == pytest.approx(extra, rel=2e-2)


@pytest.mark.parametrize("scenario", ["reference", "loaded"])
def test_energy_balance_closes_with_thermal_network_and_iron(params, scenario):
    """Electrical input = change of stored energy + every loss (iron included) + work on
    the load, with thermal = lumped and iron_loss = on, within 2e-4 (measured 2.6e-7
    and 3.6e-6; the iron loss is 2 % and 1 % of the input),
    on the reference scenario (1 s: 1 mm step at 0.01 s, 0.375 mm 1 Hz sine
    from 0.5 s) and on the loaded one of the thermal-off balance test. Leaving out the
    iron loss alone would break it."""
    model = ema.build_model(params, {"thermal": "lumped", "iron_loss": "on"})
    if scenario == "reference":
        args = (1.0, Signal.step(1e-3, 0.01) + Signal.sine(0.375e-3, 1.0, 0.5), 0.0)
    else:
        args = (0.4, Signal.step(2e-3, 0.01) + Signal.sine(1e-3, 5.0, 0.1), 10e3)
    r = ema.simulate(model, *args, solver="cvodes", dt_out=2e-6, rtol=1e-10, atol=1e-12)
    losses = sum(r[k] for k in model.outputs_of("loss"))
    lhs = np.trapezoid(r["P_dc"], r.t)
    rhs = r["E_stored"][-1] - r["E_stored"][0] + np.trapezoid(losses + r["P_load"], r.t)
    scale = np.trapezoid(np.abs(r["P_dc"]), r.t)
    assert abs(lhs - rhs) < 2e-4 * scale
    assert np.trapezoid(r["P_fe"], r.t) > 2e-4 * scale


def test_heat_reaches_the_network(params):
    """Every loss the parts declare is routed to a node: the heat into the nodes is the
    sum of the losses, sample by sample."""
    model = ema.build_model(params, {"thermal": "lumped", "iron_loss": "on", "endstop": "elastic"})
    r = ema.simulate(model, 0.2, Signal.step(1e-3, 0.01), 5e3, solver="cvodes", dt_out=1e-3)
    heat = sum(r[n] for n in model.outputs if n.startswith("P_heat_"))
    losses = sum(r[k] for k in model.outputs_of("loss"))
    np.testing.assert_allclose(heat, losses, rtol=1e-12, atol=1e-9)


def test_off_model_has_no_thermal_states_and_unit_parameters(params, model_cache):
    """thermal = off: no temperature state, no T_amb input; R, psi and the eta input
    drive the physics (the regression tests check the trajectories to 1e-12 m)."""
    model = model_cache()
    assert model.states_with("temperature") == () and "T_amb" not in model.inputs
    lumped = ema.build_model(params, {"thermal": "lumped"})
    assert lumped.states_with("temperature") == ("T_w", "T_h", "T_s", "T_inv")
    assert lumped.units["T_w"] == "degC" and lumped.units["T_amb"] == "degC"
    assert lumped.inputs[: len(model.inputs) - 3] == model.inputs[:-3]  # same order, T_amb added


# -- the parameter file's thermal values -------------------------------------------------
THERMAL_BAD = {
    "T not increasing": (("[-55.0, -20.0, 20.0, 80.0]", "[-55.0, 20.0, -20.0, 80.0]"),
                         r"\[thermal\] T_eta: temperatures must increase strictly"),
    "eta above 1": (("[0.80, 0.86, 0.90, 0.91]", "[0.80, 0.86, 0.90, 1.2]"), r"\[thermal\] eta_T: must be in \(0, 1\]"),
    "eta zero": (("[0.80, 0.86, 0.90, 0.91]", "[0.0, 0.86, 0.90, 0.91]"), r"\[thermal\] eta_T: must be in \(0, 1\]"),
    "lengths differ": (("[0.80, 0.86, 0.90, 0.91]", "[0.80, 0.86, 0.90]"),
                       r"\[thermal\] eta_T has 3 values, T_eta 4: expected one efficiency per temperature"),
    "one point": (("[-55.0, -20.0, 20.0, 80.0]", "[20.0]"), r"\[thermal\] T_eta: expected a list of 2 to 6 numbers"),
    "inverse beyond": (("[0.80, 0.86, 0.90, 0.91]", "[0.80, 0.86, 0.90, 0.01]"),
                       r"eta_T shifted by eta_inv - eta \(-0.02\) gives inverse efficiencies .* outside \(0, 1\]"),
    "switch": (("feedback_R = { value = 1,", "feedback_R = { value = 2,"), r"\[thermal\] feedback_R: must be 0 or 1"),
    "alpha_psi sign": (("value = -1.2e-3", "value = 1.2e-3"), r"\[thermal\] alpha_psi: must be zero or negative"),
    "kelvin": (('T_ref = { value = 20.0, unit = "degC" }', 'T_ref = { value = 293.15, unit = "K" }'),
               r"\[thermal\] T_ref: unit 'K' is not the expected SI unit 'degC'"),
    "below absolute zero": (('T_max_w = { value = 180.0', 'T_max_w = { value = -300.0'),
                            r"\[thermal\] T_max_w: must be a temperature in degC above -273.15"),
    "capacity": (('C_th_inv = { value = 400.0', 'C_th_inv = { value = 0.0'), r"\[thermal\] C_th_inv: must be positive"),
}


@pytest.mark.parametrize("case", list(THERMAL_BAD))
def test_thermal_parameters_are_validated(tmp_path, case):
    from conftest import REFERENCE

    (old, new), pattern = THERMAL_BAD[case]
    text = REFERENCE.read_text()
    assert old in text
    path = tmp_path / "bad.toml"
    path.write_text(text.replace(old, new, 1))
    with pytest.raises(ema.ParameterError, match=pattern) as exc:
        ema.load_parameters(path)
    assert "\n" not in str(exc.value) and str(path) in str(exc.value)


def test_old_files_load_and_tables_round_trip(tmp_path, params):
    """A file without the keys added for the thermal model (C_th_inv ... T_max_w, k_h,
    k_e) loads with the reference values; a set written back reads back the same, tables
    included; a table travels as TABLE_MAX flat entries, padded."""
    from conftest import REFERENCE
    from ema_casadi.model.params import TABLE_MAX

    new_keys = ("C_th_inv", "R_th_inv", "alpha_psi", "T_ref", "T_eta", "eta_T", "feedback_R", "feedback_psi",
                "feedback_eta", "T_max_w", "k_h", "k_e")
    lines = [ln for ln in REFERENCE.read_text().splitlines() if ln.split("=")[0].strip() not in new_keys]
    old = tmp_path / "old.toml"
    old.write_text("\n".join(lines) + "\n")
    p_old = ema.load_parameters(old)
    assert p_old.as_dict() == params.as_dict()
    back = ema.load_parameters(params.to_toml(tmp_path / "back.toml"))
    assert back.thermal == params.thermal and back.as_dict() == params.as_dict()
    d = params.as_dict()
    assert [d[f"T_eta_{i}"] for i in range(TABLE_MAX)] == [-55.0, -20.0, 20.0, 80.0, 81.0, 82.0]
    assert [d[f"eta_T_{i}"] for i in range(TABLE_MAX)] == [0.80, 0.86, 0.90, 0.91, 0.91, 0.91]
    assert params.replace(T_eta=(0.0, 50.0), eta_T=(0.85, 0.9)).thermal.T_eta == (0.0, 50.0)


def test_cavity_temperature_signals():
    assert ema.parse_signal("-40", "temperature")(np.array([1.0]))[0] == -40.0
    assert ema.parse_signal("step:-20degC@5+40", "temperature")(np.array([0.0, 6.0])).tolist() == [40.0, 20.0]
    with pytest.raises(ema.SignalError, match="unknown temperature unit 'K'"):
        ema.parse_signal("300K", "temperature")


def test_a_loss_routed_nowhere_is_an_assembly_error(params, monkeypatch):
    """A part whose loss heats no node cannot be built with the thermal network (its
    heat would vanish); without the network it does not matter."""
    from ema_casadi.model.components import REGISTRY, endstop

    class Leaky(endstop.Elastic):
        heat = {}

    monkeypatch.setitem(REGISTRY["endstop"], "elastic", Leaky)
    with pytest.raises(ema.AssemblyError, match=r"losses \['P_stop'\] heat no thermal node"):
        ema.build_model(params, {"endstop": "elastic", "thermal": "lumped"})
    assert "P_stop" in ema.build_model(params, {"endstop": "elastic"}).outputs
