"""``identify(method=...)``: single shooting, multiple shooting and collocation over the
records (the optimisation layer's transcriptions, finished by single shooting), and
``auto``'s fallback; bad requests refused before any fit."""

from __future__ import annotations

import pytest

import ema_casadi as ema
from ema_casadi.identification import FitFailed, IdentificationError, _fit, synthetic_record
from ema_casadi.identification._methods import grid

SIGMA = {"x_rod": 3e-7, "i_q": 0.05}
TRUTH = {"F_seal": 210.0, "J_m": 1.5e-3, "psi": 0.24}


@pytest.fixture(scope="module")
def step(params, tmp_path_factory):
    """50 ms of a 0.1 mm step at 2 kHz (101 samples), noise-free: the collocation NLP
    stays small (100 intervals)."""
    path = tmp_path_factory.mktemp("methods") / "step.csv"
    return synthetic_record(params, path, t_end=0.05, x_cmd="step:0.1mm@0.01", truth=TRUTH,
                            noise={"x_rod": 1e-12, "i_q": 1e-12})


@pytest.mark.parametrize("kw, words", [
    ({"method": "shooting"}, ["method", "'shooting'", "auto, single, multiple, collocation"]),
    ({"method": "collocation", "nodes": 0}, ["nodes", "at least one per record"]),
    ({"method": "multiple", "nodes": 2.5}, ["nodes"]),
])
def test_bad_requests_are_refused_before_any_fit(params, step, monkeypatch, kw, words):
    def no_fit(*a, **k):
        raise AssertionError("a fit ran")

    monkeypatch.setattr(_fit, "_best_start", no_fit)
    monkeypatch.setattr(_fit, "transcribed_fit", no_fit)
    with pytest.raises(IdentificationError) as err:
        ema.identify(params, [step], list(TRUTH), sigma=SIGMA, **kw)
    assert all(w in str(err.value) for w in words), err.value


def test_the_grid_ends_on_samples_and_covers_the_record(params, step):
    """The default grid: one interval per 0.5 ms (a sample at 2 kHz), first and last
    sample included; more nodes than samples are capped at one interval per sample."""
    from ema_casadi.identification import read_record

    rec = read_record(step, ema.build_model(params))
    idx = grid(rec, None)
    assert idx[0] == 0 and idx[-1] == rec.n - 1 and len(idx) - 1 == 100
    assert len(grid(rec, 10)) == 11
    assert len(grid(rec, 10_000)) == rec.n


def test_collocation_finished_by_single_shooting_gives_the_single_shooting_fit(params, tmp_path):
    """Collocation over a 50 ms step record with sensor noise, from the true values:
    IPOPT converges (measured: 11 iterations, 1.2 s) and the single-shooting finish from
    its estimate gives the single-shooting fit's estimates within a tenth of their
    95 % half-widths (the same optimum of the same cost, each stopped within 0.045 sd
    of it; measured 0.024 of the half-widths)."""
    path = synthetic_record(params, tmp_path / "noisy.csv", t_end=0.05, x_cmd="step:0.1mm@0.01", truth=TRUTH, seed=2)
    single = ema.identify(params, [path], list(TRUTH), sigma=SIGMA, start=TRUTH)
    coll = ema.identify(params, [path], list(TRUTH), sigma=SIGMA, start=TRUTH, method="collocation")
    assert single.info["method"] == "single" and coll.info["method"] == "collocation"
    tried = coll.info["methods"][-1]
    assert tried["method"] == "collocation" and tried["outcome"] == "converged", tried
    assert tried["ipopt_status"] in ("Solve_Succeeded", "Solved_To_Acceptable_Level") and tried["nodes"] == [100]
    for n in TRUTH:
        lo, hi = single.interval[n]
        assert abs(coll.estimate[n] - single.estimate[n]) < 0.1 * (hi - lo) / 2, n
    assert coll.adequacy["adequate"] == single.adequacy["adequate"]


def test_auto_falls_back_to_collocation_and_says_what_each_method_did(params, step):
    """Single shooting held to 2 evaluations does not converge; ``auto`` then runs
    collocation, whose finish is held to the same budget and fails too: the failure
    names both (a grid of 5 intervals keeps the NLP small; its outcome does not matter
    here)."""
    with pytest.raises(FitFailed) as err:
        ema.identify(params, [step], list(TRUTH), sigma=SIGMA, method="auto", max_evaluations=2,
                     start={"F_seal": 150.0}, nodes=5)
    assert "did not converge" in err.value.reason and "collocation" in err.value.reason, err.value.reason
    assert err.value.to_dict()["converged"] is False


def test_auto_keeps_single_shooting_where_it_converges(params, step):
    """From the true values single shooting converges to an adequate fit: ``auto``
    stops there (no transcription is built)."""
    res = ema.identify(params, [step], list(TRUTH), sigma=SIGMA, method="auto", start=TRUTH)
    assert res.adequacy["adequate"]
    assert res.info["method"] == "single" and res.info["methods"] == [{"method": "single", "outcome": "converged"}]
    assert all(abs(res.estimate[n] / v - 1) < 1e-3 for n, v in TRUTH.items())
