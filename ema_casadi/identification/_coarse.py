"""Coarse to fine (``identify(coarse_to_fine=True)``): the fit on the residuals' block
means first, then on every sample.

Where the records hold stick-slip, the moment the rod breaks away and the bursts after
it move with the breakaway force; a burst displaced by a few milliseconds is a misfit
of many noise levels. The least-squares cost over every sample is then rugged in the
friction parameters: on the witness rigs (``studies/witness.py``) every point of a grid
+-0.5 % in the breakaway ratio and +-5 % in the Stribeck velocity around the truth has
twice the truth's cost, and a local fit from the file's values stops in a valley (seal
friction +5 %, breakaway -10 %, viscous -90 %). Averaged over blocks of N samples, a
displaced burst costs little and the cost is smooth: the block mean of each channel's
residual e_k over samples k = jN .. jN + N - 1, times sqrt(N)/sigma, is one residual
(white noise keeps unit variance); a record's last partial block is left out.

The ladder :data:`COARSE_BLOCKS_S` is fitted coarsest first, each level from the
last one's point, by the Levenberg-Marquardt of :mod:`ema_casadi.optimisation`, with a
weak pull toward the level's start (:data:`COARSE_PRIOR`) so that what block means do
not determine stays put; then the fit on every sample (``identify``'s, with its noise
rounds, accuracy check and statistics) from there, and also from the first start
(as without coarse to fine): the one with the lower cost at the first weights is
kept, so coarse to fine never ends above the plain fit (on the benchmark records of
the identification guide the ladder's 200 ms level stops far from the truth, seal
friction -57 %, and the fit on every sample from there ends inadequate; the plain fit
from the file's values converges). With several starts (``starts``),
each is fitted at the coarsest level with the first start's weights, so that their
costs compare, and the lowest goes on (in parallel with ``jobs``; the result does not
depend on it).
"""

from __future__ import annotations

import numpy as np

from .._util._parallel import check_main_guard
from .._util._tasks import run_tasks
from ..model.assembly import build_model
from ..optimisation import COST_TOL, levenberg_marquardt
from ._failed import FitFailed
from ._fitting import new_fit
from ._records import IdentificationError
from ._unsettled import marked

#: The block lengths (s), coarsest first, over which the residuals are averaged before
#: the fit on every sample.
COARSE_BLOCKS_S = (0.2, 0.1, 0.05, 0.025)
#: Model evaluations per coarse level at most (apart from ``max_evaluations``).
COARSE_EVALUATIONS = 30
#: A coarse level's cost adds sum_i ((z_i - z_i0) / COARSE_PRIOR)^2 / 2 over the free
#: parameters' optimiser coordinates (log for a positive one), z0 the level's start: a
#: direction that block means do not determine (the viscous coefficient, where the
#: speeds are told apart only within a block) stays near its start instead of drifting to
#: a bound the fit on every sample cannot come back from (to 1.5e-7 of it on the built-in
#: example, measured, and 15 sd off at the end).
COARSE_PRIOR = 0.5


def levels(fit, z0, sig: dict, blocks) -> tuple[np.ndarray, list]:
    """Coarse to fine from ``z0`` for ``fit`` (a ``_Fit``): Levenberg-Marquardt on the
    residuals' block means for each block length of ``blocks`` (s) in turn, each from
    the last one's point (at most :data:`COARSE_EVALUATIONS` evaluations each; a level
    that does not converge within them still hands on its best point). Returns (the
    point, per level ``block_s``, ``cost`` (at its own weights), ``evaluations``,
    ``converged``). Their evaluations do not count against ``max_evaluations``."""
    lo, hi = fit.box()
    z = np.clip(fit.full(z0), lo, hi)
    docs, before, kept_round = [], fit.evaluations, fit.round
    fit.round = -1  # the cost history marks the coarse levels' evaluations with round -1
    try:
        for b in blocks:
            fit.blocks = [max(1, int(round(b / float(np.median(np.diff(rec.t)))))) for rec in fit.pred.records]
            n0, centre = fit.evaluations, z.copy()
            sol = levenberg_marquardt(lambda zz, c=centre: _with_prior(fit, zz, sig, c), z, lo, hi,
                                      COARSE_EVALUATIONS, COST_TOL)
            if sol["r"] is None:
                raise fit.failed(f"the model run fails at the start values: {fit.failure}", z, status="failed")
            z = sol["z"]
            docs.append({"block_s": float(b), "cost": float(sol["cost"]), "evaluations": fit.evaluations - n0,
                         "converged": bool(sol["converged"])})
    finally:
        fit.blocks, fit.round, fit._logged = None, kept_round, None
    fit.coarse_evaluations += fit.evaluations - before
    fit.evaluations = before  # max_evaluations is the fit's on every sample
    return z, docs


def _with_prior(fit, z, sig, centre):
    """A coarse level's residuals and Jacobian: the block means', then the free
    parameters' distance from ``centre`` over :data:`COARSE_PRIOR`."""
    z = np.asarray(z, float)
    r, J = fit._eval(z, sig)
    if r is None:
        return None, None
    n = len(fit.pred.free.names)
    rows = np.zeros((n, len(z)))
    rows[:, :n] = np.eye(n) / COARSE_PRIOR
    return np.concatenate([r, (z[:n] - centre[:n]) / COARSE_PRIOR]), np.vstack([J, rows])


def _coarsest(fit, z0, sig):
    """One start at the coarsest level: (its point, cost, level docs), or why it failed."""
    try:
        z, docs = levels(fit, z0, sig, COARSE_BLOCKS_S[:1])
    except FitFailed as exc:
        return exc.reason
    return z, docs[0]["cost"], docs


def coarse_to_fine(model, progress: bool, points, jobs: int, spec, leave_out: bool = False) -> tuple:
    """(fit, its optimum) coarse to fine (module docstring) from the starts ``points``
    (optimiser coordinates) on ``model``; ``spec``: identify's ``(params, variants,
    recs, fr, xs, given, max_evaluations)``. The optimum carries ``coarse_to_fine``
    (the levels of the start kept, the coarse evaluations, the starts, which end was
    kept and both ends' costs at the first weights) and ``start_costs`` (each start's
    cost at the coarsest level); ``leave_out``: the records' unsettled samples at the
    ladder's end left out of both fits on every sample (:mod:`._unsettled`)."""
    fit_spec = (model, *spec[2:])
    fit = new_fit(*fit_spec, progress)
    sig = fit.start_sigma(points[0])
    z, docs, blocks, costs, spent = points[0], [], COARSE_BLOCKS_S, None, 0
    if len(points) > 1:
        got = {}
        if jobs <= 1:
            for k, z0 in enumerate(points):
                one = new_fit(*fit_spec, False)  # a fresh fit per start, as in a worker
                got[k] = _coarsest(one, z0, sig)
                spent += one.coarse_evaluations
        else:
            check_main_guard(IdentificationError, f"identify(starts={len(points)}, jobs={jobs})")
            run_tasks(_in_worker, (*spec, points, sig), range(len(points)), got.update,
                      jobs=min(jobs, len(points)), error=IdentificationError)
            spent = sum(g[3] for g in got.values() if not isinstance(g, str))
        costs = [None if isinstance(got[k], str) else got[k][1] for k in range(len(points))]
        ok = [(c, k) for k, c in enumerate(costs) if c is not None]
        if not ok:
            raise FitFailed(f"none of the {len(points)} starts converged ({got[0]})", status="failed")
        best = min(ok)[1]
        z, docs, blocks = got[best][0], got[best][2], COARSE_BLOCKS_S[1:]
        fit = new_fit(*fit_spec, progress)
    z, more = levels(fit, z, sig, blocks)
    spent += fit.coarse_evaluations
    if leave_out:
        fit_spec = (model, marked(fit, z, sig), *spec[3:])
        fit = new_fit(*fit_spec, progress)
    plain = new_fit(*fit_spec, progress)
    ends = {"coarse": (fit, _on_every_sample(fit, z)), "plain": (plain, _on_every_sample(plain, points[0]))}
    done = {k: fo for k, fo in ends.items() if not isinstance(fo[1], FitFailed)}
    if not done:
        raise ends["coarse"][1]
    # the two optima compared at the same (the first) weights
    cost = {k: 0.5 * float(np.sum(f._eval(o["z_full"], sig)[0] ** 2)) for k, (f, o) in done.items()}
    kept = min(cost, key=lambda k: (cost[k], k != "coarse"))
    fit, out = done[kept]
    out["coarse_to_fine"] = {"levels": docs + more, "evaluations": spent, "starts": len(points), "kept": kept,
                             "costs": cost}
    return fit, {**out, "start_costs": costs if costs is not None else [out["cost"]]}


def _on_every_sample(fit, z):
    """The fit on every sample from ``z``: its optimum, or the FitFailed."""
    try:
        return fit.run(z)
    except FitFailed as exc:
        return exc


_WORKER_MODEL = [None, None]  # (payload, its model) in a worker process


def _in_worker(payload, chunk) -> dict:
    """Start index -> (its point, cost, level docs, evaluations) at the coarsest level,
    or why it failed, for the starts ``chunk`` in a worker process."""
    params, variants, recs, fr, xs, given, max_evaluations, points, sig = payload
    if _WORKER_MODEL[0] is not payload:
        _WORKER_MODEL[:] = [payload, build_model(params, variants)]
    model, outs = _WORKER_MODEL[1], {}
    for k in chunk:
        fit = new_fit(model, recs, fr, xs, given, max_evaluations, False)
        got = _coarsest(fit, points[k], sig)
        outs[k] = got if isinstance(got, str) else (*got, fit.coarse_evaluations)
    return outs
