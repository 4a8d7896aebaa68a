"""Numeric building blocks of the tuning problem: the closed-loop diagonal response in
real arithmetic, the exact discretisation of a step, its rollout on a doubling time
grid, the Kreisselmeier-Steinhauser soft minimum and a reachability search."""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

#: Step grid: _NSEG segments of _SEG samples, the spacing doubling per segment.
_SEG, _NSEG = 40, 8
#: Sharpness of the soft minimum that aggregates each constraint group (a grid of
#: frequencies or time samples) into one constraint. One constraint per group lets
#: the worst point move along the grid without IPOPT's barrier stalling on many
#: nearly active neighbours (measured on the three-load reference problem, before the
#: elastic slacks: 163 iterations with every point a constraint, 35 aggregated). The
#: bound is conservative by at most log(321)/rho = 0.019 in the normalised units.
#: Not sharper: the soft minimum's curvature grows as rho |grad g|^2 where the worst
#: point hands over to a neighbour, so at rho = 3000 the exact Hessian changed by
#: orders of magnitude within one Newton step, IPOPT corrected its inertia at almost
#: every iteration (regularisation up to 1e2) and its path hung on the last bits of
#: the linear algebra: plain `ema tune` parted between OpenBLAS kernels at the 7th
#: digit by iteration 3 and took 37 (Haswell) to over 200 (Sandybridge) iterations.
#: At 300 the same problem converges in ~20-30 on each kernel (docs/development.md).
_KS_RHO = 300.0


def _sensitivity_function(n: int, m: int) -> ca.Function:
    """(A, B, C, D, w) -> [Re; Im] (2 x m) of the diagonal of C (jwI - A)^-1 B + D
    (n states, m input/output pairs), in real arithmetic:
    (jwI - A)^-1 = (A^2 + w^2 I)^-1 (-A - jw I), one factorisation for all m."""
    A = ca.SX.sym("A", n, n)
    B = ca.SX.sym("B", n, m)
    C = ca.SX.sym("C", m, n)
    D = ca.SX.sym("D", m)
    w = ca.SX.sym("w")
    Y = ca.solve(A @ A + w**2 * ca.SX.eye(n), ca.horzcat(-A @ B, -w * B))
    re = ca.vertcat(*[C[j, :] @ Y[:, j] + D[j] for j in range(m)])
    im = ca.vertcat(*[C[j, :] @ Y[:, m + j] for j in range(m)])
    return ca.Function("closed_loop_diagonal", [A, B, C, D, w], [ca.horzcat(re, im).T])


def _expm_step(A, b, h: float, squarings: int):
    """Exact discretisation over h of x' = A x + b (constant input): (Ad, bd) from the
    matrix exponential of [[A, b], [0, 0]] h by (6,6) Pade with scaling and squaring."""
    n = A.shape[0]
    M = ca.vertcat(ca.horzcat(A, b), ca.DM.zeros(1, n + 1)) * (h / 2**squarings)
    q = 6
    coef = [1.0]
    for k in range(1, q + 1):
        coef.append(coef[-1] * (q - k + 1) / (k * (2 * q - k + 1)))
    P = ca.DM.eye(n + 1)
    N = coef[0] * P
    D = coef[0] * P
    for k in range(1, q + 1):
        P = P @ M
        N = N + coef[k] * P
        D = D + (-1) ** k * coef[k] * P
    E = ca.solve(D, N)
    for _ in range(squarings):
        E = E @ E
    return E[:n, :n], E[:n, n]


def _step_states(A, b, amp: float, t_step: float, A_norm: float):
    """Closed-loop state response to a step of ``amp`` (m) from rest over ``t_step`` (s),
    exact at the samples (matrix exponential), on a grid of _NSEG segments of _SEG
    samples whose spacing doubles per segment. ``A_norm`` is the 1-norm (1/s) of A at
    the start gains, which sets the squarings. Returns (X, t), X's first column at t = 0+."""
    n = A.shape[0]
    h0 = t_step / (_SEG * (2**_NSEG - 1))
    # the norm grows with the gains: allow for 16x (4 extra squarings cost little)
    squarings = max(0, int(math.ceil(math.log2(max(A_norm * h0, 1e-300) / 0.5)))) + 4
    Ad, bd = _expm_step(A, b * amp, h0, squarings)
    xs, Ads, bds = ca.MX.sym("x", n), ca.MX.sym("Ad", n, n), ca.MX.sym("bd", n)
    roll = ca.Function("lin_step", [xs, Ads, bds], [Ads @ xs + bds]).mapaccum("lin_roll", _SEG)
    x, X, t, h, tk = ca.MX.zeros(n), [ca.MX.zeros(n)], [0.0], h0, 0.0
    for _ in range(_NSEG):
        Xs = roll(x, Ad, bd)
        X.append(Xs)
        t.extend(tk + h * np.arange(1, _SEG + 1))
        tk += h * _SEG
        x = Xs[:, -1]
        bd = Ad @ bd + bd  # doubling the step: x(2h) = Ad (Ad x + bd) + bd
        Ad = Ad @ Ad
        h *= 2
    return ca.horzcat(*X), np.array(t)


def _soft_min(g):
    """Kreisselmeier-Steinhauser lower bound of min(g): -log(sum(exp(-rho g)))/rho,
    within log(len(g))/rho of the minimum (shifted by min(g) against overflow; the
    shift's derivative cancels exactly)."""
    if g.shape[0] == 1:
        return g
    m = ca.mmin(g)
    return m - ca.log(ca.sum1(ca.exp(-_KS_RHO * (g - m)))) / _KS_RHO


def _reachable(A: np.ndarray, B: np.ndarray) -> list[int]:
    """States reachable from the inputs through the non-zero pattern of A (graph search)."""
    seen = set(np.nonzero(np.any(B != 0, axis=1))[0].tolist())
    todo = list(seen)
    while todo:
        j = todo.pop()
        for i in np.nonzero(A[:, j] != 0)[0].tolist():
            if i not in seen:
                seen.add(i)
                todo.append(i)
    return sorted(seen)
