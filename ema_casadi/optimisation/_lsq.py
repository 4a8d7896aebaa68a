"""Least squares: Levenberg-Marquardt with a step bound and a statistical stopping
rule, the Gauss-Newton prediction, and the Newton step of a (square or not) system.

The residuals are weighted by the noise levels, so the cost 1/2 sum r^2 rises by 1/2
when the estimates move by one standard deviation (in the direction that moves it
most). The fit stops when the Gauss-Newton step predicts a decrease below
:data:`COST_TOL`: the estimates are then within about sqrt(2 COST_TOL) = 0.045 standard
deviations of the optimum, and no model evaluation is spent proving it (a relative
tolerance on a cost of ~N/2 for N residuals either stops too early on small records or
spends evaluations on noise-level improvements of large ones, where the cost's own
round-off is reached first).
"""

from __future__ import annotations

import numpy as np

__all__ = ["COST_TOL", "STEP_TOL", "STEP0", "levenberg_marquardt", "gauss_newton_decrease", "newton_step"]

#: Stop when the Gauss-Newton step predicts a cost decrease below this.
COST_TOL = 1e-3
#: ... or when no step longer than this (relative, in log-parameters) decreases the cost:
#: the cost is then resolved no finer (a model that does not fit can leave it rough).
STEP_TOL = 1e-6
#: First bound on each parameter's step (in optimiser coordinates: log-parameters, so
#: a factor e); doubled after a good step, quartered after a rejected one. Bounding each
#: component, not the step's length, keeps a weakly determined parameter whose
#: Gauss-Newton step is far too long from holding back the others.
STEP0 = 1.0


def levenberg_marquardt(evaluate, z0, lo, hi, max_evaluations: int, cost_tol: float = COST_TOL) -> dict:
    """Minimise 1/2 |r(z)|^2 within the box [lo, hi].

    Parameters
    ----------
    evaluate : callable
        ``evaluate(z) -> (r, J)``, or ``(None, None)`` where the model fails there.
    z0 : ndarray
        Start (inside the box).
    lo, hi : ndarray
        Bounds.
    max_evaluations : int
        Calls of ``evaluate`` allowed (the start's included).
    cost_tol : float
        The stopping rule (module docstring).

    Returns
    -------
    dict
        ``z``, ``r``, ``J``, ``cost``, ``converged`` (bool), ``message``, ``evaluations``.
    """
    z = np.clip(np.asarray(z0, float), lo, hi)
    r, J = evaluate(z)
    n_eval = 1
    if r is None:
        return {"z": z, "r": None, "J": None, "cost": np.inf, "converged": False, "evaluations": n_eval,
                "message": "the model run fails at the start"}
    cost = 0.5 * float(r @ r)
    lam, bound = 1e-4, STEP0
    while True:
        g, H = J.T @ r, J.T @ J
        d = np.sqrt(np.maximum(np.diag(H), 1e-300))
        Hs = H / np.outer(d, d)
        gn_pred = _predicted(g, H, z, lo, hi)
        if gn_pred < cost_tol:
            return {"z": z, "r": r, "J": J, "cost": cost, "converged": True, "evaluations": n_eval,
                    "message": "the Gauss-Newton step predicts a decrease below the tolerance"}
        step = _solve(Hs + lam * np.eye(len(z)), -g / d) / d
        step = np.clip(z + np.clip(step, -bound, bound), lo, hi) - z  # no parameter moves by more than e^bound
        pred = -(g @ step) - 0.5 * step @ H @ step
        if n_eval >= max_evaluations:
            return {"z": z, "r": r, "J": J, "cost": cost, "converged": False, "evaluations": n_eval,
                    "message": f"cost {cost:.6g} still falling (predicted decrease {pred:.3g})"}
        r_new, J_new = evaluate(z + step)
        n_eval += 1
        new = np.inf if r_new is None else 0.5 * float(r_new @ r_new)
        rho = (cost - new) / pred if pred > 0 else -1.0
        if rho > 1e-4 and np.isfinite(new):
            z, r, J, cost = z + step, r_new, J_new, new
            lam *= max(1 / 3, 1 - (2 * rho - 1) ** 3)
            if rho > 0.5:
                bound = min(2 * bound, 1e3)
        else:
            if gn_pred < 10 * cost_tol:  # what is left is below the model's own resolution of the cost
                return {"z": z, "r": r, "J": J, "cost": cost, "converged": True, "evaluations": n_eval,
                        "message": f"converged: the remaining predicted decrease {gn_pred:.2g} is not realised"}
            lam = max(lam * 4, 1e-8)
            bound /= 4
            if bound < STEP_TOL:  # as far as the cost resolves: converged to that
                return {"z": z, "r": r, "J": J, "cost": cost, "converged": True, "evaluations": n_eval,
                        "message": f"converged: no step longer than {STEP_TOL:g} decreases the cost"}


def gauss_newton_decrease(r, J, z, lo, hi) -> float:
    """The cost decrease the Gauss-Newton step from ``z`` predicts (the step kept
    within the box [lo, hi]), with residuals ``r`` and Jacobian ``J`` there.

    Parameters
    ----------
    r : ndarray
        Residuals at ``z``.
    J : ndarray
        Their Jacobian at ``z``.
    z : ndarray
        The point.
    lo, hi : ndarray
        The box.
    """
    return _predicted(J.T @ r, J.T @ J, z, lo, hi)


def _predicted(g, H, z, lo, hi) -> float:
    d = np.sqrt(np.maximum(np.diag(H), 1e-300))
    gn = _solve(H / np.outer(d, d) + 1e-12 * np.eye(len(z)), -g / d) / d
    gn = np.clip(z + gn, lo, hi) - z
    return float(-(g @ gn) - 0.5 * gn @ H @ gn)


def newton_step(J, r, *, least_squares: bool = False, rcond: float | None = None, max_step: float | None = None,
                capped: int | None = None) -> np.ndarray:
    """The Newton (Gauss-Newton) step ``dz`` of the system r(z) = 0 with Jacobian ``J``:
    J dz = -r, solved by LU (a square system), or in the least-squares sense with the
    minimum norm (a direction the equations do not fix is not moved).

    Parameters
    ----------
    J : ndarray
        Jacobian (m x n).
    r : ndarray
        Residuals (m).
    least_squares : bool
        Minimum-norm least squares (any m); else LU (m = n; ``numpy.linalg.LinAlgError``
        where J is singular).
    rcond : float, optional
        Least squares: singular values below ``rcond`` times the largest count as zero
        (None: machine precision times max(m, n)).
    max_step : float, optional
        Largest magnitude of a component: a longer step is shortened along its direction.
    capped : int, optional
        Only the first ``capped`` components are held to ``max_step`` (default all).

    Returns
    -------
    ndarray
        The step (n); not finite where J or r are not.
    """
    J, r = np.asarray(J, float), np.asarray(r, float)
    dz = np.linalg.lstsq(J, -r, rcond=rcond)[0] if least_squares else np.linalg.solve(J, -r)
    if max_step is not None:
        head = dz[:capped] if capped is not None else dz
        big = float(np.max(np.abs(head))) if head.size else 0.0
        dz = dz * (max_step / big) if big > max_step else dz
    return dz


def _solve(A, b):
    try:
        return np.linalg.solve(A, b)
    except np.linalg.LinAlgError:
        return np.linalg.lstsq(A, b, rcond=None)[0]
