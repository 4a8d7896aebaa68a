"""The acceptance case of experiment design (slow: the design ~20 s of CPU, twice; 20
fits of the designed 10 s record and 20 of the standard test's four, ~5 min of CPU):
the reference set, the seven parameters, a 10 s test within +-10 mm, I_max and a 15 kN
load capability."""

import numpy as np
import pytest

from ema_casadi.design import admissible, design_experiment

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def design(params):
    return design_experiment(params)


def test_the_design_beats_the_standard_test_and_pins_inertia_and_flux_down(design):
    c = design.comparison()
    assert c["geometric_mean_ratio"] >= 2.0, design.table()  # measured 2.79
    # measured: J_m 6.49x, psi 10.6x narrower than the standard test's (their correlation
    # 0.92 against the standard's 0.90: DC spends on F_seal what D spent on separating them)
    assert c["parameters"]["J_m"]["ratio"] >= 5 and c["parameters"]["psi"]["ratio"] >= 5, design.table()
    assert design.usage["stroke"] <= 0.95 and design.usage["current"] <= 1.005 and design.usage["load"] <= 1.0
    assert design.info["ipopt"]["status"] == "Solve_Succeeded"
    # DC: every parameter's predicted interval within the standard test's (measured: the
    # widest, F_seal, 0.957 x it; 1.64 x before the candidates were counted after a
    # lead-in and the library held stop-and-go steps)
    assert design.info["reference"]["width_ratio_realised"] <= 1.0, design.info["reference"]
    # every declared rating and the test's limits, on the designed and the standard test
    rated = {r.name for r in design.model.ratings if r.role == "rating" and r.sense != "min"}
    assert rated <= set(design.usage) and "rod_speed" in rated
    assert admissible(design.usage), design.usage
    assert admissible(design.info["standard_usage"]), design.info["standard_usage"]


def test_a_rod_speed_bound_below_the_rate_limit_changes_the_design(params, design):
    """--max-speed 80 mm/s (the ECU's rate limit on the rod itself): the designed and the
    standard test keep the rod below it, and the design is another one."""
    slow = design_experiment(params, max_speed=0.08)
    assert slow.usage["rod_speed"] <= 1.005 and slow.info["standard_usage"]["rod_speed"] <= 1.005
    assert design.usage["rod_speed"] * design.info["max_speed"] > 0.08  # the default lets it overshoot
    assert slow.segments != design.segments


@pytest.fixture(scope="module")
def verified(design):
    return design.verify(20, seed=0)


def test_verify_20_realises_the_predicted_intervals_within_the_limits(design, verified):
    v = verified
    assert v["converged"] == 20, v["failed"]
    # measured: 20 of 20 adequate from their 5 % starts, none refitted (with the library
    # before the steps and the lead-in, 2 of 20 ended in a local minimum and were refitted)
    assert v["restarted"] <= 4 and v["adequate"] >= 19, v["fits"]
    ratios = np.array(list(v["width_ratio"].values()))
    # the median realised robust width over the predicted: measured 0.998-1.011 (each fit
    # 0.905-1.134 where its scale factor is 1; 3 of 20 fits have S = 2.2-2.4, the model-
    # error test's false alarms, which pull the mean to 1.18); 10 %
    assert np.all(np.abs(ratios - 1) <= 0.1), v["width_ratio"]
    assert v["limits_respected"], v["limits_used"]
    # the true trajectory (every simulated test's: the noise is the sensors') against every
    # declared rating (current, voltage, rod speed, the actuator's stroke) and the test's own
    rated = {r.name for r in design.model.ratings if r.role == "rating" and r.sense != "min"}
    assert rated | {"stroke", "load"} <= set(v["limits_used"]), v["limits_used"]


def test_verify_20_the_design_is_no_wider_than_the_standard_test(verified):
    """The acceptance: realised widths (median over 20 fits each) of the designed test
    at most 1.1 x the standard test's (chirp, steps, slews under +7.5 and -15 kN) for
    every parameter, and 2 x narrower in geometric mean. Measured: F_seal 1.018 (the
    widest; the standard test's realised F_seal is 0.94 x its predicted, the designed
    one's 1.00 x), B 0.944, the others 0.10-0.52; geometric mean 2.71 x (by the means
    of the widths, F_seal 1.18 x and 2.31 x: the designed test's three false alarms of
    the scale factor, none among the standard test's fits)."""
    v = verified
    assert v["standard"]["converged"] == 20, v["standard"]["failed"]
    assert max(v["against_standard"].values()) <= 1.1, v["against_standard"]
    assert v["geometric_mean_ratio"] >= 2.0, v["geometric_mean_ratio"]


def test_verify_20_covers_the_truth(verified):
    """Every converged fit's 95 % intervals (after the restarts) hold the truth in 90-99 %
    of the cases. With 20 fits x 7 parameters = 140 intervals of true level 95 %, misses
    are binomial (mean 7, sd 2.6) if independent: below 90 % (15 or more) has probability
    0.4 %, above 99 % (at most 1) 0.6 %; the correlation of the parameters within a fit
    (|corr| up to 0.9) widens that somewhat. Measured: 95.7 % (134 of 140; textbook
    94.3 %; per parameter 90-100 %, B lowest)."""
    assert verified["intervals_checked"] >= 133, verified["intervals_checked"]
    assert 0.90 <= verified["coverage"] <= 0.99, (verified["coverage"], verified["coverage_per_parameter"])
