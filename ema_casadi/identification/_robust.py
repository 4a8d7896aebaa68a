"""Uncertainty that survives model error: the Newey-West (HAC) sandwich per record and
the metrology scale factor of the records' disagreement.

The textbook covariance s^2 (J^T J)^-1 assumes white residuals of the stated noise
level. A model that is close but not exact leaves a systematic part in the residuals:
correlated in time (within a record) and different from record to record. Both are
measured from the residuals at the optimum, without a refit:

Within a record (the sandwich, Newey and West 1987). With the weighted Jacobian J
(N x n, optimiser coordinates, initial states projected out) and residuals r, the
score of sample t of record k is s_t = sum_c J_tc^T r_tc (its channels summed: a
model error moves them together). Then

    M_k = sum_{|l| <= L_k} (1 - |l| / (L_k + 1)) sum_t s_t s_{t-l}^T      (Bartlett)
    C_HAC = A^-1 (sum_k M_k) A^-1,   A = J^T J,

the bandwidth L_k from Andrews' (1991) AR(1) plug-in rule for the Bartlett kernel,
L = 1.1447 (alpha N)^(1/3), alpha = sum_a 4 rho_a^2 sigma_a^4 / ((1 - rho_a)^6 (1 + rho_a)^2)
/ sum_a sigma_a^4 / (1 - rho_a)^4 over the score components a (rho_a their lag-1
autocorrelation, sigma_a^2 their innovation variance): white residuals give L near 0
and C_HAC = (J^T J)^-1 J^T diag(r^2) J (J^T J)^-1, close to the textbook covariance;
correlated ones widen it by what their correlation costs.

Between records (the scale factor, as the Particle Data Group and CODATA combine
measurements that disagree). Each record's own estimate, one Gauss-Newton step from
the joint optimum in the directions it determines (V_k, the consistency test's rule),
delta_k = -V_k (V_k^T A_k V_k)^-1 V_k^T g_k (A_k = J_k^T J_k, g_k = J_k^T r_k), is set
against the estimate of all the other records, delta_-k = -(A - A_k)^+ (g - g_k), with
their sandwich covariances (independent records: they add):

    chi2_k = d_k^T (V_k^T (C_k + C_-k) V_k)^-1 d_k,   d_k = V_k^T (delta_k - delta_-k),
    S^2 = max(1, sum_k chi2_k / sum_k dim V_k)   where the records disagree,

and the robust covariance is S^2 C_HAC (each chi2_k is chi-square(dim V_k) when the
records agree within their robust uncertainty). "Disagree": sum_k chi2_k beyond its
95 % quantile as a chi-square of sum_k dim V_k degrees of freedom (:data:`DISAGREE_P`);
otherwise S = 1.
sqrt(chi2_k / dim V_k) is record k's shift in sandwich standard deviations, and that
over S its shift in the headline (robust) ones: a record out of line with the others'
common disagreement.
"""

from __future__ import annotations

import numpy as np

#: Andrews' constant of the Bartlett kernel's optimal bandwidth.
ANDREWS_BARTLETT = 1.1447
#: The records disagree (the scale factor applies) when their robust chi-square's
#: p-value is below this; agreeing records keep S = 1 (applied always, the factor
#: widened every interval of the benchmark's fit of the right model by 15-29 % against
#: the textbook ones).
DISAGREE_P = 0.05
#: A record's direction is its own when its singular value exceeds this (the
#: consistency test's rule: 95 % half-width below log 1.5 on the record alone).
DETERMINED = 1.96 / np.log(1.5)


def record_blocks(e: dict, first_record_rows: int = 0) -> list[list[tuple[str, slice]]]:
    """Per record, its channels' rows in the joint residual vector (the order of
    ``_Fit.weighted``: records in order, channels sorted)."""
    keys = sorted(e, key=lambda k: (k[0], k[1]))
    out, at = {}, first_record_rows
    for k in keys:
        out.setdefault(k[0], []).append((k[1], slice(at, at + len(e[k]))))
        at += len(e[k])
    return [out[k] for k in sorted(out)]


def scores(J, r, blocks) -> np.ndarray:
    """The per-sample scores s_t = sum_c J_tc^T r_tc of one record (T x n)."""
    return sum(J[sl] * r[sl, None] for _, sl in blocks)


def bandwidth(S) -> int:
    """Andrews' AR(1) plug-in bandwidth of the Bartlett kernel for the scores ``S``."""
    T = len(S)
    if T < 4:
        return 0
    a, b = S[1:], S[:-1]
    den = np.einsum("ij,ij->j", b, b)
    ok = den > 0
    if not ok.any():
        return 0
    rho = np.clip(np.einsum("ij,ij->j", a[:, ok], b[:, ok]) / den[ok], -0.995, 0.995)
    s2 = np.mean((a[:, ok] - b[:, ok] * rho) ** 2, axis=0)
    num = np.sum(4 * rho**2 * s2**2 / ((1 - rho) ** 6 * (1 + rho) ** 2))
    den2 = np.sum(s2**2 / (1 - rho) ** 4)
    alpha = num / den2 if den2 > 0 else 0.0
    return int(min(T // 2, np.ceil(ANDREWS_BARTLETT * (alpha * T) ** (1 / 3))))


def hac(S, L: int) -> np.ndarray:
    """The Bartlett-weighted long-run sum of the scores (n x n)."""
    M = S.T @ S
    for lag in range(1, L + 1):
        G = S[lag:].T @ S[:-lag]
        M += (1 - lag / (L + 1)) * (G + G.T)
    return M


def _pinv(A, rcond=1e-12):
    w, V = np.linalg.eigh(0.5 * (A + A.T))
    keep = w > rcond * max(w.max(initial=0.0), 1e-300)
    return (V[:, keep] / w[keep]) @ V[:, keep].T


def robust_covariance(J, r, blocks) -> dict:
    """The robust covariance of the module docstring, in optimiser coordinates.

    Parameters
    ----------
    J : ndarray
        Weighted residual Jacobian at the optimum (N x n; initial states projected out).
    r : ndarray
        Weighted residuals at the optimum (N).
    blocks : list
        Per record its channels' row slices (:func:`record_blocks`).

    Returns
    -------
    dict
        ``cov_hac`` and ``cov`` (S^2 cov_hac) (n x n), ``scale_factor`` S, ``chi2``,
        ``dof``, per record ``bandwidth`` (samples), ``shift_sd`` (its estimates'
        shift against the others' in sandwich standard deviations, RMS over its
        directions), ``shift_robust_sd`` (the same over S) and ``directions``.
    """
    A = J.T @ J
    Ainv = _pinv(A)
    parts = []
    for blk in blocks:
        S = scores(J, r, blk)
        L = bandwidth(S)
        rows = np.concatenate([np.arange(sl.start, sl.stop) for _, sl in blk])
        Jk = J[rows]
        parts.append({"L": L, "M": hac(S, L), "A": Jk.T @ Jk, "g": S.sum(axis=0), "samples": len(S)})
    M = sum(p["M"] for p in parts)
    cov_hac = Ainv @ M @ Ainv
    g = sum(p["g"] for p in parts)
    chi2, dof, recs = 0.0, 0, []
    for p in parts:
        rec = {"bandwidth": p["L"], "directions": 0, "shift_sd": 0.0, "chi2": 0.0}
        if len(parts) > 1:
            w, Vw = np.linalg.eigh(0.5 * (p["A"] + p["A"].T))  # singular values of J_k: sqrt(w)
            V = Vw[:, np.sqrt(np.clip(w, 0, None)) > DETERMINED]
            if V.shape[1]:
                Bk = V @ np.linalg.inv(V.T @ p["A"] @ V) @ V.T
                Brest = _pinv(A - p["A"])
                d_own, d_rest = -Bk @ p["g"], -Brest @ (g - p["g"])
                Mrest = M - p["M"]
                C = V.T @ (Bk @ p["M"] @ Bk + Brest @ Mrest @ Brest) @ V
                d = V.T @ (d_own - d_rest)
                c2 = float(d @ np.linalg.lstsq(C, d, rcond=1e-12)[0])
                rec.update(directions=int(V.shape[1]), chi2=c2, shift_sd=float(np.sqrt(max(c2, 0) / V.shape[1])))
                chi2, dof = chi2 + c2, dof + V.shape[1]
        recs.append(rec)
    from scipy.special import gammaincc  # chi2.sf(x, k) = gammaincc(k / 2, x / 2)

    p_value = float(gammaincc(dof / 2, chi2 / 2)) if dof else 1.0
    S2 = max(1.0, chi2 / dof) if dof and p_value < DISAGREE_P else 1.0
    for rec in recs:  # the shift in the headline (scaled) standard deviations: a record out of line with the rest
        rec["shift_robust_sd"] = rec["shift_sd"] / np.sqrt(S2)
    return {"cov_hac": cov_hac, "cov": S2 * cov_hac, "scale_factor": float(np.sqrt(S2)), "chi2": float(chi2),
            "dof": int(dof), "p": p_value, "records": recs}
