"""Optimal moves (ema_casadi.optimal): the minimum-time move against the bang-bang bound
computed from the parameters, the limits in the optimum and in its replay, the refusals."""

import math

import numpy as np
import pytest

import ema_casadi as ema
from ema_casadi.optimal import OptimalError, optimal_move

FRICTIONLESS = {"F_seal": 0.0, "C_bear": 0.0, "c_v": 0.0, "b_m": 0.0}


@pytest.fixture(scope="module")
def params():
    return ema.load_parameters("models/cesa_ema.toml")


@pytest.fixture(scope="module")
def rigid_move(params):
    model = ema.build_model(params.replace(**FRICTIONLESS), {"screw": "rigid"})
    return model, optimal_move(model, 0.01)


def bang_bang(P, d):
    """Minimum time of a move d (m) at no load, rigid and frictionless: accelerate at the
    current limit, cruise at the voltage circle's top speed (i_d = 0, i_q = 0 at cruise:
    |v| = omega_e psi), brake at the current limit. Returns (a m/s^2, v_top m/s, T s)."""
    lead = P.p / (2 * math.pi)
    J_eq = P.J_m + P.J_s + P.M * lead**2  # inertia reflected to the shaft (kg m^2)
    K_t = 1.5 * P.pp * P.psi
    a = K_t * P.I_max / J_eq * lead
    v_top = P.k_v * P.V_dc / math.sqrt(3) / (P.pp * P.psi) * lead
    T = d / v_top + v_top / a if d > v_top**2 / a else 2 * math.sqrt(d / a)
    return a, v_top, T


def test_minimum_time_meets_the_bang_bang_bound(rigid_move):
    model, r = rigid_move
    a, v_top, T = bang_bang(model.pdict(), 0.01)
    assert a == pytest.approx(20.44, rel=1e-3) and v_top == pytest.approx(0.09821, rel=1e-3)
    assert r.ipopt["status"] == "Solve_Succeeded"
    # measured 0.10771 s against 0.10663 s (+1.0 %: the current's rise and reversal through L, the
    # R i and omega L i drops that share the voltage circle while accelerating, 40 intervals); the 2 %
    assert T <= r.duration <= 1.02 * T, (r.duration, T)
    assert {"current", "voltage"} <= set(r.binding)
    # it cruises at the voltage circle's top speed (measured +3.1e-4 at mid-move, the approach still ringing); on the
    # way up the speed overshoots it (to 0.12 m/s: the current lags through L, the back-EMF regenerates)
    v_rod = r.outputs[model.output_with("rod_velocity")]
    assert v_rod[len(v_rod) // 2] == pytest.approx(v_top, rel=1e-3)


@pytest.fixture(scope="module")
def reference(params):
    return ema.build_model(params)


def test_collocation_and_shooting_agree_on_the_reference_minimum_time(reference):
    from ema_casadi.optimal import Problem, solve

    out = {}
    for method in ("auto", "collocation"):
        prob = Problem(reference, 0.01, 0.0, "time", None, 0.0, "drive", 40, False, method=method)
        out[method] = (solve(prob), prob.method)
    (shoot, chosen), (coll, _) = out["auto"], out["collocation"]
    # no load: 40 intervals x 5 RK4 substeps = 200 <= EXPAND_LIMIT, so auto keeps the shooting
    assert chosen == "shooting" and shoot["status"] == coll["status"] == "Solve_Succeeded"
    # the same NLP but for the dynamics (the same grid, controls, limits at the nodes): measured 0.1077836 s (RK4)
    # against 0.1077831 s (Radau IIA), 4.9e-6 relative; x 10
    assert coll["T"] == pytest.approx(shoot["T"], rel=5e-5)


def test_loaded_minimum_time_by_collocation_meets_an_rk4_check(reference):
    """10 mm against 15 kN: the stiff case auto collocates (RK4 would need 695 substeps an
    interval); its controls integrated again by RK4 at those substeps give its nodes."""
    import casadi as ca

    from ema_casadi.optimal import Problem, solve
    from ema_casadi.simulation import interval_function

    prob = Problem(reference, 0.01, 15e3, "time", None, 0.0, "drive", 40, False)
    s = solve(prob)
    assert prob.method == "collocation" and s["status"] == "Solve_Succeeded", (prob.method, s["status"])
    # measured 0.114984 s; the load only slows the move: above the no-load bang-bang bound 0.10663 s
    assert s["T"] > bang_bang(reference.pdict(), 0.01)[2]
    assert {"current", "voltage"} <= {k for k, v in s["margins"].items() if v < 1e-3}
    F = interval_function(prob.model, held=True, substeps=prob.substeps)
    U, H = (np.asarray(ca.evalf(a)) for a in prob._inputs(ca.DM(s["C"])))
    x, X = s["x0"], [s["x0"]]
    for k, dt in enumerate(np.diff(s["t"])):
        x = np.asarray(F(x, U[:, k], prob.p, H[:, k], dt)).ravel()
        X.append(x)
    scale = np.maximum(prob.model.full_scale(prob.p), 1e-6)
    err = np.abs(np.array(X).T - s["X"]) / scale[:, None]
    # measured: the currents 1.2e-3 of full scale (0.03 A), the rod 6e-7 of the stroke; x 4
    assert err.max() < 5e-3, dict(zip(prob.model.states, err.max(1), strict=True))
    # the rod arrives: measured 13 nm short of the 10 mm; x ~8
    end = ca.DM(X[-1])
    rod = float(ca.evalf(prob._signal(prob.rod, end, prob._rates(end, ca.DM(s["C"][:, -1]))[1])))
    assert rod == pytest.approx(prob.target, abs=1e-7)


def test_the_replay_through_the_ecu_keeps_the_limits(rigid_move):
    model, r = rigid_move
    check = r.replay_check["ratings"]
    assert check["current"]["ratio"] <= 1.01  # I_max within 1 % (the acceptance)
    assert check["voltage"]["within"] and check["stroke"]["within"]
    # the ECU's rate limit keeps its replay slower than the drive's bound
    assert r.replay_check["settling_time_s"] > r.duration


def test_command_shaping_through_the_ecu_settles_sooner_than_its_step(params):
    # the reference actuator (elastic screw, hybrid friction in the replay): the shaped command (1 mm beyond the
    # target, back at 0.1245 s) against the ECU's own step, both replayed in the full model and judged by the
    # same 2 % settling time; measured 0.1228 s against 0.1307 s (-6 %), on the smooth variant 0.1226 s
    model = ema.build_model(params)
    r = optimal_move(model, 0.01, through="ecu")
    rep = r.replay_check
    assert r.ipopt["status"] == "Shaped"
    assert rep["settling_time_s"] < 0.98 * rep["ecu_step_settling_time_s"], rep
    # the optimum's own 2 % time and the replay's agree to the output spacing and the smooth/full difference
    assert rep["settling_time_s"] == pytest.approx(r.duration, rel=0.01)
    check = rep["ratings"]
    assert check["current"]["ratio"] <= 1.01 and check["voltage"]["within"] and check["stroke"]["within"]
    # every actuator rating held; only the drive strategy (i_d = 0 commanded) may be left by the FOC's own tracking
    # under its voltage clip (measured i_d down to -0.29 A, 1.2 % of I_max): labelled a strategy, not a limit
    assert all(c["within"] for c in check.values() if c["role"] != "strategy"), check
    assert {c["role"] for c in check.values()} == {"rating", "strategy"}
    assert check["field_weakening"]["peak"] > -0.05 * check["current"]["limit"]
    t, x = r.command_profile  # the start at t = 0, the overshoot, the target held after the return
    assert t[0] == 0 and x[0] == pytest.approx(0.0, abs=1e-12) and x[-1] == pytest.approx(0.01, rel=1e-12)
    assert abs(x).max() <= model.operating_limits()["stroke"]


def test_bad_requests_are_refused_before_any_work(params):
    model = ema.build_model(params)
    with pytest.raises(OptimalError, match="beyond the stroke"):
        optimal_move(model, 0.1)
    with pytest.raises(OptimalError, match="above the .* kN the screw holds"):
        optimal_move(model, 0.01, load=80e3)
    with pytest.raises(OptimalError, match="objective 'speed' unknown"):
        optimal_move(model, 0.01, objective="speed")
    with pytest.raises(OptimalError, match="below the minimum time .* at the rated rod speed"):
        optimal_move(model, 0.01, objective="energy", duration=0.01)
    with pytest.raises(OptimalError, match="needs its duration"):
        optimal_move(model, 0.01, objective="energy")
    with pytest.raises(OptimalError, match="through ecu: command shaping minimises the time"):
        optimal_move(model, 0.01, objective="energy", duration=0.3, through="ecu")


def test_the_figure_and_the_command_profile(rigid_move, tmp_path):
    model, r = rigid_move
    fig = r.plot()
    assert len(fig.axes) == 4  # position, speed, current, voltage (no thermal network)
    t, x = r.command_profile
    assert t[0] == 0 and x[0] == pytest.approx(0.0, abs=1e-12) and x[-1] == pytest.approx(0.01, rel=1e-9)


# 3 s with the monotone barrier (35 s with the adaptive one on the loaded machine)
def test_energy_optimal_move_draws_less_than_the_ecu_step(params):
    # 10 mm in 0.3 s on the reference actuator's rigid counterpart (smooth friction): the energy from
    # the DC link (int P_dc, the runs' own energy accounting) of the replay through the ECU against the
    # ECU's step over the same 0.3 s; measured 2.41 J against 6.02 J (the optimum itself 2.58 J)
    model = ema.build_model(params, {"screw": "rigid"})
    r = optimal_move(model, 0.01, objective="energy", duration=0.3)
    rep = r.replay_check
    assert r.ipopt["status"] == "Solve_Succeeded" and rep["window_s"] == pytest.approx(0.3)
    assert rep["link_energy_J"] < rep["ecu_step_link_energy_J"]
    assert rep["ratings"]["current"]["within"] and rep["ratings"]["voltage"]["within"]


def test_envelope_top_speed_and_largest_force(params):
    # rigid, frictionless: the top speed against a load F where |v| = k_v V_dc/sqrt(3) with
    # i_q = F (p/2pi) / (eta K_t), v_q = R i_q + omega_e psi, v_d = -omega_e L_q i_q (a quadratic in omega_e);
    # measured to 2e-6 relative (the efficiency blend is 1/eta to 1e-9 at these powers); the largest
    # load held is the screw's declared held_load (the blend's middle at standstill)
    from ema_casadi.optimal import performance_envelope

    model = ema.build_model(params.replace(**FRICTIONLESS), {"screw": "rigid"})
    env = performance_envelope(model, loads=[0.0, 20e3], distances=[5e-3], intervals=20)
    P = model.pdict()
    lead, K_t, V = P.p / (2 * math.pi), 1.5 * P.pp * P.psi, P.k_v * P.V_dc / math.sqrt(3)
    for F, v in zip(env.loads, env.top_speed[None], strict=True):
        i_q = F * lead / (P.eta * K_t)
        a, b, c = P.psi**2 + (P.L_q * i_q) ** 2, 2 * P.R * i_q * P.psi, (P.R * i_q) ** 2 - V**2
        w_e = (-b + math.sqrt(b * b - 4 * a * c)) / (2 * a)
        assert v == pytest.approx(w_e / P.pp * lead, rel=1e-4), F
    assert env.largest_force[None] == pytest.approx(model.envelope_limits()["held_load"], rel=1e-6)
    assert env.min_time[None][0] > 5e-3 / (env.top_speed[None][0])  # slower than cruising all the way


def test_envelope_on_two_processes_is_the_same_computation(params):
    # each item (a temperature's steady states, a move) is the same NLP on the same model
    # rebuilt in the worker from its parameters and variants: the same answers to rounding
    from ema_casadi.optimal import performance_envelope

    model = ema.build_model(params.replace(**FRICTIONLESS), {"screw": "rigid"})
    one = performance_envelope(model, loads=[0.0, 20e3], distances=[2e-3, 5e-3], intervals=16)
    two = performance_envelope(model, loads=[0.0, 20e3], distances=[2e-3, 5e-3], intervals=16, jobs=2)
    assert np.allclose(two.top_speed[None], one.top_speed[None], rtol=1e-9, atol=0)
    assert np.allclose(two.min_time[None], one.min_time[None], rtol=1e-9, atol=0)
    assert two.largest_force[None] == pytest.approx(one.largest_force[None], rel=1e-9)
    with pytest.raises(OptimalError, match="jobs"):
        performance_envelope(model, loads=[0.0], distances=[2e-3], jobs=0)


def test_an_optimum_slower_than_the_ecus_own_step_asks_for_more_intervals(params):
    # the drive with its voltages free can do whatever its ECU does, so a minimum time above the ECU's own
    # step is the grid's (measured: 8 intervals 1.524 s, 20 intervals 1.17 s, 40 intervals 0.775 s, ECU 0.919 s)
    from ema_casadi.optimal import Unresolved

    model = ema.build_model(params)
    with pytest.raises(Unresolved, match=r"intervals 8: too coarse .* slower than the ECU's own step \(0.919 s"
                                         r".*give intervals 40 or more"):
        optimal_move(model, 0.075, intervals=8)
    r = optimal_move(model, 0.075)
    assert r.duration < r.ecu_step["settling_time_s"] < r.replay_check["settling_time_s"]


def test_a_move_within_the_sensors_step_is_refused_naming_the_smallest(params):
    # the LVDT's step q_x = 0.5 um: the loop leaves the rod 0.52-0.57 um from its target (measured at 10, 25,
    # 30 um), so a 25 um move (band 0.5 um) never settles, 30 um does; 10 um is refused with the move whose
    # band is twice where the loop left it (57 um), which settles
    from ema_casadi.optimal import Unresolved

    model = ema.build_model(params)
    assert model.pdict().q_x == 5e-7
    with pytest.raises(Unresolved, match=r"move 10 µm: .* rests 0.5\d+ µm from the target.* at least (5\d.\d+) µm"):
        optimal_move(model, 1e-5)
    r = optimal_move(model, 57.1e-6)
    assert r.replay_check["settling_time_s"] < 0.1 and r.ecu_step["settling_time_s"] < 0.1
