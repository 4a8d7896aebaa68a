"""Coverage of the headline (robust) 95 % intervals over 50 noise realisations
(studies/coverage.py; the table in docs/guide/model-error.md): with the model right,
and under small model errors, each alone: a witness with a twice wider efficiency
switch (``blend``: P_blend 0.2 W for 0.1 W), fitted plainly and with the switch's
width declared as a structural constant (``--structural P_blend=0.05:0.2``, the
type-B term); witnesses simulated by fixed-step RK4 at 2 us (``rk4``, above its
stability limit on the rod held under load: a StepLimitWarning, expected, its chatter
is part of the model error) and at 1 us (inside it); and LuGre friction on the smooth
law's steady-state curve at two bristle stiffnesses. Slow: 350 fits of five
parameters on four records of 0.6-1 s (about 1-2 s of CPU each).

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
BLEND_RANGE = {"P_blend": (0.05, 0.2)}


@pytest.fixture(scope="module")
def right(params):
    return study.coverage(params, model="right", n=50, progress=False)


@pytest.fixture(scope="module")
def blend(params):
    return study.coverage(params, model="blend", n=50, progress=False)


@pytest.fixture(scope="module")
def blend_typeb(params):
    return study.coverage(params, model="blend", n=50, structural=BLEND_RANGE, progress=False)


@pytest.fixture(scope="module")
def rk4(params):
    return study.coverage(params, model="rk4", n=50, progress=False)


def test_no_loss_when_the_model_is_right(right):
    """Robust and textbook intervals agree within 20 % (median width ratio; measured
    0.90-1.00) and both cover the truth in 86-100 % of the realisations for every
    parameter (measured 88-98 % both); 95 % of the fits or more adequate (measured 50
    of 50)."""
    for k in study.TRUTH:
        assert 0.8 <= right["width_ratio"][k] <= 1.2, (k, right["width_ratio"])
        assert right["coverage"][k] >= LOW, (k, right["coverage"])
        assert right["coverage_textbook"][k] >= LOW, (k, right["coverage_textbook"])
    assert right["exit0"] >= 0.95 and right["failed"] == 0, right


@pytest.mark.parametrize("witness", ["blend", "blend_typeb", "rk4"])
def test_a_small_model_error_ends_with_exit_0_and_wider_intervals(witness, request):
    """Each witness's systematic misfit is below the noise (0.66 noise levels, the wider
    switch; 0.27 RK4; medians over the fits): 95 % of the fits or more end with exit 0
    (measured 50 of 50, adequate within model error), and the robust intervals are
    wider than the textbook ones (measured 3.9-5.9x; allowed > 1.5x), which miss the
    truth (textbook coverage 0-98 %)."""
    doc = request.getfixturevalue(witness)
    assert doc["exit0"] >= 0.95 and doc["failed"] == 0, doc
    for k in study.TRUTH:
        assert doc["width_ratio"][k] > 1.5, (k, doc["width_ratio"])
        assert doc["coverage"][k] >= doc["coverage_textbook"][k], k


@pytest.mark.parametrize("name", list(study.TRUTH))
def test_robust_coverage_under_a_wider_efficiency_switch(blend, blend_typeb, name):
    """The wider switch alone: covered in 86 % or more (measured 100 % for every
    parameter: the parts' scale factor, conservative); with its width declared (type B)
    every interval is at least as wide (F_seal's measured 5.7x the textbook one against
    5.5x) and covers too (measured 100 %)."""
    assert blend["coverage"][name] >= LOW, blend["coverage"]
    assert blend_typeb["coverage"][name] >= LOW, blend_typeb["coverage"]
    assert blend_typeb["width_ratio"][name] >= blend["width_ratio"][name] * (1 - 1e-9), name


@pytest.mark.parametrize("name", list(study.TRUTH))
def test_robust_coverage_under_a_coarse_rk4_step(rk4, name):
    """RK4 at 2 us: its chatter of the held rod under load biases F_seal by -0.5 % in the
    loaded records; the parts of the records disagree, and the scale factor (median 4.9)
    covers it (measured 100 % for every parameter: conservative)."""
    assert rk4["coverage"][name] >= LOW, rk4["coverage"]


@pytest.fixture(scope="module")
def lugre_1e10(params):
    return study.coverage(params, model="lugre_smooth_1e10", n=50, progress=False)


@pytest.fixture(scope="module")
def lugre_1e11(params):
    return study.coverage(params, model="lugre_smooth_1e11", n=50, progress=False)


@pytest.fixture(scope="module")
def rk4_1us(params):
    return study.coverage(params, model="rk4_1us", n=50, progress=False)


@pytest.mark.parametrize("name", list(study.TRUTH))
def test_robust_coverage_under_rk4_inside_its_stability_limit(rk4_1us, name):
    """RK4 at 1 us (0.07 noise levels of misfit): covered as with the model right
    (measured 90-98 %), every fit adequate (50 of 50)."""
    assert rk4_1us["exit0"] >= 0.95 and rk4_1us["failed"] == 0, rk4_1us
    assert rk4_1us["coverage"][name] >= LOW, rk4_1us["coverage"]


@pytest.mark.parametrize("name", list(study.TRUTH))
def test_robust_coverage_under_lugre_bristles(lugre_1e10, lugre_1e11, name):
    """LuGre on the smooth law's curve: every fit ends with exit 0 (measured 50 of 50 for
    both stiffnesses) and every parameter is covered. At sigma_0 = 1e10 N/m (0.14 noise
    levels) the bristles' compliance at rest biases F_seal and C by about 1.8 and 1.6
    textbook sd alike in every record; the records' parts disagree (the test fires in
    42 of 50) and the scale factor covers them (measured 92-98 %; 93.5-98.5 % over 200
    realisations). At 1e11 (0.08 noise levels) covered as with the model right
    (measured 88-96 %; 93-96.5 % over 200)."""
    for doc in (lugre_1e10, lugre_1e11):
        assert doc["exit0"] >= 0.95 and doc["failed"] == 0, doc
        assert doc["coverage"][name] >= LOW, (doc["model"], doc["coverage"])
