"""Consistency between records: each record re-fitted alone against all together."""

import numpy as np
import pytest

import ema_casadi as ema
from ema_casadi.cli._identify_text import fit_text
from ema_casadi.identification import example_records
from ema_casadi.identification._misfit import verdict
from ema_casadi.identification._residual_tests import MISFIT_P
from ema_casadi.identification._synthetic import EXAMPLE_TRUTH, synthetic_record

SIGMA = {"x_rod": 3e-7, "i_q": 0.05}


def _realisations(tmp_path, n, sigma):
    p = ema.load_parameters()
    out = []
    for k in range(n):
        folder = tmp_path / f"r{k}"
        folder.mkdir()
        paths, truth = example_records(p, folder, seed=100 + 7 * k)
        res = ema.identify(p, paths, list(truth), sigma=sigma)
        out.append({**res.adequacy["consistency"], "adequate": res.adequacy["adequate"]})
    return out


def _check_calibrated(tests):
    """No false alarm at the test's level, and the statistic's mean at its expectation:
    over n realisations the mean of a chi-square(h) scatters by sqrt(2 h / n); 3 of
    those allowed (measured over 20 given-noise fits: mean 3.1 for an expectation 4.0).
    The whole fit (chi-square, whiteness and consistency together) adequate in at
    least 95 % of the realisations (measured: all 20 given-noise, 49 of 50 estimated)."""
    assert np.mean([t["adequate"] for t in tests]) >= 0.95
    p = np.array([t["p"] for t in tests])
    assert np.all(p >= MISFIT_P), p
    T = np.array([t["statistic"] for t in tests])
    a, h = tests[0]["expected"], tests[0]["dof"]
    assert abs(a - 4.0) < 0.05 and abs(h - 4.0) < 0.05  # 2 records x 4 parameters each determines: (2-1) x 4
    assert abs(T.mean() - a) < 3 * np.sqrt(2 * h / len(T)), (T.mean(), a)
    assert T.min() >= -1e-6  # a re-fit alone never fits its record worse


@pytest.mark.slow  # 38 s on 2 loaded workers: 20 fits; the single-realisation checks above stay fast
def test_no_false_alarm_over_20_realisations(tmp_path):
    _check_calibrated(_realisations(tmp_path, 20, SIGMA))


@pytest.mark.slow
def test_no_false_alarm_over_50_realisations_noise_estimated(tmp_path):
    _check_calibrated(_realisations(tmp_path, 50, None))


def test_records_that_disagree_are_reported(tmp_path):
    """The chirp record's actuator has 2 % more seal friction (4 N) than the step
    record's: each record alone is explained by the noise, the joint fit's residuals
    pass the chi-square and whiteness tests (measured), and only the consistency test
    finds it (measured statistic 26 for an expectation of 4, p = 3e-5). The effect is
    below the noise and the records' estimates differ by 2.5 robust sd (RMS over the
    four directions each determines), under the 5 sd the default model error allows:
    *adequate within model error*, the intervals inflated by the scale factor of the
    records' parts, S^2 = 1 + (G + 1) tau^2 (> 1: the parts disagree, p < 0.05); with
    --model-error 0.4 (2 sd allowed) inadequate."""
    p = ema.load_parameters()
    truth = dict(EXAMPLE_TRUTH)
    a = synthetic_record(p, tmp_path / "steps.csv", t_end=1.0, x_cmd="step:1mm@0.05+step:-2mm@0.5",
                         truth=truth, seed=5)
    b = synthetic_record(p, tmp_path / "chirp.csv", t_end=1.0, x_cmd="chirp:0.5mm@1-20", f_ext="step:5kN@0.1",
                         truth=dict(truth, F_seal=1.02 * truth["F_seal"]), seed=6)
    res = ema.identify(p, [a, b], list(truth), sigma=SIGMA)
    test = res.adequacy["consistency"]
    assert not test["consistent"] and test["p"] < MISFIT_P
    assert res.adequacy["verdict"] == "adequate within model error" and res.adequacy["adequate"]
    assert [r for r in res.adequacy["reasons"] if not r.startswith("records disagree")] == []
    line = res.adequacy["reasons"][-1]
    assert "records disagree" in line and (".csv" in line)
    rob = res.robust
    parts = rob["parts"]
    assert rob["scale_factor"] == pytest.approx(np.sqrt(1 + (parts["count"] + 1) * rob["tau2"]), rel=1e-12)
    assert parts["p"] < 0.05 and rob["tau2"] > 0 and rob["scale_factor"] > 1.2 and rob["records_dof"] == 8
    for n in truth:  # the headline interval carries the scale factor over the (white-noise) sandwich
        (lo, hi), (lo_tb, hi_tb) = res.interval[n], res.interval_textbook[n]
        assert hi - lo > 1.1 * (hi_tb - lo_tb), n
    strict = verdict({k: v for k, v in res.adequacy.items() if k in ("adequate", "reasons")} | {"adequate": False},
                     res.misfits, {"records": [{"shift_sd": r["shift_sd"]} for r in rob["records"]]}, 0.4)
    assert strict["verdict"] == "inadequate" and "robust sd" in strict["reasons"][0]
    doc = res.to_dict()
    assert doc["verdict"] == "adequate within model error" and doc["consistency"]["records"][0]["directions"] == 4
    text = fit_text(doc)  # the command's report names the factor and the parts' test
    assert f"scale factor {rob['scale_factor']:.3g}: the records' {parts['count']} parts disagree" in text
    for r in test["records"]:  # each record's own estimates and how far they are from the joint ones
        assert set(r["estimate_alone"]) == set(truth) and set(r["shift_sd"]) == set(truth)
    assert sum(r["contribution"] for r in test["records"]) == pytest.approx(test["statistic"])
    # one record: nothing to test
    one = ema.identify(p, [a], ["F_seal", "J_m"], sigma=SIGMA)
    assert one.adequacy.get("consistency") is None
