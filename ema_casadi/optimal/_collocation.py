"""Direct collocation of a move's dynamics (Radau IIA) on the shooting grid: the
transcription of a stiff configuration (module docs: :mod:`ema_casadi.optimal`).

Each interval k of the grid carries ``DEGREE`` collocation states at the Radau points
tau_1 ... tau_d of [0, 1] (``ca.collocation_points``; tau_d = 1, the interval's end),
and the interpolating polynomial through the node and them has the model's rate at
every collocation point (``ca.collocation_coeff``: its slopes ``Z C / h``):

    [X_k, Z_k] C[:, r] = h_k f(Z_k,r, u_k)          r = 1 ... d
    X_k+1 = [X_k, Z_k] D                              (= Z_k,d for Radau)
    q_k = h_k sum_r B_r P(Z_k,r)                       (the energy or heat)

with the model's rate function (``f`` or ``f_held``) mapped over all N x d points at
once. Radau IIA is L-stable: a mode of the smooth friction or the screw lock far faster
than the interval (10^5 ... 10^6 1/s against 1/h ~ 10^3 1/s) is damped to its
quasi-steady state instead of bounding the step, so the interval needs no substeps and
the NLP is expanded to SX with its exact Hessian however stiff the model is. The
equations are residuals in the states' full scales (as the shooting's continuity).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

__all__ = ["DEGREE", "SCHEME", "WIDENED", "WARM", "coefficients", "collocation", "points", "widened"]

#: Collocation states per interval (Radau IIA of order 2 DEGREE - 1 = 5).
DEGREE = 3
#: The collocation points' family (``ca.collocation_points``): ``radau`` includes the
#: interval's end, the L-stable Radau IIA method.
SCHEME = "radau"
#: The continuation's first, smoother solves, in turn: the model's smooth switches at the
#: widths its parts declare (the ``switch_width`` policy; on the reference the screw's
#: efficiency switch over the transmitted power, 0.1 W: 8 mrad/s of shaft speed against
#: 15 kN, a rate of 10^5 1/s at rest, widened to 10 W, then 1 W). At the model's own width
#: the NLP under load has several optima a few 1e-4 apart in the braking, and which one
#: IPOPT reaches from the ECU's step follows the rounding (the BLAS kernel, the barrier's
#: start: 0.11496 ... 0.11662 s for 10 mm against 15 kN); from the widened optima every
#: start tried reached the same one (0.1149842 s).
WIDENED = ("wider", "wide")
#: IPOPT's warm start from the widened problem's optimum (primal and multipliers).
WARM = {"warm_start_init_point": "yes", "mu_init": 1e-4, "warm_start_bound_push": 1e-9,
        "warm_start_mult_bound_push": 1e-9, "warm_start_slack_bound_push": 1e-9}


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
    """The collocation points as fractions of the move's duration: N x d (rows: the
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


def collocation(prob, opti, Xs, C, dts, scale: np.ndarray, guess: dict) -> tuple:
    """The collocation equations of every interval: (X_next, cost, points), the states
    the polynomial ends each interval at (nx x N), the quadrature (0 without one) and,
    per collocation point r, (tau_r, X_r, Y_r): its states and outputs in every interval
    (nx x N, ny x N), for the caller's limits and rest conditions.

    The equations hold for the states the shooting makes continuous; a memory state at
    rest on its signal (``Model.rest_states``) is not integrated: the caller holds it at
    its signal at the nodes and at the collocation points.

    Parameters
    ----------
    prob : Problem
        The problem (its model, grid and rate function :meth:`Problem._rates`).
    opti : casadi.Opti
        The NLP the collocation states and equations go into.
    Xs : MX
        The scaled node states (nx x N + 1).
    C : MX
        The controls (nc x N).
    dts : MX
        The intervals' lengths (1 x N, s).
    scale : ndarray
        The states' full scales.
    guess : dict
        The initial guess (:func:`~ema_casadi.optimal.initial_guess`: ``T``, ``ecu``).
    """
    m, N, d = prob.model, prob.N, DEGREE
    tau, Cc, D, B = coefficients(d)
    Zs = [opti.variable(m.nx, N) for _ in range(d)]  # Zs[r][:, k]: interval k's point r (scaled)
    Z = [ca.diag(scale) @ z for z in Zs]
    # the rate function mapped over all N d points at once (point-major columns r N + k)
    xdot, y = prob._rates(ca.horzcat(*Z), ca.repmat(C, 1, d))
    free = _free(prob)
    cols = [Xs[:, :-1], *Zs]
    for r in range(d):
        slope = sum(Cc[j, r] * cols[j] for j in range(d + 1))
        rate = ca.diag(1 / scale) @ xdot[:, r * N:(r + 1) * N] * ca.repmat(dts, m.nx, 1)
        opti.subject_to(ca.vec((slope - rate)[free, :]) == 0)
    X_next = ca.diag(scale) @ sum(D[j] * cols[j] for j in range(d + 1))
    power = prob._power_outputs()
    cost = 0
    if power:
        P = sum(y[m.yindex(n), :] for n in power)
        cost = ca.sum2(dts * sum(B[r] * P[:, r * N:(r + 1) * N] for r in range(d)))
    _initial(prob, opti, Zs, scale, guess, tau)
    return X_next, cost, [(Z[r], y[:, r * N:(r + 1) * N]) for r in range(d)]


def widened(prob) -> list:
    """The parameter vectors of the continuation's first solves (:data:`WIDENED`: each
    declared width wider than the model's own, in turn); [] where the model declares none."""
    names = prob.model.param_names
    out = []
    for value in WIDENED:
        p = np.array(prob.p, float)
        for n, w in prob.model.small_signal(switch_width=value).items():
            i = names.index(n)
            p[i] = w if 0 < p[i] < w else p[i]
        if not np.array_equal(p, prob.p):
            out.append(p)
    return out


def _free(prob) -> list:
    """The states the collocation equations integrate (not a memory state at rest on its signal)."""
    rest_on = prob.model.rest_states(prob.p)
    return [i for i, n in enumerate(prob.model.states) if n not in rest_on]


def _initial(prob, opti, Zs, scale, guess, tau) -> None:
    """The collocation states' guess: the ECU's step (the guess's run) at their times."""
    T = guess["T"] if prob.objective == "time" else prob.duration
    res = guess["ecu"]
    fr = prob.fractions()
    for r, z in enumerate(Zs):
        t = T * (fr[:-1] + np.diff(fr) * tau[r])
        opti.set_initial(z, np.array([np.interp(t, res.t, res[n]) for n in prob.model.states]) / scale[:, None])
