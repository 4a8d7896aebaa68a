"""Real sensors (``sensor = "real"``): what the ECU reads, against closed forms.

Each test states where its number comes from. Runs are sampled (the ECU at its rates,
``zoh=True``), RK4 at 10 us, the reference set with the noises off unless a test is
about them.
"""

import math

import numpy as np
import pytest

import ema_casadi as ema

QUIET = dict(sigma_x=0.0, sigma_theta=0.0, sigma_i=0.0)


@pytest.fixture(scope="module")
def real(params):
    return ema.build_model(params.replace(**QUIET), {"sensor": "real"})


def _held(model, x_cmd, t_end=0.4, **p):
    r = ema.simulate(model, t_end, x_cmd=f"step:{x_cmd}@0.01", zoh=True, dt_out=1e-4, p=model.p(**p),
                     solver="rk4")  # the default step, inside RK4's stability limit
    return r["x_rod"][-1000:], r["x_s"][-1000:]  # the last 0.1 s


def test_bias_shifts_the_held_rod_by_minus_b(real):
    # the loop regulates x_s = x_rod + b to x_cmd, so the rod settles b lower; the
    # quantiser can leave it anywhere within one step q of that (measured: 0.4 um off
    # at q = 5 um, b = 50 um)
    q, b = 5e-6, 5e-5
    x0, _ = _held(real, 1e-3, q_x=q)
    xb, _ = _held(real, 1e-3, q_x=q, b_x=b)
    assert abs((xb.mean() - x0.mean()) - (-b)) <= q


@pytest.mark.parametrize("offset", [0.0, 0.34])
def test_quantisation_bounds_the_static_error(real, offset):
    # a command between two steps (offset in steps): the loop hunts between the two
    # readings around it, and the rod stays within q/2 of the command. The backlash
    # adds nothing here: the LVDT reads the rod itself, the gap is inside the loop
    # (it shows as the hunting, 0.7 um peak to peak measured, within the q/2 bound)
    q = 5e-6
    x_cmd = 1e-3 + offset * q
    x, xs = _held(real, x_cmd, q_x=q)
    assert np.max(np.abs(x - x_cmd)) <= q / 2
    # every reading is a whole number of steps
    assert np.allclose(xs / q, np.round(xs / q), rtol=0, atol=1e-9)


def test_resolver_quantisation_steps_the_speed_estimate(real, params):
    # at a constant speed the difference quotient of the quantised angle over one
    # speed-loop sample is a whole number of dtheta f_s_w (2 pi/2^16 x 8 kHz =
    # 0.767 rad/s) and takes the two values around the true speed
    # The step dt = 3.125 us divides every ECU period and is inside RK4's 5.57 us limit (at
    # 10 us the 8 kHz samples fell 12 or 13 steps apart and the quotient jittered by +-4 %)
    v = 0.04  # m/s, rod ramp
    r = ema.simulate(real, 0.3, x_cmd=f"ramp:{v}", zoh=True, dt=3.125e-6, dt_out=1.25e-4, solver="rk4")
    step = 2 * math.pi / 2**16 * params.control.f_s_w
    w = r["omega_s"][-800:]
    n = w / step
    assert np.allclose(n, np.round(n), rtol=0, atol=1e-6)
    omega = v * 2 * math.pi / params.screw.p
    levels = np.unique(np.round(n))
    assert set(levels) <= {math.floor(omega / step), math.ceil(omega / step)}
    # and its mean is the true speed (to a tenth of a step over 0.1 s: 8 % measured)
    assert abs(w.mean() - r["omega"][-800:].mean()) < 0.1 * step


def test_noise_is_seeded_and_reproducible(params):
    model = ema.build_model(params, {"sensor": "real"})
    runs = [ema.simulate(model, 0.05, x_cmd="step:1mm", zoh=True, p=model.p(noise_seed=s), solver="rk4")
            for s in (3, 3, 4)]
    assert np.array_equal(runs[0]["x_s"], runs[1]["x_s"])  # same seed, same run, bit for bit
    assert np.array_equal(runs[0]["i_q"], runs[1]["i_q"])
    assert not np.array_equal(runs[0]["x_s"], runs[2]["x_s"])
    # the LVDT noise has the declared standard deviation per sample (2000 samples at
    # 2 kHz over 1 s of the sequence: 1.6 % standard error, 5 % allowed)
    from ema_casadi.simulation import noise_signal

    n = noise_signal(3, "n_x", 2000.0, 1.0)(np.arange(2000) / 2000.0)
    assert abs(np.std(n) - 1.0) < 0.05 and abs(np.mean(n)) < 0.1


def test_linearisation_keeps_the_sensors_linear_part(real, params):
    # the loop regulates x_s = (1 + k_g) x_rod: the closed loop's DC gain is 1/(1 + k_g);
    # the quantisation (q_x > 0 in the set) is left to the time-domain analyses, so the
    # loop does not look open; with the position loop open at its break the LVDT's lag
    # is a pole at -1/tau_x of the loop transfer
    k_g = 0.02
    op = ema.operating_point(real, p=real.p(k_g_x=k_g))
    lm = ema.linear_model(real, op, inputs=["x_cmd"], outputs=["x_rod"])
    dc = float((lm.D - lm.C @ np.linalg.solve(lm.A, lm.B))[0, 0])
    assert dc == pytest.approx(1 / (1 + k_g), rel=1e-6)
    L = ema.linearisation.loop_model(real, "position", op)
    eig = np.linalg.eigvals(L.A)
    assert np.min(np.abs(eig + 1 / params.sensor.tau_x)) < 1e-6 / params.sensor.tau_x
