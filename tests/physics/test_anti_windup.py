"""The ECU structure options: ``anti_windup = clamping`` against an independent NumPy
implementation of the equations in ``docs/guide/ecu-structure.md``
(``_cascade_reference.py``), the linearisation and the margins unchanged by the
options away from saturation, the smooth limit's shape and the efficiency switch's
width ``P_blend``.

The saturating step: a 20 mm position step under a 20 kN load on the PI cascade
(position PI with K_i_x = 400 1/s^2, speed PI, current PI of the dc-equivalent motor)
and a rigid drive train without friction, backlash or efficiency loss, so that the
reference needs only the controller and a one-mass shaft. The step drives the rate
limit (0.25 s of slew at 80 mm/s), the current limit (the acceleration and the stop)
and the voltage limit (each current step) into saturation; with clamping the rod
overshoots by 48 um, with back-calculation by 646 um.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from _cascade_reference import simulate_cascade

import ema_casadi as ema
from ema_casadi.model.components import ballscrew, controller

STEP, LOAD, T_END = 0.02, 20e3, 0.4  # m, N, s
DT = 1 / 64000  # s: every ECU rate (16, 8, 2 kHz) a whole number of steps
VARIANTS = dict(controller="PI", motor="dc", screw="rigid")

# Model against the reference with the same (banded) law: measured 4.4e-10 m, sampled
# and continuous ECU alike; it comes from the rigid screw's play operator with B = 0,
# whose output (the fed-back rod position) lags the nut by up to 4.1e-10 m (an RK4 stage
# that sees the gap at -1 ulp holds it). Tolerance 5x.
SAME_LAW_TOL = 2e-9  # m
# Model (band w = 1 % of each limit) against exact conditional integration, continuous
# ECU: measured 2.23 um; the reference puts the band's effect at 1.14 um for a 0.5 %
# band and 4.44 um for 2 % (linear in the band width, so it is the band's). Tolerance
# 1.5x the measured effect; the two anti-windup laws differ by 690 um on this step.
BAND_TOL = 3.5e-6  # m


@pytest.fixture(scope="module")
def rig(params):
    return params.replace(F_seal=0.0, C_bear=0.0, c_v=0.0, b_m=0.0, eta=1.0, eta_inv=1.0, B=0.0, K_i_x=400.0)


def _model_step(rig, anti_windup, zoh):
    model = ema.build_model(rig, {**VARIANTS, "anti_windup": anti_windup})
    res = ema.simulate(model, T_END, x_cmd=STEP, f_ext=LOAD, dt=DT, zoh=zoh, solver="rk4", decimate=1)
    return np.asarray(res["x_rod"], float), np.asarray(res["i_cmd"], float)


def _saturated(i_cmd, rig):
    return np.mean(np.abs(i_cmd) >= rig.motor.I_max * (1 - 1e-12))


def test_sampled_clamping_matches_the_numpy_cascade(rig):
    x, i_cmd = _model_step(rig, "clamping", zoh=True)
    assert _saturated(i_cmd, rig) > 1e-3  # the speed PI sits on its limit (0.25 % of the samples)
    ref = simulate_cascade(rig.as_dict(), STEP, LOAD, T_END, DT, "band", zoh=True)[:, 0]
    assert np.abs(x - ref).max() <= SAME_LAW_TOL
    back = simulate_cascade(rig.as_dict(), STEP, LOAD, T_END, DT, "backcalc", zoh=True)[:, 0]
    assert np.abs(x - back).max() > 1e5 * SAME_LAW_TOL  # the test tells the two laws apart


def test_continuous_clamping_matches_numpy_within_the_band(rig):
    x, _ = _model_step(rig, "clamping", zoh=False)
    P = rig.as_dict()
    same = simulate_cascade(P, STEP, LOAD, T_END, DT, "band")[:, 0]
    exact = simulate_cascade(P, STEP, LOAD, T_END, DT, "exact")[:, 0]
    assert np.abs(x - same).max() <= SAME_LAW_TOL
    assert np.abs(x - exact).max() <= BAND_TOL
    # clamping's own effect on the overshoot, far above the band's
    x_back, _ = _model_step(rig, "backcalc", zoh=False)
    assert (x_back.max() - STEP) > 10 * (x.max() - STEP) > 100 * BAND_TOL


@pytest.mark.parametrize("variants", [{}, {"motor": "dc"}, {"controller": "PI"}], ids=["pmsm", "dc", "PI"])
@pytest.mark.parametrize("f_ext", [0.0, 15e3], ids=["rest", "15kN"])
def test_margins_do_not_depend_on_the_options(params, variants, f_ext):
    """Away from saturation the anti-windup terms and their derivatives vanish and the
    smooth limit is the identity: the same linearisation, the same margins (1e-9 rel)."""
    p = params.replace(K_i_x=400.0)
    base = ema.loop_margins(ema.build_model(p, variants), f_ext=f_ext)
    for option in ({"anti_windup": "clamping"}, {"limit_shape": "smooth"}):
        other = ema.loop_margins(ema.build_model(p, {**variants, **option}), f_ext=f_ext)
        for loop, m in base.items():
            for name in ("gm_db", "pm_deg", "f_gc_hz", "disk_margin", "delay_margin_s"):
                a, b = getattr(m, name), getattr(other[loop], name)
                assert (a is None and b is None) or a == pytest.approx(b, rel=1e-9, abs=0), (option, loop, name)


def test_option_values_are_declared_and_checked(params):
    from ema_casadi.model.components import OPTIONS, VariantError, validate_variants

    assert OPTIONS["anti_windup"] == ("backcalc", "clamping")
    assert OPTIONS["limit_shape"] == ("clip", "smooth")
    with pytest.raises(VariantError, match="anti_windup"):
        validate_variants({"anti_windup": "clamp"})
    model = ema.build_model(params.replace(), {"anti_windup": "clamping"})
    assert model.variants["anti_windup"] == "clamping" and model.ignored == ()


def test_smooth_limit_is_c1_and_exact_outside_its_knee():
    u = ca.SX.sym("u")
    lim, knee = 24.0, 0.05  # the reference w_knee
    y = controller.soft_clip(u, lim, knee)
    f = ca.Function("f", [u], [y, ca.jacobian(y, u)])
    inner = np.linspace(-(1 - knee) * lim, (1 - knee) * lim, 101)
    outer = np.concatenate([np.linspace((1 + knee) * lim, 3 * lim, 11), -np.linspace((1 + knee) * lim, 3 * lim, 11)])
    vi, di = (np.asarray(v).ravel() for v in f(inner.reshape(1, -1)))
    vo, do = (np.asarray(v).ravel() for v in f(outer.reshape(1, -1)))
    assert np.array_equal(vi, inner) and np.all(di == 1)  # the identity, bit for bit
    # beyond the knee the limit, to rounding (u - (b + r - 2b) + 0: a few ulp of u)
    np.testing.assert_allclose(vo, np.sign(outer) * lim, rtol=1e-14, atol=0)
    assert np.all(do == 0)
    # C1 across the knee: the slope falls linearly from 1 to 0 (finite differences agree)
    k = np.linspace((1 - knee) * lim, (1 + knee) * lim, 201)
    vk, dk = (np.asarray(v).ravel() for v in f(k.reshape(1, -1)))
    np.testing.assert_allclose(dk, 1 - (k - (1 - knee) * lim) / (2 * knee * lim), atol=1e-12)
    assert np.all(np.diff(vk) >= 0) and vk.max() <= lim


def _g(P_blend, F, omega, eta=0.9, eta_inv=0.88, p=5e-3):
    Fs, ws, Ps = ca.SX.sym("F"), ca.SX.sym("w"), ca.SX.sym("P_blend")
    P = type("P", (), {"p": p, "P_blend": Ps, "eta_inv": eta_inv})
    g = ballscrew.efficiency_factor(Fs, ws, eta, P)
    fn = ca.Function("g", [Fs, ws, Ps], [g, ca.jacobian(g, Fs)])
    return (np.asarray(v).ravel() for v in fn(F.reshape(1, -1), omega, P_blend))


def test_efficiency_switch_width_is_the_parameter():
    F = np.linspace(-2e3, 2e3, 401)
    omega, r = 10.0, 5e-3 / (2 * np.pi)
    q = F * omega * r  # W
    g, dg = _g(0.1, F, omega)
    w = 0.5 * (1 + np.tanh(q / 0.1))
    np.testing.assert_allclose(g, w / 0.9 + (1 - w) * 0.88, rtol=1e-15, atol=0)
    g2, _ = _g(0.02, F, omega)
    w2 = 0.5 * (1 + np.tanh(q / 0.02))
    np.testing.assert_allclose(g2, w2 / 0.9 + (1 - w2) * 0.88, rtol=1e-15, atol=0)
    # 0: the exact switch, 1/eta driving, eta_inv back-driven, the mean at q = 0; slope 0
    g0, dg0 = _g(0.0, F, omega)
    expect = np.where(q > 0, 1 / 0.9, np.where(q < 0, 0.88, 0.5 * (1 / 0.9 + 0.88)))
    np.testing.assert_allclose(g0, expect, rtol=1e-15, atol=0)
    assert np.all(np.isfinite(dg0)) and np.all(dg0 == 0) and np.all(np.isfinite(dg))


def test_negative_blend_width_is_refused(params):
    with pytest.raises(ema.ParameterError, match="P_blend"):
        params.replace(P_blend=-0.1)


def test_the_option_from_the_command_line_and_from_the_file(tmp_path, capsys):
    """``--variant anti_windup=clamping`` and ``[model] anti_windup = "clamping"`` build
    the same model: the same variants and the same run, bit for bit (one process)."""
    import json

    from conftest import REFERENCE
    from ema_casadi.cli import main

    text = REFERENCE.read_text()
    assert 'anti_windup = "backcalc"' in text
    clamp = tmp_path / "clamping.toml"
    clamp.write_text(text.replace('anti_windup = "backcalc"', 'anti_windup = "clamping"'))
    runs = []
    for args in ([str(REFERENCE), "--variant", "anti_windup=clamping"], [str(clamp)]):
        out = tmp_path / f"run{len(runs)}.csv"
        assert main(["simulate", *args, "--x-cmd", "step:10mm", "--f-ext", "10kN", "--t-end", "0.05",
                     "--out", str(out), "--json"]) == 0
        runs.append((json.loads(capsys.readouterr().out)["variants"], out.read_text()))
    assert runs[0][0]["anti_windup"] == "clamping" and runs[0] == runs[1]


def _gate(d, w):
    s = np.clip(d / w, 0.0, 1.0)
    return s * s * (3 - 2 * s)


@pytest.mark.parametrize("w_aw", [0.01, 0.04])
def test_pmsm_clamping_rates_follow_the_equations(params, w_aw):
    """The PMSM's per-axis clamping (docs: each axis's excess v_k_u - v_k on the voltage
    circle) and the speed PI's, at random states that put the loops on and off their
    limits: the integrator rates of the model against NumPy from the documented
    equations (rtol 1e-12: the same arithmetic up to reordering), at the reference band
    and at a band four times wider (the band is the parameter w_aw)."""
    params = params.replace(w_aw=w_aw)
    model = ema.build_model(params, {"anti_windup": "clamping"})
    P = params.as_dict()
    r = P["p"] / (2 * np.pi)
    rng = np.random.default_rng(7)
    hits = {"z_w": 0, "z_d": 0, "z_q": 0}
    for _ in range(300):
        x = dict(zip(model.states, rng.normal(size=model.nx) * [20, 150, 150, 20, 20, 50, 80, 2e-3, 0.05],
                     strict=True))
        x["x_rod"] = x["phi"] * r
        x_cmd = rng.normal() * 2e-3
        xdot = dict(zip(model.states, np.asarray(model.f(list(x.values()), model.u(x_cmd=x_cmd), model.p())[0])
                        .ravel(), strict=True))
        # position P loop and speed PI (current limit I_max)
        w_max = P["v_max"] / r
        w_cmd = np.clip(P["K_x"] / r * (x_cmd - x["x_rod"]), -w_max, w_max)
        e_w = w_cmd - x["omega"]
        u = P["K_p_w"] * e_w + x["z_w"]
        d = u - np.clip(u, -P["I_max"], P["I_max"])
        w = P["w_aw"] * P["I_max"]
        K_i = P["K_p_w"] / P["T_i_w"]
        z_w_dot = K_i * (e_w - _gate(d, w) * max(e_w, 0) - _gate(-d, w) * min(e_w, 0))
        # FOC current PIs on the voltage circle
        i_cmd = u - d
        w_e = P["pp"] * x["omega"]
        e = {"z_d": -x["i_d"], "z_q": i_cmd - x["i_q"]}
        v_u = {"z_d": P["K_p_i"] * e["z_d"] + x["z_d"] - w_e * P["L_q"] * x["i_q"],
               "z_q": P["K_p_i"] * e["z_q"] + x["z_q"] + w_e * (P["L_d"] * x["i_d"] + P["psi"])}
        v_lim = P["k_v"] * P["V_dc"] / np.sqrt(3)
        scale = min(1.0, v_lim / np.sqrt(v_u["z_d"] ** 2 + v_u["z_q"] ** 2 + 1e-12))
        expect = {"z_w": z_w_dot}
        for k in ("z_d", "z_q"):
            dk = v_u[k] * (1 - scale)
            gw = P["w_aw"] * v_lim
            expect[k] = P["K_i_i"] * (e[k] - _gate(dk, gw) * max(e[k], 0) - _gate(-dk, gw) * min(e[k], 0))
            hits[k] += int(abs(dk) > 0 and e[k] * dk > 0)
        hits["z_w"] += int(d != 0 and e_w * d > 0)
        for k, v in expect.items():
            assert xdot[k] == pytest.approx(v, rel=1e-12, abs=1e-12 * P["K_i_i"]), k
    assert min(hits.values()) > 20, hits  # the clamping branch was exercised on every loop
