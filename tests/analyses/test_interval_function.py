"""The public symbolic interval integrator (multiple shooting): its state after an
interval agrees with the toolkit's own variable-step simulation, and its derivatives are exact."""

import casadi as ca
import numpy as np
import pytest

import ema_casadi as ema
from ema_casadi.simulation import SimulationError, interval_function


@pytest.fixture(scope="module")
def model():
    return ema.build_model(ema.load_parameters("models/cesa_ema.toml"), {"motor": "dc", "screw": "elastic"})


def test_matches_simulate(model):
    # 20 intervals of 1 ms under a 1 mm step command, cascade in the loop, against RODAS4 at rtol 1e-8
    F = interval_function(model, substeps=100)  # 10 us substeps, the rk4 default step
    p, u = model.p(), model.u(x_cmd=1e-3)
    x = model.x0()
    for _ in range(20):
        x = np.array(F(x, u, p, 1e-3)).ravel()
    res = ema.simulate(model, 0.02, x_cmd=1e-3, solver="rosenbrock", rtol=1e-8, atol=1e-12, dt_out=1e-3)
    x_ref = np.array([res[n][-1] for n in model.states])
    err = np.abs(x - x_ref) / model.full_scale()
    # RK4 at 10 us against RODAS4: measured 4.4e-7 of full scale (the rod at 0.87 mm of 1 mm); bound x25
    assert err.max() < 1e-5, dict(zip(model.states, err, strict=True))


def test_derivatives_exact(model):
    # the Jacobian w.r.t. dt against a central difference (step 1e-7 s): measured 4.7e-9 relative, bound x20
    F = interval_function(model, substeps=100)
    p, u, x0 = model.p(), model.u(x_cmd=1e-3), model.x0()
    dt = ca.MX.sym("dt")
    J = ca.Function("J", [dt], [ca.jacobian(F(x0, u, p, dt), dt)])
    d = 1e-7
    fd = (np.array(F(x0, u, p, 1e-3 + d)) - np.array(F(x0, u, p, 1e-3 - d))).ravel() / (2 * d)
    ad = np.array(J(1e-3)).ravel()
    scale = np.abs(ad).max()
    assert np.abs(ad - fd).max() < 1e-7 * scale


def test_held_and_refusals(model):
    F = interval_function(model, held=True)
    assert F.name_in() == ["x", "u", "p", "h", "dt"]
    hybrid = ema.build_model(ema.load_parameters("models/cesa_ema.toml"), {"friction": "hybrid"})
    with pytest.raises(SimulationError, match="hybrid"):
        interval_function(hybrid)
    with pytest.raises(SimulationError, match="substeps"):
        interval_function(model, substeps=0)
