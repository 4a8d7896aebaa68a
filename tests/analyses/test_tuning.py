"""Gain tuning by nonlinear optimisation (CasADi Opti + IPOPT; docs: tune)

The acceptance tests tune once from a deliberately poor start (every gain x 0.2 of the
reference, T_i_w kept so K_i_w = K_p_w/T_i_w scales too) over 0, 15 and 30 kN and then
check the result independently of the optimiser: python-control margins of loop
transfers freshly linearised with the tuned gains, and a nonlinear step simulation.
"""

import json
import math

import casadi as ca
import control as ct
import numpy as np
import pytest

from conftest import REFERENCE, assert_glance
from ema_casadi import Signal, simulate
from ema_casadi import frequency as fr
from ema_casadi import linearisation as lz
from ema_casadi import tuning as T
from ema_casadi.cli import main

LOADS = (0.0, 15e3, 30e3)
#: the requirements of the tunes from a poor start (gains x 0.2)
POOR_START = T.Requirements(separation=0.0, command_noise=0.0)


def _margins(L):
    """Independent GM/PM from python-control: every crossover in 0.01 Hz - 100 kHz
    (outside, python-control reports spurious ones near 0 Hz and ~1e9 Hz)."""
    with np.errstate(invalid="ignore"):  # python-control compares NaN phases inside
        gm, pm, _, wpc, wgc, _ = ct.stability_margins(L, returnall=True)
    gm, pm, wpc, wgc = (np.atleast_1d(np.asarray(v, float)) for v in (gm, pm, wpc, wgc))
    keep_pc = (wpc > 2 * np.pi * 1e-2) & (wpc < 2 * np.pi * 1e5) & np.isfinite(gm)
    keep_gc = (wgc > 2 * np.pi * 1e-2) & (wgc < 2 * np.pi * 1e5)
    gm_db = 20 * np.log10(gm[keep_pc])
    pm_dist = np.abs((pm[keep_gc] + 180) % 360 - 180)  # angular distance of L to -1
    return gm_db, pm_dist


def _step(model, params, amp=1e-3, t0=0.01, t_end=0.4):
    """Overshoot (fraction) and 2 % settling time (s, from the step) of a nonlinear step."""
    res = simulate(model, t_end, x_cmd=Signal.step(amp, t0), p=params.vector(), solver="cvodes",
                   dt=1e-4, dt_out=1e-4, rtol=1e-7, atol=1e-10)
    t, x = res.t, res["x_rod"] / amp
    after = t >= t0
    out = np.nonzero(np.abs(x[after] - 1) > 0.02)[0]
    if not len(out):
        settle = 0.0
    else:
        settle = t[after][out[-1] + 1] - t0 if out[-1] + 1 < after.sum() else math.inf
    return max(0.0, x.max() - 1), settle


# ----------------------------------------------------------------------------------
def test_exclusion_disk_geometry():
    """The GM/PM disk passes through -10^(-GM/20) and -e^(+-j PM) (exactly); past
    cos(PM) <= 10^(-GM/20) it is the disk through the PM points centred at -1/cos(PM);
    the Ms form is |1 + L| >= 1/Ms."""
    c, R = T.exclusion_disk(T.Requirements(gm_db=6, pm_deg=45))
    a = 10 ** (-6 / 20)
    assert abs(-a + c) == pytest.approx(R, rel=1e-12)
    p = -np.exp(1j * np.radians(45))
    assert abs(p + c) == pytest.approx(R, rel=1e-12)
    assert -c - R == pytest.approx(-3.13, abs=0.01)  # lower GM guaranteed: 9.9 dB
    c, R = T.exclusion_disk(T.Requirements(gm_db=6, pm_deg=70))
    assert c == pytest.approx(1 / math.cos(math.radians(70)), rel=1e-12)
    assert R == pytest.approx(math.tan(math.radians(70)), rel=1e-12)
    assert abs(-np.exp(1j * np.radians(70)) + c) == pytest.approx(R, rel=1e-12)
    assert abs(-a + c) < R  # the GM point is inside: GM holds too
    assert T.exclusion_disk(T.Requirements(ms=1.6)) == (1.0, pytest.approx(1 / 1.6))
    gm, pm = T.Requirements(ms=2.0).margin_targets()
    assert gm == pytest.approx(20 * math.log10(2)) and pm == pytest.approx(2 * math.degrees(math.asin(0.25)))


def test_spectral_abscissa_gradient_matches_finite_differences():
    """The eigenvalue callback's analytic gradient (eigenvector sensitivity) equals central
    differences on a random matrix with a complex rightmost pair (rel. 1e-6)."""
    rng = np.random.default_rng(3)
    A = rng.normal(size=(6, 6))
    cb = T.spectral_abscissa(6, "sa_test")
    X = ca.MX.sym("A", 6, 6)
    g = ca.Function("g", [X], [ca.gradient(cb(X), X)])
    G = np.array(g(A))
    h = 1e-6
    fd = np.zeros_like(A)
    for i in range(6):
        for j in range(6):
            E = np.zeros_like(A)
            E[i, j] = h
            fd[i, j] = (np.max(np.linalg.eigvals(A + E).real) - np.max(np.linalg.eigvals(A - E).real)) / (2 * h)
    assert np.allclose(G, fd, rtol=1e-6, atol=1e-8)


@pytest.mark.parametrize("variants", [{}, {"motor": "dc", "screw": "rigid"}, {"controller": "PI"}])
def test_optimiser_loop_transfers_equal_fresh_linearisation(params, model_cache, variants):
    """The optimiser's symbolic loop sensitivities S = 1 + G_jj (closed loop, balanced,
    reduced states, real arithmetic) equal 1/(1 + L) of the loop transfers linearised
    with each loop opened (ema_casadi.linearisation), at 0 and 30 kN, within 1e-7."""
    model = model_cache(**variants)
    free = T.default_free(model)
    start = T.scaled_gains(params, 0.7, free)
    if "K_i_x" in start:
        start["K_i_x"] = 400.0
    f = np.logspace(-0.3, 4, 15)
    prob = T.TuningProblem(model, params, free, [0.0, 30e3], T.Requirements(), "tracking", start, f)
    for case, op in enumerate(prob.cases):
        sensitivities = prob.loop_sensitivities(case)  # at the start gains, on the grid f
        fresh = lz.operating_point(model, f_ext=op.f_ext, p=params.vector(**start))
        for loop in model.loops:  # the actuator cascade (the aircraft loop needs an airframe)
            S = sensitivities[loop]
            L = fr.freqresp(lz.loop_model(model, loop, fresh), f)[0, 0]
            assert np.max(np.abs(S - 1 / (1 + L))) < 1e-7, (loop, op.f_ext)


def test_step_constraint_samples_equal_python_control(params, model_cache):
    """The optimiser's exact-discretisation step (matrix exponential, doubling grid)
    equals python-control's step response of the fresh closed loop at its samples."""
    model = model_cache()
    free = T.default_free(model)
    req = T.Requirements(step=1e-4, t_step=0.05)
    start = T.scaled_gains(params, 1.0, free)
    prob = T.TuningProblem(model, params, free, [30e3], req, "tracking", start, np.logspace(0, 3, 4))
    t, Y = prob.step_response(0)  # rows x_rod, i_q, v_d, v_q at the start gains
    op = prob.cases[0]
    lin = lz.linear_model(model, op, inputs=["x_cmd"], outputs=["x_rod", "i_q", "v_d", "v_q"])
    sys_ = ct.ss(lin.A, lin.B, lin.C, lin.D)
    t_fine = np.linspace(0, req.t_step, 50001)
    ref = ct.forced_response(sys_, t_fine, np.full_like(t_fine, req.step)).outputs
    for row in range(4):
        r = np.interp(t[1:], t_fine, ref[row])
        scale = np.max(np.abs(ref[row]))
        assert np.max(np.abs(Y[row, 1:] - r)) < 1e-4 * scale, row


@pytest.mark.parametrize("variants", [{}, {"controller": "PI"}])
def test_trim_is_gain_independent_and_loads_share_dynamics(params, model_cache, variants):
    """The premise of solving the trim once per load case: the operating point at 30 kN
    is the same for the reference gains and for gains x 0.2 (the integrators hold the
    loop outputs, the position error is zero), and under the small-signal policy the
    three load cases give one linearisation (one set of frequency constraints)."""
    model = model_cache(**variants)
    free = T.default_free(model)
    gains = T.scaled_gains(params, 0.2, free)
    if "K_i_x" in gains:
        gains["K_i_x"] = 500.0
    x_ref = lz.operating_point(model, f_ext=30e3, p=params.vector(K_i_x=2500.0)).x
    x_poor = lz.operating_point(model, f_ext=30e3, p=params.vector(**gains)).x
    assert np.allclose(x_poor, x_ref, rtol=1e-9, atol=1e-12)
    prob = T.TuningProblem(model, params, free, LOADS, T.Requirements(), "bandwidth", gains, np.logspace(0, 3, 4))
    assert prob.n_linearisations == 1 and prob.n_step_responses == 1
    kinds = [(g.kind, tuple(g.loads)) for g in prob.groups]
    assert ("margin", LOADS) in kinds and ("current", (30e3,)) in kinds  # limits stay per load


# ----------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def tuned(params, model_cache):
    """Tune from every gain x 0.2 over 0, 15, 30 kN (bandwidth objective, GM 6 dB,
    PM 45 deg, overshoot 5 %, the outer-open margins; without the loop separation and the
    noise bound: from this start IPOPT does not find their feasible set, which the
    reference gains show exists - the cascade tests start from the reference)."""
    model = model_cache()
    start = T.scaled_gains(params, 0.2, T.default_free(model))
    res = T.tune(params, model=model, loads=LOADS, start=start, verify_step=0.0, requirements=POOR_START)
    return model, res


def test_poor_start_converges(tuned):
    model, res = tuned
    assert res.status == "Solve_Succeeded", res.message
    assert res.success and not res.violations
    assert "success=True" in assert_glance(res)
    # the start really is poor: slow (2.6 Hz) and PM below 45 deg on the inner loops
    before = res.verification_before
    assert before["worst"]["bandwidth_hz"] < 5 and before["worst"]["pm_deg"] < 45
    assert res.objective_value > 40  # Hz; the reference gains give ~20 Hz
    # the optimiser's bandwidth variable is the true -3 dB frequency of the fresh model
    assert res.verification_after["worst"]["bandwidth_hz"] == pytest.approx(res.objective_value, rel=0.02)


def test_tuned_margins_verified_independently(params, tuned):
    """Fresh trim + AD linearisation with the tuned gains, every loop broken with the
    others closed, python-control margins: |GM| >= 6 dB and PM >= 45 deg in every load
    case; closed loop stable."""
    model, res = tuned
    p = res.params.vector()
    for F in LOADS:
        op = lz.operating_point(model, f_ext=F, p=p)
        for loop in model.loops:  # the actuator cascade (the aircraft loop needs an airframe)
            gm_db, pm = _margins(lz.loop_transfer(model, loop, op))
            assert pm.size and np.min(pm) >= 45 - 1e-6, (F, loop, pm)
            assert np.all(np.abs(gm_db) >= 6 - 1e-6), (F, loop, gm_db)
        A = lz.linear_model(model, op).A
        lam = np.linalg.eigvals(A)
        assert np.max(lam.real) < 0


def test_tuned_nonlinear_step_beats_reference(params, tuned):
    """Full nonlinear model (friction, backlash, limits), 1 mm step at no load:
    overshoot <= 5 % and a shorter 2 % settling time than the reference gains."""
    model, res = tuned
    os_t, ts_t = _step(model, res.params)
    os_r, ts_r = _step(model, params)
    assert os_t <= 0.05
    assert ts_t < ts_r, (ts_t, ts_r)


def test_tuned_file_round_trip(tuned, tmp_path):
    from ema_casadi import load_parameters

    _, res = tuned
    path = res.write(tmp_path / "tuned.toml")
    back = load_parameters(path).as_dict()
    for g, v in res.gains_after.items():
        assert back[g] == pytest.approx(v, rel=1e-15)
    assert "Solve_Succeeded" in path.read_text().splitlines()[0]


def test_tuned_result_plots_before_and_after(tuned):
    """TuneResult.plot(): the Bode figure (closed loop and each loop transfer), the
    step figure, one line per gain set (before, after), and the cascade view (each loop
    with its outer loops open)."""
    from matplotlib.figure import Figure

    model, res = tuned
    bode_fig, step_fig, cascade_fig = res.plot(model)
    assert isinstance(bode_fig, Figure) and isinstance(step_fig, Figure) and isinstance(cascade_fig, Figure)
    assert len(cascade_fig.axes) == 2 * len(model.loops)
    assert len(bode_fig.axes) == 2 * (1 + len(model.loops))
    assert {line.get_label().split(":")[0] for line in step_fig.axes[0].lines} >= {"before", "after"}
    assert repr(res).startswith("TuneResult(success=True")


# ----------------------------------------------------------------------------------
def test_infeasible_request_names_the_constraint(capsys):
    """PM >= 89 deg with bandwidth >= 20 Hz cannot be met: exit 2 and one line that
    names the violated requirement - no traceback."""
    code = main(["tune", str(REFERENCE), "--pm", "89", "--bandwidth-min", "20", "--objective", "tracking",
                 "--sim-step", "0"])
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and "Traceback" not in err
    assert "infeasible request" in err and "PM >= 89 deg" in err


@pytest.mark.parametrize("argv, needle", [
    (["--free", "K_x,K_q"], "'K_q' is not a tunable gain"),
    (["--free", "K_i_x"], "controller=PI"),
    (["--loads", "0,15kg"], "--loads"),
    (["--pm", "95"], "--pm"),
    (["--ms", "0.5"], "--ms"),
    (["--out", "tuned.txt"], "--out"),
    (["--loads", "60kN"], "60 kN"),
])
def test_cli_user_errors_are_one_line(capsys, argv, needle):
    code = main(["tune", str(REFERENCE), *argv])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and needle in err, err


def test_cli_json_writes_file_and_plots(tmp_path, capsys):
    """A small tune (K_x only, from the reference) through the CLI: JSON result with
    gains before/after, margins, objective and status; tuned file and plots written."""
    out = tmp_path / "tuned.toml"
    code = main(["tune", str(REFERENCE), "--free", "K_x", "--loads", "0,30kN", "--out", str(out),
                 "--plot-dir", str(tmp_path / "plots"), "--sim-step", "0", "--json"])
    r = json.loads(capsys.readouterr().out)
    assert code == 0 and r["success"] and r["status"] == "Solve_Succeeded"
    assert set(r["gains_after"]) == {"K_x"} and r["gains_after"]["K_x"] > r["gains_before"]["K_x"]
    loops = r["after"]["loads"]["30 kN"]["loops"]
    assert set(loops) == {"position", "velocity", "current"}
    # both gain margins >= 0 by construction, each >= 6 dB here; JSON carries inf as "inf"
    assert all(float(m["gm_db"]) >= 6 and float(m["gm_down_db"]) >= 6 and m["pm_deg"] >= 45 for m in loops.values())
    assert out.exists() and (tmp_path / "plots" / "tune_bode.png").exists()
    assert (tmp_path / "plots" / "tune_step.png").exists()


@pytest.mark.slow
@pytest.mark.parametrize("variants, kwargs", [
    ({}, {"objective": "tracking", "loads": LOADS}),
    ({"controller": "PI"}, {"loads": (0.0, 30e3)}),
    ({"motor": "dc", "screw": "rigid"}, {"loads": (0.0, 30e3)}),
    ({}, {"requirements": T.Requirements(ms=1.6, separation=0.0, command_noise=0.0)}),
    ({}, {"requirements": T.Requirements(sigma=50.0, separation=0.0, command_noise=0.0)}),
    ({}, {"objective": "tracking",
          "requirements": T.Requirements(bandwidth_min_hz=30.0, separation=0.0, command_noise=0.0)}),
])
def test_other_variants_and_requirements_converge(params, model_cache, variants, kwargs):
    """From gains x 0.2: IPOPT converges, no slack, and the independent check passes
    (5-20 s each)."""
    model = model_cache(**variants)
    start = T.scaled_gains(params, 0.2, T.default_free(model))
    if "K_i_x" in start:
        start["K_i_x"] = 0.0
    kwargs.setdefault("requirements", POOR_START)
    res = T.tune(params, model=model, start=start, verify_step=0.0, **kwargs)
    assert res.success, res.message


# ----------------------------------------------------------------------------------
# Tuning from a feasible start (the reference gains meet every requirement): the
# tuner must end at gains that still meet every requirement, no worse than the start.
def _independent_failures(model, params, loads, req, start_bandwidth=None):
    """Every requirement checked without the optimiser or the toolkit's verification:
    a fresh trim and AD linearisation per load case, python-control margins of each loop
    (others closed), closed-loop eigenvalues, python-control step response of x_rod,
    i_q and |v_dq| (with the operating values), loop gain below 1 above the ECU rate /
    rate_ratio (to 10 kHz, the tuner's grid) and the -3 dB bandwidth against the start's.
    Returns the failures as texts (empty: all met)."""
    fails = []
    pv = params.as_dict()
    p = params.vector()
    v_lim = pv["k_v"] * pv["V_dc"] / math.sqrt(3)
    rates = {"position": pv["f_s_x"], "velocity": pv["f_s_w"], "current": pv["f_s_i"]}
    for F in loads:
        op = lz.operating_point(model, f_ext=F, p=p)
        for loop in model.loops:  # the actuator cascade (the aircraft loop needs an airframe)
            L = lz.loop_transfer(model, loop, op)
            gm_db, pm = _margins(L)
            if not (pm.size and np.min(pm) >= req.pm_deg - 1e-6):
                fails.append(f"{F:g} N {loop}: PM {pm}")
            if np.any(np.abs(gm_db) < req.gm_db - 1e-6):
                fails.append(f"{F:g} N {loop}: GM {gm_db}")
            if req.rate_ratio > 0:
                f = np.logspace(math.log10(rates[loop] / req.rate_ratio), 4, 400)
                mag = np.abs(ct.frequency_response(L, 2 * np.pi * f).complex.ravel())
                if np.max(mag) > 1 + 1e-3:
                    fails.append(f"{F:g} N {loop}: |L| {np.max(mag):.4f} above the ECU-rate floor")
        fails.extend(_cascade_failures(model, op, req, pv["I_max"]))
        lin = lz.linear_model(model, op, inputs=["x_cmd"], outputs=["x_rod", "i_q", "v_d", "v_q"])
        keep = [i for i in range(lin.A.shape[0]) if np.any(lin.A[:, i] != 0)]
        alpha = np.max(np.linalg.eigvals(lin.A[np.ix_(keep, keep)]).real)
        # (<= as the requirement: with K_i_x = 0 the PI position loop's integrator is a
        # disconnected state, eigenvalue 0)
        if not alpha <= -req.sigma + 1e-9 * max(1.0, abs(alpha)):
            fails.append(f"{F:g} N: eigenvalue at {alpha:.4g} 1/s")
        sys_ = ct.ss(lin.A[np.ix_(keep, keep)], lin.B[keep], lin.C[:, keep], lin.D)
        t = np.linspace(0.0, req.t_step, int(round(req.t_step / 2e-5)) + 1)  # 20 us, as verify
        y = ct.forced_response(sys_, t, np.full_like(t, req.step)).outputs
        x, i_q = y[0] / req.step, op.output("i_q") + y[1]
        v = np.hypot(op.output("v_d") + y[2], op.output("v_q") + y[3])
        if x.max() - 1 > req.overshoot + 1e-4:
            fails.append(f"{F:g} N: overshoot {100 * (x.max() - 1):.3f} %")
        if np.max(np.abs(i_q)) > pv["I_max"] * (1 + 1e-4):
            fails.append(f"{F:g} N: current {np.max(np.abs(i_q)):.4g} A")
        if np.max(v) > v_lim * (1 + 1e-4):
            fails.append(f"{F:g} N: voltage {np.max(v):.4g} V > {v_lim:.4g} V")
        if start_bandwidth is not None:
            bw = _bandwidth_hz(sys_[0, 0])
            if not bw >= start_bandwidth * (1 - 1e-3):
                fails.append(f"{F:g} N: bandwidth {bw:.4g} Hz below the start's {start_bandwidth:.4g} Hz")
    return fails


def _outer_open_loop(lin, loop):
    """python-control loop transfer L = -G(injection -> measurement) of a loop from a
    linear model (A, B, C, D with names) exported with that loop and its outer loops open."""
    inj, meas = {"position": ("d_x", "x_rod"), "velocity": ("d_w", "omega"), "current": ("d_i", "i_q")}[loop]
    i, o = list(lin.inputs).index(inj), list(lin.outputs).index(meas)
    return ct.ss(lin.A, lin.B[:, [i]], -lin.C[[o], :], -lin.D[[o]][:, [i]])


def _cascade_failures(model, op, req, I_max):
    """The cascade requirements by python-control: each loop with its outer loops open
    closed-loop stable, unconditionally stable (every phase crossover with |L| <=
    10^(-GM/20), none where the gain may only fall), PM at every gain crossover; the
    lowest gain crossover of each inner loop at least req.separation x the highest of
    the next outer one; the peak of |i_cmd / d_x| (0.01 Hz - 10 kHz) within the bound."""
    fails, fcs = [], {}
    order = list(model.loops)
    for k, loop in enumerate(order):
        lin = lz.linear_model(model, op, open_loops=order[:k + 1])
        L = _outer_open_loop(lin, loop)
        with np.errstate(invalid="ignore"):  # python-control compares NaN phases inside
            gm, pm, _, wpc, wgc, _ = ct.stability_margins(L, returnall=True)
        gm, pm, wpc, wgc = (np.atleast_1d(np.asarray(v, float)) for v in (gm, pm, wpc, wgc))
        sel_pc = (wpc > 2 * np.pi * 1e-2) & (wpc < 2 * np.pi * 1e5) & np.isfinite(gm)
        sel_gc = (wgc > 2 * np.pi * 1e-2) & (wgc < 2 * np.pi * 1e5)
        gm_db = 20 * np.log10(gm[sel_pc])
        pm_dist = np.abs((pm[sel_gc] + 180) % 360 - 180)
        fcs[loop] = wgc[sel_gc] / (2 * np.pi)
        closed = ct.feedback(L, 1)
        if np.max(closed.poles().real) > 1e-6 * max(1.0, np.max(np.abs(closed.poles()))):
            fails.append(f"{op.f_ext:g} N {loop} (outer open): closed loop unstable")
        if np.any(gm_db < req.gm_db - 1e-6):
            fails.append(f"{op.f_ext:g} N {loop} (outer open): phase crossovers at GM {gm_db} dB")
        if not (pm_dist.size and np.min(pm_dist) >= req.pm_deg - 1e-6):
            fails.append(f"{op.f_ext:g} N {loop} (outer open): PM {pm_dist}")
    for outer, inner in zip(order[:-1], order[1:], strict=True):
        if req.separation > 0 and not np.min(fcs[inner]) >= req.separation * np.max(fcs[outer]) * (1 - 1e-6):
            fails.append(f"{op.f_ext:g} N: {inner} crossovers {fcs[inner]} Hz not {req.separation:g} x "
                         f"the {outer} loop's {fcs[outer]} Hz")
    bound = req.noise_gain_max(I_max)
    if bound is not None:
        lin = lz.linear_model(model, op, inputs=["d_x"], outputs=["i_cmd"])
        H = ct.frequency_response(ct.ss(lin.A, lin.B, lin.C, lin.D), 2 * np.pi * np.logspace(-2, 4, 601))
        if np.max(np.abs(H.complex)) > bound * (1 + 1e-4):
            fails.append(f"{op.f_ext:g} N: noise gain {np.max(np.abs(H.complex)):.4g} A/m > {bound:.4g} A/m")
    return fails


def _bandwidth_hz(sys_):
    """First frequency (Hz) where |x_rod/x_cmd| falls below 1/sqrt(2) of its value at
    0.01 Hz (python-control frequency response, 1000 per decade, log-interpolated)."""
    f = np.logspace(-2, 4, 6001)
    mag = np.abs(ct.frequency_response(sys_, 2 * np.pi * f).complex.ravel())
    below = np.nonzero(mag < mag[0] / math.sqrt(2))[0]
    if not len(below):
        return math.inf
    k = below[0]
    a, b = np.log(mag[k - 1] / mag[0] * math.sqrt(2)), np.log(mag[k] / mag[0] * math.sqrt(2))
    return float(np.exp(np.log(f[k - 1]) + (np.log(f[k]) - np.log(f[k - 1])) * a / (a - b)))


def _start_bandwidth(model, params):
    op = lz.operating_point(model, f_ext=0.0, p=params.vector())
    lin = lz.linear_model(model, op, inputs=["x_cmd"], outputs=["x_rod"])
    keep = [i for i in range(lin.A.shape[0]) if np.any(lin.A[:, i] != 0)]
    return _bandwidth_hz(ct.ss(lin.A[np.ix_(keep, keep)], lin.B[keep], lin.C[:, keep], lin.D))


def _tune_from_reference(params, model_cache, variants, loads):
    model = model_cache(**variants)
    assert not _independent_failures(model, params, loads, T.Requirements())  # the start is feasible
    res = T.tune(params, model=model, loads=loads, verify_step=0.0)
    assert res.success, res.message
    # IPOPT's own converged answer, no safety net
    assert res.fallback is None and res.status in ("Solve_Succeeded", "Solved_To_Acceptable_Level"), res.message
    assert not res.violations and res.verification_after["meets"]
    fails = _independent_failures(model, res.params, loads, res.requirements, _start_bandwidth(model, params))
    assert not fails, fails
    return res


_VARIANTS = [dict(zip(("motor", "screw", "friction", "controller"), combo, strict=False)) for combo in
             __import__("itertools").product(("pmsm", "dc"), ("elastic", "rigid"), ("smooth", "hybrid"), ("P", "PI"))]


def test_plain_ema_tune_succeeds_from_the_reference(capsys):
    """The issue: plain `ema tune` (one load case, 0 kN, bandwidth) started from the
    reference gains, which meet every requirement, ended 'infeasible' after 200 IPOPT
    iterations. Now exit 0, IPOPT's own converged answer, and the returned gains meet
    every requirement by the independent check, with a wider bandwidth than the start."""
    from ema_casadi import build_model, load_parameters

    code = main(["tune", str(REFERENCE), "--json", "--sim-step", "0"])
    r = json.loads(capsys.readouterr().out)
    assert code == 0 and r["success"] and r["fallback"] is None, r["message"]
    assert r["status"] in ("Solve_Succeeded", "Solved_To_Acceptable_Level"), r["message"]
    # 27 iterations in 2 solves measured on the Haswell, Sandybridge and Prescott kernels
    # (docs/development.md); the kernel-dependent paths of the sharper soft minimum took
    # 37-200: a budget of 100 leaves x3.7
    assert r["iterations"] < 100
    params = load_parameters(REFERENCE)
    model = build_model(params)
    tuned = params.replace(**r["gains_after"])
    fails = _independent_failures(model, tuned, [0.0], T.Requirements(), _start_bandwidth(model, params))
    assert not fails, fails
    assert r["after"]["worst"]["bandwidth_hz"] > 2 * r["before"]["worst"]["bandwidth_hz"]


def test_feasible_start_is_feasible_point_of_the_problem(params, model_cache):
    """The reference gains satisfy every constraint group of the optimiser (zero slack);
    a poor start does not, and its slacks start at its violations, so both starts are
    feasible points of the elastic problem."""
    model = model_cache()
    free = T.default_free(model)
    prob = T.TuningProblem(model, params, free, [0.0], T.Requirements(), "bandwidth")
    assert prob.start_feasible and np.all(prob.start_values >= 0)
    poor = T.TuningProblem(model, params, free, [0.0], T.Requirements(), "bandwidth", T.scaled_gains(params, 0.2, free))
    assert not poor.start_feasible
    slack0 = np.array(poor._opti.debug.value(poor._slack, poor._opti.initial())).ravel()
    assert np.all(poor.start_values + slack0 >= -1e-12) and np.any(slack0 > 0)


def test_safety_net_returns_verified_gains_no_worse_than_start(params, model_cache):
    """Last resort only: when IPOPT stops early (here: 6 iterations) from a feasible
    start, the result is the best verified-feasible iterate (at least the start), never
    'infeasible' or worse than the start, and the message says so."""
    model = model_cache()
    res = T.tune(params, model=model, max_iter=6, verify_step=0.0)
    assert res.status == "Maximum_Iterations_Exceeded"
    assert res.success and res.fallback in ("iterate", "start") and "safety net" in res.message, res.message
    assert not res.violations
    fails = _independent_failures(model, res.params, [0.0], res.requirements, _start_bandwidth(model, params))
    assert not fails, fails


@pytest.mark.parametrize("variants, loads", [
    ({"motor": "dc", "screw": "rigid", "friction": "hybrid", "controller": "PI"}, LOADS),
])
def test_tune_from_reference_representative(params, model_cache, variants, loads):
    """A representative variant from the reference gains, three load cases (the full
    matrix, both load sets: the slow test below)."""
    _tune_from_reference(params, model_cache, variants, loads)


@pytest.mark.slow
@pytest.mark.parametrize("loads", [(0.0,), LOADS], ids=["0kN", "0-15-30kN"])
@pytest.mark.parametrize("variants", _VARIANTS, ids=["-".join(v.values()) for v in _VARIANTS])
def test_tune_from_reference_every_variant(params, model_cache, variants, loads):
    """motor x screw x friction x controller, 0 kN alone and 0/15/30 kN, from the
    reference gains: IPOPT converges, and every requirement holds by the independent
    python-control check, with no less bandwidth than the start (3-8 s each)."""
    _tune_from_reference(params, model_cache, variants, loads)
