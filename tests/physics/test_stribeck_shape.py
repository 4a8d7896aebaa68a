"""The Stribeck hump's shape exponent ``delta_st``: h(v) = exp(-(|v|/v_st)^delta_st),
2 the Gaussian hump (the default, written as before), 1 the exponential one. Checked
against the formula evaluated independently in NumPy, and for finite derivatives at
rest, where |v|^delta has a kink."""

import math
from types import SimpleNamespace

import casadi as ca
import numpy as np
import pytest

import ema_casadi as ema
from ema_casadi.model.components.friction import stribeck_hump


@pytest.mark.parametrize("delta", [2.0, 1.0, 0.7])
def test_the_hump_is_the_generalised_stribeck_curve(delta):
    """Against exp(-(|v|/v_st)^delta) to 1e-15 relative (round-off of a few operations),
    symbolic exponent and numeric alike."""
    v_st = 1.5e-3
    v = np.array([-4e-3, -1.5e-3, -1e-5, 0.0, 1e-9, 7e-4, 1.5e-3, 6e-3])
    want = np.exp(-((np.abs(v) / v_st) ** delta))
    vs, d = ca.SX.sym("v"), ca.SX.sym("d")
    f = ca.Function("h", [vs, d], [stribeck_hump(vs, SimpleNamespace(v_st=v_st, delta_st=d))])
    got = np.array([float(f(x, delta)) for x in v])
    num = np.array([float(ca.DM(stribeck_hump(x, SimpleNamespace(v_st=v_st, delta_st=delta)))) for x in v])
    assert got == pytest.approx(want, rel=1e-15, abs=1e-300)
    assert num == pytest.approx(want, rel=1e-15, abs=1e-300)
    assert got[3] == 1.0 and got[6] == pytest.approx(math.exp(-1.0), rel=1e-15)


def test_the_derivatives_are_finite_at_rest():
    """d h/d v and d h/d delta at v = 0 for delta = 1 (the exponential hump's kink): finite,
    d h/d delta = 0 there (h = 1 whatever delta) but for the floor 1e-300 times its log."""
    vs, d = ca.SX.sym("v"), ca.SX.sym("d")
    h = stribeck_hump(vs, SimpleNamespace(v_st=1e-3, delta_st=d))
    J = ca.Function("J", [vs, d], [ca.jacobian(h, ca.vertcat(vs, d))])
    for delta in (1.0, 2.0, 1.5):
        got = np.array(J(0.0, delta)).ravel()
        assert np.all(np.isfinite(got)) and abs(got[1]) < 1e-290  # the floor 1e-300 times its log


def test_a_model_with_the_exponential_hump_runs_and_sticks_harder(params):
    """stribeck = on with delta_st = 1 against 2: the same breakaway at rest, a lower
    friction at speed (exp(-x) < exp(-x^2) for x > 1), so under the same slow command
    the rod is not held back more; both runs finite."""
    model = ema.build_model(params, {"stribeck": "on"})
    out = {}
    for delta in (1.0, 2.0):
        res = ema.simulate(model, 0.2, p=params.vector(delta_st=delta), x_cmd="step:0.2mm@0.01", dt_out=1e-3)
        assert np.all(np.isfinite(res["x_rod"]))
        out[delta] = res
    assert float(out[1.0]["x_rod"][-1]) == pytest.approx(float(out[2.0]["x_rod"][-1]), abs=2e-6)
