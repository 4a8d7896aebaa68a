"""RK4's stability limit from the model's Jacobian (``rk4_step_limit``) and the sampled
ECU's exact instants (steps split at them): analytic modes, the chatter a step above
the limit makes, the refusal on the command line, the fault table's step inside."""

import json
import math
import subprocess
import sys
import warnings

import numpy as np
import pytest

import ema_casadi as ema
from ema_casadi.simulation import RK4_REAL_REACH, StepLimitWarning, rk4_reach, rk4_step_limit


def test_rk4_reach_on_the_axes():
    # |R(z)| = 1: z = -2.78529356 on the real axis (the root of 1 + z + z^2/2 + z^3/6 + z^4/24 = 1),
    # |y| = 2 sqrt(2) on the imaginary axis (|R(iy)|^2 = 1 - y^6/72 + y^8/576); bisection to 1e-12
    assert RK4_REAL_REACH == pytest.approx(2.785293563405, rel=1e-11)
    assert rk4_reach(-1j) == pytest.approx(2 * math.sqrt(2), rel=1e-11)
    assert rk4_reach(1.0) == math.inf  # a growing mode sets no step limit


def test_the_limit_is_the_rods_friction_mode(model_cache):
    # at rest the rod in the gap is held by its friction alone: lambda = -(F_r/v_s + c_v)/M with
    # F_r = F_seal (no load; the gap decouples the rod: exact to 1e-9 measured); held under F on a
    # flank F_r = F_seal + |F| (2 pi/p) C_bear and the contact couples the rod to the shaft and its
    # efficiency blend: 0.44 % faster measured, checked within 1 %
    model = model_cache()
    P = model.pdict()
    limit = rk4_step_limit(model, load=5e3)
    rest = next(q for q in limit.points if q[0] == "at rest, no load")
    held = next(q for q in limit.points if q[0] == "held under +5 kN")
    for (_, h, lam, state), F_r, rel in ((rest, P.F_seal, 1e-7),
                                         (held, P.F_seal + 5e3 * 2 * math.pi / P.p * P.C_bear, 1e-2)):
        expected = -(F_r / P.v_s + P.c_v) / P.M
        assert state == "v_rod"
        assert lam.real == pytest.approx(expected, rel=rel)
        assert h == pytest.approx(RK4_REAL_REACH / abs(lam), rel=1e-9)
    assert limit.dt_max == pytest.approx(2.4577e-6, rel=1e-4)  # the held point sets it
    assert rk4_step_limit(model_cache(friction="hybrid"), load=5e3).dt_max > 1e-4  # Karnopp: no slope at rest


def _held(model, dt):
    # 400 samples of 10 steps at either step: one compiled rollout serves both runs
    return ema.simulate(model, 4000 * dt, x_cmd=1e-3, f_ext=5e3, solver="rk4", dt=dt, dt_out=10 * dt, from_trim=True)


def test_a_step_above_the_limit_is_warned_and_chatters(model_cache):
    # held under 5 kN (limit 2.46 us): at 5 us the rod's velocity chatters (std 1.1e-8 m/s measured),
    # at 2 us it stays at rest to round-off (1.5e-33 measured)
    model = model_cache()
    with pytest.warns(StepLimitWarning, match=r"above RK4's stability limit 2.46e-06 s .* held under \+5 kN"):
        above = _held(model, 5e-6)
    with warnings.catch_warnings():
        warnings.simplefilter("error", StepLimitWarning)
        inside = _held(model, 2e-6)
    half = len(above.t) // 2
    assert np.std(above["v_rod"][half:]) > 1e-9
    assert np.std(inside["v_rod"][half:]) < 1e-20
    assert inside.info["tolerance"]["dt_max"] == pytest.approx(2.4577e-6, rel=1e-4)


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "ema_casadi.cli", "simulate", *args], capture_output=True, text=True)


def test_cli_refuses_a_step_above_the_limit_and_defaults_inside(model_cache):
    # the reference scenario (1 mm step, 0.375 mm 1 Hz sine, 30 kN) held under 30 kN: limit 0.652 us
    scenario = ["--zoh", "--solver", "rk4", "--x-cmd", "step:1mm@0.01+sine:0.375mm@1@0.5", "--f-ext", "30kN"]
    r = _cli(*scenario, "--dt", "1e-5", "--t-end", "0.02")
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1
    assert "--dt 1e-05 s is above RK4's stability limit 6.52e-07 s" in r.stderr and "held under +30 kN" in r.stderr
    # the default without --dt is simulate()'s (one rule, default_step): the largest step under
    # 0.8 x the limit dividing 62.5, 125 and 500 us (and the run's 20 ms and 0.1 ms samples)
    r = _cli(*scenario, "--t-end", "0.02", "--json")
    assert r.returncode == 0, r.stderr
    assert "warning" not in r.stderr.lower()
    model = model_cache()
    limit = rk4_step_limit(model, load=30e3, zoh=True)
    dt = ema.simulation.default_step(model, 0.02, lambda: ({"x_cmd": "step:1mm@0.01+sine:0.375mm@1@0.5",
                                                             "f_ext": 30e3}, model.p()), True, 1e-4)
    assert dt == pytest.approx(62.5e-6 / 120, rel=1e-12) and dt <= 0.8 * limit.dt_max
    assert json.loads(r.stdout)["steps"] == pytest.approx(0.02 / dt, abs=1)


def test_samples_fall_on_their_own_instants_at_dt_1e5(model_cache):
    # dt = 10 us does not divide the 125 us speed loop nor the 62.5 us current loop: each step
    # holding an instant is split there. The held speed-loop output i_cmd (and omega_cmd) then
    # matches a run at 1.25 us (which divides every period) at every 10 us sample: 1.3e-6 and
    # 1.6e-6 of their peaks measured, checked at 1e-5; without the split the loop sampled at the
    # start of the step holding its instant (120/130 us) and i_cmd was 1.2e-3 of its peak off.
    model = model_cache(friction="hybrid")  # RK4's limit 0.26 ms: 10 us is inside
    kw = dict(x_cmd="step:1mm@0.001", zoh=True, solver="rk4", dt_out=1e-5)
    split = ema.simulate(model, 0.004, dt=1e-5, **kw)
    fine = ema.simulate(model, 0.004, dt=1.25e-6, **kw)
    assert split.info["split_samples"] and not fine.info["split_samples"]
    for name in ("i_cmd", "omega_cmd"):
        assert np.abs(split[name] - fine[name]).max() < 1e-5 * np.abs(fine[name]).max(), name
    # the held command changes only in the steps that hold a speed-loop instant (k x 125 us)
    steps = np.nonzero(np.diff(split["i_cmd"]))[0]  # the step from t[j] to t[j+1] changed it
    t0 = split.t[steps]
    k = np.ceil(t0 / 125e-6 - 1e-9)
    assert np.all(k * 125e-6 < split.t[steps + 1] - 1e-12)


def test_reference_fault_table_steps_are_inside_the_limit(params):
    from ema_casadi.faults import load_faults

    spec = load_faults(ema.packaged_file("faults_reference.toml"), params)
    for what, variants, dt in (("table", spec.variants, spec.scenario["dt"]),
                               ("healthy runs", spec.healthy_variants, spec.healthy["dt"])):
        model = ema.build_model(spec.params, variants)
        limit = rk4_step_limit(model, load=5e3, zoh=True)
        assert dt <= 0.8 * limit.dt_max, what


def test_simulates_default_step_is_inside_the_limit(model_cache):
    # without dt, simulate() keeps 1e-5 s where it is under 0.8 x the limit (hybrid
    # friction: 0.44 ms) and otherwise takes the largest step under it: on the smooth
    # law 2.5 us at rest (limit 5.57 us), 1.25 us held under 5 kN (2.46 us), and with
    # the sampled ECU a step that divides the sample periods (62.5, 125, 500 us): no
    # warning. Against the same run at an eighth of the step the rod is within 0.1 um
    # (measured 0.023 um over these 20 ms, 4 x; docs: fixed steps)
    from ema_casadi.simulation import sample_periods

    smooth, hybrid = model_cache(), model_cache(friction="hybrid")
    with warnings.catch_warnings():
        warnings.simplefilter("error", StepLimitWarning)
        for model, kw, expected in ((smooth, {}, 2.5e-6), (smooth, {"f_ext": 5e3}, 1.25e-6),
                                    (hybrid, {}, 1e-5), (smooth, {"zoh": True}, None)):
            r = ema.simulate(model, 0.02, x_cmd="step:1mm@0.01", solver="rk4", **kw)
            dt, limit = r.info["dt"], r.info["tolerance"]["dt_max"]
            assert dt <= 0.8 * limit
            if expected is not None:
                assert dt == expected
            else:  # the sampled ECU: a whole number of steps per sample period
                assert all(abs(T / dt - round(T / dt)) < 1e-9 for T in sample_periods(model).values())
    fine = ema.simulate(smooth, 0.02, x_cmd="step:1mm@0.01", solver="rk4", dt=2.5e-6 / 8)
    coarse = ema.simulate(smooth, 0.02, x_cmd="step:1mm@0.01", solver="rk4")
    assert np.max(np.abs(coarse["x_rod"] - fine["x_rod"])) < 1e-7


def test_a_fault_file_without_dt_steps_inside_the_limit(params, tmp_path):
    # the reference fault file on the smooth law, its dt removed: the default is the
    # largest step under 0.8 x the limit held under the scenario's 5 kN (2.46 us) that
    # divides the sample periods and the 0.1 ms output spacing (1.25 us); on its hybrid
    # friction (0.26 ms) the 12.5 us cap
    from conftest import ROOT
    from ema_casadi.faults import load_faults

    text = (ROOT / "models" / "faults_reference.toml").read_text()
    assert "dt = 1.25e-5" in text and 'friction = "hybrid"' in text
    for friction, expected in (("smooth", 1.25e-6), ("hybrid", 1.25e-5)):
        path = tmp_path / f"{friction}.toml"
        path.write_text(text.replace("dt = 1.25e-5", "").replace('friction = "hybrid"', f'friction = "{friction}"'))
        sc = load_faults(path, params).scenario
        assert sc["dt"] == expected and sc["dt_out"] == pytest.approx(1e-4, rel=1e-12)
