"""After a fit: the profile likelihood of a parameter, and the prediction of records
not used in the fit (validation)."""

from __future__ import annotations

import numpy as np

from .._util._checks import nearest
from ..model.assembly import build_model
from ._problem import Predictor
from ._records import IdentificationError, Record, read_record
from ._residual_tests import autocorrelation, channel_stats
from ._result import Z95

#: chi-square(1) 95 % quantile: the profile interval is where the cost rises by
#: CHI2_95 s^2 / 2 above its minimum.
CHI2_95 = 3.841458820694124


def profile(result, name: str, points: int = 9, span: float = 3.0) -> dict:
    """Profile likelihood of one free parameter: the parameter fixed on a grid of
    ``points`` values over +-``span`` of its Wald interval half-widths (log scale for a
    positive one), the others fitted again at each (noise levels held at the fit's),
    and the 95 % interval where the cost rises by 3.84 s^2 / 2.

    Parameters
    ----------
    result : IdentResult
        A fit of :func:`~ema_casadi.identification.identify`.
    name : str
        One of ``result.names``.
    points : int
        Grid points (odd: the estimate is one).
    span : float
        Half-width of the grid in Wald half-widths.

    Returns
    -------
    dict
        ``values``, ``cost`` (on the grid), ``interval`` (interpolated; an end at the
        grid's edge means the rise was not reached there), ``wald`` (the Fisher
        interval, for comparison).
    """
    from ._fit import _Fit
    from ._problem import free_parameters

    if name not in result.names:
        raise IdentificationError(f"profile: '{name}' is not a fitted parameter{nearest(name, result.names)}")
    model, recs = _model_records(result)
    est = result.estimate[name]
    lo, hi = result.interval[name]
    log = lo > 0 and est > 0
    h = (np.log(hi / est) if log else hi - est) * span
    grid = np.linspace(-h, h, points)
    values = est * np.exp(grid) if log else est + grid
    others = [n for n in result.names if n != name]
    s2 = result.info["s2"]
    costs = []
    for v in values:
        start = {n: result.estimate[n] for n in others}
        base = model.p()
        for n, val in {**result.estimate, name: v}.items():
            base[model.param_names.index(n)] = val
        if others:
            fr = free_parameters(model, others, start=start)
            fit = _Fit(Predictor(model, recs, fr, base), dict(result.sigma), 60, False)
            costs.append(fit.run(fr.z(fr.theta0))["cost"])
        else:
            costs.append(_cost(model, recs, base, name, v, result.sigma))
    costs = np.array(costs)
    rise = costs - costs.min()
    limit = CHI2_95 * s2 / 2
    return {"values": values.tolist(), "cost": costs.tolist(), "rise_95": limit,
            "interval": [_crossing(values, rise, limit, -1), _crossing(values, rise, limit, 1)],
            "wald": [lo, hi]}


def _crossing(values, rise, limit, side) -> float:
    """Where ``rise`` crosses ``limit`` left (side -1) or right (+1) of its minimum."""
    k = int(np.argmin(rise))
    idx = range(k, -1, -1) if side < 0 else range(k, len(values))
    prev = k
    for i in idx:
        if rise[i] >= limit:
            a, b = rise[prev], rise[i]
            w = (limit - a) / (b - a) if b != a else 0.0
            return float(values[prev] + w * (values[i] - values[prev]))
        prev = i
    return float(values[0] if side < 0 else values[-1])


def _model_records(result):
    model = build_model(result.fitted_params, result.info["variants"])
    recs = [read_record(p, model) for p in result.info["records"]]
    return model, recs


def _cost(model, recs, base, name, value, sigma) -> float:
    """The cost with every parameter fixed (``name`` at ``value``)."""
    from ._problem import free_parameters

    pred = Predictor(model, recs, free_parameters(model, [name], start={name: value}), base)
    out = pred.predict([value])
    return 0.5 * float(sum(np.sum(((rec.channels[c][1:] - o["y"][c][1:]) / sigma[c]) ** 2)
                           for rec, o in zip(recs, out, strict=True) for c in rec.channels))


def validate(result, records) -> list[dict]:
    """Predict records not used in the fit with the estimates: per record and channel
    the NRMSE (RMS of the prediction error over the standard deviation of the measured
    signal), the RMS error against the fit's noise level, and the residual
    autocorrelation (lag 1, Ljung-Box over 20 lags).

    Parameters
    ----------
    result : IdentResult
        A fit.
    records : sequence of str, Path or Record
        The validation records.
    """
    model = build_model(result.fitted_params, result.info["variants"])
    recs = [r if isinstance(r, Record) else read_record(r, model) for r in records]
    names = list(result.names)
    from ._problem import free_parameters

    fr = free_parameters(model, names)
    pred = Predictor(model, recs, fr, model.p())
    out = pred.predict(fr.theta0)
    errors, sigma = {}, dict(result.sigma)
    for i, (rec, o) in enumerate(zip(recs, out, strict=True)):
        for c in rec.channels:
            errors[i, c] = rec.channels[c][1:] - o["y"][c][1:]
            sigma.setdefault(c, float(np.std(errors[i, c])) or 1.0)
    stats = channel_stats(recs, out, errors, sigma)
    for st, (i, c) in zip(stats, errors, strict=True):
        meas = recs[i].channels[c][1:]
        st["nrmse"] = float(np.sqrt(np.mean(errors[i, c] ** 2)) / (np.std(meas) or 1.0))
        st["autocorrelation"] = autocorrelation(errors[i, c], 20).tolist()
    return stats


__all__ = ["profile", "validate", "CHI2_95", "Z95"]
