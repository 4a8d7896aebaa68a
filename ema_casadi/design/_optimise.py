"""Optimal designs over a library of segments: the criteria, the weights by IPOPT, and
the rounding to whole segments.

The information of a test made of segments is (nearly) the sum of its segments'
information, so a design is a set of weights ``w_i >= 0``, ``sum w_i = 1`` (the share of
the test time given to candidate segment ``i``) with information ``M(w) = N sum_i w_i
M_i``: the approximate design of Kiefer and Wolfowitz. Every criterion below is convex
in ``w``, so the optimum is global and unique in its value, and IPOPT (exact first and
second derivatives of the criterion by CasADi's AD, the ``M_i`` from exact forward
sensitivities) finds it from any start on any BLAS kernel. The weights are then
rounded to whole segments (efficient rounding, Pukelsheim and Rieder 1992), and the
realised test's information is computed exactly (the sum is an approximation: each
segment starts from where the last one ended).

Criteria on the covariance ``C = M^-1`` of the optimiser coordinates (relative units),
with weights ``W`` on named parameters (default 1 each; 0 leaves a parameter out):

- ``D``: ``log det C_ss`` over the parameters of nonzero weight (D_s-optimal: the
  volume of their confidence ellipsoid; with all weights 1, ``-log det M``);
- ``A``: ``trace(W C)`` (the weighted sum of the variances);
- ``E``: the largest eigenvalue of ``W^1/2 C W^1/2``, as ``(trace S^16)^(1/16)`` (Kiefer's
  Phi_p with p = 16: smooth, convex, within ``n^(1/16)`` (13 % for 7) of the largest
  eigenvalue, whose own derivative does not exist where two eigenvalues cross).
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from ..optimisation import solve_ipopt

__all__ = ["CRITERIA", "criterion", "optimal_weights", "efficient_rounding"]

#: The criteria (``--criterion``).
CRITERIA = ("D", "A", "E")
#: Phi_p exponent of the E criterion.
E_POWER = 16


def _expression(M, crit: str, weights: np.ndarray):
    """The criterion (to be minimised) of a symbolic or numeric information ``M``."""
    n = M.shape[0]
    Ci = ca.solve(M, ca.DM.eye(n))
    keep = [k for k in range(n) if weights[k] > 0]
    if crit == "D":
        sub = Ci[keep, keep]
        return ca.log(ca.det(sub)) if len(keep) < n else -ca.log(ca.det(M))
    if crit == "A":
        return ca.dot(ca.DM(weights), ca.diag(Ci))
    s = ca.DM(np.sqrt(weights))
    S = (s @ s.T) * Ci
    for _ in range(int(math.log2(E_POWER))):
        S = S @ S
    return ca.log(ca.trace(S)) / E_POWER


def criterion(M, crit: str = "D", weights=None) -> float:
    """The value of a criterion (smaller is better) for information ``M``.

    Parameters
    ----------
    M : ndarray
        Information (n x n), optimiser coordinates.
    crit : {"D", "A", "E"}
        The criterion.
    weights : array_like, optional
        Weight of each parameter (default 1 each).
    """
    M = np.asarray(M, float)
    w = np.ones(M.shape[0]) if weights is None else np.asarray(weights, float)
    x = ca.MX.sym("M", *M.shape)
    f = ca.Function("crit", [x], [_expression(x, crit, w)])
    value = float(f(M))
    return value if np.isfinite(value) else math.inf


def optimal_weights(Ms, crit: str = "D", weights=None, slots: int = 1) -> dict:
    """The optimal share of each candidate: IPOPT on ``min criterion(slots sum_i w_i M_i)``
    over the simplex.

    Parameters
    ----------
    Ms : sequence of ndarray
        The candidates' information per segment (n x n each).
    crit : {"D", "A", "E"}
        The criterion.
    weights : array_like, optional
        Weight of each parameter (default 1 each).
    slots : int
        Segments in the test (scales M: the values then belong to the test).

    Returns
    -------
    dict
        ``w`` (shares), ``value`` (the criterion), ``status`` and ``iterations`` of IPOPT.
    """
    Ms = np.asarray(Ms, float)
    K, n = Ms.shape[0], Ms.shape[1]
    pw = np.ones(n) if weights is None else np.asarray(weights, float)
    scale = float(np.mean([np.trace(m) for m in Ms])) / n or 1.0
    opti = ca.Opti()
    w = opti.variable(K)
    stack = ca.DM((Ms / scale).reshape(K, n * n))
    M = ca.reshape(ca.mtimes(stack.T, w), n, n)
    opti.minimize(_expression(M, crit, pw))
    opti.subject_to(ca.sum1(w) == 1)
    opti.subject_to(opti.bounded(0.0, w, 1.0))
    opti.set_initial(w, np.full(K, 1.0 / K))
    res = solve_ipopt(opti, {"tol": 1e-10, "max_iter": 500}, simple_bounds=True)
    stats = res.stats
    ws = np.clip(np.atleast_1d(np.array(res.value(w), float).ravel()), 0.0, None)
    ws /= ws.sum()
    return {"w": ws, "value": criterion(slots * np.tensordot(ws, Ms, 1), crit, pw), "status": stats["return_status"],
            "iterations": int(stats["iter_count"]), "success": bool(stats["success"])}


def efficient_rounding(w, N: int, tiny: float = 1e-4) -> np.ndarray:
    """Whole counts summing to N from the shares w, by efficient rounding.

    Pukelsheim and Rieder 1992: the rounded design's loss is the least possible for any
    criterion; shares below ``tiny`` drop out.

    Parameters
    ----------
    w : array_like
        Shares (sum 1).
    N : int
        Whole segments.
    tiny : float
        Shares below this are the optimiser's zeros.
    """
    w = np.where(np.asarray(w, float) >= tiny, np.asarray(w, float), 0.0)
    w = w / w.sum()
    support = np.flatnonzero(w)
    p = len(support)
    n = np.zeros(len(w), int)
    n[support] = np.ceil((N - p / 2) * w[support]).astype(int)
    while n.sum() < N:
        j = support[np.argmin(n[support] / w[support])]
        n[j] += 1
    while n.sum() > N:
        cand = support[n[support] > 0]
        j = cand[np.argmax((n[cand] - 1) / w[cand])]
        n[j] -= 1
    return n
