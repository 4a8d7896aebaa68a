"""Uncertainty that survives model error: the Newey-West (HAC) sandwich per record and
a scale factor from the disagreement of the records' parts.

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

Between records (each record's shift). Each record's own estimate, one Gauss-Newton
step from the joint optimum in the directions it determines (V_k, the consistency
test's rule), delta_k = -V_k (V_k^T A_k V_k)^-1 V_k^T g_k (A_k = J_k^T J_k, g_k = J_k^T r_k),
is set against the estimate of all the other records, delta_-k = -(A - A_k)^+ (g - g_k),
with their sandwich covariances (independent records: they add):

    chi2_k = d_k^T (V_k^T (C_k + C_-k) V_k)^-1 d_k,   d_k = V_k^T (delta_k - delta_-k).

sqrt(chi2_k / dim V_k) is record k's shift in sandwich standard deviations (the
verdict's measure, :mod:`._misfit`), and that over S its shift in the headline ones.

The model error the records share (the scale factor S). The same test over the parts
of the records -- each record cut into :data:`PARTS` consecutive pieces in time, every
channel alike, G parts that determine a direction in all -- measures a model error that
moves the estimates from part to part. It is read as a random effect (DerSimonian and
Laird's model, in the directions each part determines): part g's effective parameters
are theta + b + u_g, u_g ~ N(0, T) independent, and the records' common part b, which no
comparison can see, is taken as large as the part-to-part one, b ~ N(0, T) (the
prediction rule of random-effects meta-analysis, Higgins, Thompson and Spiegelhalter
2009; metrology's "dark uncertainty"): the estimate is off the truth by b plus the
parts' mean of u, variance T (1 + 1/G). With T = tau^2 G C_HAC (one average part's
covariance; one number to estimate), E[chi2_g] = dim V_g + tau^2 (1 + 1/(G - 1)) t_g,
t_g = tr((V_g^T (C_g + C_-g) V_g)^-1 V_g^T G C_HAC V_g) (C_HAC here from the parts'
sandwiches, each part's own bandwidth), so by moments

    tau^2 = max(0, sum_g chi2_g - sum_g dim V_g) / ((1 + 1/(G - 1)) sum_g t_g),
    S^2 = 1 + (G + 1) tau^2,

applied where the parts disagree (sum_g chi2_g beyond its 95 % quantile as a
chi-square of sum_g dim V_g degrees of freedom, :data:`DISAGREE_P`), else S = 1; the
robust covariance is S^2 C_HAC. Without the common part (b = 0) the same moments give
S^2 = 1 + tau^2 ~ chi2 / dof, the scale factor by which the Particle Data Group and
CODATA combine measurements that disagree: it covers a model error that averages out
over the parts, not one they share (docs/guide/model-error.md: the coverage study
that chose this rule and the number of parts).
"""

from __future__ import annotations

import numpy as np

#: Andrews' constant of the Bartlett kernel's optimal bandwidth.
ANDREWS_BARTLETT = 1.1447
#: The parts disagree (the scale factor applies) when their chi-square's p-value is
#: below this; agreeing parts keep S = 1 (applied always, the records' PDG factor widened
#: every interval of the benchmark's fit of the right model by 15-29 % against the
#: textbook ones).
DISAGREE_P = 0.05
#: Parts per record of the scale factor's test (module docstring). Chosen by the
#: coverage study (docs/guide/model-error.md): over whole records (1 part) the test
#: detects the bristle-compliance witness's shared bias in 46 % of its realisations, with
#: 2 and 4 parts in 88 % and 85 %; on the right model's 200 realisations 4 parts fire in
#: 4.5 % (a 5 % test), 2 parts in 8 %.
PARTS = 4
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


def _disagreement(A, Ainv, M, parts) -> tuple[float, int, list[dict]]:
    """Each part's own estimate against the rest's (module docstring): per part its
    chi-square, directions, RMS shift in sandwich sd, and ``trace``, t_g / G of the
    module docstring (its chi-square's growth per unit of a random effect of covariance
    C_HAC = A^-1 M A^-1)."""
    g = sum(p["g"] for p in parts)
    shape = Ainv @ M @ Ainv
    chi2, dof, out = 0.0, 0, []
    for p in parts:
        rec = {"directions": 0, "shift_sd": 0.0, "chi2": 0.0, "trace": 0.0}
        w, Vw = np.linalg.eigh(0.5 * (p["A"] + p["A"].T))  # singular values of J_k: sqrt(w)
        V = Vw[:, np.sqrt(np.clip(w, 0, None)) > DETERMINED]
        if V.shape[1] and len(parts) > 1:
            Bk = V @ np.linalg.inv(V.T @ p["A"] @ V) @ V.T
            Brest = _pinv(A - p["A"])
            d = V.T @ (Brest @ (g - p["g"]) - Bk @ p["g"])
            C = V.T @ (Bk @ p["M"] @ Bk + Brest @ (M - p["M"]) @ Brest) @ V
            Ci = np.linalg.pinv(C, rcond=1e-12)
            c2 = float(d @ Ci @ d)
            rec.update(directions=int(V.shape[1]), chi2=c2, shift_sd=float(np.sqrt(max(c2, 0) / V.shape[1])),
                       trace=float(np.trace(Ci @ V.T @ shape @ V)))
            chi2, dof = chi2 + c2, dof + V.shape[1]
        out.append(rec)
    return chi2, dof, out


def _parts(blocks, pieces: int) -> list[list[tuple[str, slice]]]:
    """Each record's channels cut into ``pieces`` consecutive parts in time (every
    channel at the same fractions)."""
    out = []
    for blk in blocks:
        for m in range(pieces):
            out.append([(c, slice(sl.start + ((sl.stop - sl.start) * m) // pieces,
                                  sl.start + ((sl.stop - sl.start) * (m + 1)) // pieces)) for c, sl in blk])
    return [g for g in out if all(sl.stop > sl.start for _, sl in g)]


def _sandwich_parts(J, r, blocks) -> list[dict]:
    """Per block of rows its Bartlett long-run sum (``M``), information (``A``), score
    sum (``g``) and bandwidth (``L``)."""
    parts = []
    for blk in blocks:
        S = scores(J, r, blk)
        L = bandwidth(S)
        rows = np.concatenate([np.arange(sl.start, sl.stop) for _, sl in blk])
        Jk = J[rows]
        parts.append({"L": L, "M": hac(S, L), "A": Jk.T @ Jk, "g": S.sum(axis=0)})
    return parts


def _p_value(chi2, dof) -> float:
    from scipy.special import gammaincc  # chi2.sf(x, k) = gammaincc(k / 2, x / 2)

    return float(gammaincc(dof / 2, chi2 / 2)) if dof else 1.0


def robust_covariance(J, r, blocks, pieces: int = PARTS) -> dict:
    """The robust covariance of the module docstring, in optimiser coordinates.

    Parameters
    ----------
    J : ndarray
        Weighted residual Jacobian at the optimum (N x n; initial states projected out).
    r : ndarray
        Weighted residuals at the optimum (N).
    blocks : list
        Per record its channels' row slices (:func:`record_blocks`).
    pieces : int
        Parts per record of the scale factor's test (:data:`PARTS`).

    Returns
    -------
    dict
        ``cov_hac`` and ``cov`` (S^2 cov_hac) (n x n), ``scale_factor`` S, ``tau2``,
        the parts' test (``parts``: their count G, ``chi2``, ``dof``, ``p``), the
        records' (``chi2``, ``dof``, ``p``) and per record ``bandwidth`` (samples),
        ``shift_sd`` (its estimates' shift against the others' in sandwich standard
        deviations, RMS over its directions), ``shift_robust_sd`` (the same over S) and
        ``directions``.
    """
    A = J.T @ J
    Ainv = _pinv(A)
    recs = _sandwich_parts(J, r, blocks)
    M = sum(p["M"] for p in recs)
    cov_hac = Ainv @ M @ Ainv
    chi2, dof, shifts = _disagreement(A, Ainv, M, recs)
    pieces_ = _sandwich_parts(J, r, _parts(blocks, pieces))
    c2g, dofg, per = _disagreement(A, Ainv, sum(p["M"] for p in pieces_), pieces_)
    G = sum(1 for q in per if q["directions"])
    p_g = _p_value(c2g, dofg)
    trace = (1 + 1 / (G - 1)) * G * sum(q["trace"] for q in per) if G > 1 else 0.0
    tau2 = max(0.0, c2g - dofg) / trace if trace > 0 and p_g < DISAGREE_P else 0.0
    S2 = 1.0 + (G + 1) * tau2
    out = []
    for p, s in zip(recs, shifts, strict=True):
        out.append({"bandwidth": p["L"], "directions": s["directions"], "shift_sd": s["shift_sd"],
                    "chi2": s["chi2"], "shift_robust_sd": s["shift_sd"] / np.sqrt(S2)})
    return {"cov_hac": cov_hac, "cov": S2 * cov_hac, "scale_factor": float(np.sqrt(S2)), "tau2": float(tau2),
            "parts": {"count": G, "per_record": int(pieces), "chi2": float(c2g), "dof": int(dofg), "p": p_g},
            "chi2": float(chi2), "dof": int(dof), "p": _p_value(chi2, dof), "records": out}
