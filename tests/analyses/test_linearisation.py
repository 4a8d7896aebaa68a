"""Operating points and exact linearisation.

Tolerances are stated where used; analytic values come from the physics reference (docs: physics).
"""

import math
import warnings

import numpy as np
import pytest

import ema_casadi as ema
from ema_casadi import frequency as fr
from ema_casadi import linearisation as lz

VARIANTS = [{}, {"screw": "rigid"}, {"motor": "dc"}, {"controller": "PI"}]
POINTS = {"rest": (2e-3, 0.0, 0.0), "loaded": (2e-3, 20e3, 0.0), "moving": (-1e-3, 10e3, 0.03)}


def _id(v):
    return "-".join(f"{k}={x}" for k, x in v.items()) or "reference"


@pytest.mark.parametrize("variants", VARIANTS, ids=_id)
@pytest.mark.parametrize("point", list(POINTS))
def test_ad_jacobian_equals_central_difference(model_cache, variants, point):
    """A, B, C, D from CasADi AD equal a central finite difference of the same Function
    at the linearisation point within 1e-6 relative. Each entry is measured against
    itself or, if it is much smaller than its row, against the row's size at full scale
    (the row's terms with every variable at its full-scale value, divided by this
    variable's full scale): round-off of an O(1e8) row is no error of a zero entry.
    Steps are 1e-7 of full scale: truncation (h^2 f''') and round-off (eps f/h) both stay
    below 1e-8 relative.

    One exclusion: the rigid screw's play operator is discontinuous in the gap at the
    contact edge (a moving rod leaves the contact for a negative gap), so its rate has
    no derivative with respect to phi and x_play there; AD gives the contact side's 0."""
    model = model_cache(**variants)
    x_cmd, f_ext, v_rod = POINTS[point]
    op = lz.operating_point(model, x_cmd, f_ext, v_rod)
    x, u, p = op.x, op.u_lin, op.p_lin
    _, _, A, B, C, D = (np.array(v) for v in lz.jacobian_function(model)(x, u, p))
    x_fs = model.full_scale(p)
    u_fs = np.array([0.075, 5e4, 1.0, 0.075, 100.0, 24.0])  # x_cmd, f_ext, eta, d_x, d_w, d_i
    sig = [model.outputs.index(n) for n in lz.signal_outputs(model)]

    def central(which, base, scale):
        cols = []
        for j in range(len(base)):
            h = 1e-7 * scale[j]
            lo, hi = base.copy(), base.copy()
            lo[j] -= h
            hi[j] += h
            args_lo = (lo, u, p) if which == "x" else (x, lo, p)
            args_hi = (hi, u, p) if which == "x" else (x, hi, p)
            f_lo = [np.array(v).ravel() for v in model.f(*args_lo)]
            f_hi = [np.array(v).ravel() for v in model.f(*args_hi)]
            cols.append([(a - b) / (2 * h) for a, b in zip(f_hi, f_lo, strict=True)])
        return np.array([c[0] for c in cols]).T, np.array([c[1] for c in cols]).T

    A_fd, C_fd = central("x", x, x_fs)
    B_fd, D_fd = central("u", u, u_fs)
    for name, J, J_fd, scale in (("A", A, A_fd, x_fs), ("B", B, B_fd, u_fs),
                                 ("C", C[sig], C_fd[sig], x_fs), ("D", D[sig], D_fd[sig], u_fs)):
        row = (np.abs(J) @ scale)[:, None] / scale[None, :]
        ref = np.maximum(np.abs(J), row)
        err = np.abs(J_fd - J)
        ok = err <= 1e-6 * ref
        if name == "A" and "x_play" in model.states:
            ip = model.index("x_play")
            ok[ip, [model.index("phi"), ip]] = True
        assert ok.all(), f"{name}: worst relative error {np.max(err / np.where(ref > 0, ref, 1)):.2e}"


def test_trim_under_load_matches_statics(model_cache, params):
    """At rest under load the speed PI's integral removes the position error
    (x_rod = x_cmd exactly), the screw deflects F/C, and the current holds
    T = (p/2pi) F g with g = (1/eta + eta_inv)/2 (the efficiency blend at omega = 0)."""
    model = model_cache()
    F = 20e3
    op = lz.operating_point(model, 1e-3, F)
    s = params.screw
    r = s.p / (2 * math.pi)
    g = 0.5 / s.eta + 0.5 * s.eta_inv
    assert op.output("x_rod") == pytest.approx(1e-3, abs=1e-15)
    assert op.output("x_in") - op.output("x_rod") == pytest.approx(F / s.C, rel=1e-9)
    assert op.output("i_q") == pytest.approx(r * F * g / params.K_t, rel=1e-9)
    assert op.output("i_d") == pytest.approx(0.0, abs=1e-12)
    assert op.policy["g_eff"] == pytest.approx(g, rel=1e-12)
    assert np.max(np.abs(op.xdot)) == 0.0


def test_moving_point_is_a_relative_equilibrium(model_cache, params):
    """At constant rod velocity the P position loop runs a following error v/K_x, the
    shaft turns at v/r, and only the positions change."""
    model = model_cache()
    v = 0.05
    op = lz.operating_point(model, 0.0, 5e3, v)
    r = params.screw.p / (2 * math.pi)
    assert op.output("x_rod") == pytest.approx(-v / params.control.K_x, rel=1e-9)
    assert op.output("omega") == pytest.approx(v / r, rel=1e-12)
    assert op.output("v_rod") == pytest.approx(v, rel=1e-12)
    xdot = np.array(model.f(op.x, op.u, op.p)[0]).ravel()
    np.testing.assert_allclose(xdot, op.xdot, atol=1e-9 * v / r)
    moving = {"phi", "x_rod"}
    assert all(op.xdot[i] == 0 for i, n in enumerate(model.states) if n not in moving)


@pytest.mark.parametrize("screw", ["elastic", "rigid"])
def test_load_above_holding_limit_has_no_operating_point(model_cache, params, screw):
    """At rest the blend gives g = (1/eta + eta_inv)/2, so the 24 A current limit holds
    F_hold = K_t I_max / (r g) = 54.5 kN; just below it a trim exists, just above it the
    trim reports the current limit. (The 46.9 kN stall of the reference set, docs: physics, is the load the motor
    can still *push*: g = 1/eta plus seal and bearing friction; with the rod extending
    against the load, v_rod > 0, the limit is that one.)"""
    model = model_cache(screw=screw)
    r = params.screw.p / (2 * math.pi)
    g = 0.5 / params.screw.eta + 0.5 * params.screw.eta_inv
    F_hold = params.K_t * params.motor.I_max / (r * g)
    assert F_hold == pytest.approx(54.5e3, rel=2e-3)
    lz.operating_point(model, 0.0, 0.999 * F_hold)
    with pytest.raises(lz.OperatingPointError, match=r"current limit I_max = 24 A"):
        lz.operating_point(model, 0.0, 1.001 * F_hold)
    # extending against the load with friction kept: the 46.9 kN stall
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        lz.operating_point(model, 0.0, 46.5e3, 1e-3, friction="smooth")
        with pytest.raises(lz.OperatingPointError, match="I_max"):
            lz.operating_point(model, 0.0, 47.3e3, 1e-3, friction="smooth")


def test_rate_and_stroke_limits(model_cache):
    model = model_cache()
    with pytest.raises(lz.OperatingPointError, match="rate limit"):
        lz.operating_point(model, 0.0, 0.0, 0.09)
    with pytest.raises(lz.OperatingPointError, match="outside the stroke"):
        lz.operating_point(model, 0.1)
    with pytest.raises(lz.LinearizationError, match="friction policy 'wet' unknown"):
        lz.operating_point(model, friction="wet")


@pytest.mark.parametrize("loop", list(lz.LOOPS))
def test_loop_break_by_flag_equals_closed_loop_identity(model_cache, loop):
    """Opening a loop by its flag gives the same L as the closed-loop identity: with the
    loop closed, the injection d reaches the measurement as T_d = -L/(1+L), so
    L = -T_d/(1+T_d). Two routes through the model, agreement to round-off (1e-8). The
    aircraft loop on the transport, trimmed at its flight condition."""
    if loop == "aircraft":
        model = model_cache(airframe="transport")
        op = lz.flight_point(model)
    else:
        model = model_cache()
        op = lz.operating_point(model, 0.0, 10e3)
    L = lz.loop_model(model, loop, op)
    _, inj, meas = lz.LOOPS[loop]
    Td = lz.linear_model(model, op, inputs=[inj], outputs=[meas])
    f = np.array([0.3, 3.0, 30.0, 300.0, 3000.0])
    if loop == "aircraft":  # its band (|L| is 1e-12 at 3 kHz: round-off)
        f = f / 100
    L_flag = fr.freqresp(L, f)[0, 0]
    T = fr.freqresp(Td, f)[0, 0]
    np.testing.assert_allclose(L_flag, -T / (1 + T), rtol=1e-8)


def test_hybrid_variant_linearises_like_smooth(model_cache):
    """The small-signal policy (Coulomb friction off, stick band closed) makes the hybrid
    variant's linear model identical to the smooth one's - no special case."""
    a = lz.linear_model(model_cache(), x_cmd=1e-3, f_ext=15e3)
    b = lz.linear_model(model_cache(friction="hybrid"), x_cmd=1e-3, f_ext=15e3)
    for k in "ABCD":
        np.testing.assert_allclose(getattr(b, k), getattr(a, k), rtol=1e-12, atol=0)


def test_backlash_keep_decouples_at_rest_and_preloaded_under_load(model_cache):
    model = model_cache()
    with pytest.warns(UserWarning, match="inside the .* gap"):
        op = lz.operating_point(model, backlash="keep")
    lin = lz.linear_model(model, op)
    i_v = model.index("v_rod")
    assert lin.A[i_v, model.index("phi")] == 0.0  # no spring: the rod is decoupled
    keep = lz.linear_model(model, f_ext=5e3, backlash="keep")
    off = lz.linear_model(model, f_ext=5e3)
    np.testing.assert_allclose(keep.A, off.A, rtol=1e-12)


def test_smooth_friction_policy_warns_and_stiffens(model_cache):
    """Linearised at rest, tanh friction acts as viscous damping F_seal/v_s = 1.5e6 N s/m."""
    model = model_cache()
    with pytest.warns(UserWarning, match="depends on v_s"):
        lin = lz.linear_model(model, friction="smooth")
    off = lz.linear_model(model)
    i_v = model.index("v_rod")
    extra = -(lin.A[i_v, i_v] - off.A[i_v, i_v]) * model.params.screw.M
    assert extra == pytest.approx(150.0 / 1e-4, rel=1e-9)


def test_linearize_returns_named_statespace(model_cache):
    import control

    model = model_cache()
    sys = lz.linearize(model, f_ext=1e3)
    assert isinstance(sys, control.StateSpace)
    assert list(sys.state_labels) == list(model.states)
    assert list(sys.input_labels) == list(model.inputs)
    assert "x_rod" in sys.output_labels and "P_cu" not in sys.output_labels
    L = lz.loop_transfer(model, "position")
    assert list(L.input_labels) == ["d_x"] and list(L.output_labels) == ["-x_s"]  # the fed-back (sensed) rod position


def _first_harmonic(t, y, f):
    w = 2 * np.pi * f
    M = np.column_stack([np.sin(w * t), np.cos(w * t), np.ones_like(t)])
    a, b, _ = np.linalg.lstsq(M, y, rcond=None)[0]
    return complex(a, b)


def test_linear_closed_loop_equals_small_signal_sine_stream(model_cache, params):
    """Linear x_rod/x_cmd equals the nonlinear model's first harmonic (friction and
    backlash off, 0.05 % of the stroke) within 0.3 dB and 3 deg at six frequencies.
    CVODES (rtol 1e-8); 0.3 s settling (slowest closed-loop pole -48 1/s: e^-14),
    then the harmonic is fitted over whole periods on a 1e-4 s grid."""
    model = model_cache()
    op = lz.operating_point(model)
    T = fr.closed_loop(model, op)
    amp = 0.0005 * params.actuator.stroke
    dt = 1e-4
    for f in (0.1, 0.5, 2.0, 5.0, 20.0, 50.0):
        period = 1 / f
        n_per = max(1, math.ceil(0.1 * f))
        t_end = 0.3 + n_per * period
        res = ema.simulate(model, t_end, ema.Signal.sine(amp, f), 0.0, solver="cvodes", p=op.p, dt_out=dt)
        n = int(round(n_per * period / dt))
        t, y = res.t[-n - 1 : -1], res["x_rod"][-n - 1 : -1]
        g = _first_harmonic(t, y, f) / amp
        h = fr.freqresp(T, [f])[0, 0, 0]
        assert 20 * np.log10(abs(g) / abs(h)) == pytest.approx(0.0, abs=0.3), f
        assert np.degrees(np.angle(g / h)) == pytest.approx(0.0, abs=3.0), f


def test_reference_closed_loop_flat_and_spec_anchors(model_cache):
    """Within 0.5 dB of flat up to 2 Hz; the reference set's small-signal predictions (docs: physics) to the digits
    quoted there (0.01 dB, 0.06 deg); -3 dB near 20 Hz; drive-train mode near 1.42 kHz."""
    model = model_cache()
    T = fr.closed_loop(model)
    f = np.linspace(0.01, 2.0, 400)
    assert np.max(np.abs(20 * np.log10(np.abs(fr.freqresp(T, f)[0, 0])))) < 0.5
    anchors = {1.0: (-0.03, -4.8), 2.0: (-0.12, -9.4), 5.0: (-0.57, -22.0), 10.0: (-1.33, -39.3)}
    H = fr.freqresp(T, list(anchors))[0, 0]
    for (fa, (mag, ph)), h in zip(anchors.items(), H, strict=True):
        assert 20 * np.log10(abs(h)) == pytest.approx(mag, abs=0.01), fa
        assert np.degrees(np.angle(h)) == pytest.approx(ph, abs=0.06), fa
    assert fr.bandwidth(T) == pytest.approx(20.0, abs=1.0)
    f_n = max(m["f_n_hz"] for m in fr.modes(T))
    assert f_n == pytest.approx(1420.0, rel=0.01)
