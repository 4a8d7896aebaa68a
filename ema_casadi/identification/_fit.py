"""``identify()``: weighted least squares (maximum likelihood with Gaussian sensor
noise) by Levenberg-Marquardt (:func:`ema_casadi.optimisation.levenberg_marquardt`)
with the exact Jacobian, noise levels estimated where not given, then the
Fisher-information uncertainty and the identifiability verdicts."""

from __future__ import annotations

import time

import numpy as np

from .._util._checks import instance, integer, nearest, number
from .._util._parallel import check_main_guard
from .._util._tasks import run_tasks
from ..model.assembly import Model, build_model
from ..model.params import Parameters
from . import _consistency, _misfit
from ._accuracy import add_numerical, numerical_of, refined
from ._coarse import coarse_to_fine
from ._failed import FitFailed
from ._fitting import _Fit, new_fit
from ._friction_start import friction_start as friction_start_of
from ._friction_start import start_points
from ._hints import friction_hint, hints_at, hump_score
from ._hold import check_hold, held_doc
from ._methods import check_method, grid, run_method, transcribed_fit
from ._problem import Predictor, free_parameters, given_model, x0_states
from ._records import IdentificationError, Record, read_record, record_list
from ._result import IdentResult, initial_states, uncertainty
from ._robust import record_blocks, robust_covariance
from ._starts import fit_state, install_state
from ._structural import add_structural, check_structural, structural_covariance
from ._unsettled import ROUNDS, check_marks, check_unsettled, left_out_count, marked
from ._unsettled import report as unsettled_report


def identify(params: Parameters, records, free, *, bounds: dict | None = None, sigma: dict | None = None,
             variants: dict | None = None, start: dict | None = None, starts: int = 1, seed: int = 0,
             max_evaluations: int = 60, hold=None, hold_unidentifiable: bool = False, estimate_x0=False,
             consistency: bool = True, model_error: float = _misfit.MODEL_ERROR, allow_misfit: bool = False,
             jobs: int = 1, structural: dict | None = None, method: str = "single", nodes: int | None = None,
             progress: bool = False, model: Model | None = None, friction_start: str = "off",
             coarse_to_fine: bool = False, unsettled: str = "keep") -> IdentResult:
    """Fit named parameters of ``params`` to test records.

    Parameters
    ----------
    params : Parameters
        The parameter set (from :func:`~ema_casadi.model.params.load_parameters`); its values
        are the start of the fit and the values of everything not free.
    records : sequence of str, Path or Record
        Record files (CSV or ``.mat``, see :func:`read_record`) or records read.
    free : sequence of str
        Flat names of the parameters to fit (``["F_seal", "c_v", "J_m"]``).
    bounds : dict, optional
        Name -> (lo, hi) in SI; a log-scaled (positive) parameter needs lo > 0.
    sigma : dict, optional
        Channel -> noise standard deviation (SI). Channels without one take the
        record's field ``sigma_<channel>`` if every record gives it, else are
        estimated from the residuals (one level per channel, over all records).
    variants : dict, optional
        Variant overrides of the model the records are fitted with.
    start : dict, optional
        Name -> start value (SI) instead of the file's.
    starts : int
        Fits from different starts (the first the file's values, the others drawn
        log-normally around it, or a Latin hypercube over the friction parameters
        after a friction start, seeded by ``seed``); the lowest cost wins.
    seed, jobs : int
        Seed of the extra starts; worker processes for them (a script needs a main
        guard for jobs > 1); the result is the same for any jobs.
    max_evaluations : int
        Model evaluations per fit at most; a fit that needs more did not converge.
    hold : dict or sequence of str, optional
        Free parameters to hold after the fit (:mod:`._hold`): name -> value (SI), or
        None for the start value (a sequence of names: each at its start value). The
        others are fitted again without them; each held one adds its type-B term (its
        range: ``structural``'s entry, else its interval while free) to their robust
        intervals. Nothing is held unless asked: a parameter whose robust interval is
        wider than +-50 % is reported with its estimate and marked poorly determined.
    hold_unidentifiable : bool
        Also hold every poorly determined parameter at its start value (as ``hold``).
    estimate_x0 : bool or sequence of str
        Estimate each record's initial state instead of starting it at rest: True for
        the mechanical states (:data:`X0_ROLES`: positions and speeds) and the outer
        loops' integrals, or the state names. Extra free values per record, with exact sensitivities; the parameters'
        intervals include what the unknown start costs.
    consistency : bool
        With several records, test that they agree (each re-fitted alone against all
        together, :mod:`._consistency`).
    model_error : float
        The systematic misfit tolerated, in noise levels (:mod:`._misfit`): a fit whose
        statistical tests fail (chi-square, whiteness, consistency) is *adequate within
        model error* (robust intervals, the misfit named) when every record's and
        channel's systematic misfit is at most this and no record's estimates shift by
        more than 5 x this sandwich sd against the others'; else inadequate.
    allow_misfit : bool
        Confirms a ``model_error`` above :data:`~._misfit.MAX_MODEL_ERROR` (10).
    structural : dict, optional
        Name -> (lo, hi) (SI): constants of the structure held at their values whose
        plausible range adds a type-B component to the headline covariance, the
        estimates' linearised shift over the range (:mod:`._structural`); an entry for
        a parameter named in ``hold`` is that one's range.
    method : {"single", "multiple", "collocation", "auto"}
        How the estimate is found (:mod:`._methods`): single shooting (the
        Levenberg-Marquardt fit from the start values); multiple shooting or Radau
        collocation over the records (node states and parameters as decision variables,
        IPOPT), finished by the single-shooting fit from their estimate; ``auto``: single
        shooting, then collocation where it does not converge or is inadequate. The
        statistics, intervals and verdict are the single-shooting fit's in every case;
        ``info["method"]`` says which ran.
    nodes : int, optional
        Multiple shooting and collocation: intervals per record (default one per 0.5 ms
        of record); at least 1.
    progress : bool
        One line of progress on stderr.
    friction_start : {"off", "auto", "records"}
        Free friction parameters started at the steady-state curve of the records' steady
        segments (:mod:`._friction_start`): ``auto`` where they tell one, ``records``
        requires that (else an IdentificationError), ``off`` (default) the file's values.
    coarse_to_fine : bool
        Fit the residuals' means over blocks of :data:`._coarse.COARSE_BLOCKS_S` (0.2 s, then
        0.1, 0.05, 0.025 s) in turn before every sample: where the records hold
        stick-slip, whose timing moves with the breakaway force by more than the noise,
        the cost over every sample is rugged (a local minimum every few tenths of a
        per cent of the breakaway) and the block means' is smooth. With ``starts`` > 1
        every start is fitted at the coarsest level and the lowest continues
        (``info["coarse_to_fine"]``: the levels' costs, their evaluations, which do not
        count against ``max_evaluations``; ``start_costs`` at the coarsest level). The
        fit on every sample runs from the ladder's end and from the first start, the
        lower cost at the first weights kept (``kept``, ``costs``); the statistics are
        that fit's. Default False.
    unsettled : {"keep", "leave-out"}
        ``leave-out``: the samples the model predicts differently at rtol 1e-8 and
        1e-10 (by more than a third of the noise level, +-20 ms: chaotic stick-slip bursts) get
        weight zero in the fit and its statistics (:mod:`._unsettled`), found at the
        point the fit on every sample starts from and at each optimum (at most two more,
        the fit going on from each); ``info["unsettled"]`` lists them and the points
        searched.
        Default ``keep`` (every sample counts).
    model : Model, optional
        The model of ``params`` and ``variants``, built once by the caller and passed
        down; default built here (a worker process of ``jobs`` builds its own).

    Returns
    -------
    IdentResult
        Estimates, intervals, correlation, identifiability, residuals, trajectories;
        ``info["prediction_accuracy"]``: the predictions checked at the optimum (:mod:`._accuracy`).

    Raises
    ------
    IdentificationError
        A mistake in the request (before any fit).
    FitFailed
        The fit did not converge, or the model fails at the start values.
    """
    t_wall = time.perf_counter()
    instance(params, Parameters, "params", IdentificationError, " (from load_parameters)")
    starts = integer(starts, "starts", IdentificationError, minimum=1)
    seed = integer(seed, "seed", IdentificationError, minimum=0)
    if not isinstance(coarse_to_fine, bool):
        raise IdentificationError(f"coarse_to_fine: expected True or False, got {coarse_to_fine!r}")
    max_evaluations = integer(max_evaluations, "max_evaluations", IdentificationError, minimum=2)
    if isinstance(free, str):
        free = [s.strip() for s in free.split(",") if s.strip()]
    model = given_model(model, params, variants)
    recs = [r if isinstance(r, Record) else read_record(r, model) for r in record_list(records)]
    if not recs:
        raise IdentificationError("records: give at least one record")
    fr, fstart = friction_start_of(model, recs, free_parameters(model, free, bounds, start), friction_start)
    given = _sigmas(recs, sigma)
    xs = x0_states(model, estimate_x0)
    jobs = integer(jobs, "jobs", IdentificationError, minimum=1)
    model_error = _misfit.check_model_error(model_error, allow_misfit)
    if not isinstance(hold_unidentifiable, bool):
        raise IdentificationError(f"hold_unidentifiable: expected True or False, got {hold_unidentifiable!r}")
    values, ranges, structural = check_hold(fr, hold, structural)
    structural = check_structural(model, structural, fr.names)
    method, nodes = check_method(method, nodes, len(recs))
    leave_out = check_unsettled(unsettled)
    check_marks(recs)
    spec = (params, variants, recs, fr, xs, given, max_evaluations)

    def single(first=None):
        try:
            fit, best = _best_start(model, recs, fr, xs, given, max_evaluations, progress, starts, seed, jobs, spec,
                                    fstart, first, coarse_to_fine, leave_out)
            if leave_out:
                fit, best, points = _settled(fit, best, progress)
            marks = fit.pred.records  # with the samples left out marked (unsettled="leave-out")
            fit, best, accuracy = refined(fit, best, lambda rtol, atol: _Fit(
                Predictor(model, marks, fr, model.p(), xs, rtol, atol), given, max_evaluations, progress))
        except FitFailed as exc:  # where the misfit sits at the last iterate: a structure hint
            if exc.iterate and exc.status == "not converged":
                exc.hints = hints_at(new_fit(model, recs, fr, xs, given, 2, False),
                                     [exc.iterate[n] for n in fr.names], fr.names)
            raise
        res = _finish(fit, best, marks, model, params, t_wall, (values, ranges, hold_unidentifiable), consistency,
                      model_error, structural)
        res.info["prediction_accuracy"] = accuracy
        if leave_out or any(r.left_out for r in marks):  # found here, or the records' own marks
            res.info["unsettled"] = {**unsettled_report(marks), "points": points if leave_out else 0}
        if coarse_to_fine:
            res.info["coarse_to_fine"] = {**best["coarse_to_fine"], "start_costs": best["start_costs"]}
        if fstart["mode"] != "off":  # the curve, or why not, and each start's cost
            res.info["friction_start"] = {**fstart, "start_costs": best["start_costs"]}
        return res

    res = run_method(method, single, lambda how: transcribed_fit(model, recs, fr, model.p(), given, how, nodes),
                     sum(len(grid(r, nodes)) - 1 for r in recs))
    res.info["variant_overrides"] = dict(variants or {})
    return res


def _best_start(model, recs, fr, xs, given, max_evaluations, progress, starts, seed, jobs, spec, design=None,
                first=None, coarse=False, leave_out=False):
    """(fit, its optimum): the lowest-cost fit of ``starts`` (ties: the earlier start),
    each from a fresh predictor, on ``jobs`` processes (the result does not depend on
    ``jobs``: a worker's fit is the same computation, its final state handed back);
    ``first`` (SI values: a multiple-shooting or collocation estimate) replaces the first start;
    ``coarse``: coarse to fine (:func:`._coarse.coarse_to_fine`); ``leave_out``: the
    records' unsettled samples left out (:mod:`._unsettled`), found at the first start
    (coarse to fine: at the ladder's end)."""
    points = start_points(fr, starts, seed, design if design and design["used"] else None)
    if first is not None:
        lo, hi = fr.z_bounds()
        points[0] = np.clip(fr.z(first), lo, hi)
    if coarse:
        return coarse_to_fine(model, progress, points, jobs, spec, leave_out)
    if leave_out:
        recs = marked(new_fit(model, recs, fr, xs, given, max_evaluations, False), points[0])
        spec = (*spec[:2], recs, *spec[3:])
    results = []
    if jobs <= 1 or starts == 1:
        for z0 in points:
            fit = new_fit(model, recs, fr, xs, given, max_evaluations, progress)
            try:
                results.append((fit, fit.run(z0)))
            except FitFailed as exc:
                if starts == 1:
                    raise
                results.append((None, exc))
    else:
        check_main_guard(IdentificationError, f"identify(starts={starts}, jobs={jobs})")
        outs = {}  # the records reach each worker once; a task carries start indices
        run_tasks(_starts_in_worker, (*spec, points), range(starts), outs.update, jobs=min(jobs, starts),
                  error=IdentificationError)
        for got in (outs[k] for k in range(starts)):
            if isinstance(got, str):
                results.append((None, got))
                continue
            fit = new_fit(model, recs, fr, xs, given, max_evaluations, progress)
            install_state(fit, got["state"])
            results.append((fit, got["out"]))
    done = [(k, f, o) for k, (f, o) in enumerate(results) if f is not None]
    if not done:
        first = results[0][1]
        why = f"none of the {starts} starts converged ({getattr(first, 'reason', first)})"
        if isinstance(first, FitFailed):  # the first start's last iterate and history
            raise FitFailed(why, status=first.status, iterate=first.iterate, cost=first.cost, history=first.history)
        raise FitFailed(why, status="not converged")
    _, fit, out = min(done, key=lambda t: (t[2]["cost"], t[0]))
    return fit, {**out, "start_costs": [o["cost"] if f is not None else None for f, o in results]}


def _settled(fit, best, progress):
    """(fit, optimum) with the samples unsettled at the optimum left out too
    (:mod:`._unsettled`): where the predictions at the optimum part on samples not yet
    left out, those are added and the fit goes on from the optimum, at most
    :data:`._unsettled.ROUNDS` times (whether a burst is chaotic moves with the
    parameters: found at the start point alone, the windows miss some that the
    optimum's predictions have). Returns (fit, optimum, the points searched); the
    evaluations and cost history carry over."""
    points = 1  # the start point's (or the ladder end's) detection
    for _ in range(ROUNDS):
        more = marked(fit, best["z_full"], best["sigma"])
        points += 1
        if left_out_count(more) == left_out_count(fit.pred.records):  # a union: nothing new
            break
        pred = fit.pred
        nxt = _Fit(Predictor(pred.model, more, pred.free, pred.base, pred.x0_states, pred.rtol, pred.atol),
                   fit.given, fit.max_eval, progress)
        extra = {k: v for k, v in best.items() if k in ("coarse_to_fine", "start_costs")}
        try:
            out = nxt.run(best["z_full"])
        except FitFailed:
            break  # the last optimum, on the windows found so far, stands
        nxt.pred.evaluations += pred.evaluations
        nxt.history = fit.history + nxt.history
        fit, best = nxt, {**out, **extra}
    return fit, best, points


_WORKER_MODEL = [None, None]  # (payload, its model) in a worker process


def _starts_in_worker(payload, chunk) -> dict:
    """Start index -> its optimum and the fit's final state, or the reason it failed, for
    the starts ``chunk`` in a worker process (its model built once per identify)."""
    params, variants, recs, fr, xs, given, max_evaluations, points = payload
    if _WORKER_MODEL[0] is not payload:
        _WORKER_MODEL[:] = [payload, build_model(params, variants)]
    model, outs = _WORKER_MODEL[1], {}
    for k in chunk:
        fit = new_fit(model, recs, fr, xs, given, max_evaluations, False)
        try:
            out = fit.run(points[k])
        except FitFailed as exc:
            outs[k] = exc.reason
            continue
        outs[k] = {"out": out, "state": fit_state(fit)}
    return outs


def _sigmas(recs, sigma) -> dict:
    """Given noise levels: the argument's, then fields ``sigma_<channel>`` present in
    every record that measures the channel."""
    channels = sorted({c for r in recs for c in r.channels})
    out = {}
    for c, v in (sigma or {}).items():
        if c not in channels:
            raise IdentificationError(f"--sigma {c}: no record measures it{nearest(c, channels)}")
        out[c] = number(v, f"--sigma {c}", IdentificationError, positive=True)
    for c in channels:
        if c in out:
            continue
        vals = [r.fields.get(f"sigma_{c}") for r in recs if c in r.channels]
        if vals and all(isinstance(v, float) and v > 0 for v in vals):
            out[c] = float(np.mean(vals))
    return out


def robust_of(fit: _Fit, out: dict, structural: dict | None = None) -> dict:
    """The robust covariance (:mod:`._robust`) of the fit at its optimum ``out``, with the
    type-B term of the ``structural`` constants (:mod:`._structural`) where declared."""
    _, e, _ = fit._raw(out["z_full"])
    rob = robust_covariance(out["J"], out["r"], record_blocks(e))
    return add_numerical(add_structural(rob, structural_covariance(fit, out, structural or {})), out)


def _finish(fit: _Fit, out: dict, recs, model: Model, params, t_wall, hold: tuple,
            consistency_test: bool = True, model_error: float = _misfit.MODEL_ERROR,
            structural: dict | None = None) -> IdentResult:
    """Uncertainty, identifiability (a wide interval: poorly determined, reported with
    its estimate); the parameters ``hold`` asks for (:func:`._hold.check_hold`'s values
    and ranges, and whether to hold every poorly determined one at its start) held and
    the others fitted again, the held ones' type-B term in their intervals; the result."""
    values, ranges, hold_wide = hold
    fr = fit.pred.free
    start = dict(zip(fr.names, fr.theta0.tolist(), strict=True))
    estimated = bool(out["estimated"])
    unc = uncertainty(fr, out["z"], out["J"], out["r"], estimated, robust_of(fit, out, structural), out["samples"])
    evaluations = fit.pred.evaluations
    history = list(fit.history)
    if hold_wide:
        values = {**{n: float(fr.theta0[k]) for k, n in enumerate(fr.names) if unc["wide"][k]}, **values}
    held = {}
    if values and len(values) < len(fr.names):
        theta = fr.theta(out["z"])
        held = held_doc(fr, theta, unc, values, ranges)
        keep = [n for n in fr.names if n not in held]
        base = fit.pred.base.copy()
        base[fr.index] = [held[n]["held_at"] if n in held else v for n, v in zip(fr.names, theta, strict=True)]
        pred = Predictor(model, recs, fr.subset(keep, theta), base, fit.pred.x0_states, fit.pred.rtol, fit.pred.atol)
        sig = {c: out["sigma"][c] for c in out["estimated"]}
        fit2 = _Fit(pred, {**fit.given, **sig}, fit.max_eval, fit.progress)
        z0 = np.concatenate([pred.free.z(pred.free.theta0), out["z_full"][len(fr.names):]])
        out = {**fit2.run(z0), "estimated": out["estimated"], **numerical_of(out, fr.names, keep)}
        fit, fr = fit2, pred.free
        typeb = {**(structural or {}), **{n: tuple(h["range"]) for n, h in held.items()}}
        unc = uncertainty(fr, out["z"], out["J"], out["r"], estimated, robust_of(fit, out, typeb), out["samples"])
        evaluations += pred.evaluations
        history += fit2.history
    theta = fr.theta(out["z"])
    preds, e, _ = fit._raw(out["z_full"])
    res = IdentResult._build(model=model, params=params, free=fr, theta=theta, unc=unc, out=out, records=recs,
                             preds=preds, errors=e, held=held, wall_time=time.perf_counter() - t_wall,
                             evaluations=evaluations, start=start)
    res.info["initial_state"] = initial_states(fit, out)
    res.info["cost_history"] = history
    if consistency_test and len(recs) > 1:
        test = _consistency.consistency(fit, out)
        res.adequacy["consistency"] = test
        extra = _consistency.reasons(test)
        if extra:
            res.adequacy["reasons"] = [*res.adequacy["reasons"], *extra]
            res.adequacy["adequate"] = False
    res.misfits = _misfit.misfits(recs, preds, e, out["sigma"], out["estimated"], model, res.info["units"])
    res.adequacy = _misfit.verdict(res.adequacy, res.misfits, unc["robust"], model_error)
    if not res.adequacy["adequate"]:
        res.info["hints"] = friction_hint(model, recs, preds, e, out["sigma"], out["estimated"], [*fr.names, *held],
                                          hump_score(fit, theta, out["sigma"]))
    return res
