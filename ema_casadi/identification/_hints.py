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
is given when

    S >= FRICTION_SHARE  and  S >= CONCENTRATION * T,

on a fit that is inadequate or did not converge: the misfit is concentrated at the
friction's switching points. It names the friction options the structure does not yet
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
#: The friction options a hint may name: (key, value, what it adds).
FRICTION_OPTIONS = (("stribeck", "on", "a breakaway (Stribeck) hump above the sliding level"),
                    ("friction", "lugre_smooth", "bristles at rest on the smooth law (pre-sliding)"))


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


def friction_hint(model, records, preds, errors, sigma, estimated, free) -> list[dict]:
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
    """
    got = concentration(model, records, preds, errors, sigma, estimated)
    if got["share"] < FRICTION_SHARE or got["share"] < CONCENTRATION * got["time_share"]:
        return []
    from ..model.assembly import build_model

    used = set(model.used_params)
    candidates = []
    for key, value, what in FRICTION_OPTIONS:
        if model.variants.get(key) == value:
            continue
        other = build_model(model.params, {**model.variants, key: value})
        adds = [n for n in other.param_names if n in other.used_params and n not in used]
        current = model.variants.get(key, "")
        candidates.append({"option": f"{key}={value}", "adds": adds, "what": what,
                           "command": (f"ema identify {' '.join(Path(r.path).name for r in records)} --free "
                                       f"{','.join([*free, *[a for a in adds if a not in free]])} "
                                       f"--compare {key}={current},{value}")})
    if not candidates:
        return []
    names = "; ".join(f"{c['option']} ({c['what']}; frees {', '.join(c['adds']) or 'nothing new'})"
                      for c in candidates)
    text = (f"the systematic misfit sits at reversals and starts ({100 * got['share']:.0f} % of it in "
            f"{100 * got['time_share']:.0f} % of the time): the friction structure is the suspect; candidates: "
            f"{names}; compare: {candidates[0]['command']}")
    return [{"kind": "friction", "text": text, **got, "candidates": candidates}]


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
    return friction_hint(fit.pred.model, fit.pred.records, preds, e, sigma, estimated, free)
