"""Coverage of the headline (robust) 95 % intervals over 50 noise realisations
(studies/coverage.py): with the model right, and under a small model error (a witness
with a twice wider efficiency switch, simulated by RK4 at 2 us). Slow: 100 fits of
five parameters on four records of 0.6-1 s (about 10 s each on one core; the witness
half measured 434 s on the loaded 2-core machine). The witness's RK4 step is above the
stability limit of the rod held under load (a StepLimitWarning, expected: its chatter
is part of the model error).

Tolerances: with 50 realisations a true 95 % coverage gives 43 or more hits with
probability 0.99 (binomial), so a share below 0.86 is a real shortfall."""

from __future__ import annotations

import sys

import pytest

from conftest import ROOT

sys.path.insert(0, str(ROOT / "studies"))
import coverage as study  # noqa: E402

pytestmark = pytest.mark.slow

LOW = 0.86  # 43 of 50 (module docstring)


@pytest.fixture(scope="module")
def right(params):
    return study.coverage(params, model="right", n=50, progress=False)


@pytest.fixture(scope="module")
def witness(params):
    return study.coverage(params, model="witness", n=50, progress=False)


def test_no_loss_when_the_model_is_right(right):
    """Robust and textbook intervals agree within 20 % (median width ratio; measured
    0.93-1.01) and both cover the truth in 86-100 % of the realisations for every
    parameter (measured 90-98 % and 88-98 %); 95 % of the fits or more adequate
    (measured 50 of 50)."""
    for k in study.TRUTH:
        assert 0.8 <= right["width_ratio"][k] <= 1.2, (k, right["width_ratio"])
        assert right["coverage"][k] >= LOW, (k, right["coverage"])
        assert right["coverage_textbook"][k] >= LOW, (k, right["coverage_textbook"])
    assert right["exit0"] >= 0.95 and right["failed"] == 0, right


def test_a_small_model_error_ends_with_exit_0_and_wider_intervals(witness):
    """The witness's systematic misfit is below the noise (0.7 noise levels at most):
    95 % of the fits or more end with exit 0 (measured 50 of 50, adequate within model
    error), and the robust intervals are wider than the textbook ones (measured
    2.8-4.2x; allowed > 1.5x), which miss the truth (textbook coverage 0-84 %)."""
    assert witness["exit0"] >= 0.95 and witness["failed"] == 0, witness
    for k in study.TRUTH:
        assert witness["width_ratio"][k] > 1.5, (k, witness["width_ratio"])
        assert witness["coverage"][k] >= witness["coverage_textbook"][k], k


@pytest.mark.parametrize("name", list(study.TRUTH))
def test_robust_coverage_under_a_small_model_error(witness, name):
    if name == "F_seal":
        pytest.xfail("F_seal: the witness's wider efficiency switch biases it by -1.3 % in every record alike; "
                     "neither the sandwich nor the records' scale factor can see a bias the records share "
                     "(measured coverage 18 %; docs/guide/model-error.md)")
    assert witness["coverage"][name] >= LOW, witness["coverage"]
