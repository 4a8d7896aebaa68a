"""Acceptance: the reference actuator's physics, at every screw fidelity.

Tolerances: each test states where its number comes from (analytic values of the reference set,
an independent solver, or a conservation law).
"""

import math

import numpy as np
import pytest

import ema_casadi as ema
from ema_casadi import Signal


def first_harmonic(t, y, f, periods=1):
    """Amplitude and phase (deg) of the first harmonic of y over the last whole periods."""
    T = periods / f
    sel = t >= t[-1] - T - 1e-12
    tt, yy = t[sel], y[sel]
    w = 2 * np.pi * f
    a = 2 / T * np.trapezoid(yy * np.sin(w * tt), tt)
    b = 2 / T * np.trapezoid(yy * np.cos(w * tt), tt)
    return math.hypot(a, b), math.degrees(math.atan2(b, a))


@pytest.mark.parametrize("screw", ["elastic", "rigid"])
def test_stall_load_45kN_extends_52kN_cannot(model_cache, screw):
    # Stall at the 24 A limit: T = 1.5 pp psi I = 43.2 N m -> F_in = T (2 pi/p) eta =
    # 48.9 kN = F_ext + F_r(F_ext) -> F_ext = 46.9 kN (the stall, docs: physics). 45 kN is below, 52 kN above.
    model = model_cache(screw=screw)
    moved = {}
    for load in (45e3, 52e3):
        r = ema.simulate(model, 0.5, Signal.step(10e-3, 0.05), load, solver="cvodes", dt_out=1e-3)
        i0 = np.searchsorted(r.t, 0.05)
        moved[load] = r["x_rod"][-1] - r["x_rod"][i0]
        if load == 52e3:
            assert r["i_q"][-1] == pytest.approx(24.0, rel=1e-6)  # at the current limit
    assert moved[45e3] > 5e-3  # extends most of the 10 mm in 0.45 s
    assert moved[52e3] <= 1e-5  # cannot extend (it is pushed in or held)


@pytest.mark.parametrize("screw", ["elastic", "rigid"])
def test_unloaded_slew_at_rate_limit(model_cache, screw):
    model = model_cache(screw=screw)
    r = ema.simulate(model, 0.3, Signal.step(20e-3, 0.01), solver="cvodes", dt_out=1e-3)
    plateau = r["v_rod"][(r.t > 0.1) & (r.t < 0.2)]
    np.testing.assert_allclose(plateau, 0.080, rtol=0.01)


@pytest.mark.parametrize("screw", ["elastic", "rigid"])
def test_1mm_step_settles_without_steady_state_error(model_cache, screw):
    model = model_cache(screw=screw)
    r = ema.simulate(model, 0.5, Signal.step(1e-3, 0.01), solver="cvodes", dt_out=1e-4)
    e = np.abs(r["x_rod"] - 1e-3)
    # within +-1 % of the step from 0.1 s on (the loop's time constant is 1/K_x = 13 ms)
    assert e[r.t >= 0.1].max() <= 1e-5
    # zero steady-state error: the P loop on a type-1 plant has none; what is left is the
    # smooth-friction rod creeping through the backlash gap (< B/2 = 10 um, ~0.6 um here)
    assert e[-1] < 1e-6


@pytest.mark.parametrize("screw", ["elastic", "rigid"])
def test_steady_extension_against_30kN_draws_the_analytic_current(params, model_cache, screw):
    model = model_cache(screw=screw)
    v = 0.040
    r = ema.simulate(model, 0.6, Signal.ramp(v), 30e3, solver="cvodes", dt_out=1e-3)
    sel = r.t > 0.3
    np.testing.assert_allclose(r["v_rod"][sel], v, rtol=1e-3)
    p, fr = params.screw.p, params.friction
    omega = v * 2 * np.pi / p
    F_r = fr.F_seal + 30e3 * (2 * np.pi / p) * fr.C_bear
    i_analytic = ((30e3 + F_r + fr.c_v * v) * p / (2 * np.pi * params.screw.eta) + fr.b_m * omega) / params.K_t
    np.testing.assert_allclose(r["i_q"][sel], i_analytic, rtol=0.02)


def test_dc_and_pmsm_give_the_same_rod_response(model_cache):
    x_cmd = Signal.sine(0.5e-3, 2.0)
    out = {}
    for motor in ("pmsm", "dc"):
        r = ema.simulate(model_cache(motor=motor), 1.5, x_cmd, solver="cvodes", dt_out=1e-4)
        out[motor] = first_harmonic(r.t, r["x_rod"], 2.0)
    (a1, ph1), (a2, ph2) = out["pmsm"], out["dc"]
    assert abs(a1 - a2) <= 0.02 * 0.5e-3
    assert abs(ph1 - ph2) <= 3.0


def test_drive_train_mode_in_the_jacobian(params):
    # friction off: the mode of the rod mass M on the spring C against the referred
    # rotating inertia J_rot (2 pi/p)^2: omega_n^2 = C (1/M + (p/2 pi)^2 / J_rot)
    model = ema.build_model(params)
    p = model.p(F_seal=0.0, C_bear=0.0, B=0.0)
    import casadi as ca

    x = ca.SX.sym("x", model.nx)
    J = ca.Function("J", [x], [ca.jacobian(model.f(x, model.u(), p)[0], x)])
    lam = np.linalg.eigvals(np.asarray(J(np.zeros(model.nx))))
    r = params.screw.p / (2 * np.pi)
    J_rot = params.motor.J_m + params.screw.J_s
    f_expected = math.sqrt(params.screw.C * (1 / params.screw.M + r**2 / J_rot)) / (2 * np.pi)
    f_modes = np.abs(lam[np.abs(lam.imag) > 0]) / (2 * np.pi)
    f_near = f_modes[np.argmin(np.abs(f_modes - f_expected))]
    assert f_near == pytest.approx(f_expected, rel=0.02)
    assert f_expected == pytest.approx(1420, rel=0.01)  # the reference set's note


def test_rk4_and_cvodes_agree_on_the_reference_scenario(model_cache):
    # reference scenario: 1 mm step at 0.01 s, 0.375 mm 1 Hz sine added from 0.5 s
    model = model_cache()
    x_cmd = Signal.step(1e-3, 0.01) + Signal.sine(0.375e-3, 1.0, 0.5)
    ref = ema.simulate(model, 1.0, x_cmd, solver="cvodes", dt_out=1e-4, rtol=1e-10, atol=1e-12)
    rk = ema.simulate(model, 1.0, x_cmd, solver="rk4", dt=5e-6, dt_out=1e-4)
    np.testing.assert_array_equal(rk.t.round(9), ref.t.round(9))
    assert np.abs(rk["x_rod"] - ref["x_rod"]).max() < 0.1e-6


def test_energy_balance_closes(model_cache):
    # electrical input = change of stored energy + losses + work on the load
    model = model_cache()
    r = ema.simulate(model, 0.4, Signal.step(2e-3, 0.01) + Signal.sine(1e-3, 5.0, 0.1), 10e3,
                     solver="cvodes", dt_out=2e-6, rtol=1e-10, atol=1e-12)
    # every loss the parts declare, the inverter's included (P_dc is upstream of it)
    losses = sum(r[k] for k in model.outputs_of("loss"))
    lhs = np.trapezoid(r["P_dc"], r.t)
    rhs = r["E_stored"][-1] - r["E_stored"][0] + np.trapezoid(losses + r["P_load"], r.t)
    scale = np.trapezoid(np.abs(r["P_dc"]), r.t)
    # trapezoid error at 2 us spacing: measured 3.7e-6, asserted x5; leaving out the
    # contact-damping loss alone (2.7e-3) breaks it
    assert abs(lhs - rhs) < 2e-5 * scale
    assert np.trapezoid(r["P_contact"], r.t) > 100 * 2e-5 * scale


def test_sampled_ecu_stays_close_to_continuous(model_cache):
    model = model_cache()
    x_cmd = Signal.step(1e-3, 0.01)
    cont = ema.simulate(model, 0.1, x_cmd, dt=5e-6, dt_out=1e-4, solver="rk4")
    zoh = ema.simulate(model, 0.1, x_cmd, dt=5e-6, dt_out=1e-4, zoh=True, solver="rk4")
    # the slowest ECU rate (2 kHz) delays the position loop by ~1/4 ms: a few % of the
    # transient, nothing at the end
    assert np.abs(zoh["x_rod"] - cont["x_rod"]).max() < 0.05e-3
    assert abs(zoh["x_rod"][-1] - 1e-3) < 1e-5


def test_decimation_bounds_the_stored_samples(model_cache):
    model = model_cache()
    r = ema.simulate(model, 0.05, Signal.step(1e-3), dt=5e-6, dt_out=1e-3, solver="rk4")
    assert len(r.t) == 51
    assert r.info["steps"] == 10000
