"""Identification by multiple shooting or collocation: the records' trajectories
transcribed into one NLP (:func:`ema_casadi.optimisation.transcribe`) and solved by
IPOPT (:func:`ema_casadi.optimisation.solve_ipopt`), the estimate then finished by
the single-shooting fit, whose statistics, intervals and verdict are the result's.

Each record's grid has ``nodes`` intervals (default: about one per
:data:`NODE_STEP` of record) ending on samples. The node states are decision
variables (scaled by the states' full scales), started from the measured channels
where a state is measured (rod position and, through the travel, the other position
states; shaft angle, speed, currents) and from a simulation at the start values
elsewhere. Each record starts at rest (as the single-shooting fit's records).
The free parameters are decision variables in the fit's own coordinates (log scale
for a positive one). The NLP minimises

    1/(2 M) sum_records sum_channels sum_nodes ((y_meas - y(X_k, u_k, p)) / sigma)^2

over node states and parameters, M the residuals' count, subject to the dynamics of
each interval:

- ``multiple``: the interval's end state from an implicit integrator (Radau IIA
  collocation with Newton iterations inside the interval, ``ca.integrator``): an
  explicit RK4 would need thousands of substeps where the smooth friction is stiff
  (RK4's stable step at rest is about 6 us on the reference actuator);
- ``collocation``: Radau IIA collocation states of every interval as variables too.

Continuity at every node. The inputs are held over an interval at their value in its
middle; the residuals are taken at the nodes. The transcription's grid is coarser than
the records' and its inputs held: its estimate carries a discretisation bias, which the
single-shooting finish (the compiled RODAS4 on every sample) removes.
"""

from __future__ import annotations

import time

import casadi as ca
import numpy as np

from .._util._checks import integer
from ..optimisation import SUCCESS, decision_parameters, solve_ipopt, transcribe
from ..simulation import RunFailed, captured_stderr, input_matrix, input_signals
from ._failed import FitFailed
from ._problem import Predictor, rest_state
from ._records import IdentificationError

__all__ = ["METHODS", "NODE_STEP", "FALLBACK", "check_method", "run_method", "transcribed_fit"]

#: The methods of ``identify(method=...)``.
METHODS = ("auto", "single", "multiple", "collocation")
#: What ``auto`` tries where single shooting does not converge or its fit is inadequate.
FALLBACK = "collocation"
#: ``auto`` tries :data:`FALLBACK` only where the records' grids have at most this many
#: intervals in all (0.1 s of record at 2 kHz): measured under a load of 15-20 on 2
#: cores, collocation took 28-70 s on 200 intervals and 97-400 s on 600 (37-126 s CPU),
#: beyond the fit's time goal of a minute; longer records keep single shooting's outcome.
AUTO_INTERVALS = 200
#: The default interval of the transcription's grid (s): a sample interval of a 2 kHz
#: record. From the true values of a noise-free 50 ms step record IPOPT converges on this
#: grid (3 parameters, 105 iterations) and stops at its iteration limit on a 1 ms one.
NODE_STEP = 5e-4
#: The free parameters' coordinates stay within this box (a factor e^2.5 = 12 either way): the
#: model is evaluated nowhere its parameters make no sense.
Z_BOX = 2.5
#: IPOPT's settings: the exact Hessian; the cost's scale is 1/2 per residual at the
#: optimum, so tol 1e-8 resolves the estimates far below their standard deviations.
IPOPT = {"max_iter": 300, "tol": 1e-8, "acceptable_tol": 1e-6, "mu_strategy": "adaptive"}
#: The implicit integrator's finite elements per interval (multiple shooting).
ELEMENTS = 2


def check_method(method, nodes, n_records: int) -> tuple[str, int | None]:
    """(method, nodes) checked: a method of :data:`METHODS`; ``nodes`` (intervals per
    record) None or at least 1.

    Parameters
    ----------
    method : str
        The estimation method.
    nodes : int or None
        Intervals per record (None: about one per :data:`NODE_STEP`).
    n_records : int
        The records.
    """
    if method not in METHODS:
        raise IdentificationError(f"method: '{method}' is not a method; choose one of {', '.join(METHODS)}")
    if nodes is not None:
        nodes = integer(nodes, "nodes", IdentificationError)
        if nodes < 1:
            raise IdentificationError(f"nodes: {nodes} intervals per record; give at least one per record "
                                      f"({n_records} records)")
    return method, nodes


def grid(rec, nodes: int | None) -> np.ndarray:
    """The sample indices of a record's nodes (its first and last sample included)."""
    n = rec.n - 1
    N = max(1, round((rec.t[-1] - rec.t[0]) / NODE_STEP)) if nodes is None else nodes
    N = min(N, n)
    return np.unique(np.round(np.linspace(0, n, N + 1)).astype(int))


def _guess(model, rec, X_sim: np.ndarray) -> np.ndarray:
    """The node states' guess at every sample: the simulation, with the measured states
    where measured. (A position state is not derived from a measured one through its
    travel: an elastic screw's deflection, a micrometre, carries the load, and the
    guess would set it to zero.)"""
    X = np.array(X_sim, float)
    for c, meas in rec.channels.items():
        if c in model.states:
            X[model.index(c)] = meas
    return X


def _implicit_interval(model, elements: int | None = None) -> ca.Function:
    """``F(x, u, p, dt) -> x_next``: one interval by Radau IIA collocation solved by
    Newton inside the interval (``ca.integrator``, time scaled to [0, 1])."""
    elements = ELEMENTS if elements is None else elements
    key = ("ident_implicit_interval", elements)
    if key not in model.cache:
        x = ca.MX.sym("x", model.nx)
        u = ca.MX.sym("u", model.nu)
        p = ca.MX.sym("p", len(model.param_names))
        dt = ca.MX.sym("dt")
        q = ca.vertcat(u, p, dt)
        ode = dt * model.f(x, u, p)[0]
        integ = ca.integrator("ident_interval", "collocation", {"x": x, "p": q, "ode": ode}, 0.0, 1.0,
                              {"number_of_finite_elements": elements, "interpolation_order": 3,
                               "collocation_scheme": "radau", "rootfinder": "newton", "simplify": True})
        xn = integ(x0=x, p=q)["xf"]
        model.cache[key] = ca.Function("ident_interval", [x, u, p, dt], [xn])
    return model.cache[key]


def transcribed_fit(model, recs, fr, base, given: dict, method: str, nodes: int | None) -> dict:
    """The free parameters' estimate by ``method`` (``multiple`` or ``collocation``).

    Parameters
    ----------
    model : Model
        The model (continuous).
    recs : list of Record
        The records.
    fr : Free
        The free parameters (their start values: the parameters' guess).
    base : ndarray
        The full parameter vector (SI).
    given : dict
        Channel -> noise level (SI); a channel without one is weighted by its misfit at
        the start (the simulation's RMS residual).
    method : {"multiple", "collocation"}
        The transcription.
    nodes : int or None
        Intervals per record (:func:`grid`).

    Returns
    -------
    dict
        ``estimate`` (SI), ``success``, ``status`` (IPOPT's), ``iterations``, ``wall_s``,
        ``cost`` (per residual), ``nodes`` (intervals per record).

    Raises
    ------
    RunFailed
        The simulation at the start values (the node states' guess) fails.
    """
    t0 = time.perf_counter()
    pred = Predictor(model, recs, fr, base)
    sims = pred.predict(fr.theta0)  # raises RunFailed: the caller's
    pv0 = pred.p(fr.theta0)
    channels = sorted({c for r in recs for c in r.channels})
    sig = {}
    for c in channels:
        e = np.concatenate([r.channels[c] - s["y"][c] for r, s in zip(recs, sims, strict=True) if c in r.channels])
        sig[c] = max(given.get(c, 0.0), float(np.sqrt(np.mean(e * e)))) or 1.0
    opti = ca.Opti()
    p, z = decision_parameters(opti, pv0, fr.index, log=list(fr.log),
                               lower=[None if (lg and lo <= 0) else lo for lg, lo in zip(fr.log, fr.lo, strict=True)],
                               upper=list(fr.hi))
    opti.subject_to(opti.bounded(-Z_BOX, z, Z_BOX))
    scale = np.maximum(model.full_scale(pv0), 1e-6)  # the states' full scales (the records' excursions: worse)
    residuals, counts = [], []
    F = _implicit_interval(model) if method == "multiple" else None
    for rec, sim in zip(recs, sims, strict=True):
        idx = grid(rec, nodes)
        counts.append(len(idx) - 1)
        sigs = input_signals(model, rec.signals(), pv0)
        tn = rec.t[idx]
        U_mid = ca.DM(input_matrix(model, sigs, 0.5 * (tn[:-1] + tn[1:])))
        U_node = ca.DM(input_matrix(model, sigs, tn))
        dts = ca.DM(np.diff(tn)).T
        guess = _guess(model, rec, sim["X"])[:, idx]
        N = len(idx) - 1
        P = ca.repmat(p, 1, N)

        def rates(X, U, P=P):
            return model.f.map(X.shape[1])(X, U, ca.repmat(p, 1, X.shape[1]))

        x0 = rest_state(model, rec, pv0)
        guess[:, 0] = x0
        tr = transcribe(opti, method, x0=x0, guess=guess, scale=scale, U=U_mid, dts=dts, rates=rates,
                        interval=F, interval_args=(U_mid, P, dts))
        X = tr.X[:, 1:]
        Y = model.f.map(N)(X, U_node[:, 1:], P)[1]
        for c, meas in rec.channels.items():
            val = X[model.index(c), :] if c in model.states else Y[model.yindex(c), :]
            residuals.append((ca.DM(meas[idx[1:]]).T - val) / sig[c])
    r = ca.horzcat(*residuals)
    M = r.shape[1]
    opti.minimize(0.5 * ca.sumsqr(r) / M)
    res = solve_ipopt(opti, IPOPT, expand=method == "collocation")
    theta = np.array(res.value(p), float).ravel()[fr.index]
    return {"estimate": theta, "success": bool(res.success and res.status in SUCCESS), "status": res.status,
            "iterations": res.iterations, "wall_s": time.perf_counter() - t0, "cost": float(res.value(opti.f)),
            "nodes": counts}


def run_method(method: str, single, transcription, intervals: int = 0):
    """The fit by ``method``: ``single()`` (single shooting from the start values) or
    ``single(theta)`` (from the estimate ``transcription(how)["estimate"]`` of multiple
    shooting or collocation); ``auto``: single shooting, then :data:`FALLBACK` where
    it does not converge or its fit is inadequate, the better fit kept (adequate first,
    then the lower cost). ``info["method"]`` names the method of the result and
    ``info["methods"]`` what each method tried did.

    Parameters
    ----------
    method : str
        One of :data:`METHODS`.
    single : callable
        ``single(first=None) -> IdentResult``: the single-shooting fit (raises FitFailed).
    transcription : callable
        ``transcription(how) -> dict``: :func:`transcribed_fit` bound to the request.
    intervals : int
        The records' grid intervals in all (``auto`` falls back only up to
        :data:`AUTO_INTERVALS`).
    """
    if method == "single":
        return _tagged(single(), "single", [{"method": "single", "outcome": "converged"}])
    if method in ("multiple", "collocation"):
        tried = []
        return _tagged(_finished(method, single, transcription, tried), method, tried)
    tried = []
    try:
        res = single()
    except FitFailed as exc:
        tried.append({"method": "single", "outcome": exc.reason})
        first = exc
    else:
        if res.adequacy["adequate"]:
            return _tagged(res, "single", [{"method": "single", "outcome": "converged"}])
        tried.append({"method": "single", "outcome": "inadequate", "cost": res.info["cost"]})
        first = res
    if intervals > AUTO_INTERVALS:
        tried.append({"method": FALLBACK, "outcome": f"not tried: {intervals} intervals, above {AUTO_INTERVALS}"})
        if isinstance(first, FitFailed):
            first.reason = f"{first.reason}; {FALLBACK}: {tried[-1]['outcome']}"
            first.args = (first.reason,)
            raise first
        return _tagged(first, "single", tried)
    try:
        other = _finished(FALLBACK, single, transcription, tried)
    except FitFailed:
        if isinstance(first, FitFailed):
            first.reason = f"{first.reason}; {FALLBACK}: {tried[-1]['outcome']}"
            first.args = (first.reason,)
            raise first from None
        return _tagged(first, "single", tried)
    if isinstance(first, FitFailed) or other.adequacy["adequate"] or other.info["cost"] < first.info["cost"]:
        return _tagged(other, FALLBACK, tried)
    return _tagged(first, "single", tried)


def _finished(how: str, single, transcription, tried: list):
    """The transcription's estimate finished by single shooting (FitFailed where either
    fails; ``tried`` gets its outcome)."""
    try:
        with captured_stderr():  # an implicit integrator's failed Newton iterations: IPOPT's business
            est = transcription(how)
    except RunFailed as exc:
        tried.append({"method": how, "outcome": f"the model run fails at the start values: {exc.reason}"})
        raise FitFailed(f"{how}: {tried[-1]['outcome']}", status="failed") from None
    entry = {"method": how, "ipopt_status": est["status"], "iterations": est["iterations"],
             "wall_s": round(est["wall_s"], 3), "nodes": est["nodes"]}
    tried.append(entry)
    if not est["success"]:
        entry["outcome"] = f"IPOPT stopped ({est['status']}) after {est['iterations']} iterations"
        raise FitFailed(f"{how}: {entry['outcome']}", status="not converged")
    try:
        res = single(est["estimate"])
    except FitFailed as exc:
        entry["outcome"] = f"the single-shooting finish did not converge ({exc.reason})"
        exc.reason = f"{how}: {entry['outcome']}"
        exc.args = (exc.reason,)
        raise
    entry["outcome"] = "converged"
    return res


def _tagged(res, method: str, tried: list):
    res.info["method"] = method
    res.info["methods"] = tried
    return res
