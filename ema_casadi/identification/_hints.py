"""Structure hints: where a fit's systematic misfit sits names the structural options
to try.

Friction that the default smooth law does not describe (a breakaway hump above the
sliding level, bristles at rest) shows where the rod's speed changes sign or leaves
rest: there the model's friction force is wrong for a few milliseconds and elsewhere
right. Per record and channel the systematic part of the residual is measured as in
:mod:`._misfit` (the running mean m over its window W, the excess m^2 - s_n^2 / W over
the noise floor); the samples *at reversals and starts* are those within
:data:`._misfit.REVERSAL_S` of a sign change of the fitted rod speed or of its leaving
rest (speed above :data:`._misfit.HOLD_FRACTION` of its limit after a sample below),
and those at speeds below :data:`LOW_SPEED` times the set's Stribeck velocity v_st
(where a hump acts).
With S the share of the excess, in noise levels squared and summed over every record
and channel, that sits there and T the share of the samples that are there, the hint
are reported with the hint. Where the misfit sits does not decide, though: an inertia
error also sits at the starts (a 1 mm step with the rotor inertia +25 %: 74 % of the
misfit in 21 % of the time), and a hump acting over a whole slow chirp is spread over
it (41 % in 32 %). What decides is a score test (:func:`hump_score`): on a fit that is
inadequate or did not converge, the Gauss-Newton decrease of the cost that freeing the
hump's height r_start at r_start = 1 (no hump: the same trajectory) would give, against
the decrease from freeing any one of the usual parameters held (:data:`RIVALS`) alone.
The hint is given when the hump's decrease exceeds :data:`SCORE_COST` (half the
chi-square of one degree of freedom at p = 1e-6), :data:`SCORE_FRACTION` of the cost,
and every rival's. It names the friction options the structure does not yet
use (``stribeck = on``: the Stribeck hump, parameters r_start, v_st; ``friction =
lugre_smooth``: bristles on the smooth law, sigma_0, sigma_1 where the parts use them),
each with the parameters it adds, and the command that compares them
(``--compare stribeck=off,on`` with those parameters freed; :mod:`._compare` fits a
parameter only in the combinations whose parts use it).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from . import _misfit

#: The hint needs at least this share of the systematic misfit at reversals and starts ...
FRICTION_SHARE = 0.5
#: ... and that share at least this multiple of their share of the time.
CONCENTRATION = 2.0
#: Speeds below this multiple of the Stribeck velocity count as the hump's (exp(-9) of
#: its height left there for the Gaussian one).
LOW_SPEED = 3.0
#: The score test's threshold (cost units, half a chi-square): 1 degree of freedom at
#: p = 1e-6 (chi-square 23.93), and at least SCORE_FRACTION of the cost.
SCORE_COST = 23.93 / 2
SCORE_FRACTION = 0.01
#: The parameters held that the score test weighs the hump against (each freed alone):
#: a misfit one of them explains better is not named friction's.
RIVALS = ("F_seal", "C_bear", "c_v", "B", "C", "J_m", "psi")
#: The friction options a hint may name: (key, value, what it adds).
#: (key, value, what it adds, the parameters it adds).
FRICTION_OPTIONS = (("stribeck", "on", "a breakaway (Stribeck) hump above the sliding level", ("r_start", "v_st")),
                    ("friction", "lugre_smooth", "bristles at rest on the smooth law (pre-sliding)",
                     ("sigma_0", "sigma_1")))


def option_parameters(variants: dict) -> set:
    """The parameters of the friction options that ``variants`` leave off (a comparison
    fits them only where their option is on)."""
    return {n for key, value, _, names in FRICTION_OPTIONS if variants.get(key) != value for n in names}


def switching_mask(model, pred, t) -> np.ndarray:
    """True at the samples within :data:`._misfit.REVERSAL_S` of a sign change of the
    fitted rod speed or of its leaving rest, and where the speed is below
    :data:`LOW_SPEED` times the Stribeck velocity ``v_st`` of the parameter set."""
    X = np.asarray(pred["X"])
    try:
        v = X[model.index(model.state_with("rod_velocity"))]
    except Exception:  # noqa: BLE001 - a model without a rod speed: no friction hint
        return np.zeros(len(t), bool)
    v_max = float(model.limit_values().get("rod_speed", np.max(np.abs(v)) or 1.0))
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 1.0
    k = max(1, int(round(_misfit.REVERSAL_S / dt)))
    still = np.abs(v) <= _misfit.HOLD_FRACTION * v_max
    events = np.concatenate([np.nonzero(np.sign(v[1:]) * np.sign(v[:-1]) < 0)[0],
                             np.nonzero(still[:-1] & ~still[1:])[0]])
    mask = np.zeros(len(t), bool)
    for f in events:
        mask[max(0, f - k):min(len(t), f + k + 1)] = True
    return mask


def concentration(model, records, preds, errors, sigma, estimated) -> dict:
    """S and T of the module docstring (``share``, ``time_share``) and the systematic
    excess summed (noise levels squared, ``excess``)."""
    at, total, n_at, n = 0.0, 0.0, 0, 0
    for i, (rec, pr) in enumerate(zip(records, preds, strict=True)):
        full = switching_mask(model, pr, rec.t)
        for c in rec.channels:
            e = np.asarray(errors[i, c], float)
            mask = full[len(rec.t) - len(e):]
            dt = float(np.median(np.diff(rec.t))) if len(rec.t) > 1 else 1.0
            w = int(max(5, min(len(e), round(_misfit.WINDOW_S / dt))))
            m = _misfit.running_mean(e, w)
            s_n = float(np.sqrt(np.mean(np.diff(e) ** 2) / 2)) if c in estimated else float(sigma[c])
            excess = np.maximum(m * m - s_n**2 / w, 0.0) / max(s_n, 1e-300) ** 2
            at += float(excess[mask].sum())
            total += float(excess.sum())
            n_at += int(mask.sum())
            n += len(e)
    return {"share": at / total if total > 0 else 0.0, "time_share": n_at / n if n else 0.0, "excess": total}


def friction_hint(model, records, preds, errors, sigma, estimated, free, score=None) -> list[dict]:
    """The hint of the module docstring (a list of one, or empty).

    Parameters
    ----------
    model : Model
        The model fitted.
    records : sequence of Record
        The records.
    preds : list of dict
        Each record's prediction at the fit's end (``X``: the states).
    errors : dict
        (record index, channel) -> residual (SI).
    sigma : dict
        Channel -> noise level (SI).
    estimated : sequence of str
        The channels whose noise level was estimated.
    free : sequence of str
        The free parameters (the command's ``--free``).
    score : dict, optional
        :func:`hump_score` at the same point.
    """
    got = concentration(model, records, preds, errors, sigma, estimated)
    at_switching = got["share"] >= FRICTION_SHARE and got["share"] >= CONCENTRATION * got["time_share"]
    hump = score or {}
    if hump.get("decrease", 0.0) < max(SCORE_COST, SCORE_FRACTION * hump.get("cost", 0.0),
                                       *hump.get("rivals", {}).values()):
        return []
    candidates = []
    for key, value, what, adds in FRICTION_OPTIONS:
        if {**model.variants, key: value} == dict(model.variants):  # the structure has it already
            continue
        current = model.variants.get(key, "")
        candidates.append({"option": f"{key}={value}", "adds": list(adds), "what": what,
                           "command": (f"ema identify {' '.join(Path(r.path).name for r in records)} --free "
                                       f"{','.join([*free, *[a for a in adds if a not in free]])} "
                                       f"--compare {key}={current},{value}")})
    if not candidates:
        return []
    names = "; ".join(f"{c['option']} ({c['what']}; frees {', '.join(c['adds'])})"
                      for c in candidates)
    rivals = hump.get("rivals") or {}
    best = max(rivals, key=rivals.get) if rivals else None
    why = (f"a Stribeck hump would lower the cost by {hump['decrease']:.4g} (score test, 1 degree of freedom: "
           f"above {SCORE_COST:.3g}, p < 1e-6)" + (f", more than freeing any one of {', '.join(rivals)} (best "
                                                  f"{best}: {rivals[best]:.3g})" if best else "")
           + f"; {100 * got['share']:.0f} % of the systematic misfit sits at reversals and starts "
           f"({100 * got['time_share']:.0f} % of the time)")
    text = (f"{why}: the friction structure is the suspect; candidates: {names}; compare: {candidates[0]['command']}"
            "; then fit the chosen structure with --friction-start auto --starts 6 --coarse-to-fine where the "
            "records stick and slip (their cost is rugged in the breakaway)")
    return [{"kind": "friction", "text": text, **got, "at_switching": at_switching, "score": hump,
             "candidates": candidates}]


def hump_score(fit, theta, sigma) -> dict | None:
    """The score (Lagrange-multiplier) test of the Stribeck hump at ``theta``: the model
    with ``stribeck = on`` at ``r_start = 1`` (no hump: the same trajectory) and
    ``v_st`` the file's, its residuals' Jacobian with the column of r_start added; the
    Gauss-Newton decrease of the cost with that column, less the decrease without it,
    is what freeing the hump's height would gain to first order (half a chi-square with
    one degree of freedom when the hump is absent). None where the structure has the
    hump already or the run fails.

    Parameters
    ----------
    fit : _Fit
        The fit (its predictor).
    theta : array_like
        The free parameters' values (SI).
    sigma : dict
        Channel -> noise level (SI): the weights.
    """
    from ..model.assembly import build_model
    from ..optimisation import gauss_newton_decrease
    from ..simulation import RunFailed
    from ._problem import Predictor, free_parameters

    model, pred = fit.pred.model, fit.pred
    key, value = FRICTION_OPTIONS[0][:2]  # the hump's option
    hump = {**model.variants, key: value}
    if key not in model.variants or hump == dict(model.variants):
        return None
    other = build_model(model.params, hump)
    if "r_start" not in other.used_params or "r_start" in pred.free.names:
        return None
    rivals = [n for n in RIVALS if n not in pred.free.names and n in other.used_params]
    names = [*pred.free.names, "r_start", *rivals]
    fr = free_parameters(other, names, start={**dict(zip(pred.free.names, np.asarray(theta, float).tolist(),
                                                         strict=True)), "r_start": 1.0})
    base = pred.base.copy()
    base[other.param_names.index("r_start")] = 1.0
    p2 = Predictor(other, pred.records, fr, base, pred.x0_states)
    p2.dx0 = list(pred.dx0)
    try:
        _, e, de = type(fit)(p2, fit.given, 2, False).errors(fr.theta0)
    except RunFailed:
        return None
    r, J = fit.weighted(e, de, sigma)
    n = len(pred.free.names)
    x0 = list(range(len(names), J.shape[1]))  # estimated initial states: always in

    def gain(extra):
        cols = [*range(n), *extra, *x0]
        z = np.zeros(len(cols))
        return gauss_newton_decrease(r, J[:, cols], z, np.full(len(z), -np.inf), np.full(len(z), np.inf))

    without = gain([])
    return {"decrease": float(gain([n]) - without), "cost": 0.5 * float(r @ r),
            "rivals": {name: float(gain([n + 1 + k]) - without) for k, name in enumerate(rivals)},
            "v_st": float(base[other.param_names.index("v_st")])}


def hints_at(fit, theta, free) -> list[dict]:
    """:func:`friction_hint` at parameter values ``theta`` (SI; a fit that did not
    converge: its last iterate) from one prediction of ``fit`` (a ``_fit._Fit``), the
    noise levels the given ones, else the residuals' RMS there; none when the run fails.

    Parameters
    ----------
    fit : _Fit
        A fit (its predictor: model, records, free parameters).
    theta : array_like
        The free parameters' values (SI).
    free : sequence of str
        The free parameters' names (the command's ``--free``).
    """
    from ..simulation import RunFailed

    try:
        preds, e, _ = fit.errors(np.asarray(theta, float))
    except RunFailed:
        return []
    sigma = {c: fit.given.get(c) or float(np.sqrt(np.mean(np.concatenate([e[k] for k in e if k[1] == c]) ** 2)))
             for c in fit.channels}
    estimated = [c for c in fit.channels if c not in fit.given]
    return friction_hint(fit.pred.model, fit.pred.records, preds, e, sigma, estimated, free,
                         hump_score(fit, theta, sigma))
