"""The Fisher information of a test, from the same predictor and forward sensitivities
as ``identify``, and the trajectory's distance to the declared limits.

For records of a test with Gaussian sensor noise of standard deviation ``sigma_c`` on
channel ``c``, the information about the free parameters' optimiser coordinates ``z``
(``log theta`` for a positive parameter: relative units) is

    M = sum_records sum_c sum_k (dy_c(t_k)/dz)^T (dy_c(t_k)/dz) / sigma_c^2,

the first sample left out as ``identify`` leaves it out (it fixes the start); its
inverse is the covariance ``identify`` reports for a fit of these records with these
noise levels (the Cramer-Rao bound at the parameters). The derivatives come from one
run per record of :class:`~ema_casadi.identification.Predictor` (the compiled RODAS4
with forward sensitivities, ``simulation.forward_sensitivities``): the very numbers the
fit's Jacobian is made of.
"""

from __future__ import annotations

import numpy as np

from ..identification import Z95, Predictor, Record
from ..simulation import input_matrix, input_signals, outputs_at

__all__ = ["Information", "information", "limit_usage", "intervals", "PHYSICAL"]


class Information:
    """The Fisher information of a test and the predicted trajectories it came from.

    Parameters
    ----------
    M : ndarray
        Information matrix (n x n) in the optimiser coordinates of ``free``.
    free : Free
        The free parameters.
    theta : ndarray
        Where it was evaluated (SI).
    usage : dict
        Limit name -> largest value over the test as a fraction of the limit.
    runs : list of dict
        Per record: ``t`` and ``y`` (output name -> predicted values, SI).
    """

    def __init__(self, M, free, theta, usage, runs):
        self.M, self.free, self.theta, self.usage, self.runs = np.asarray(M, float), free, theta, usage, runs

    def intervals(self) -> dict:
        """Predicted 95 % intervals: :func:`intervals` of :attr:`M`."""
        return intervals(self.M, self.free, self.theta)


def intervals(M, free, theta) -> dict:
    """Predicted 95 % intervals from an information matrix: ``cov`` (optimiser
    coordinates), ``corr``, ``width`` (relative width (hi - lo) / theta of each interval,
    inf where the information is singular in that parameter), ``interval`` (SI).

    Parameters
    ----------
    M : ndarray
        Information (n x n) in optimiser coordinates.
    free : Free
        The free parameters.
    theta : array_like
        The parameter values (SI).
    """
    theta = np.asarray(theta, float)
    M = np.asarray(M, float)
    w, V = np.linalg.eigh(0.5 * (M + M.T))
    good = w > max(w[-1], 0.0) * 1e-14
    with np.errstate(divide="ignore"):
        inv = np.where(good, 1.0 / np.where(good, w, 1.0), np.inf)
    cov = (V * np.where(np.isinf(inv), 0.0, inv)) @ V.T
    singular = np.any(np.abs(V[:, ~good]) > 1e-8, axis=1) if (~good).any() else np.zeros(len(theta), bool)
    sd = np.where(singular, np.inf, np.sqrt(np.maximum(np.diag(cov), 0.0)))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(sd, sd)
    corr = np.where(np.isfinite(corr), corr, 0.0)
    np.fill_diagonal(corr, 1.0)
    h = Z95 * sd
    with np.errstate(over="ignore", invalid="ignore"):
        lo = np.where(free.log, theta * np.exp(-h), theta - h * free.dtheta_dz(theta))
        hi = np.where(free.log, theta * np.exp(h), theta + h * free.dtheta_dz(theta))
        width = np.where(np.isfinite(h), (hi - lo) / np.abs(theta), np.inf)
    return {"cov": cov, "corr": corr, "sd": sd, "width": width, "interval": np.column_stack([lo, hi])}


def _records(model, test, channels) -> list:
    """The test's records as identification records (zero measurements: only the
    predictions and their derivatives are used)."""
    out = []
    for r in test.records:
        t = np.asarray(r["t"], float)
        out.append(Record(r["name"], t, {k: np.asarray(v, float) for k, v in r["inputs"].items()},
                          {c: np.zeros_like(t) for c in channels}))
    return out


def information(model, test, free, sigma: dict, theta=None, threads: int | None = None, stroke: float | None = None,
                max_load: float | None = None, max_speed: float | None = None, lead_in: float = 0.0) -> Information:
    """The Fisher information of ``test`` about ``free`` at ``theta``, and how close its
    predicted trajectory comes to the model's declared limits.

    Parameters
    ----------
    model : Model
        The assembled model.
    test : Test
        The records to run (command and load).
    free : Free
        The free parameters (``identification.free_parameters``).
    sigma : dict
        Measured channel -> noise standard deviation (SI).
    theta : array_like, optional
        Parameter values (SI); default the start values of ``free``.
    threads : int, optional
        Records run at once.
    stroke, max_load : float, optional
        The test's stroke (m) and load capability (N), checked with the declared limits.
    max_speed : float, optional
        The rod speed bound (m/s); default the declared one.
    lead_in : float
        Time (s) at the start of each record that is run but whose samples are not
        counted in ``M`` (a candidate's lead-in: the state it starts its counted part
        from is the one a test reaches, not rest); the limits count every sample.
    """
    theta = free.theta0 if theta is None else np.asarray(theta, float)
    recs = _records(model, test, list(sigma))
    pred = Predictor(model, recs, free, model.p())
    out = pred.predict(theta, threads)
    n = len(free.names)
    M = np.zeros((n, n))
    for rec, pr in zip(recs, out, strict=True):
        # the first sample fixes the start; with a lead-in, its last sample is its own
        first = 1 + (int(np.searchsorted(rec.t, rec.t[0] + lead_in - 1e-9)) if lead_in > 0 else 0)
        for c, s in sigma.items():
            d = pr["dy"][c][first:]
            M += d.T @ d / s**2
    pv = pred.p(theta)
    usage, runs = {}, []
    for rec, pr in zip(recs, out, strict=True):
        sig = input_signals(model, rec.signals(), pv)
        U = input_matrix(model, sig, rec.t)
        Y = outputs_at(model, pr["X"], U, pv)
        y = {name: np.asarray(pr["X"])[k] for k, name in enumerate(model.states)}
        y.update({name: Y[k] for k, name in enumerate(model.outputs)})
        y.update({name: U[k] for k, name in enumerate(model.inputs)})
        runs.append({"t": rec.t, "y": y})
        for name, v in limit_usage(model, y, pv, stroke, max_load, max_speed).items():
            usage[name] = max(usage.get(name, 0.0), v)
    return Information(M, free, theta, usage, runs)


#: The ECU's limits checked on the physical signal they protect (the signal with this
#: role) rather than on the controller's command they clip, where no rating bounds that
#: signal: the current limit on the motor current, the rate limit on the rod speed. A
#: test may run the ECU into its limiters (a step test does); the motor current and the
#: rod speed must stay within their bounds (the loops' overshoot counts).
PHYSICAL = {"current": "motor_current", "rod_speed": "rod_velocity"}


def _peak(model, lim, y: dict, P) -> np.ndarray:
    """|value| of a trim limit along a trajectory (on its physical signal, :data:`PHYSICAL`)."""
    role = PHYSICAL.get(lim.name)
    if role is not None and model.outputs_with(role):
        return np.abs(np.asarray(y[model.output_with(role)], float))
    try:
        return np.abs(np.asarray(lim.value(y, P), float))
    except TypeError:  # a limit written for one sample (math functions): sample by sample
        n = len(next(iter(y.values())))
        return np.array([lim.value({k: a[i] for k, a in y.items()}, P) for i in range(n)])


def limit_usage(model, y: dict, pv, stroke: float | None = None, max_load: float | None = None,
                max_speed: float | None = None) -> dict:
    """The largest value over a trajectory of each limit as a fraction of it: the parts'
    ratings (``model.ratings`` of role ``rating`` whose signals the trajectory holds, the
    operating limits ``ema optimal`` keeps too: the current and voltage vectors, the
    actuator's stroke, the rated rod speed, the thermal nodes' temperatures with a
    thermal network); the ECU's limits (``model.trim_limits``) that no rating of the
    same name bounds, on the physical signal they protect (:data:`PHYSICAL`); and, where
    given, the test's stroke (rod position) and load capability.

    Parameters
    ----------
    model : Model
        The model.
    y : dict
        State, output and input name -> values along the trajectory (SI).
    pv : array_like
        Parameter vector (SI).
    stroke, max_load : float, optional
        The test's stroke (m) and load capability (N).
    max_speed : float, optional
        The rod speed bound (m/s) in place of the declared one.
    """
    P = model.pdict(pv)
    out = {}

    def use(name, value):
        out[name] = max(out.get(name, 0.0), float(value))

    rated = [r for r in model.ratings if r.role == "rating" and r.sense != "min" and all(n in y for n in r.signals)]
    for r in rated:
        s = np.array([np.asarray(y[n], float) for n in r.signals])
        peak = np.max(np.sqrt((s**2).sum(0))) if r.sense == "norm" else np.max(s[0])
        use(r.name, peak / (max_speed if r.name == "rod_speed" and max_speed else r.limit(P)))
    for lim in model.trim_limits:
        if lim.name not in {r.name for r in rated}:
            use(lim.name, np.max(_peak(model, lim, y, P)) / (max_speed if lim.name == "rod_speed" and max_speed
                                                             else lim.limit(P)))
    if stroke is not None:
        use("stroke", np.max(np.abs(y[model.output_with("rod_position")])) / stroke)
    if max_load:
        out["load"] = float(np.max(np.abs(y[model.input_with("load")])) / max_load)
    return out
