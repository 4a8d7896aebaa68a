"""The optimisation layer on problems with known answers: the IPOPT wrapper (status, log,
fallback chain, warm start, interrupt between iterations), least squares (LM, the
Newton step) and the three transcriptions of a trajectory with a parameter estimated."""

import os
import signal

import casadi as ca
import numpy as np
import pytest

from ema_casadi._util import _interrupts
from ema_casadi.optimisation import (
    COST_TOL,
    METHODS,
    decision_parameters,
    levenberg_marquardt,
    newton_step,
    solve_ipopt,
    transcribe,
)


def _rosenbrock(constrained=True):
    opti = ca.Opti()
    x = opti.variable(2)
    opti.minimize((1 - x[0]) ** 2 + 100 * (x[1] - x[0] ** 2) ** 2)
    if constrained:
        opti.subject_to(x[0] + x[1] <= 10)  # inactive at the optimum (1, 1)
    opti.set_initial(x, [-1.2, 1.0])
    return opti, x


def test_ipopt_reaches_the_rosenbrock_minimum_with_its_log():
    opti, x = _rosenbrock()
    res = solve_ipopt(opti, {"tol": 1e-10})
    assert res.success and res.status == "Solve_Succeeded"
    # the analytic minimum (1, 1); IPOPT's tol 1e-10 on the scaled KKT error: 1e-9 on x
    np.testing.assert_allclose(res.value(x), [1.0, 1.0], atol=1e-8)
    # the log holds the start and every iteration; the objective falls to ~0
    assert len(res.log["obj"]) == res.iterations + 1
    assert res.log["obj"][0] == pytest.approx(24.2) and res.log["obj"][-1] < 1e-15
    assert res.attempts == [{"status": "Solve_Succeeded", "iterations": res.iterations}]


def test_a_fallback_chain_tries_the_next_option_set_from_the_same_start():
    opti, x = _rosenbrock()
    res = solve_ipopt(opti, [{"max_iter": 3}, {"tol": 1e-10}])
    assert [a["status"] for a in res.attempts] == ["Maximum_Iterations_Exceeded", "Solve_Succeeded"]
    plain = solve_ipopt(_rosenbrock()[0], {"tol": 1e-10})
    # the second set starts where the first did (the initial values), not at its last iterate
    assert res.attempts[1]["iterations"] == plain.iterations
    np.testing.assert_allclose(res.value(x), [1.0, 1.0], atol=1e-8)


def test_a_warm_start_from_the_solution_stays_there():
    opti, x = _rosenbrock()
    first = solve_ipopt(opti, {"tol": 1e-10})
    again = solve_ipopt(opti, {"tol": 1e-10, "mu_init": 1e-9}, warm=first.warm)
    assert again.success and again.iterations <= 1  # measured 1 (from scratch: 23)
    np.testing.assert_allclose(again.value(x), first.value(x), atol=1e-10)


def test_iteration_hook_sees_every_iterate():
    opti, x = _rosenbrock()
    seen = []
    res = solve_ipopt(opti, {"tol": 1e-10}, on_iteration=lambda k, value: seen.append((k, value(x))))
    assert [k for k, _ in seen] == list(range(res.iterations + 1))
    np.testing.assert_allclose(seen[-1][1], res.value(x))


def _interrupting(k, value):
    if k == 2:
        os.kill(os.getpid(), signal.SIGINT)


def test_sigint_stops_ipopt_at_the_end_of_the_iteration():
    opti, _ = _rosenbrock()
    iterations = []

    def hook(k, value):
        iterations.append(k)
        _interrupting(k, value)

    with pytest.raises(KeyboardInterrupt):
        solve_ipopt(opti, {"tol": 1e-10}, on_iteration=hook)
    # the signal at iteration 2: its handler runs at the next bytecode, inside the same
    # callback; IPOPT stops there (plain: 20+ iterations)
    assert iterations == [0, 1, 2]
    assert opti.stats()["return_status"] == "User_Requested_Stop"


def test_the_command_lines_interrupt_flag_stops_ipopt():
    opti, _ = _rosenbrock()
    with pytest.raises(_interrupts.Interrupted), _interrupts.handling():
        solve_ipopt(opti, {"tol": 1e-10}, on_iteration=_interrupting)
    assert opti.stats()["iter_count"] <= 2


def test_ipopt_options_take_no_prefix():
    with pytest.raises(ValueError, match="ipopt.tol"):
        solve_ipopt(_rosenbrock()[0], {"ipopt.tol": 1e-8})


def test_levenberg_marquardt_reaches_the_linear_least_squares_solution():
    rng = np.random.default_rng(3)
    A = rng.normal(size=(40, 3))
    b = A @ np.array([0.5, -1.0, 2.0]) + rng.normal(size=40)
    out = levenberg_marquardt(lambda z: (A @ z - b, A), np.zeros(3), -np.inf * np.ones(3), np.inf * np.ones(3), 50)
    exact = np.linalg.lstsq(A, b, rcond=None)[0]
    assert out["converged"]
    # the stop: the Gauss-Newton step predicts a decrease below COST_TOL; on a linear
    # problem the prediction is exact, so the cost is within COST_TOL of its minimum
    # (the estimates within sqrt(2 COST_TOL) = 0.045 standard deviations)
    dz = out["z"] - exact
    assert 0.5 * dz @ (A.T @ A) @ dz < COST_TOL
    assert out["cost"] == pytest.approx(0.5 * np.sum((A @ exact - b) ** 2), abs=COST_TOL)


def test_levenberg_marquardt_keeps_the_box():
    A, b = np.eye(2), np.array([2.0, -3.0])
    out = levenberg_marquardt(lambda z: (A @ z - b, A), np.zeros(2), np.array([-1.0, -1.0]), np.array([1.0, 1.0]), 50)
    np.testing.assert_allclose(out["z"], [1.0, -1.0])


def test_newton_step_square_and_minimum_norm():
    J = np.array([[2.0, 1.0], [1.0, 3.0]])
    r = np.array([1.0, -2.0])
    np.testing.assert_allclose(J @ newton_step(J, r), -r, atol=1e-14)
    # a direction the equation does not fix is not moved: min-norm of [1 1] dz = -1
    np.testing.assert_allclose(newton_step(np.array([[1.0, 1.0]]), np.array([1.0]), least_squares=True, rcond=1e-13),
                               [-0.5, -0.5])
    full = newton_step(J, r)
    np.testing.assert_allclose(newton_step(J, 100 * r, max_step=0.1), full * 0.1 / np.abs(full).max())
    np.testing.assert_allclose(newton_step(J, 100 * r, max_step=0.1, capped=1), 100 * full * 0.1 / abs(100 * full[0]))
    with pytest.raises(np.linalg.LinAlgError):
        newton_step(np.ones((2, 2)), r)


def _rk4(substeps=4):
    x, u, a, dt = ca.SX.sym("x"), ca.SX.sym("u"), ca.SX.sym("a"), ca.SX.sym("dt")

    def f(x):
        return -a * x + u

    h, xk = dt / substeps, x
    for _ in range(substeps):
        k1 = f(xk)
        k2 = f(xk + h / 2 * k1)
        k3 = f(xk + h / 2 * k2)
        k4 = f(xk + h * k3)
        xk = xk + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return ca.Function("F", [x, u, a, dt], [xk])


@pytest.mark.parametrize("method", METHODS)
def test_each_transcription_estimates_a_decay_rate(method):
    # x' = -a x + u, u = 1, x(0) = 0: x(t) = (1 - exp(-a t)) / a; records of x at 20 nodes
    a_true, N, T = 3.0, 20, 2.0
    t = np.linspace(0, T, N + 1)
    data = (1 - np.exp(-a_true * t)) / a_true
    opti = ca.Opti()
    p, z = decision_parameters(opti, [2.0], [0])  # started 33 % off
    U = ca.DM.ones(1, N)
    dts = ca.DM(np.diff(t)).T
    tr = transcribe(opti, method, x0=[0.0], guess=data.reshape(1, -1), scale=np.array([0.3]), U=U, dts=dts,
                    rates=lambda X, Uc: (-p * X + Uc, X), interval=_rk4(),
                    interval_args=(U, ca.repmat(p, 1, N), dts))
    opti.minimize(ca.sumsqr(tr.X - data.reshape(1, -1)) * 1e4)
    res = solve_ipopt(opti, {"tol": 1e-12}, expand=True)
    assert res.success
    # RK4 at h = 0.025 (error ~(a h)^4 / 120 = 2.5e-7 per step) and Radau IIA of order 5 at
    # h = 0.1: the estimate within 1e-6 of the truth (measured 4e-8 and 5e-8)
    assert float(res.value(p)) == pytest.approx(a_true, rel=1e-6)
