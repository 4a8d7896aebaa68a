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
  eigenvalue, whose own derivative does not exist where two eigenvalues cross);
- ``DC`` (the default of ``design_experiment``): D, constrained so that no named
  parameter (nonzero weight) is predicted less well than by a reference test of the
  same length (the standard test), with reference variances ``v_k`` (the diagonal of
  ``M_ref^-1``). D-optimality alone trades a parameter that matters (the seal
  friction, which tracks wear) against others already far better determined; the
  constraint forbids that trade. In two convex steps:

      t* = min_w max_k C_kk(w) / v_k                   (max-min: each parameter's
                                                        variance against the reference)
      w* = argmin_w log det C_ss(w)  s.t.  C_kk(w) <= b v_k  for every named k,
      b  = max(RATIO, t* (1 + 1e-3)),

  ``RATIO`` = :data:`WIDTH_RATIO` squared: the predicted intervals at most 0.95 x the
  reference's (a margin for the rounding to whole segments and the additive
  approximation); where the library cannot reach that for every parameter (t* above
  it), the design keeps every ratio at the max-min optimum's and says so. Both steps
  are convex (``C_kk = e_k^T M^-1 e_k`` is convex in ``M``, ``M`` linear in ``w``).
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from ..optimisation import solve_ipopt

__all__ = ["CRITERIA", "criterion", "optimal_weights", "efficient_rounding"]

#: The criteria (``--criterion``).
CRITERIA = ("DC", "D", "A", "E")
#: ``DC``: each named parameter's predicted interval at most this fraction of the
#: reference test's, where the library allows.
WIDTH_RATIO = 0.95
#: Phi_p exponent of the E criterion.
E_POWER = 16


def _expression(M, crit: str, weights: np.ndarray):
    """The criterion (to be minimised) of a symbolic or numeric information ``M``."""
    n = M.shape[0]
    Ci = ca.solve(M, ca.DM.eye(n))
    keep = [k for k in range(n) if weights[k] > 0]
    if crit in ("D", "DC"):
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


def optimal_weights(Ms, crit: str = "D", weights=None, slots: int = 1, reference=None, factor=None) -> dict:
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
    reference : array_like, optional
        ``DC``: the reference test's information (n x n) (its variances ``v_k``).
    factor : array_like, optional
        ``DC``: per parameter, a factor on its reference variance (default 1 each): the
        caller's correction where the realised test fell short of the additive one.

    Returns
    -------
    dict
        ``w`` (shares), ``value`` (the criterion), ``status`` and ``iterations`` of IPOPT;
        with ``DC`` also ``maxmin`` (t*), ``bound`` (b) and ``ratios`` (the predicted
        variance over the reference's, per parameter, for the additive design).
    """
    Ms = np.asarray(Ms, float)
    K, n = Ms.shape[0], Ms.shape[1]
    pw = np.ones(n) if weights is None else np.asarray(weights, float)
    if crit == "DC" and reference is None:
        raise ValueError("optimal_weights: the DC criterion needs the reference test's information")
    scale = float(np.mean([np.trace(m) for m in Ms])) / n or 1.0
    extra = {}
    if crit == "DC":  # the variances against the reference's, in the scaled information's units
        v_ref = np.diag(np.linalg.inv(np.asarray(reference, float))) * (1.0 if factor is None else np.asarray(factor))
        v = v_ref * scale * slots  # the scaled information sum_i w_i M_i / scale has variances C_kk slots scale
        named = [k for k in range(n) if pw[k] > 0]
        M0 = np.tensordot(np.full(K, 1.0 / K), Ms / scale, 1)
        t0 = 2.0 * max(float(np.linalg.pinv(M0)[k, k] / v[k]) for k in named)
        t, _ = _solve(Ms / scale, K, n, lambda M, tt: (tt, [_variance(M, k) / v[k] <= tt for k in named]), t0)
        tmax = float(t["t"])
        bound = max(WIDTH_RATIO**2, tmax * (1 + 1e-3))
        got, res = _solve(Ms / scale, K, n, lambda M, tt: (_expression(M, "D", pw),
                                                           [_variance(M, k) / v[k] <= bound for k in named]))
        Mw = slots * np.tensordot(got["w"], Ms, 1)
        extra = {"maxmin": tmax, "bound": bound, "ratios": (np.diag(np.linalg.inv(Mw)) / v_ref).tolist()}
    else:
        got, res = _solve(Ms / scale, K, n, lambda M, tt: (_expression(M, crit, pw), []))
    stats = res.stats
    ws = got["w"]
    return {"w": ws, "value": criterion(slots * np.tensordot(ws, Ms, 1), crit, pw), "status": stats["return_status"],
            "iterations": int(stats["iter_count"]), "success": bool(stats["success"]), **extra}


def _variance(M, k: int):
    """``e_k^T M^-1 e_k`` (symbolic)."""
    e = ca.DM.zeros(M.shape[0])
    e[k] = 1.0
    return ca.dot(e, ca.solve(M, e))


def _solve(Ms, K: int, n: int, problem, t0: float | None = None) -> tuple[dict, object]:
    """Minimise ``problem(M, t) -> (objective, constraints)`` over the simplex of
    weights ``w``, ``M = sum_i w_i Ms_i`` (and a scalar ``t`` from ``t0`` where given,
    else None): the weights (clipped, summing to 1), ``t``, and IPOPT's result."""
    opti = ca.Opti()
    w = opti.variable(K)
    t = None if t0 is None else opti.variable()
    stack = ca.DM(np.asarray(Ms).reshape(K, n * n))
    M = ca.reshape(ca.mtimes(stack.T, w), n, n)
    objective, constraints = problem(M, t)
    opti.minimize(objective)
    opti.subject_to(ca.sum1(w) == 1)
    opti.subject_to(opti.bounded(0.0, w, 1.0))
    for c in constraints:
        opti.subject_to(c)
    opti.set_initial(w, np.full(K, 1.0 / K))
    if t is not None:
        opti.set_initial(t, t0)
    res = solve_ipopt(opti, {"tol": 1e-10, "max_iter": 500}, simple_bounds=True)
    ws = np.clip(np.atleast_1d(np.array(res.value(w), float).ravel()), 0.0, None)
    return {"w": ws / ws.sum(), "t": None if t is None else float(res.value(t))}, res


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
