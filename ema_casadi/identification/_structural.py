"""Structural uncertainty, a "type B" component (as the GUM calls what is not
estimated from the data at hand): constants of the model's structure that the fit
holds at their values but that the rig may not share.

A model error that acts alike in every record (a screw-efficiency switch wider than
the model's, say) biases the estimates identically in each record: the residuals'
autocorrelation and the records' disagreement -- what the robust covariance
(:mod:`._robust`) measures -- do not see it. What the user knows about such a
constant is a plausible range. For each declared constant s_j, its range [lo_j, hi_j]
containing its value s_j0, the estimates' linearised shift per unit of the constant's
optimiser coordinate u_j (log(s_j / s_j0) for a positive constant, else
(s_j - s_j0) / |s_j0|) is one Gauss-Newton step from the optimum,

    G_j = -A^-1 J^T J_j,   A = J^T J,

with J_j = dr/du_j the weighted residuals' derivative (exact forward sensitivities,
one run per record; estimated initial states projected out of both). With u_j
uniform over [a_j, b_j] (the range's ends in u, a_j < 0 < b_j), its mean square about
the value is E[u_j^2] = (a_j^2 + a_j b_j + b_j^2) / 3 (a range symmetric about the
value, b_j = -a_j: the rectangular distribution's b_j^2 / 3), and

    C_B = sum_j E[u_j^2] G_j G_j^T,
    C = S^2 C_HAC + C_B

is the headline covariance (the constants independent of each other and of the
noise: the components add, in quadrature for each parameter's standard deviation).
Nothing is added unless constants are declared: with the model right, the robust
intervals stay those of :mod:`._robust`.
"""

from __future__ import annotations

import math

import numpy as np

from .._util._checks import nearest
from ._problem import Predictor, free_parameters, marginal
from ._records import IdentificationError
from ._robust import _pinv


def check_structural(model, structural, free_names) -> dict:
    """``structural`` checked: name -> (lo, hi) floats, the name a parameter the model
    uses, not free, its value inside (lo, hi), lo > 0 for a positive one.

    Parameters
    ----------
    model : Model
        The model fitted.
    structural : dict or None
        Name -> (lo, hi) in SI.
    free_names : sequence of str
        The free parameters.
    """
    out = {}
    p0 = model.p()
    for name, rng in dict(structural or {}).items():
        if name not in model.param_names:
            raise IdentificationError(f"structural '{name}' is not a parameter{nearest(name, model.param_names)}")
        if name in free_names:
            raise IdentificationError(f"structural '{name}' is free: a free parameter's uncertainty is its interval")
        if name not in model.used_params:
            raise IdentificationError(f"structural '{name}': {model.unused_reason(name)}")
        try:
            lo, hi = (float(v) for v in rng)
        except (TypeError, ValueError):
            raise IdentificationError(f"structural {name}: expected (LO, HI), two numbers (SI)") from None
        value = float(p0[model.param_names.index(name)])
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < value < hi):
            raise IdentificationError(f"structural {name}={lo:g}:{hi:g}: the range must hold the value "
                                      f"{value:g} strictly inside (LO < value < HI)")
        if free_parameters(model, [name]).log[0] and lo <= 0:
            raise IdentificationError(f"structural {name}={lo:g}:{hi:g}: {name} is positive (log-scaled); "
                                      "LO must be > 0")
        out[name] = (lo, hi)
    return out


def structural_covariance(fit, out: dict, structural: dict) -> dict | None:
    """The type-B covariance ``C_B`` of the module docstring (optimiser coordinates of
    the free parameters) at the optimum ``out`` of ``fit`` (a ``_fit._Fit``), and per
    constant its range, value, RMS coordinate and the estimates' shift at the range's
    ends (relative, linearised), per free parameter its type-B standard deviation
    (relative). None when ``structural`` is empty.

    Parameters
    ----------
    fit : _Fit
        The fit (its predictor: model, records, free parameters, base vector).
    out : dict
        Its optimum (``z``, ``z_full``, ``sigma``, ``J``).
    structural : dict
        Name -> (lo, hi), checked (:func:`check_structural`).
    """
    if not structural:
        return None
    pred = fit.pred
    fr = pred.free
    n, names = len(fr.names), list(structural)
    theta = fr.theta(out["z"])
    base = pred.p(theta)
    model = pred.model
    start = {**dict(zip(fr.names, theta.tolist(), strict=True)),
             **{s: float(base[model.param_names.index(s)]) for s in names}}
    big = free_parameters(model, [*fr.names, *names], start=start)
    p2 = Predictor(model, pred.records, big, base, pred.x0_states)
    if pred.x0_states:
        p2.dx0 = list(np.asarray(out["z_full"][n:], float).reshape(len(pred.records), -1))
    fit2 = type(fit)(p2, fit.given, 2, False)
    _, e, de = fit2.errors(big.theta0)
    _, Jbig = fit2.weighted(e, de, out["sigma"])
    Jm = marginal(Jbig, n + len(names))
    J, Js = Jm[:, :n], Jm[:, n:]
    G = -_pinv(J.T @ J) @ (J.T @ Js)  # n x k: d z / d u_j
    sub = big.subset(names, big.theta0)
    ends = np.column_stack([sub.z([structural[s][0] for s in names]), sub.z([structural[s][1] for s in names])])
    msq = (ends[:, 0] ** 2 + ends[:, 0] * ends[:, 1] + ends[:, 1] ** 2) / 3
    cov = (G * msq) @ G.T
    D = fr.dtheta_dz(theta) / np.where(theta != 0, np.abs(theta), 1.0)  # relative change per unit z
    doc = {s: {"range": list(structural[s]), "value": start[s], "rms_coordinate": float(np.sqrt(msq[j])),
               "shift_at_ends": {p: [float(G[k, j] * ends[j, 0] * D[k]), float(G[k, j] * ends[j, 1] * D[k])]
                                 for k, p in enumerate(fr.names)}}
           for j, s in enumerate(names)}
    sd = {p: float(np.sqrt(max(cov[k, k], 0.0)) * D[k]) for k, p in enumerate(fr.names)}
    return {"cov": cov, "constants": doc, "relative_sd": sd}


def add_structural(robust: dict, typeb: dict | None) -> dict:
    """``robust`` (:func:`._robust.robust_covariance`) with the type-B covariance added
    to its headline ``cov`` (kept apart as ``cov_structural``, the constants' account as
    ``structural``); unchanged when ``typeb`` is None."""
    if typeb is None:
        return robust
    return {**robust, "cov": robust["cov"] + typeb["cov"], "cov_structural": typeb["cov"],
            "structural": typeb["constants"], "structural_sd": typeb["relative_sd"]}
