"""Direct collocation (Radau IIA) of a trajectory's dynamics on a grid of intervals.

Each interval k of the grid carries ``degree`` collocation states at the Radau points
tau_1 ... tau_d of [0, 1] (``ca.collocation_points``; tau_d = 1, the interval's end),
and the interpolating polynomial through the node and them has the model's rate at
every collocation point (``ca.collocation_coeff``: its slopes ``Z C / h``):

    [X_k, Z_k] C[:, r] = h_k f(Z_k,r, u_k)          r = 1 ... d
    X_k+1 = [X_k, Z_k] D                              (= Z_k,d for Radau)
    q_k = h_k sum_r B_r P(Z_k,r)                       (a quadrature: energy, heat)

with the rate function mapped over all N x d points at once. Radau IIA is L-stable: a
mode far faster than the interval (a smooth friction's or a screw lock's, 10^5 ...
10^6 1/s against 1/h ~ 10^3 1/s) is damped to its quasi-steady state instead of
bounding the step, so the interval needs no substeps and the NLP is expanded to SX with
its exact Hessian however stiff the model is. The equations are residuals in the
states' full scales (as a shooting's continuity).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

__all__ = ["DEGREE", "SCHEME", "coefficients", "points", "collocation"]

#: Collocation states per interval (Radau IIA of order 2 DEGREE - 1 = 5).
DEGREE = 3
#: The collocation points' family (``ca.collocation_points``): ``radau`` includes the
#: interval's end, the L-stable Radau IIA method.
SCHEME = "radau"


def coefficients(degree: int = DEGREE, scheme: str = SCHEME) -> tuple:
    """(tau, C, D, B): the collocation points in [0, 1], the (d+1) x d slope matrix,
    the (d+1) continuity weights and the d quadrature weights (``ca.collocation_coeff``).

    Parameters
    ----------
    degree : int
        Collocation points per interval.
    scheme : str
        ``radau`` or ``legendre``.
    """
    tau = ca.collocation_points(degree, scheme)
    C, D, B = (np.array(ca.DM(a)) for a in ca.collocation_coeff(tau))
    return np.array(tau), C, D.ravel(), B.ravel()


def points(fractions: np.ndarray, degree: int = DEGREE) -> np.ndarray:
    """The collocation points as fractions of the trajectory's duration: N x d (rows: the
    intervals), from the nodes' fractions.

    Parameters
    ----------
    fractions : ndarray
        The nodes (N + 1 fractions of the duration, 0 ... 1).
    degree : int
        Collocation points per interval.
    """
    tau = coefficients(degree)[0]
    return fractions[:-1, None] + np.diff(fractions)[:, None] * tau[None, :]


def collocation(opti: ca.Opti, rates, Xs, U, dts, scale: np.ndarray, *, free=None, integrand=None,
                start=None, degree: int = DEGREE) -> tuple:
    """The collocation equations of every interval, added to ``opti``: returns
    (X_next, q, points), the states the polynomial ends each interval at (nx x N,
    physical), the quadrature of ``integrand`` (1 x N per interval; 0 without one) and,
    per collocation point r, (X_r, Y_r): its states and outputs in every interval
    (nx x N, ny x N), for the caller's path constraints.

    Parameters
    ----------
    opti : casadi.Opti
        The NLP the collocation states and equations go into.
    rates : callable
        ``rates(X, U) -> (xdot, y)`` at the columns of X (physical states) with the
        inputs of the columns of U (the caller binds the parameters: numbers, or
        decision variables where they are estimated).
    Xs : MX
        The scaled node states (nx x N + 1; physical = ``diag(scale) Xs``).
    U : MX or DM
        The inputs (or controls) of every interval (columns: the N intervals).
    dts : MX or DM
        The intervals' lengths (1 x N, s).
    scale : ndarray
        The states' full scales.
    free : sequence of int, optional
        The states the equations integrate (default all; a state held by an algebraic
        rule of the caller's is left out).
    integrand : callable, optional
        ``integrand(y) -> 1 x cols``: an output expression integrated over each interval.
    start : callable, optional
        ``start(tau) -> nx x N`` (physical): the guess of the point at fraction ``tau``
        of every interval (default: the nodes' initial values are not copied).
    degree : int
        Collocation points per interval.
    """
    nx, N = Xs.shape[0], Xs.shape[1] - 1
    tau, Cc, D, B = coefficients(degree)
    free = list(range(nx)) if free is None else list(free)
    Zs = [opti.variable(nx, N) for _ in range(degree)]  # Zs[r][:, k]: interval k's point r (scaled)
    Z = [ca.diag(scale) @ z for z in Zs]
    # the rate function mapped over all N d points at once (point-major columns r N + k)
    xdot, y = rates(ca.horzcat(*Z), ca.repmat(U, 1, degree))
    cols = [Xs[:, :-1], *Zs]
    for r in range(degree):
        slope = sum(Cc[j, r] * cols[j] for j in range(degree + 1))
        rate = ca.diag(1 / scale) @ xdot[:, r * N:(r + 1) * N] * ca.repmat(dts, nx, 1)
        opti.subject_to(ca.vec((slope - rate)[free, :]) == 0)
    X_next = ca.diag(scale) @ sum(D[j] * cols[j] for j in range(degree + 1))
    q = 0
    if integrand is not None:
        P = integrand(y)
        q = dts * sum(B[r] * P[:, r * N:(r + 1) * N] for r in range(degree))
    if start is not None:
        for r, z in enumerate(Zs):
            opti.set_initial(z, np.asarray(start(float(tau[r])), float) / scale[:, None])
    return X_next, q, [(Z[r], y[:, r * N:(r + 1) * N]) for r in range(degree)]
