"""Experiment design: the Fisher information of a test is the covariance identify
reports, the criteria and the optimal weights against analytic optima, the rounding,
a small design end to end, and bad requests refused before any work."""

import math

import numpy as np
import pytest

from conftest import assert_glance
from ema_casadi.design import (
    DesignError,
    Segment,
    criterion,
    design_experiment,
    efficient_rounding,
    information,
    optimal_weights,
    realise,
)
from ema_casadi.identification import free_parameters, identify, synthetic_record
from ema_casadi.signals import Signal

SIGMA = {"x_rod": 0.3e-6, "i_q": 0.05}


@pytest.fixture(scope="module")
def small(params):
    """A two-parameter, two-segment design from a three-segment library (2 s at 1 kHz)."""
    lib = [Segment("multisine", (1.0, 8.0), 0.0, 2e-3), Segment("slews", (2, 0.2), 8e3, 4e-3),
           Segment("multisine", (4.0, 16.0), -8e3, 1e-3)]
    return design_experiment(params, ["F_seal", "psi"], 2.0, library=lib, rate=1000.0, max_load=8e3)


def test_information_is_the_covariance_identify_reports(params, model_cache, tmp_path):
    """The inverse of the predicted information is the covariance identify computes from
    its Jacobian when it fits the same test, noise-free, with these noise levels (it
    starts at the truth and stays there): its textbook intervals (the headline ones are
    the robust sandwich, which scales with the residuals: zero here)."""
    model = model_cache()
    seg = Segment("multisine", (1.0, 8.0), 5e3, 2e-3)
    test = realise([seg], 1.0, 1000.0, "x_cmd", "f_ext")
    fr = free_parameters(model, ["F_seal", "J_m"])
    info = information(model, test, fr, SIGMA)
    rec = test.records[0]
    path = synthetic_record(params, tmp_path / "r.csv", t_end=1.0, x_cmd=Signal.table(rec["t"], rec["inputs"]["x_cmd"]),
                            f_ext=Signal.table(rec["t"], rec["inputs"]["f_ext"]), noise={c: 0.0 for c in SIGMA},
                            rate=1000.0)
    res = identify(params, [path], ["F_seal", "J_m"], sigma=SIGMA, consistency=False, hold_unidentifiable=False)
    # identify's 95 % intervals in log coordinates: half-width 1.96 sd_z
    sd_pred = np.sqrt(np.diag(np.linalg.inv(info.M)))
    sd_fit = np.array([math.log(res.interval_textbook[n][1] / res.interval_textbook[n][0]) / (2 * 1.959963984540054)
                       for n in ("F_seal", "J_m")])
    # the same sensitivities on the same steps: measured 1.2e-10 relative (the CSV's 17 digits,
    # the fit's last step of 1e-10); 1e-6 leaves room for another CPU's rounding and step choice
    assert np.allclose(sd_fit, sd_pred, rtol=1e-6), (sd_fit, sd_pred)


def test_d_and_a_criteria_are_the_textbook_ones():
    rng = np.random.default_rng(1)
    A = rng.normal(size=(4, 6))
    M = A @ A.T
    assert criterion(M, "D") == pytest.approx(-np.linalg.slogdet(M)[1], rel=1e-12)
    assert criterion(M, "A") == pytest.approx(np.trace(np.linalg.inv(M)), rel=1e-12)
    lam = np.linalg.eigvalsh(np.linalg.inv(M))[-1]
    # Phi_16 lies between the largest eigenvalue and n^(1/16) times it (log form)
    assert math.log(lam) <= criterion(M, "E") <= math.log(lam) + math.log(4) / 16 + 1e-12
    # D_s on the first two: log det of their covariance block
    C = np.linalg.inv(M)
    assert criterion(M, "D", [1, 1, 0, 0]) == pytest.approx(np.linalg.slogdet(C[:2, :2])[1], rel=1e-12)


def test_optimal_weights_reach_the_analytic_optimum():
    """Two candidates that each see one parameter: D-optimal splits the time equally;
    A-optimal with information 4 and 1 per unit time minimises 1/(4w) + 1/(1-w): w = 1/3."""
    Ms = [np.diag([1.0, 0.0]), np.diag([0.0, 1.0])]
    d = optimal_weights(Ms, "D")
    assert d["success"] and np.allclose(d["w"], [0.5, 0.5], atol=1e-7)
    a = optimal_weights([np.diag([4.0, 0.0]), np.diag([0.0, 1.0])], "A")
    assert a["success"] and np.allclose(a["w"], [1 / 3, 2 / 3], atol=1e-7)


def test_the_dc_criterion_keeps_every_parameter_within_the_reference():
    """Two candidates, each informative on one of two parameters: D alone shares them
    equally (w = 0.5), which leaves parameter 1 with variance 1/5.5 against the
    reference's 1/6. DC: the D optimum subject to each variance at most 0.95^2 of the
    reference's: analytically w1 = (6 / 0.9025 - 1) / 9 (the constraint active, the
    nearest point to D's optimum). A reference no share can reach (variances 1/12 and
    1/2): the max-min optimum equalises the two ratios, 12 / (9 w + 1) = 2 / (10 - 9 w),
    at w1 = 59/63, t* = 14/11; the design is then the D optimum within the bound
    b = 1.001 t*: parameter 1's constraint active, 12 / (9 w1 + 1) = b."""
    from ema_casadi.design._optimise import WIDTH_RATIO

    Ms = [np.diag([10.0, 1.0]), np.diag([1.0, 10.0])]
    assert optimal_weights(Ms, "D")["w"] == pytest.approx([0.5, 0.5], abs=1e-6)
    got = optimal_weights(Ms, "DC", reference=np.diag([6.0, 2.0]))
    w1 = (6 / WIDTH_RATIO**2 - 1) / 9
    assert got["w"][0] == pytest.approx(w1, abs=1e-6) and got["maxmin"] < WIDTH_RATIO**2
    assert max(got["ratios"]) <= WIDTH_RATIO**2 * (1 + 1e-6)
    far = optimal_weights(Ms, "DC", reference=np.diag([12.0, 2.0]))
    assert far["maxmin"] == pytest.approx(14 / 11, rel=1e-6)
    assert max(far["ratios"]) <= far["bound"] * (1 + 1e-6) and far["bound"] == pytest.approx(14 / 11 * 1.001)
    assert far["w"][0] == pytest.approx((12 / far["bound"] - 1) / 9, abs=1e-6)


def test_efficient_rounding_keeps_the_total_and_the_support():
    n = efficient_rounding([0.5, 0.3, 0.2, 0.0], 10)
    assert n.sum() == 10 and n[3] == 0 and list(n) == [5, 3, 2, 0]
    n = efficient_rounding([0.62, 0.38], 3)
    assert n.sum() == 3 and all(n >= 1)


def test_a_small_design_beats_its_worst_single_segment_and_keeps_the_limits(small):
    assert_glance(small)
    r = small
    assert r.info["ipopt"]["status"] == "Solve_Succeeded"
    assert sum(s["count"] for s in r.segments) == 2
    assert r.usage["stroke"] <= 0.95 and r.usage["current"] <= 1.005
    c = r.comparison()
    assert set(c["parameters"]) == {"F_seal", "psi"} and np.isfinite(c["geometric_mean_ratio"])
    assert abs(r.correlation("F_seal", "psi")) < 1
    assert "| F_seal |" in r.table()


def test_the_design_is_written_in_the_toolkits_layout(small, tmp_path):
    from ema_casadi.design import output_names
    from ema_casadi.signals import parse_signal

    folder = small.write(tmp_path / "out")
    assert sorted(p.name for p in folder.iterdir()) == sorted(output_names())
    rec = small.test.records[0]
    for col, kind in (("x_cmd", "length"), ("f_ext", "force")):  # the table ema simulate plays, read back
        sig = parse_signal(f"{folder / 'design.csv'}:{col}", kind)
        assert np.array_equal(sig(rec["t"]), rec["inputs"][col])


@pytest.mark.parametrize("kwargs, match", [
    ({"free": ["F_seel"]}, "F_seel"),
    ({"duration": 0.5}, "too short for the lowest frequency"),
    ({"criterion": "G"}, "unknown"),
    ({"max_load": 60e3}, "current limit holds"),
    ({"stroke": 0.2}, "travel"),
    ({"weights": {"psi_x": 1.0}}, "psi_x"),
    ({"sigma": {"omega": 0.1}}, "not a measured channel"),
    ({"max_speed": 0.5}, "rated rod speed"),
])
def test_bad_requests_are_refused_before_any_work(params, kwargs, match):
    kw = {"free": ["F_seal", "psi"], "duration": 2.0, **kwargs}
    with pytest.raises(DesignError, match=match):
        design_experiment(params, kw.pop("free"), kw.pop("duration"), **kw)


def test_the_rod_speed_is_bounded_on_the_rods_own_speed(small):
    """The rod speed's use is the predicted rod velocity's peak over the bound (the
    declared rated rod speed by default, ``max_speed`` in its place), not the ECU's
    clipped speed command."""
    model, y = small.model, small.runs[0]["y"]
    from ema_casadi.design import limit_usage

    peak = float(np.max(np.abs(y[model.output_with("rod_velocity")])))
    limit = model.operating_limits()["rod_speed"]
    assert small.info["max_speed"] == limit
    assert small.usage["rod_speed"] == pytest.approx(peak / limit, rel=1e-12)
    half = limit_usage(model, y, model.p(), max_speed=limit / 2)
    assert half["rod_speed"] == pytest.approx(2 * peak / limit, rel=1e-12)


def test_the_standard_test_commands_within_the_speed_bound():
    """Its steps are ramps at STANDARD_SPEED of the bound and the chirp's peak rate is
    below it (a step the rate limiter slews lets the speed loop overshoot the limit)."""
    from ema_casadi.design import STANDARD_SPEED, standard_test

    v = 0.08
    st = standard_test(10.0, 0.01, 15e3, 2000.0, "x_cmd", "f_ext", max_speed=v)
    for rec in st.records:
        rate = np.max(np.abs(np.diff(rec["inputs"]["x_cmd"]) * 2000.0))
        # a ramp's sampled slope is its speed to round-off; the chirp's is below v
        assert rate <= STANDARD_SPEED * v * (1 + 1e-9), (rec["name"], rate)
    assert max(np.max(np.abs(r["inputs"]["x_cmd"])) for r in st.records) == pytest.approx(0.005, rel=1e-9)


def test_a_shape_that_leaves_a_limit_gets_a_candidate_at_the_limits():
    """The largest admissible amplitude scaled until the first use (proportional to the
    amplitude) reaches AIM of its bound; never beyond the inadmissible amplitude above."""
    from ema_casadi.design import AIM, LIMIT_TOLERANCE, STROKE_MARGIN, at_limits

    segs = [Segment("multisine", (1.0, 4.0), 0.0, a) for a in (1e-3, 3e-3, 9e-3)]
    use = [{"stroke": 0.1, "rod_speed": 0.25, "load": 0.0}, {"stroke": 0.3, "rod_speed": 0.75, "load": 0.0},
           {"stroke": 0.9, "rod_speed": 1.2, "load": 0.0}]
    new = at_limits(segs, [(None, u) for u in use])
    # from 3 mm: the rod speed reaches AIM x 1.005 at 3 mm x AIM x 1.005 / 0.75 (the stroke later)
    assert len(new) == 1 and new[0].amplitude == pytest.approx(3e-3 * AIM * LIMIT_TOLERANCE / 0.75, rel=1e-12)
    assert new[0].amplitude < 3e-3 * AIM * STROKE_MARGIN / 0.3
    # every point admissible, or none: nothing to add
    assert at_limits(segs[:2], [(None, u) for u in use[:2]]) == []
    assert at_limits(segs[2:], [(None, u) for u in use[2:]]) == []


def test_a_robust_design_averages_the_information_over_the_prior_and_is_reproducible(params):
    """A prior (name -> estimate and 95 % interval, as a fitted file gives them): the
    design's information is the mean over the draws, not the nominal's; the same seed
    gives the same draws and the same design."""
    lib = [Segment("multisine", (1.0, 8.0), 0.0, 2e-3), Segment("slews", (2, 0.2), 8e3, 4e-3)]
    prior = {"F_seal": (150.0, 100.0, 225.0), "psi": (0.3, 0.27, 0.333)}
    kw = {"library": lib, "rate": 1000.0, "max_load": 8e3, "prior": prior, "draws": 3, "seed": 4}
    a = design_experiment(params, ["F_seal", "psi"], 2.0, **kw)
    b = design_experiment(params, ["F_seal", "psi"], 2.0, **kw)
    assert len(a.thetas) == 3 and np.array_equal(np.array(a.thetas), np.array(b.thetas))
    assert np.array_equal(a.M, b.M) and a.segments == b.segments
    # the draws' spread is the prior's: log(hi/lo)/(2 x 1.96)
    assert a.info["prior_sd"]["F_seal"] == pytest.approx(math.log(2.25) / 3.919927969, rel=1e-6)
    nominal = design_experiment(params, ["F_seal", "psi"], 2.0, library=lib, rate=1000.0, max_load=8e3)
    assert not np.allclose(a.M, nominal.M, rtol=1e-3)



def test_a_candidate_counted_after_its_lead_in_adds_up_to_a_test_of_its_copies(model_cache):
    """Three copies of a loaded segment in a row: the information of the test is the
    first copy's (from rest, the load ramped from zero) plus twice the copy counted after
    a lead-in of itself, to the integrator's tolerance (measured 1e-4 relative); three
    copies each counted from rest overstate what the test holds: under a constant load
    the backlash stays closed (only the ramp from zero crosses it: 3x, measured 3.000)
    and the rod's deflection does not change (the stiffness 2.2x, measured 1/0.462)."""
    model = model_cache()
    fr = free_parameters(model, ["F_seal", "C", "B"])
    seg = Segment("multisine", (4.0, 16.0), 15e3, 3e-3)

    def info(n, lead_in=0.0):
        return information(model, realise([seg] * n, 1.0, 2000.0, "x_cmd", "f_ext"), fr, SIGMA,
                           lead_in=lead_in).M

    first, counted, three = info(1), info(2, lead_in=1.0), info(3)
    assert np.allclose(np.diag(three), np.diag(first + 2 * counted), rtol=1e-3), (np.diag(three),
                                                                                  np.diag(first + 2 * counted))
    over = np.diag(3 * first) / np.diag(three)
    assert over[1] > 2.0 and over[2] == pytest.approx(3.0, rel=1e-3), over


def test_a_steps_segment_rests_its_share_of_the_time_between_moves_at_constant_speed():
    """``steps`` (n, r): n moves between -A and +A, the command at rest (speed 0) a share
    r of the time, each move at one constant speed but for its rise from rest; the peak
    is A (the taper at either end only lowers what lies within it)."""
    from ema_casadi.design import TAPER, segment_command

    t = np.arange(20001) / 20000.0
    x = segment_command(Segment("steps", (4, 0.8), 0.0, 5e-3), t, 1.0)
    inner = (t > TAPER) & (t < 1 - TAPER)
    v = np.gradient(x, t)[inner]
    rest = np.abs(v) < 1e-9
    # the rests straddle the taper's ends, so the share inside is r to a few samples
    assert np.mean(rest) == pytest.approx(0.8, abs=0.03)
    speed = np.max(np.abs(v))
    moving = np.abs(v[~rest])
    assert np.mean(moving > 0.99 * speed) > 0.8  # constant speed but for the rises
    assert np.max(np.abs(x)) == pytest.approx(5e-3, rel=1e-3)


@pytest.mark.slow
def test_verification_is_the_same_on_one_and_on_two_workers(small):
    """Each simulated test and its fit are computed from its index alone (its noise and
    start seeded by it): the fits on two workers equal those on one, bit for bit (the
    estimates, costs and messages the report derives from). ~90 s under load."""
    one = small.verify(3, seed=4, jobs=1)
    two = small.verify(3, seed=4, jobs=2)
    assert one["fits"] == two["fits"] and one["converged"] == 3
