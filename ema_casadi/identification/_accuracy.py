"""The predictions' own accuracy at the optimum: the estimates must not move with the
integration tolerance.

A fit's predictions run at the tolerance :data:`._problem.RTOL`; their discretisation
error is a deterministic residual the fit absorbs into the estimates. At the optimum the
predictions are run again at a tenth of the tolerance, and the shift of the estimates
that the difference implies is computed from the fit's own Jacobian J (the weighted
residuals' derivatives in optimiser coordinates, the noise levels of the fit):

    delta z = J^+ (r_fine - r),    shift_k = delta z_k / sd_k,    sd = sqrt(diag((J^T J)^-1))

(the Gauss-Newton step the finer predictions would take, in standard deviations; J^+
leaves out the directions with singular values below :data:`RCOND` of the largest, which
the records do not determine, while sd counts every direction: a parameter the records
cannot tell has a wide sd and no shift that matters). Where
a parameter shifts by more than :data:`SHIFT_TOL` standard deviations the fit goes on
from its optimum at the finer tolerance, and is checked again, down to :data:`RTOL_MIN`.
The report (``info["prediction_accuracy"]``) gives each check's tolerance and largest
shift.

Where the shift still exceeds the limit at :data:`RTOL_MIN`, the predictions are not
numerically determined to the noise's level: a stick-slip event whose timing flips with
the integrator's error (on the witness rig's steps record the load cell at rtol 1e-10
and 1e-12 differs by 4 noise levels over 25 ms, by 3 at 1e-8), or bristles stiff enough
(sigma_0 = 1e10 N/m) that every tolerance resolves them differently. Then no finer
tolerance settles the estimates, and the intervals say so: the shifts toward a tenth and
a hundredth of the tolerance, delta z_1 and delta z_2, give the numerical covariance

    C_num = (delta z_1 delta z_1^T + delta z_2 delta z_2^T) / 2

(the estimate moves by about that much with the integration error, as by a random
error of that covariance), added to the robust covariance. The report's ``numerical``
gives the largest shift and each parameter's numerical standard deviation (relative).

Why: on the benchmark's recovery records the shift at rtol 1e-4 is 0.15 sd (kept), but on records
whose loaded stops stick and slip (a Stribeck hump steeper than the screw's damping: the
witness rigs' push and pull records) the error of the 1e-4 predictions in the load
cell's force reaches 330 N against 10 N of noise; at the true values the squared
prediction error (noise units, against the noise-free records) was 146 681 at 1e-4
against 1 520 at 1e-5 and 985 at 1e-8; on the records as first integrated (rtol 1e-9)
the fit at 1e-4 ended inadequate with F_seal's interval 25 x as wide, and from the truth
it moved c_v 3.4 % and F_seal 0.7 % away (at 1e-5: 0.05 % and 0.15 %).
"""

from __future__ import annotations

import numpy as np

__all__ = ["SHIFT_TOL", "RCOND", "RTOL_MIN", "estimate_shift", "refined", "add_numerical",
           "numerical_of"]

#: The largest shift of an estimate (standard deviations) the predictions' error may cause:
#: a 95 % interval shifted by 0.2 sd still holds the truth 94.5 % of the time.
SHIFT_TOL = 0.2
#: Singular values of J below this fraction of the largest: directions not determined.
RCOND = 1e-10
#: The finest tolerance the check goes to (a tenth of it is the last check).
RTOL_MIN = 1e-6


def estimate_shift(fit, out: dict, fine) -> tuple[np.ndarray, np.ndarray]:
    """Per free parameter: the shift of the estimates at the optimum ``out`` of ``fit``
    if its predictions were those of ``fine`` (a fit on the same records at a finer
    tolerance), in standard deviations and in optimiser coordinates; the module
    docstring's formula.

    Parameters
    ----------
    fit, fine : _Fit
        The fit and the same fit at a finer tolerance.
    out : dict
        The fit's optimum (``z``, ``z_full``, ``r``, ``J_full``, ``sigma``).
    """
    n = len(fit.pred.free.names)
    fine.pred.dx0 = [np.array(d, float) for d in fit.pred.dx0]
    _, e, de = fine.errors(fit.pred.free.theta(out["z"]))
    r_fine, _ = fit.weighted(e, de, out["sigma"])
    U, s, Vt = np.linalg.svd(np.asarray(out["J_full"], float), full_matrices=False)
    keep = s > RCOND * s[0]
    dz = Vt[keep].T @ ((U[:, keep].T @ (r_fine - out["r"])) / s[keep])  # the step in what the records determine
    sd = np.sqrt(np.sum((Vt[keep] / s[keep, None]) ** 2, axis=0))
    sd[np.sum(Vt[~keep] ** 2, axis=0) > RCOND] = np.inf  # on an undetermined direction: no shift that matters
    return np.abs(dz[:n] / sd[:n]), dz[:n]


def add_numerical(robust: dict, out: dict) -> dict:
    """``robust`` (:func:`._robust.robust_covariance`) with the numerical covariance of
    :func:`refined` added to its headline ``cov`` (kept apart as ``cov_numerical``);
    unchanged where the optimum ``out`` has none."""
    if out.get("numerical_cov") is None:
        return robust
    return {**robust, "cov": robust["cov"] + out["numerical_cov"], "cov_numerical": out["numerical_cov"]}


def numerical_of(out: dict, names, keep) -> dict:
    """``{"numerical_cov": ...}`` of the parameters ``keep`` (of ``names``) where the
    optimum ``out`` has a numerical covariance, else empty: the term carried to a fit
    that holds the others (the same coordinates; the held ones' shifts are dropped with
    them, their own type-B range taking their place)."""
    if out.get("numerical_cov") is None:
        return {}
    idx = [list(names).index(n) for n in keep]
    return {"numerical_cov": np.asarray(out["numerical_cov"])[np.ix_(idx, idx)]}


def _numerical(fit, out: dict, make_fit, first) -> dict:
    """The numerical term of an optimum the finest tolerance leaves unsettled: the shifts
    toward a tenth (``first``: its (shift, step)) and a hundredth of the tolerance, their
    mean outer product as a covariance (``out["numerical_cov"]``); the report."""
    rtol, atol = fit.pred.rtol, fit.pred.atol
    second = estimate_shift(fit, out, make_fit(rtol / 100, atol / 100))
    steps = [first[1], second[1]]
    out["numerical_cov"] = sum(np.outer(d, d) for d in steps) / len(steps)
    fr = fit.pred.free
    theta = fr.theta(out["z"])
    rel = np.sqrt(np.diag(out["numerical_cov"])) * np.abs(fr.dtheta_dz(theta)) / np.where(theta != 0, np.abs(theta), 1)
    shift = np.maximum(first[0], second[0])
    return {"compared_rtol": [rtol / 10, rtol / 100], "largest_shift_sd": float(shift.max()),
            "parameter": fr.names[int(np.argmax(shift))], "relative_sd": dict(zip(fr.names, rel.tolist(), strict=True))}


def refined(fit, out: dict, make_fit) -> tuple:
    """(fit, optimum, report): the fit checked at a tenth of its tolerance and, where an
    estimate shifts by more than :data:`SHIFT_TOL` sd, continued from its optimum at that
    tolerance (``make_fit(rtol, atol)`` builds the finer fit; its evaluations and cost
    history are added to the earlier ones), until the shift is small or the tolerance
    reaches :data:`RTOL_MIN`.

    Parameters
    ----------
    fit : _Fit
        The converged fit.
    out : dict
        Its optimum.
    make_fit : callable
        ``make_fit(rtol, atol) -> _Fit`` on the same records, free parameters and noise.
    """
    checks = []
    while True:
        rtol, atol = fit.pred.rtol, fit.pred.atol
        fine = make_fit(rtol / 10, atol / 10)
        shift, step = estimate_shift(fit, out, fine)
        worst = int(np.argmax(shift))
        checks.append({"rtol": rtol, "largest_shift_sd": float(shift[worst]),
                       "parameter": fit.pred.free.names[worst]})
        if shift[worst] <= SHIFT_TOL:
            break
        if rtol / 10 < RTOL_MIN:
            return fit, out, {"rtol": rtol, "checks": checks, "shift_tol_sd": SHIFT_TOL,
                              "numerical": _numerical(fit, out, make_fit, (shift, step))}
        evaluations, history = fit.pred.evaluations + fine.pred.evaluations, list(fit.history)
        extra = {k: v for k, v in out.items() if k not in ("z", "z_full", "sigma", "r", "J", "J_full", "cost",
                                                            "message", "estimated", "samples")}
        fine.pred.evaluations = 0
        out = {**fine.run(out["z_full"]), **extra}
        fine.pred.evaluations += evaluations
        fine.history = history + fine.history
        fit = fine
    return fit, out, {"rtol": fit.pred.rtol, "checks": checks, "shift_tol_sd": SHIFT_TOL}
