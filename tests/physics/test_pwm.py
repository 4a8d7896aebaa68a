"""Acceptance: the switched PWM bridge (inverter = "pwm").

The carrier-synchronous stepper integrates each sub-interval between two switching
instants with RK4 at its own length; the switching instants come in closed form from
the duty cycles. Each test states where its number comes from; the measured value and
the safety factor stand next to each tolerance.
"""

import math

import numpy as np
import pytest

import ema_casadi as ema
from ema_casadi import Signal

F_SW = 16e3
V_DC = 270.0


@pytest.fixture(scope="module")
def pwm(model_cache):
    return model_cache(inverter="pwm")


@pytest.fixture(scope="module")
def ramp_runs(pwm):
    """The rod driven at 40 mm/s against 20 kN (steady: f_e = pp v/p = 32 Hz, |i_dq|
    = 10.3 A), every sub-interval kept; without and with the 1.5 us dead time."""
    out = {}
    for td in (0.0, 1.5e-6):
        out[td] = ema.simulate(pwm, 0.15, Signal.ramp(0.04), 20e3, p=pwm.p(t_dead=td), solver="rk4",
                               decimate=1)
    return out


def _window(r, t0=0.08, t1=0.14):
    """Sample indices of [t0, t1) and the time weights of the piecewise-constant
    sub-intervals starting there (each sample's leg states hold until the next)."""
    sel = (r.t >= t0) & (r.t < t1)
    w = np.where(sel[:-1], np.diff(r.t), 0.0)
    i0, i1 = np.nonzero(sel)[0][[0, -1]]
    return w, i0, i1


def _wmean(r, w, name):
    return float(np.sum(r[name][:-1] * w) / np.sum(w))


def _window_power(r, name, i0, i1):
    """Mean power over samples i0..i1 from the run's exact running integral."""
    E = r.info["energy_series"][name]
    return (E[i1] - E[i0]) / (r.t[i1] - r.t[i0])


def test_switching_instants_exact_under_halved_step(pwm):
    # only the smooth dynamics between the exact switching instants are integrated:
    # halving the RK4 step bound inside every sub-interval (5 us -> 2.5 us) over the 1.5 mm
    # 1 Hz sine changes the rod by 1.8e-12 m and the phase current by 9.4e-9 A (measured;
    # 4th-order: at 2.5 -> 1.25 us 2.5e-14 m); asserted < 1 nm, < 1 mA (the stated bound).
    # Not switching effects, and not asserted: a 1 mm step whose nut crosses the 20 um
    # backlash gap puts the dead-zone spring's kink inside a step (first order: 1.8 nm at
    # 5 us, 0.9 nm at 2.5 us); held at rest against 10 kN the smooth friction's stiff mode
    # (F_r/(M v_s) = 1.8e6 1/s) is beyond RK4 at 5 us (0.29 um), as in the averaged model.
    x_cmd = Signal.sine(1.5e-3, 1.0)
    a = ema.simulate(pwm, 0.05, x_cmd, dt=5e-6, dt_out=1e-3, solver="rk4")
    b = ema.simulate(pwm, 0.05, x_cmd, dt=2.5e-6, dt_out=1e-3, solver="rk4")
    assert a.info["rk4_max_per_subinterval"] == 7 and b.info["rk4_max_per_subinterval"] == 13
    assert np.abs(a["x_rod"] - b["x_rod"]).max() < 1e-9
    assert np.abs(a["i_a"] - b["i_a"]).max() < 1e-3
    assert np.abs(a["x_rod"]).max() > 0.2e-3 and np.abs(a["i_a"]).max() > 0.1  # it did move (m, A)


def _first_harmonic(t, y, f):
    w = 2 * np.pi * f
    T = t[-1] - t[0]
    a = 2 / T * np.trapezoid(y * np.sin(w * t), t)
    b = 2 / T * np.trapezoid(y * np.cos(w * t), t)
    return math.hypot(a, b), math.degrees(math.atan2(b, a))


def test_pwm_rod_response_matches_averaged(pwm, model_cache):
    # 1.5 mm (2 % of the stroke) 1 Hz sine, second period: the switched bridge against
    # the averaged one with the same sampled ECU. Measured: amplitude ratio - 1 = -1.5e-6,
    # phase difference 7e-4 deg; asserted 2 % and 3 deg (the stated bound)
    x_cmd = Signal.sine(1.5e-3, 1.0)
    sw = ema.simulate(pwm, 2.0, x_cmd, dt=5e-6, dt_out=1e-3, solver="rk4")
    av = ema.simulate(model_cache(), 2.0, x_cmd, dt=5e-6, dt_out=1e-3, zoh=True, solver="rk4")
    sel = sw.t >= 1.0 - 1e-12
    A_sw, ph_sw = _first_harmonic(sw.t[sel], sw["x_rod"][sel], 1.0)
    A_av, ph_av = _first_harmonic(av.t[sel], av["x_rod"][sel], 1.0)
    assert abs(A_sw / A_av - 1) < 0.02
    assert abs(ph_sw - ph_av) < 3.0


def test_fundamental_of_switched_voltage_is_the_averaged_voltage(ramp_runs):
    # the synchronous-frame mean (over whole sub-intervals, 60 ms = 1.9 electrical periods)
    # of the Park transform of the switched phase voltages is their fundamental; against
    # the averaged bridge's voltage. Measured ratio 0.999998; asserted 2 % (the stated bound)
    r = ramp_runs[0.0]
    w, _, _ = _window(r)
    v = math.hypot(_wmean(r, w, "v_d"), _wmean(r, w, "v_q"))
    v_avg = math.hypot(_wmean(r, w, "v_d_avg"), _wmean(r, w, "v_q_avg"))
    assert v_avg > 50  # a real modulation (back-EMF 60 V at 32 Hz)
    assert abs(v / v_avg - 1) < 0.02


def test_dead_time_voltage_error(ramp_runs):
    # each leg's mean voltage is off by -sign(i) t_d f_sw V_dc: a square wave whose
    # fundamental is (4/pi) t_d f_sw V_dc = 8.25 V (the star point removes only triplen
    # harmonics). Measured 8.22 V (0.4 %) at |i| = 10.3 A, ripple ~1 A; asserted 10 %
    r = ramp_runs[1.5e-6]
    w, _, _ = _window(r)
    err = math.hypot(_wmean(r, w, "v_d") - _wmean(r, w, "v_d_avg"), _wmean(r, w, "v_q") - _wmean(r, w, "v_q_avg"))
    expected = 4 / math.pi * 1.5e-6 * F_SW * V_DC
    assert abs(err / expected - 1) < 0.10


def _ripple(r, f_sw, t0):
    """Mean over the carrier periods after t0 of the peak-to-peak phase-a current within
    each period (its extremes fall on the kept switching instants)."""
    sel = r.t >= t0
    k = np.floor(r.t[sel] * f_sw + 1e-9).astype(int)
    i = r["i_a"][sel]
    pp = [np.ptp(i[k == n]) for n in np.unique(k)[:-1]]
    return float(np.mean(pp))


def test_doubling_the_carrier_halves_the_ripple(pwm):
    # the rod at 40 mm/s against 20 kN: the ripple of a sub-interval is ~ v T/L, so
    # doubling f_sw (the synchronous current loop with it) halves it. Measured 0.2415 A
    # and 0.1208 A p-p (ratio 0.5000, mean over 1.3 electrical periods); asserted 10 %
    pp = {}
    for f in (16e3, 32e3):
        r = ema.simulate(pwm, 0.1, Signal.ramp(0.04), 20e3, p=pwm.p(f_sw=f, f_s_i=f, t_dead=0.0),
                         solver="rk4", decimate=1)
        pp[f] = _ripple(r, f, 0.06)
    assert pp[16e3] > 0.1  # a ripple to measure (A)
    assert abs(pp[32e3] / pp[16e3] - 0.5) < 0.05


def _device_formulas(I, V, phi, P):
    """Per-device conduction losses over an electrical period of i = I cos(theta), the
    phase reference V cos(theta + phi), carrier-averaged (IGBT of the upper device of leg
    a, on with the duty d, for i > 0; the diode of the lower device, on with 1 - d):
      P_T = 1/(2 pi) int_{i>0} d(theta) (V_CE0 i + r_CE i^2) dtheta
      P_D = 1/(2 pi) int_{i>0} (1 - d(theta)) (V_F0 i + r_F i^2) dtheta
    with the SVPWM duty d = 1/2 + (v_a + v_0)/V_dc, v_0 = -(max + min)/2 of the three
    phase references. For sine PWM (v_0 = 0) these are the classic closed forms
      P_T = V_CE0 I (1/(2 pi) + M cos(phi)/8) + r_CE I^2 (1/8 + M cos(phi)/(3 pi)),
      P_D = V_F0 I (1/(2 pi) - M cos(phi)/8) + r_F I^2 (1/8 - M cos(phi)/(3 pi)),
    M = 2 V/V_dc; returned too (the zero sequence moves only the i^2 terms)."""
    th = np.linspace(-np.pi, np.pi, 200001)
    v = [V * np.cos(th + phi - k * 2 * np.pi / 3) for k in range(3)]
    v0 = -(np.maximum.reduce(v) + np.minimum.reduce(v)) / 2
    d = 0.5 + (v[0] + v0) / V_DC
    i = I * np.cos(th)
    pos = i > 0
    P_T = np.trapezoid(np.where(pos, d * (P.V_CE0 * i + P.r_CE * i**2), 0), th) / (2 * np.pi)
    P_D = np.trapezoid(np.where(pos, (1 - d) * (P.V_F0 * i + P.r_F * i**2), 0), th) / (2 * np.pi)
    m = 2 * V / V_DC * math.cos(phi)
    cl_T = P.V_CE0 * I * (1 / (2 * math.pi) + m / 8) + P.r_CE * I**2 * (1 / 8 + m / (3 * math.pi))
    cl_D = P.V_F0 * I * (1 / (2 * math.pi) - m / 8) + P.r_F * I**2 * (1 / 8 - m / (3 * math.pi))
    return P_T, P_D, cl_T, cl_D


def test_device_losses_match_the_analytic_formulas(ramp_runs, pwm, model_cache):
    # steady sinusoidal currents (32 Hz, 10.3 A). Measured against the formulas: IGBT
    # -0.18 %, diode +1.0 %, switching +0.19 %; averaged bridge against switched total
    # +0.15 %; asserted 3 %, 3 %, 3 %, 5 % (the stated bound). The classic sine-PWM forms differ
    # from the SVPWM integrals by +0.14 % (IGBT) and -0.35 % (diode)
    r = ramp_runs[0.0]
    w, i0, i1 = _window(r)
    P = pwm.pdict()
    I = math.hypot(_wmean(r, w, "i_d"), _wmean(r, w, "i_q"))
    vd, vq = _wmean(r, w, "v_d_avg"), _wmean(r, w, "v_q_avg")
    phi = math.atan2(vq, vd) - math.atan2(_wmean(r, w, "i_q"), _wmean(r, w, "i_d"))
    P_T, P_D, cl_T, cl_D = _device_formulas(I, math.hypot(vd, vq), phi, P)
    sw_T = _window_power(r, "P_inv_cond", i0, i1)  # IGBTs + diodes, from the quadrature
    # the split between the devices from the sub-interval-weighted instantaneous values
    share_T = _wmean(r, w, "P_cond_T") / (_wmean(r, w, "P_cond_T") + _wmean(r, w, "P_cond_D"))
    got_T, got_D = share_T * sw_T / 6, (1 - share_T) * sw_T / 6
    assert abs(cl_T / P_T - 1) < 0.01 and abs(cl_D / P_D - 1) < 0.01  # measured +0.14 %, -0.35 %
    assert abs(got_T / P_T - 1) < 0.03
    assert abs(got_D / P_D - 1) < 0.03
    sw = _window_power(r, "P_inv_sw", i0, i1) / 6
    expected = P.f_sw * P.E_sw * (V_DC / P.V_sw_ref) * (I / (math.pi * P.I_sw_ref))
    assert abs(sw / expected - 1) < 0.03
    av = ema.simulate(model_cache(), 0.15, Signal.ramp(0.04), 20e3, dt_out=5e-6, zoh=True, solver="rk4")
    sel = (av.t >= 0.08) & (av.t <= 0.14)
    total_av = np.trapezoid((av["P_inv_cond"] + av["P_inv_sw"])[sel], av.t[sel]) / 0.06
    total_sw = sw_T + 6 * sw
    assert abs(total_sw / total_av - 1) < 0.05


REFERENCE = Signal.step(1e-3, 0.01) + Signal.sine(0.375e-3, 1.0, 0.5)
SCENARIOS = {"reference": (0.6, REFERENCE, 0.0), "sine_20kN": (1.0, Signal.sine(1.5e-3, 1.0), 20e3)}


def _balance(model, r, E):
    """(input energy, its balance: input - stored - losses - load work)."""
    losses = sum(E[k] for k in model.outputs_of("loss"))
    dE = r["E_stored"][-1] - r["E_stored"][0]
    return E["P_dc"], E["P_dc"] - dE - losses - E["P_load"]


@pytest.mark.parametrize("supply", ["ideal", "line"])
@pytest.mark.parametrize("scenario", list(SCENARIOS))
def test_energy_balance_at_the_input(model_cache, supply, scenario):
    # int P_dc = Delta(kinetic + spring + magnetic + link) + int(all losses: inverter,
    # copper, screw, friction, viscous, contact, line) + work on the load. The switched run
    # integrates its powers as quadratures in its own steps; the averaged one by trapezoid
    # at 5 us. Both at their default steps inside RK4's stability limit under 20 kN (0.5 and
    # 0.74 us): measured |residual| / int |P_dc| under 20 kN: averaged 1.2e-5 (the trapezoid),
    # switched 2.4e-11 (at 5 us, above the limit, 7.6e-5 and 1.44e-4: the smooth friction's
    # chatter; <= 5e-9 on the reference scenario); asserted 0.5 % (the stated bound). The scale
    # int |P_dc| (12.3 J, 199 J) from the averaged run.
    t_end, x_cmd, load = SCENARIOS[scenario]
    av_model = model_cache(supply=supply)
    sw_model = model_cache(inverter="pwm", supply=supply)
    av = ema.simulate(av_model, t_end, x_cmd, load, dt_out=5e-6, solver="rk4")
    scale = np.trapezoid(np.abs(av["P_dc"]), av.t)
    sw = ema.simulate(sw_model, t_end, x_cmd, load, dt_out=1e-3, solver="rk4")
    for model, r in ((av_model, av), (sw_model, sw)):
        E_in, residual = _balance(model, r, r.energies())
        assert E_in > 0.2 * scale  # a net draw (the rest is regenerated and drawn again)
        assert abs(residual) < 5e-3 * scale


def _link_step_peak(P):
    """Peak of the DC link's dip per ampere of a step in the bridge's current, from the
    line alone: with C dv/dt = i_line - i_b, L di_line/dt = -R i_line - v (deviations),
    v/i_b = -(R + sL)/(LC s^2 + RC s + 1), whose step response is
      h(t) = R (1 - e^{-at}(cos w t + (a/w) sin w t)) + e^{-at} sin(w t)/(C w),
    a = R/(2L), w = sqrt(1/(LC) - a^2). Returns (max h (Ohm), its time (s))."""
    R, L, C = P.R_line, P.L_line, P.C_dc
    a = R / (2 * L)
    w = math.sqrt(1 / (L * C) - a**2)
    t = np.linspace(0, 2e-3, 200001)
    h = R * (1 - np.exp(-a * t) * (np.cos(w * t) + a / w * np.sin(w * t))) + np.exp(-a * t) * np.sin(w * t) / (C * w)
    return float(h.max()), float(t[h.argmax()])


def test_line_dip_on_a_30kN_acceleration(model_cache):
    # a 5 mm step against 30 kN: the current loop saturates its voltage at once, so the
    # bridge's current steps (1.8 A -> 12.9 A in one 5 us sample, then 15.3 A at 0.11 ms).
    # Hand calculation: dip = max h x (i_b at the peak time of h, 0.11 ms, less before),
    # max h = 0.340 Ohm for 0.1 Ohm, 20 uH, 200 uF (a 2.5 kHz resonance, zeta 0.16).
    # Measured 4.25 V against 4.55 V predicted (-7 %: the current still rises during the
    # dip); asserted 10 % (the stated bound)
    model = model_cache(supply="line")
    P = model.pdict()
    r = ema.simulate(model, 0.03, Signal.step(5e-3, 0.02), 30e3, dt_out=5e-6, solver="rk4")
    i_b = r["P_bridge"] / r["v_dc"]
    before = (r.t > 0.018) & (r.t < 0.02)
    after = r.t > 0.02
    h_max, t_peak = _link_step_peak(P)
    d_i = np.interp(0.02 + t_peak, r.t, i_b) - i_b[before].mean()
    dip = r["v_dc"][before].mean() - r["v_dc"][after].min()
    assert d_i > 10  # a real step of the bridge's current (A)
    assert abs(dip / (h_max * d_i) - 1) < 0.10


def test_line_at_250V_still_reaches_80mm_s(model_cache):
    # MIL-STD-704F's lowest normal voltage behind the line: the back-EMF at 80 mm/s is
    # 121 V against the FOC limit 0.95 x 250/sqrt(3) = 137 V (less the line's drop), so the
    # 10 mm slew runs at the rate limit. Measured mean speed over the slew 80.3 mm/s, the
    # link at >= 248.0 V; asserted 99 % of 80 mm/s
    model = model_cache(inverter="pwm", supply="line")
    r = ema.simulate(model, 0.15, Signal.step(10e-3, 0.005), 0.0, dt=5e-6, dt_out=62.5e-6, p=model.p(V_dc=250.0),
                     solver="rk4")
    slew = (r.t > 0.05) & (r.t < 0.1)
    assert r["v_rod"][slew].mean() > 0.99 * 0.08


def test_cli_simulates_and_plots_the_switched_bridge(tmp_path, capsys):
    # `ema simulate --variant inverter=pwm` picks the carrier-synchronous stepper by itself
    from conftest import REFERENCE
    from ema_casadi.cli import main

    png, csv = tmp_path / "pwm.png", tmp_path / "pwm.csv"
    rc = main(["simulate", str(REFERENCE), "--variant", "inverter=pwm", "--variant", "supply=line", "--t-end", "0.01",
               "--plot", str(png), "--out", str(csv)])
    assert rc in (0, None)
    assert png.stat().st_size > 10_000 and csv.stat().st_size > 0
    head = csv.read_text().splitlines()[0].split(",")
    assert {"i_a", "s_a", "v_an", "v_ab", "i_dc", "v_dc", "P_dc"} <= set(head)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["pwm.csv", "pwm.png"]


def test_double_update_and_refused_rates(pwm):
    # double update (ECU at peak and valley, f_s_i = 2 f_sw) halves the reference's hold
    # time: the rod follows the same 1 mm step; measured 0.61 um apart over 0.02 s (a
    # faster current loop); asserted 2 um. A current loop not
    # synchronous with the carrier is refused in one line.
    single = ema.simulate(pwm, 0.02, Signal.step(1e-3, 0.002), dt_out=1e-3, solver="rk4")
    double = ema.simulate(pwm, 0.02, Signal.step(1e-3, 0.002), dt_out=1e-3, p=pwm.p(f_s_i=2 * F_SW),
                          solver="rk4")
    assert single.info["update"] == "single" and double.info["update"] == "double"
    assert np.abs(double["x_rod"] - single["x_rod"]).max() < 2e-6
    with pytest.raises(ema.SimulationError, match="single update"):
        ema.simulate(pwm, 0.001, p=pwm.p(f_s_i=10e3), solver="rk4", decimate=1)
