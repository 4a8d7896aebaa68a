"""Consistency between records: each record fitted alone against all together (a
likelihood-ratio test).

If the records come from one actuator and the structure is right, letting each record
have its own parameters lowers the weighted cost only by what the noise allows. Per
record r the parameters are re-fitted alone, from the joint optimum, in the
directions that record determines by itself (the right singular vectors of its
weighted Jacobian whose 95 % half-width is below log 1.5, the identifiability rule:
the others only wander on that record's noise), its estimated initial state (if any)
re-fitted with them. The statistic is the cost reduction

    T = sum_r 2 (C_joint,r - C_alone,r)

(C the record's half sum of squared weighted residuals). For a linear model with
Gaussian noise T is exactly a weighted sum of chi-square(1) variables with weights the
eigenvalues of I - Q^T U U^T Q (Q an orthonormal basis of the records' own directions,
block by block, U of the joint fit's Jacobian): (R - 1) n_theta ones when every record
determines every parameter. Its p-value is taken from the Satterthwaite approximation
T / g ~ chi-square(h) with the weights' first two moments (exact when they are 0 or 1).
The re-fits are real model runs (Levenberg-Marquardt from the joint optimum, a few
evaluations): the nonlinearity the linearised version misses where one record
determines a parameter poorly is what the restriction to determined directions and the
actual re-fit take care of.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
from scipy import stats

from .._util._parallel import cores
from ..optimisation import levenberg_marquardt
from ._problem import Predictor, marginal
from ._residual_tests import MISFIT_P

#: A direction counts as determined by one record when its 95 % half-width (in the
#: optimiser's coordinates, log-parameters) is below log 1.5: 1.96 / s < log 1.5.
DETERMINED = 1.96 / np.log(1.5)
#: Model evaluations per record's re-fit at most, its start included. In units of the
#: record's own standard deviations (the re-fit's coordinates) its optimum lies a few
#: units from the joint one; on the worked example's records 12 evaluations give the
#: same statistic as 6 in all 20 realisations tried. Stopped early the statistic is a
#: little low (a test that errs towards no alarm).
REFIT_EVALUATIONS = 6
#: The re-fits stop when the Gauss-Newton step predicts less than this decrease: the
#: statistic (2 x the sum of the decreases) is then short by at most 2 R REFIT_TOL,
#: against its standard deviation sqrt(2 h) (0.4 for four records, against 5.7 for h = 16).
REFIT_TOL = 0.05


def consistency(fit, out: dict) -> dict | None:
    """The test for the fit ``fit`` (a ``_Fit``) at its optimum ``out``; None for one
    record or nothing to test.

    Returns
    -------
    dict
        ``statistic``, ``expected``, ``dof`` (Satterthwaite h), ``p``, ``consistent``
        (p >= :data:`MISFIT_P`) and per record its contribution, its expectation, the
        directions it determines and its own estimates (with their shifts in joint
        standard deviations).
    """
    pred = fit.pred
    R, n, m = len(pred.records), len(pred.free.names), len(pred.x0_states)
    if R < 2:
        return None
    z_full, sig = out["z_full"], out["sigma"]
    _, e, de = fit._raw(z_full)
    U = np.linalg.svd(out["J_full"], full_matrices=False)[0]
    rows = _record_rows(e, R)
    theta = pred.free.theta(z_full[:n])
    blocks, records, std = [], [], _joint_std(out["J_full"], n, out, pred.free, theta)
    fit._raw(z_full)  # the joint fit's step sequences at its optimum (cached)
    directions = [_directions(fit, e, de, sig, k, n, m) for k in range(R)]
    with ThreadPoolExecutor(min(R, cores()), thread_name_prefix="ema-consistency") as pool:
        refits = list(pool.map(lambda k: _refit(fit, k, directions[k], z_full, sig)
                               if directions[k][0].shape[1] + m else None, range(R)))
    for k in range(R):
        V, rk, Jt, Jx, _ = directions[k]
        A = np.hstack([Jt @ V, Jx])
        if A.shape[1] == 0:
            records.append({"record": pred.records[k].path, "directions": 0, "contribution": 0.0, "expected": 0.0})
            continue
        Q = np.linalg.svd(A, full_matrices=False)[0]
        blocks.append((Q, U[rows[k]]))
        c_joint = 0.5 * float(rk @ rk)
        alone = refits[k]
        theta_alone = pred.free.theta(z_full[:n] + V @ alone[: V.shape[1]]) if alone is not None else None
        contribution = 2 * (c_joint - alone[-1]) if alone is not None else float("nan")
        M = np.eye(Q.shape[1]) - (Q.T @ U[rows[k]]) @ (U[rows[k]].T @ Q)
        rec = {"record": pred.records[k].path, "directions": int(V.shape[1]), "contribution": float(contribution),
               "expected": float(np.trace(M))}
        if theta_alone is not None:
            rec["estimate_alone"] = dict(zip(pred.free.names, theta_alone.tolist(), strict=True))
            rec["shift_sd"] = {nm: float((a - b) / sd) for nm, a, b, sd
                               in zip(pred.free.names, theta_alone, theta, std, strict=True)}
        records.append(rec)
    if not blocks:
        return None
    lam = _weights(blocks)
    a, b = float(lam.sum()), float((lam * lam).sum())
    T = float(sum(r["contribution"] for r in records))
    if not a > 1e-9 or not np.isfinite(T):
        return None
    g, h = b / a, a * a / b
    p = float(stats.chi2.sf(max(T, 0.0) / g, h))
    return {"statistic": T, "expected": a, "dof": h, "p": p, "consistent": bool(p >= MISFIT_P),
            "records": records, "rule": "likelihood ratio: each record re-fitted alone in the directions it "
                                        "determines (95 % half-width < log 1.5), against all together"}


def reasons(test: dict | None) -> list[str]:
    """One line when the records disagree: which record, by how much."""
    if test is None or test["consistent"]:
        return []
    worst = max(test["records"], key=lambda r: r["contribution"] - r["expected"])
    shifts = sorted(worst.get("shift_sd", {}).items(), key=lambda kv: -abs(kv[1]))[:2]
    moved = ", ".join(f"{nm} {v:+.1f} sd" for nm, v in shifts)
    return [f"records disagree: fitted alone they lower the cost by {test['statistic']:.4g} (expected "
            f"{test['expected']:.3g}, p = {test['p']:.2g}); most {Path(worst['record']).name} "
            f"({worst['contribution']:.4g}, expected {worst['expected']:.3g}; alone: {moved})"]


def _directions(fit, e, de, sig, k, n, m):
    """(V, r_k, J_theta, J_x0) of record ``k``: the parameter directions it determines
    alone (its initial state marginalised), its weighted residuals and Jacobian."""
    rk, Jk = _record_residuals(e, de, sig, k)
    Jt, Jx = Jk[:, :n], Jk[:, [n + k * m + j for j in range(m)]]
    Jm = Jt - Jx @ np.linalg.lstsq(Jx, Jt, rcond=1e-12)[0] if m else Jt
    _, s, Vt = np.linalg.svd(Jm, full_matrices=False)
    keep = s > DETERMINED
    return Vt[: len(s)][keep].T, rk, Jt, Jx, s[keep]


def _record_rows(e, R) -> list[slice]:
    """The rows of each record in the joint residual vector (records in order, their
    channels sorted: ``_Fit.weighted``'s order)."""
    out, at = [], 0
    for k in range(R):
        size = sum(len(v) for (i, _), v in e.items() if i == k)
        out.append(slice(at, at + size))
        at += size
    return out


def _record_residuals(e, de, sig, k):
    keys = sorted((key for key in e if key[0] == k), key=lambda key: key[1])
    return (np.concatenate([e[key] / sig[key[1]] for key in keys]),
            np.concatenate([de[key] / sig[key[1]] for key in keys]))


def _joint_std(J, n, out, free, theta) -> np.ndarray:
    """Standard deviations of the joint estimates (SI), initial states marginalised."""
    N = out.get("samples", len(out["r"]))
    s2 = float(out["r"] @ out["r"]) / max(1, N - J.shape[1]) if out["estimated"] else 1.0
    Jm = marginal(J, n)
    return np.sqrt(np.maximum(np.diag(s2 * np.linalg.pinv(Jm.T @ Jm)), 0)) * np.abs(free.dtheta_dz(theta))


def _refit(fit, k: int, directions, z_full, sig):
    """Record ``k`` alone from the joint optimum, its parameters moving along its
    determined directions (and its initial-state offsets): (coordinates ..., cost), or
    None if it fails. The record's step sequence is the joint fit's last, replayed for
    every evaluation of the re-fit, its start included (costs on different step
    sequences differ by their discretisation error, as large as the cost's rise over
    one standard deviation for weakly determined parameters; a replay that does not fit
    falls back to chosen steps).
    The re-fit's coordinates are in units of the record's own standard deviations along
    each direction (the optimiser's first step bound is then one of them)."""
    V, _, _, Jx, s = directions
    pred = fit.pred
    n, m = len(pred.free.names), len(pred.x0_states)
    one = Predictor(pred.model, [pred.records[k]], pred.free, pred.base, pred.x0_states)
    one.steps, one.rows = [pred.steps[k]], [pred.rows[k]]
    sub = type(fit)(one, dict(sig), REFIT_EVALUATIONS, False)
    x0k = z_full[n + k * m : n + (k + 1) * m]
    z_start = np.concatenate([z_full[:n], x0k])
    sub.z_grid, sub.regrid = z_start.copy(), np.inf  # one step sequence for the whole re-fit
    T = np.zeros((n + m, V.shape[1] + m))
    T[:n, : V.shape[1]] = V / s
    T[n:, V.shape[1]:] = np.diag(1.0 / np.maximum(np.linalg.norm(Jx, axis=0), 1e-300)) if m else np.zeros((0, 0))

    def evaluate(a):
        r, J = sub._eval(z_start + T @ a, sig)
        return (None, None) if r is None else (r, J @ T)

    sol = levenberg_marquardt(evaluate, np.zeros(T.shape[1]), np.full(T.shape[1], -np.inf),
                              np.full(T.shape[1], np.inf), REFIT_EVALUATIONS, REFIT_TOL)
    if sol["r"] is None:
        return None
    return np.concatenate([sol["z"][: V.shape[1]] / s, [sol["cost"]]])  # along V (z = z_joint + V c)


def _weights(blocks) -> np.ndarray:
    """The eigenvalues of I - Q^T U U^T Q, Q = blockdiag of the records' bases."""
    B = np.vstack([Q.T @ Ur for Q, Ur in blocks])  # (sum k_r) x n_U
    M = np.eye(B.shape[0]) - B @ B.T
    return np.clip(np.linalg.eigvalsh(M), 0.0, 1.0)
