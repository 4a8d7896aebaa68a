"""The verdict by effect size: how large the systematic part of the misfit is, where it
sits, and whether it is within the model error the user tolerates.

Per record and channel, the residual e (measured - fitted, SI) is split into a slow
part, its centred running mean m over W samples (:data:`WINDOW_S`), and the rest. For
white noise of level s_n the running mean has variance s_n^2 / W, so the systematic
misfit is

    e_sys = sqrt(max(0, mean(m^2) - s_n^2 / W)),

with s_n the channel's stated noise level, or, where it was estimated from these
residuals, the first-difference estimate sqrt(mean(diff(e)^2) / 2) (blind to a slow
systematic part). It is reported in the signal's unit and in units of s_n, with where
it sits: each sample is labelled from the fitted run as *hold* (rod speed below 1 % of
its limit), *reversal* (within 10 ms of a change of the rod's direction), *saturation*
(a current at 95 % of its limit or the rod at 95 % of its speed limit) or *motion*, and
the share of mean(m^2) in each label and the time span that carries most of it are
named.

Three outcomes (:func:`verdict`): *adequate* when every statistical test passes
(chi-square, whiteness, records' consistency); *adequate within model error* when some
fail but every channel's systematic misfit is at most ``model_error`` noise levels and
no record's estimates shift against the others' by more than ``SHIFT_SD x
model_error`` sandwich standard deviations (:mod:`._robust`; RMS over the directions
the record determines: when the records agree its square is chi-square(d) / d, so 5 is
beyond any noise, P < 1e-6 for d >= 1); *inadequate* otherwise. A smaller disagreement
widens the intervals by the scale factor of the records' parts instead (:mod:`._robust`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..signals import format_quantity
from ._unsettled import kept

#: Running-mean window of the systematic misfit (s): 20 ms, 40 samples at 2 kHz (the
#: noise floor of the mean is then 0.16 noise levels).
WINDOW_S = 0.02
#: The default tolerated systematic misfit, in noise levels (``--model-error``): a model
#: error below the sensor noise passes.
MODEL_ERROR = 1.0
#: The largest ``model_error`` taken without ``allow_misfit`` (noise levels): a larger
#: tolerance passes what a wrong structure leaves (the clamping rig's records fitted
#: with the default structure: 35-80 noise levels, docs: inadequate fit), and at 1e6 a
#: 61-sigma misfit was called adequate.
MAX_MODEL_ERROR = 10.0
#: A record's estimates may shift against the others' by up to SHIFT_SD x model_error
#: sandwich standard deviations (per direction, RMS). On the coverage study's witness
#: (a model error of 0.7 noise levels) the records' shifts reach 2-4.
SHIFT_SD = 5.0
#: Labels of the samples.
SEGMENTS = ("hold", "reversal", "saturation", "motion")
#: Rod speed below this fraction of its limit: held; a reversal is a sign change of the
#: rod speed with this fraction of the limit reached within REVERSAL_S on both sides.
HOLD_FRACTION = 0.01
REVERSAL_S = 0.01
#: A current or the rod speed at this fraction of its limit: saturated.
SATURATION_FRACTION = 0.95


def check_model_error(model_error, allow_misfit: bool = False) -> float:
    """``model_error`` as a positive finite float, at most :data:`MAX_MODEL_ERROR` unless
    ``allow_misfit`` confirms it (``IdentificationError`` naming it otherwise).

    Parameters
    ----------
    model_error : float
        The tolerated systematic misfit (noise levels).
    allow_misfit : bool
        The confirmation of a tolerance above the ceiling.
    """
    from .._util._checks import number
    from ._records import IdentificationError

    v = number(model_error, "model_error", IdentificationError, positive=True)
    if not isinstance(allow_misfit, bool):
        raise IdentificationError(f"allow_misfit: expected True or False, got {allow_misfit!r}")
    if v > MAX_MODEL_ERROR and not allow_misfit:
        raise IdentificationError(f"model error {v:g} noise levels: above the ceiling of {MAX_MODEL_ERROR:g}, where "
                                  "a wrong structure passes as adequate; confirm it with allow_misfit "
                                  f"(--allow-misfit) or give at most {MAX_MODEL_ERROR:g}")
    return v


def running_mean(e, w: int) -> np.ndarray:
    """Centred running mean of ``e`` over ``w`` samples (shorter at the ends)."""
    c = np.concatenate([[0.0], np.cumsum(e)])
    n = len(e)
    i = np.arange(n)
    lo, hi = np.clip(i - w // 2, 0, n), np.clip(i - w // 2 + w, 0, n)
    return (c[hi] - c[lo]) / np.maximum(hi - lo, 1)


def labels(model, pred, t) -> np.ndarray:
    """The segment label (index into :data:`SEGMENTS`) of each sample, from the fitted
    run's states (rod speed, currents) and the model's limits."""
    X = np.asarray(pred["X"])
    lim = model.limit_values()
    out = np.full(len(t), SEGMENTS.index("motion"))
    try:
        v = X[model.index(model.state_with("rod_velocity"))]
    except Exception:  # noqa: BLE001 - a model without a rod speed: all motion
        return out
    v_max = float(lim.get("rod_speed", np.max(np.abs(v)) or 1.0))
    moving = np.abs(v) > HOLD_FRACTION * v_max
    out[~moving] = SEGMENTS.index("hold")
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 1.0
    k = max(1, int(round(REVERSAL_S / dt)))
    flips = np.nonzero(np.sign(v[1:]) * np.sign(v[:-1]) < 0)[0]
    for f in flips:
        a, b = max(0, f - k), min(len(v), f + k + 1)
        if np.any(v[a:f + 1] * np.sign(v[f]) > HOLD_FRACTION * v_max) and np.any(
                v[f + 1:b] * np.sign(v[f + 1]) > HOLD_FRACTION * v_max):
            out[a:b] = SEGMENTS.index("reversal")
    sat = np.abs(v) >= SATURATION_FRACTION * v_max
    if "current" in lim:
        for s in model.states_with("current"):
            sat |= np.abs(X[model.index(s)]) >= SATURATION_FRACTION * float(lim["current"])
    out[sat] = SEGMENTS.index("saturation")
    return out


def misfits(records, preds, errors, sigma, estimated, model, units) -> list[dict]:
    """Per record and channel the systematic misfit (module docstring).

    Returns
    -------
    list of dict
        ``record``, ``channel``, ``systematic`` (SI), ``systematic_sigma`` (noise
        levels), ``noise`` (the level used), ``window_s``, ``segments`` (share of the
        systematic part per label), ``mostly`` (label), ``span`` ([t0, t1] s), ``text``,
        ``t`` and ``mean`` (the running mean, SI, for the figure).
    """
    out = []
    for i, (rec, pr) in enumerate(zip(records, preds, strict=True)):
        lab_full = labels(model, pr, rec.t)
        for c in rec.channels:
            e = np.asarray(errors[i, c], float)
            t = rec.t[len(rec.t) - len(e):]
            lab = lab_full[len(rec.t) - len(e):]
            dt = float(np.median(np.diff(t))) if len(t) > 1 else 1.0
            w = int(max(5, min(len(e), round(WINDOW_S / dt))))
            m = running_mean(e, w)
            keep = kept(rec, c, len(rec.t) - len(e))  # left-out samples (zeros) count nowhere
            if keep is None:
                keep, de = slice(None), np.diff(e)
            else:  # the running mean over the kept samples; the noise from kept neighbours
                frac = running_mean(keep.astype(float), w)
                m = np.where(keep & (frac > 0), m / np.maximum(frac, 1e-12), 0.0)
                de = np.diff(e)[keep[1:] & keep[:-1]]
            s_n = float(np.sqrt(np.mean(de**2) / 2)) if c in estimated and len(de) else float(sigma[c])
            floor = s_n**2 / w
            sys = float(np.sqrt(max(0.0, np.mean(m[keep] ** 2) - floor)))
            excess = np.maximum(m * m - floor, 0.0)
            tot = float(excess.sum())
            shares = {s: (float(excess[lab == j].sum()) / tot if tot > 0 else 0.0) for j, s in enumerate(SEGMENTS)}
            mostly = max(shares, key=shares.get)
            span = _span(t, excess, w)
            sys_sigma = sys / s_n if s_n > 0 else 0.0
            unit = units.get(c, "")
            where = (f", mostly {span[0]:.3g}-{span[1]:.3g} s, {mostly} ({100 * shares[mostly]:.0f} %)"
                     if sys_sigma > 0.05 else "")
            out.append({"record": rec.path, "channel": c, "systematic": sys, "systematic_sigma": sys_sigma,
                        "noise": s_n, "window_s": w * dt, "segments": shares, "mostly": mostly, "span": span,
                        "text": f"{Path(rec.path).name}: {c}: {format_quantity(sys, unit or '1', 3)} systematic "
                                f"({sys_sigma:.2f} sigma)"
                                f"{where}", "t": t, "mean": m})
    return out


def _span(t, excess, w) -> list[float]:
    """The contiguous time span (gaps shorter than a window bridged) holding the largest
    share of the systematic part."""
    if not np.any(excess > 0):
        return [float(t[0]), float(t[-1])]
    on = excess > 0.1 * excess.max()
    idx = np.nonzero(on)[0]
    runs, start, prev = [], idx[0], idx[0]
    for j in idx[1:]:
        if j - prev > w:
            runs.append((start, prev))
            start = j
        prev = j
    runs.append((start, prev))
    a, b = max(runs, key=lambda r: excess[r[0]:r[1] + 1].sum())
    return [float(t[a]), float(t[b])]


def verdict(adequacy: dict, found: list[dict], robust: dict | None, model_error: float) -> dict:
    """The three outcomes of the module docstring.

    Parameters
    ----------
    adequacy : dict
        The statistical tests (``adequate``, ``reasons``).
    found : list of dict
        :func:`misfits`.
    robust : dict or None
        :func:`._robust.robust_covariance` (its per-record shifts).
    model_error : float
        Tolerated systematic misfit in noise levels.

    Returns
    -------
    dict
        The adequacy updated: ``verdict``, ``adequate`` (False only when inadequate),
        ``exact`` (every statistical test passed) and ``model_error`` (the threshold,
        the misfits over 0.05 noise levels, the largest shift).
    """
    shifts = [r["shift_sd"] for r in (robust or {}).get("records", [])]
    worst = max(found, key=lambda m: m["systematic_sigma"]) if found else None
    doc = {"threshold_sigma": float(model_error), "threshold_shift_sd": SHIFT_SD * float(model_error),
           "largest_sigma": worst["systematic_sigma"] if worst else 0.0,
           "largest_shift_sd": max(shifts, default=0.0),
           "misfits": [{k: v for k, v in m.items() if k not in ("t", "mean")}
                       for m in sorted(found, key=lambda m: -m["systematic_sigma"]) if m["systematic_sigma"] > 0.05]}
    out = {**adequacy, "exact": bool(adequacy["adequate"]), "model_error": doc}
    if adequacy["adequate"]:
        return {**out, "verdict": "adequate"}
    too_big = [m for m in found if m["systematic_sigma"] > model_error]
    moved = max(shifts, default=0.0) > SHIFT_SD * model_error
    if not too_big and not moved:
        return {**out, "verdict": "adequate within model error", "adequate": True}
    extra = [f"systematic misfit above the tolerated {model_error:g} sigma: {m['text']}"
             for m in sorted(too_big, key=lambda m: -m["systematic_sigma"])[:3]]
    if moved:
        extra.append(f"records' estimates shift by up to {max(shifts):.2g} robust sd against the others' "
                     f"(tolerated {SHIFT_SD * model_error:g})")
    return {**out, "verdict": "inadequate", "adequate": False, "reasons": [*extra, *adequacy["reasons"]]}
