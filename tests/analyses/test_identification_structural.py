"""The structural (type B) uncertainty of ``identify(structural=...)``
(:mod:`ema_casadi.identification._structural`): a constant the fit holds, given a
plausible range, widens the headline intervals by the estimates' linearised shift over
that range, added in quadrature; nothing changes without it."""

from __future__ import annotations

import numpy as np
import pytest

from ema_casadi import identification as idn

FREE = ["F_seal", "J_m"]
SIGMA = {"x_rod": 0.3e-6, "i_q": 0.05}


@pytest.fixture(scope="module")
def record(params, tmp_path_factory):
    """A 5 mm slew at the rate limit under +8 kN (the screw changes between driving and
    back-driving at its start and stop: where the efficiency switch's width P_blend acts)."""
    path = tmp_path_factory.mktemp("structural") / "slew.csv"
    return idn.synthetic_record(params, path, t_end=0.3, x_cmd="step:5mm@0.05", f_ext="step:8kN@0.01",
                                truth={"F_seal": 225.0, "J_m": 1.44e-3}, seed=2)


@pytest.fixture(scope="module")
def fits(params, record):
    plain = idn.identify(params, [record], FREE, sigma=SIGMA)
    typeb = idn.identify(params, [record], FREE, sigma=SIGMA, structural={"P_blend": (0.08, 0.125)})
    return plain, typeb


def test_the_type_b_term_adds_in_quadrature(fits):
    """Same estimates (the term is an uncertainty, not a correction); each parameter's
    headline variance is the robust one plus its type-B variance (the docs' C = S^2
    C_HAC + C_B), to rounding."""
    plain, typeb = fits
    assert "structural" not in plain.robust
    sd_b = typeb.robust["structural_relative_sd"]
    for n in FREE:
        assert typeb.estimate[n] == pytest.approx(plain.estimate[n], rel=1e-12)
        rel_plain = plain.std[n] / plain.estimate[n]
        rel_typeb = typeb.std[n] / typeb.estimate[n]
        assert rel_typeb**2 == pytest.approx(rel_plain**2 + sd_b[n] ** 2, rel=1e-9), n
        assert sd_b[n] > 0


def test_the_linearised_shift_matches_refits(params, record, fits):
    """The estimates' shift across the range (P_blend 0.08 to 0.125 W, about 0.1 W by
    a factor 1.25 either way) against an independent computation: the fit redone at
    each end. The secant over the two ends cancels the curvature to first order; the
    Gauss-Newton step neglects the residuals' second derivatives (sum r d2r), which
    measured 11 % of F_seal's shift on this 0.3 s record (-0.148 % for -0.166 %): within
    20 %, or 2 % of the estimate's sd."""
    _, typeb = fits
    doc = typeb.robust["structural"]["P_blend"]
    assert doc["range"] == [0.08, 0.125] and doc["value"] == pytest.approx(0.1)
    # E[u^2] of a uniform u over [log 0.8, log 1.25]: (a^2 + ab + b^2) / 3
    a, b = np.log(0.8), np.log(1.25)
    assert doc["rms_coordinate"] == pytest.approx(np.sqrt((a * a + a * b + b * b) / 3), rel=1e-12)
    ends = [idn.identify(params.replace(P_blend=v), [record], FREE, sigma=SIGMA) for v in doc["range"]]
    for n in FREE:
        real = ends[1].estimate[n] / ends[0].estimate[n] - 1
        lin = doc["shift_at_ends"][n][1] - doc["shift_at_ends"][n][0]
        tol = max(0.20 * abs(real), 0.02 * typeb.std[n] / typeb.estimate[n])
        assert abs(lin - real) <= tol, (n, lin, real)


@pytest.mark.parametrize("structural, words", [
    ({"F_seal": (100.0, 300.0)}, "is free"),
    ({"P_blend": (0.2, 0.3)}, "strictly inside"),
    ({"P_blend": (0.0, 0.2)}, "LO must be > 0"),
    ({"P_blendd": (0.05, 0.2)}, "did you mean"),
])
def test_a_bad_range_is_refused_before_any_fit(params, record, structural, words):
    with pytest.raises(idn.IdentificationError, match=words):
        idn.identify(params, [record], FREE, sigma=SIGMA, structural=structural)
