"""Hybrid (Karnopp stick-slip) friction (docs: physics) and its integrator wrapper.

The rod is "held" by a constant motor current: position and speed loops open at
their loop breaks (the speed PI's integrator then holds the current command), the
current loop closed, the drive train preloaded to the force that current produces.
"""

import math

import numpy as np
import pytest

import ema_casadi as ema
from ema_casadi import Signal

SCREWS = ("elastic", "rigid")
REFERENCE = Signal.step(1e-3, 0.01) + Signal.sine(0.375e-3, 1.0, 0.5)


@pytest.fixture(scope="module")
def hybrid(model_cache):
    return lambda screw="elastic", **v: model_cache(friction="hybrid", screw=screw, **v)


def g_rest(params):
    """Screw efficiency factor at standstill: the blend midpoint of 1/eta and eta_inv."""
    return 0.5 / params.screw.eta + 0.5 * params.screw.eta_inv


def F_start(params, f_ext=0.0):
    F_r = params.friction.F_seal + abs(f_ext) * 2 * math.pi / params.screw.p * params.friction.C_bear
    return params.friction.r_start * F_r


def held(model, params, F0):
    """(x0, p) with the motor current producing the rod force F0 (N), at equilibrium."""
    r = params.screw.p / (2 * math.pi)
    I0 = F0 * r * g_rest(params) / params.K_t
    x0 = model.x0()
    x0[model.index("z_w")] = I0
    x0[model.index("i_q")] = I0
    x0[model.index("z_q")] = params.motor.R * I0  # the current PI's steady output
    if "v_rod" in model.states:  # spring preloaded to F0, rod in contact
        x0[model.index("phi")] = (params.screw.B / 2 + F0 / params.screw.C) / r
    return x0, model.p(loop_x=0, loop_w=0)


def contact_position(res, screw):
    """Position of the friction contact: the rod (elastic) or the nut = phi p/2pi (rigid)."""
    return res["x_rod"] if screw == "elastic" else res["x_in"]


@pytest.mark.parametrize("solver", ["rk4", "cvodes"])
@pytest.mark.parametrize("screw", SCREWS)
def test_rod_held_below_breakaway_stays_still_for_1s(params, hybrid, screw, solver):
    model = hybrid(screw)
    F0 = 0.9 * F_start(params)
    x0, p = held(model, params, F0)
    res = ema.simulate(model, 1.0, 0.0, x0=x0, p=p, dt=1e-4, solver=solver, rtol=1e-10, atol=1e-13)
    x = contact_position(res, screw)
    assert np.abs(x - x[0]).max() < 1e-12
    assert np.all(res["stick"] == 1)
    # RK4 holds v at exactly 0; CVODES's Newton updates leave rounding dust (~1e-32 m/s)
    assert np.abs(res["v_rod"]).max() <= (0.0 if solver == "rk4" else 1e-20)
    assert res.info["mode_switches"] == 0
    # held by friction: it carries the whole applied force (F_friction = F_in - F_ext at rest)
    assert res["F_friction"][-1] == pytest.approx(F0, rel=1e-6)


@pytest.mark.parametrize("screw", SCREWS)
def test_raising_the_force_above_F_start_starts_motion_within_one_step(params, hybrid, screw):
    model = hybrid(screw)
    x0, p = held(model, params, 0.9 * F_start(params))
    # with the position loop open, x_cmd acts as a speed command K_x (2 pi/p) x_cmd; with
    # the speed loop open, a step in it raises the current command by dI at once and
    # then ramps it by dI per integral time T_i_w
    dI = 0.01
    step = dI / (params.control.K_p_w * params.control.K_x * 2 * math.pi / params.screw.p)
    res = ema.simulate(model, 0.1, Signal.step(step, 0.05), x0=x0, p=p, dt=1e-4, solver="rk4", decimate=1)
    F_hold = np.abs(res["F_in"] - res["f_ext"])  # force the friction has to hold
    x = contact_position(res, screw)
    n_force = int(np.argmax(F_hold > F_start(params)))
    n_move = int(np.argmax(np.abs(x - x[0]) > 0))
    assert res.t[n_force] > 0.05
    assert n_force <= n_move <= n_force + 1
    assert np.all(res["stick"][:n_force] == 1) and res["stick"][n_move] == 0


@pytest.mark.parametrize("screw", SCREWS)
def test_sliding_friction_is_F_r_with_its_bearing_term(params, hybrid, screw):
    model = hybrid(screw)
    f_ext = 10e3  # N, pushes the rod in: F_r = F_seal + |F_ext| (2 pi/p) C_bear
    res = ema.simulate(model, 0.5, Signal.sine(2e-3, 2.0), f_ext, dt=1e-5, dt_out=1e-4, solver="rk4")
    F_r = params.friction.F_seal + f_ext * 2 * math.pi / params.screw.p * params.friction.C_bear
    assert F_r == pytest.approx(527.0, rel=1e-3)  # the bearing term is 2.5x the seal here
    v = res["v_rod"]
    sliding = np.abs(v) >= params.friction.eps
    assert sliding.sum() > 0.8 * len(v)
    F_c = res["F_friction"] - params.friction.c_v * v  # Coulomb part
    np.testing.assert_allclose(F_c[sliding], F_r * np.sign(v[sliding]), rtol=1e-9)


@pytest.mark.parametrize("solver", ["rk4", "cvodes"])
def test_no_creep_inside_the_dead_band(params, hybrid, solver):
    model = hybrid()
    x0, p = held(model, params, 0.5 * F_start(params))
    v_in_band = 0.5 * params.friction.eps
    x0[model.index("v_rod")] = v_in_band
    u0 = model.u()
    xdot = np.asarray(model.f(x0, u0, p)[0]).ravel()
    # the continuous law alone would let the rod creep at its in-band velocity ...
    assert xdot[model.index("x_rod")] == v_in_band and xdot[model.index("v_rod")] == 0
    # ... the wrapper resets it on entering stick
    res = ema.simulate(model, 2.0, 0.0, x0=x0, p=p, dt=1e-4, solver=solver, rtol=1e-10, atol=1e-13)
    assert np.abs(res["x_rod"]).max() < 1e-12
    assert res["v_rod"][0] == 0


@pytest.mark.parametrize("solver", ["rk4", "cvodes"])
def test_stuck_intervals_of_the_reference_scenario_hold_the_rod_exactly(params, hybrid, solver):
    res = ema.simulate(hybrid(), 1.0, REFERENCE, dt=1e-4, solver=solver, rtol=1e-10, atol=1e-13)
    stuck = res["stick"] > 0.5
    edges = np.flatnonzero(np.diff(np.r_[0, stuck.astype(int), 0]))
    runs = list(zip(edges[::2], edges[1::2], strict=True))
    assert len(runs) >= 3  # at rest before the step, after settling, at the sine's reversal
    for a, b in runs:
        assert np.ptp(res["x_rod"][a:b]) < 1e-12
        assert np.abs(res["v_rod"][a:b]).max() < 1e-20


def test_mode_switches_are_counted_at_every_step(hybrid):
    res = ema.simulate(hybrid(), 0.9, REFERENCE, dt=1e-5, dt_out=1e-5, solver="rk4")
    # dense output: the switches seen in the stick signal are all the switches
    assert res.info["mode_switches"] == np.count_nonzero(np.diff(res["stick"]))
    assert res.info["mode_switches"] >= 4
    decimated = ema.simulate(hybrid(), 0.9, REFERENCE, dt=1e-5, dt_out=1e-3, solver="rk4")
    assert decimated.info["mode_switches"] == res.info["mode_switches"]


def test_smooth_model_has_no_stick_mode(model_cache):
    res = ema.simulate(model_cache(), 0.1, REFERENCE, dt_out=1e-3, solver="rk4")  # the step inside RK4's limit
    assert np.all(res["stick"] == 0) and "mode_switches" not in res.info


@pytest.mark.parametrize("solver", ["rk4", "cvodes"])
def test_breakaway_under_a_load_ramp_at_the_analytic_instant(params, hybrid, solver):
    # rod centred in the backlash gap (F_in = 0), the controller at rest; the external
    # force ramps at R: the rod is held until |F_ext| = F_start(F_ext) = r (F_seal + k |F_ext|)
    fr, s = params.friction, params.screw
    k = 2 * math.pi / s.p * fr.C_bear
    R = 1e3  # N/s
    t_star = fr.r_start * fr.F_seal / (1 - fr.r_start * k) / R  # 0.20505 s
    dt = 1e-4
    res = ema.simulate(hybrid(), 0.21, 0.0, Signal.ramp(R), dt=dt, solver=solver, event_tol=1e-8,
                       rtol=1e-10, atol=1e-13)
    n_move = int(np.argmax(np.abs(res["x_rod"]) > 0))
    n_star = int(np.ceil(t_star / dt))  # first sample at or after the instant
    assert n_star <= n_move <= n_star + 1
    if solver == "cvodes":
        assert abs(res.info["switch_times"][0] - t_star) <= 1e-8


def test_cvodes_switch_instants_converge_with_event_tol_and_agree_with_fine_rk4(hybrid):
    model = hybrid()
    t_end = 0.15  # the step, its settling and the first stick-slip episodes
    fine = ema.simulate(model, t_end, REFERENCE, dt=1e-6, dt_out=1e-6, solver="rk4")
    t_rk4 = fine.t[np.flatnonzero(np.diff(fine["stick"])) + 1]
    runs = {tol: ema.simulate(model, t_end, REFERENCE, solver="cvodes", dt_out=1e-3, rtol=1e-10, atol=1e-13,
                              event_tol=tol) for tol in (1e-7, 1e-9)}
    t7, t9 = (runs[tol].info["switch_times"] for tol in (1e-7, 1e-9))
    assert len(t7) == len(t9) == len(t_rk4) == fine.info["mode_switches"] >= 5
    assert np.abs(t7 - t9).max() <= 1e-7 + 1e-9
    # the switches near F = F_start come slowly, so their instants are sensitive to the
    # trajectory: RK4 at 1e-6 s finds them 0.2-2.4 us later
    assert np.all((t_rk4 - t9 >= 0) & (t_rk4 - t9 <= 5e-6))
    assert np.abs(runs[1e-9]["x_rod"] - fine["x_rod"][::1000]).max() < 5e-9


def test_rk4_at_1e4_s_tracks_the_event_located_reference(hybrid):
    model = hybrid()
    ref = ema.simulate(model, 1.0, REFERENCE, solver="cvodes", dt_out=1e-4, rtol=1e-10, atol=1e-13, event_tol=1e-9)
    for dt, tol in ((1e-4, 1.5e-6), (1e-5, 0.15e-6)):  # measured 1.05 and 0.107 um: first order
        res = ema.simulate(model, 1.0, REFERENCE, dt=dt, dt_out=1e-4, solver="rk4")
        assert np.abs(res["x_rod"] - ref["x_rod"]).max() < tol
        assert res.info["mode_switches"] == ref.info["mode_switches"]


def first_harmonic(res, f, t0):
    """x_rod/x_cmd at f (Hz) over [t0, end] (a whole number of periods): (dB, deg)."""
    sel = res.t >= t0 - 1e-12
    t = res.t[sel]
    w = np.exp(-2j * np.pi * f * t)
    g = np.trapezoid(res["x_rod"][sel] * w, t) / np.trapezoid(res["x_cmd"][sel] * w, t)
    return 20 * np.log10(abs(g)), np.degrees(np.angle(g))


def _sine_run(model, amplitude, f, **kw):
    """Sine from rest, at least 2 s (one compiled rollout shape), then whole periods
    after a 0.2 s transient. Returns (result, start of the analysed window)."""
    periods = max(1, math.ceil((2.0 - 0.2) * f))
    t_end = 0.2 + periods / f
    return ema.simulate(model, t_end, Signal.sine(amplitude, f), **kw), 0.2


@pytest.mark.parametrize("f", [0.1, 0.5, 1.0, 2.0, 5.0])
def test_small_cycles_dwell_at_each_reversal(params, hybrid, f):
    # 0.5 % of the stroke: the rod reverses only through a stuck interval (stiction)
    res, t0 = _sine_run(hybrid(), 0.005 * params.actuator.stroke, f, dt=1e-4)
    v, stuck = res["v_rod"], res["stick"] > 0.5
    moving = np.flatnonzero((res.t >= t0) & ~stuck)
    turns = np.flatnonzero(np.diff(np.sign(v[moving])) != 0)
    assert len(turns) >= 1
    for c in turns:
        a, b = moving[c], moving[c + 1]  # last sample before the turn, first after
        dwell = res.t[b] - res.t[a]
        assert b > a + 1 and np.all(stuck[a + 1 : b])
        assert np.ptp(res["x_rod"][a + 1 : b]) == 0.0
        assert dwell > 5e-3  # measured 11 ms at 5 Hz ... 230 ms at 0.1 Hz


@pytest.mark.parametrize("f", [0.1, 0.5, 1.0, 2.0, 5.0])
def test_smooth_and_hybrid_agree_at_2_percent(params, model_cache, hybrid, f):
    A = 0.02 * params.actuator.stroke
    h, t0 = _sine_run(hybrid(), A, f, dt=1e-4)
    s, _ = _sine_run(model_cache(), A, f, solver="cvodes", dt=1e-4, rtol=1e-8, atol=1e-11)
    (gh, ph), (gs, ps) = first_harmonic(h, f, t0), first_harmonic(s, f, t0)
    # measured at most 1.5e-5 dB and 3.8e-4 deg over these frequencies; x3
    assert abs(gh - gs) < 5e-5 and abs(ph - ps) < 1.2e-3
