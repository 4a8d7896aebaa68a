"""The fit's free parameters (scaling, bounds) and the model's predictions of the
records with their exact derivatives.

Free parameters are named parameters of the file; the optimiser works on
``z = log(theta / theta_0)`` for a parameter that must be positive (its schema says so,
or it is non-negative and starts positive) and on ``z = (theta - theta_0) / |theta_0|``
otherwise: z = 0 at the start, and a unit step is a relative change of order one. One
prediction of a record is one run of the compiled RODAS4 with forward sensitivities
(``simulation.forward_sensitivities``) on the record's own sample grid, its inputs the record's columns
as piecewise-linear tables; the records run on a thread pool (the compiled driver
releases the GIL).
"""

from __future__ import annotations

import math
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, fields

import casadi as ca
import numpy as np

from .._util._checks import instance, nearest
from .._util._compiled import BufferCall, compile_function
from .._util._parallel import cores
from ..model.assembly import Model, build_model
from ..model.params import GROUPS, NONNEG, POS, Parameters
from ..simulation import forward_sensitivities, input_signals
from ._records import IdentificationError, Record, available_bytes

#: Tolerances of the prediction runs (RODAS4, the CVODES error norm), where a fit starts.
#: Measured on the seven-parameter recovery case (four records, 12.5 s at 2 kHz,
#: noise-free, at the true values): the bias the discretisation error puts into the
#: estimates is at most 0.16 of their standard deviations with 19 800 steps (0.04 at
#: rtol 3e-5 with 26 600, 0.003 at 1e-6 with 78 000). Not enough everywhere: on records
#: whose loaded stops stick and slip (a Stribeck hump steeper than the damping) the
#: error at 1e-4 is three times the noise's own share of the cost, so every fit checks
#: its optimum at a tenth of the tolerance and tightens it where the estimates move
#: (:mod:`._accuracy`).
RTOL, ATOL = 1e-4, 1e-7

#: The states estimated by ``estimate_x0=True``: the mechanism's positions and speeds,
#: what a record cut from the middle of a motion starts away from, and the integral
#: parts of the outer (non-current) loops, which hold the current that carries the
#: load and friction then. The currents and the current loops' integrals settle within
#: a millisecond of any start (two samples at 2 kHz: not identifiable, and freeing
#: them led the test fit into a worse local minimum); name them explicitly if needed.
X0_ROLES = ("rod_position", "shaft_angle", "rod_velocity", "shaft_speed")

_CHECK = {f.name: f.metadata["check"] for cls in GROUPS.values() for f in fields(cls)}


@dataclass
class Free:
    """The free parameters: names, where they sit in ``p``, their scaling and bounds.

    Attributes
    ----------
    names : tuple of str
        Flat parameter names.
    index : ndarray of int
        Their positions in the model's parameter vector.
    log : ndarray of bool
        Log-scaled (positive) parameters.
    theta0 : ndarray
        The start values (SI).
    lo, hi : ndarray
        Bounds (SI; -inf/inf where none).
    """

    names: tuple
    index: np.ndarray
    log: np.ndarray
    theta0: np.ndarray
    lo: np.ndarray
    hi: np.ndarray

    def z(self, theta) -> np.ndarray:
        """Optimiser coordinates of ``theta``.

        Parameters
        ----------
        theta : array_like
            Parameter values (SI).
        """
        theta = np.asarray(theta, float)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(self.log, np.log(np.abs(theta) / np.where(self.log, self.theta0, 1.0)),
                            (theta - self.theta0) / self._scale())

    def theta(self, z) -> np.ndarray:
        """Parameter values (SI) at optimiser coordinates ``z``.

        Parameters
        ----------
        z : array_like
            Optimiser coordinates.
        """
        z = np.asarray(z, float)
        return np.where(self.log, self.theta0 * np.exp(z), self.theta0 + z * self._scale())

    def dtheta_dz(self, theta) -> np.ndarray:
        """d theta / d z at ``theta``.

        Parameters
        ----------
        theta : array_like
            Parameter values (SI).
        """
        return np.where(self.log, np.asarray(theta, float), self._scale())

    def z_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Bounds in optimiser coordinates."""
        return self.z(self.lo), self.z(self.hi)

    def _scale(self) -> np.ndarray:
        return np.where(self.theta0 != 0, np.abs(self.theta0), 1.0)

    def subset(self, names, theta) -> Free:
        """The free parameters ``names`` only, starting at their values in ``theta``.

        Parameters
        ----------
        names : sequence of str
            A subset of :attr:`names`.
        theta : array_like
            Values of all of :attr:`names` (SI).
        """
        k = [self.names.index(n) for n in names]
        return Free(tuple(names), self.index[k], self.log[k], np.asarray(theta, float)[k], self.lo[k], self.hi[k])


def free_parameters(model, names, bounds: dict | None = None, start: dict | None = None) -> Free:
    """Check the free parameter names and bounds against ``model``.

    Parameters
    ----------
    model : Model
        The model (its parameter names and the parameters its parts use).
    names : sequence of str
        Flat parameter names.
    bounds : dict, optional
        Name -> (lo, hi) in SI.
    start : dict, optional
        Name -> start value (SI); default the model's parameter set.
    """
    names = tuple(names)
    if not names:
        raise IdentificationError("free: name at least one parameter to fit")
    if model.hybrid or model.switched:
        what = "hybrid (stick-slip) friction" if model.hybrid else "a switched PWM bridge"
        raise IdentificationError(f"variants {model.variants}: {what} has no derivatives with respect to the "
                                  "parameters across its switches; identify with the continuous variant "
                                  "(friction=smooth, inverter=ideal)")
    p0 = model.p()
    used = model.used_params
    for n in names:
        if n not in model.param_names:
            raise IdentificationError(f"free parameter '{n}' is not a parameter{nearest(n, model.param_names)}")
        if n not in used:
            raise IdentificationError(f"free parameter '{n}': {model.unused_reason(n)}; no record can tell its "
                                      "value")
        if names.count(n) > 1:
            raise IdentificationError(f"free parameter '{n}' named twice")
    start = dict(start or {})
    for n in start:
        if n not in names:
            raise IdentificationError(f"start value for '{n}', which is not free{nearest(n, names)}")
    index = np.array([model.param_names.index(n) for n in names])
    theta0 = np.array([float(start.get(n, p0[i])) for n, i in zip(names, index, strict=True)])
    check = [_CHECK.get(n) for n in names]
    log = np.array([c == POS or (c == NONNEG and t > 0) for c, t in zip(check, theta0, strict=True)])
    lo = np.where(log, 0.0, -np.inf)
    hi = np.full(len(names), np.inf)
    for k, c in enumerate(check):
        if c == "fraction":
            hi[k] = 1.0
        if c == "signed fraction":  # a band that may sit above (> 0) or below (< 0) a limit
            lo[k], hi[k] = -1.0, 1.0
    bounds = dict(bounds or {})
    for n, (a, b) in bounds.items():
        if n not in names:
            raise IdentificationError(f"--bounds {n}: not a free parameter{nearest(n, names)}")
        k = names.index(n)
        if not (math.isfinite(a) or math.isinf(a)) or not a < b:
            raise IdentificationError(f"--bounds {n}={a:g}:{b:g}: expected LO < HI")
        if log[k] and a <= 0:
            raise IdentificationError(f"--bounds {n}={a:g}:{b:g}: {n} is fitted in log scale (it must be positive); "
                                      f"LO must be > 0")
        lo[k], hi[k] = a, b
    for k, n in enumerate(names):
        if not lo[k] <= theta0[k] <= hi[k] or (log[k] and not theta0[k] > 0):
            raise IdentificationError(f"start value of {n} ({theta0[k]:g}) is outside its bounds "
                                      f"[{lo[k]:g}, {hi[k]:g}]")
    return Free(names, index, log, theta0, lo, hi)


def rest_state(model, rec: Record, pv) -> np.ndarray:
    """The state at rest at the record's first sample: the declared initial state with
    every position-like state at the rod position of the first sample: the command
    ``x_cmd`` where recorded (a servo at rest holds its command; a measured position
    carries its sensor noise into every later sample), else the measured rod
    position, else 0."""
    x0 = model.x0()
    pos = model.state_with("rod_position") if model.states_with("rod_position") else None
    cmd = model.inputs_with("command")
    first = rec.inputs.get(cmd[0]) if cmd and cmd[0] in rec.inputs else rec.channels.get(pos)
    if first is None:
        return x0
    P = model.pdict(pv)
    for n, s in model.state_info.items():
        if s.travel is not None:
            x0[model.index(n)] = first[0] / float(s.travel(P))
    return x0


class Predictor:
    """The model's predictions of a set of records and their derivatives with respect to
    the free parameters' optimiser coordinates.

    Parameters
    ----------
    model : Model
        The model (built once; the parameters are an input).
    records : list of Record
        The records.
    free : Free
        The free parameters.
    base : ndarray
        The full parameter vector the free values are put into.
    x0_states : sequence of str
        States whose initial values are estimated per record (default none: each
        record starts at rest, :func:`rest_state`).
    rtol, atol : float
        Tolerances of the prediction runs (default :data:`RTOL`, :data:`ATOL`).
    """

    def __init__(self, model, records, free: Free, base, x0_states=(), rtol: float | None = None,
                 atol: float | None = None):
        self.model, self.records, self.free = model, list(records), free
        self.rtol, self.atol = float(rtol or RTOL), float(atol or ATOL)
        self.base = np.asarray(base, float)
        self.evaluations = 0
        self.x0_states = tuple(x0_states)
        self.x0_index = np.array([model.index(n) for n in self.x0_states], int)
        #: Units of the estimated initial-state offsets: the states' declared full scale.
        self.x0_scale = model.full_scale(self.base)[self.x0_index] if self.x0_states else np.zeros(0)
        #: Per record: the estimated initial-state offsets (in units of :attr:`x0_scale`).
        self.dx0 = [np.zeros(len(self.x0_states)) for _ in self.records]
        m = len(self.x0_states)
        for rec in self.records:
            _check_memory(model, rec, len(free.names) + m)
        self.steps = [None] * len(self.records)  # the frozen step sequences (None: choose and record)
        self.rows = [None] * len(self.records)  # steps landing on the table rows (chosen at the first run)
        self._signals = [rec.signals() for rec in self.records]  # built once: the tables are checked then
        self._sig = {}
        self._out = None
        if any(c not in model.states for rec in self.records for c in rec.channels):
            self._out = _output_sensitivity(model, len(free.names) + m)

    def x0(self, k: int, pv) -> np.ndarray:
        """Record ``k``'s initial state: at rest (:func:`rest_state`) plus its estimated
        offsets.

        Parameters
        ----------
        k : int
            The record.
        pv : array_like
            The full parameter vector.
        """
        x0 = rest_state(self.model, self.records[k], pv)
        x0[self.x0_index] += self.dx0[k] * self.x0_scale
        return x0

    def refresh(self) -> None:
        """Choose the step sequences anew at the next prediction (error control at the
        parameters then), and freeze them for the ones after."""
        self.steps = [None] * len(self.records)

    def p(self, theta) -> np.ndarray:
        """The full parameter vector with the free values ``theta``.

        Parameters
        ----------
        theta : array_like
            Free parameter values (SI).
        """
        pv = self.base.copy()
        pv[self.free.index] = theta
        return pv

    def predict(self, theta, threads: int | None = None) -> list[dict]:
        """Per record: ``{"X": states (nx x n), "y": {channel: values}, "dy": {channel:
        n x n_free}, "dy0": {channel: n x n_x0}}`` at ``theta`` (derivatives in optimiser
        coordinates; ``dy0`` along the record's estimated initial-state offsets). Raises
        RunFailed where a run fails.

        Parameters
        ----------
        theta : array_like
            Free parameter values (SI).
        threads : int, optional
            Records run at once (default: the cores).
        """
        theta = np.asarray(theta, float)
        pv = self.p(theta)
        W = np.zeros((len(pv), len(theta)))
        W[self.free.index, np.arange(len(theta))] = self.free.dtheta_dz(theta)
        self.evaluations += 1
        n_threads = min(len(self.records), threads or cores())
        if n_threads <= 1:
            return [self._one(k, pv, W) for k in range(len(self.records))]
        with ThreadPoolExecutor(n_threads, thread_name_prefix="ema-identify") as pool:
            return list(pool.map(lambda k: self._one(k, pv, W), range(len(self.records))))

    def _inputs(self, k: int, pv) -> dict:
        """The record's input signals (the undriven inputs at their declared defaults,
        which may name a parameter: rebuilt when such a parameter changes)."""
        model = self.model
        defaults = tuple(pv[model.param_names.index(i.default)] for i in model.input_info.values()
                         if isinstance(i.default, str))
        key = (k, defaults)
        if key not in self._sig:
            self._sig = {kk: v for kk, v in self._sig.items() if kk[0] != k}
            self._sig[key] = input_signals(model, self._signals[k], pv)
        return self._sig[key]

    def _one(self, k: int, pv, W) -> dict:
        model = self.model
        rec = self.records[k]
        sig = self._inputs(k, pv)
        x0 = self.x0(k, pv)
        m, ns = len(self.x0_states), W.shape[1]
        if m:  # the initial-state directions: no parameter change, a unit offset of the state at t0
            W = np.hstack([W, np.zeros((W.shape[0], m))])
        S0 = np.zeros((model.nx, ns + m))
        S0[self.x0_index, ns + np.arange(m)] = self.x0_scale
        if self.rows[k] is None:  # the first run: steps across the table rows, or landing on them if fewer
            X, SX, info = forward_sensitivities(model, sig, rec.t, pv, x0, W, S0, self.rtol, self.atol)
            if info["steps"] > rec.n:
                alt = forward_sensitivities(model, sig, rec.t, pv, x0, W, S0, self.rtol, self.atol, rows=True)
                if alt[2]["steps"] < info["steps"]:
                    X, SX, info = alt
                    self.rows[k] = True
            self.rows[k] = bool(self.rows[k])
        else:
            X, SX, info = forward_sensitivities(model, sig, rec.t, pv, x0, W, S0, self.rtol, self.atol, self.steps[k],
                                           rows=self.rows[k])
        self.steps[k] = info["step_sizes"]
        y, dy = {}, {}
        outs = [c for c in rec.channels if c not in model.states]
        if outs:
            U = sig_value(sig, model, rec.t)
            Y, dY = self._out(X, U, pv, SX, W)
            for c in outs:
                k = model.yindex(c)
                y[c], dy[c] = Y[k], dY[:, :, k]
        for c in rec.channels:
            if c in model.states:
                k = model.index(c)
                y[c], dy[c] = X[k], SX[:, :, k]
        dy0 = {c: d[:, ns:] for c, d in dy.items()}
        dy = {c: d[:, :ns] for c, d in dy.items()}
        return {"X": X, "y": y, "dy": dy, "dy0": dy0, "info": info}


def sig_value(sig: dict, model, t) -> np.ndarray:
    """Inputs (nu x n) of the signals at ``t``."""
    from ..simulation import input_matrix

    return input_matrix(model, sig, t)


_CHUNK = 512


def _output_sensitivity(model, ns: int):
    """``(X, U, p, SX, W) -> (Y ny x n, dY n x ns x ny)``: the outputs and their
    derivatives along the state sensitivities and parameter directions (one compiled,
    mapped call per chunk of samples)."""
    key = ("ident_outputs", ns)
    if key not in model.cache:
        x = ca.SX.sym("x", model.nx)
        u = ca.SX.sym("u", model.nu)
        p = ca.SX.sym("p", len(model.param_names))
        V = ca.SX.sym("V", model.nx, ns)
        W = ca.SX.sym("W", len(model.param_names), ns)
        y = model.f(x, u, p)[1]
        g = ca.Function("ident_out", [x, u, p, V, W], [y, ca.densify(ca.jtimes(y, ca.vertcat(x, p),
                                                                             ca.vertcat(V, W)))])
        gm = g.map(_CHUNK)
        Xs, Us = ca.MX.sym("X", model.nx, _CHUNK), ca.MX.sym("U", model.nu, _CHUNK)
        Ps, Vs = ca.MX.sym("p", len(model.param_names)), ca.MX.sym("V", model.nx, ns * _CHUNK)
        Ws = ca.MX.sym("W", len(model.param_names), ns)
        F = ca.Function(f"ident_out_map_{ns}", [Xs, Us, Ps, Vs, Ws], gm(Xs, Us, Ps, Vs, Ws))
        model.cache[key] = BufferCall(compile_function(F)[0])
    call = model.cache[key]

    def run(X, U, pv, SX, W):
        n, nx, ny = X.shape[1], model.nx, model.ny
        V = SX.reshape(n * ns, nx).T  # nx x (n ns): sample k's block in columns k ns .. k ns + ns - 1
        Y, dY = np.empty((ny, n)), np.empty((ny, n * ns))
        for c in range(0, n, _CHUNK):
            m = min(_CHUNK, n - c)
            Xc, Uc, Vc = np.zeros((nx, _CHUNK)), np.zeros((model.nu, _CHUNK)), np.zeros((nx, ns * _CHUNK))
            Xc[:, :m], Uc[:, :m], Vc[:, : m * ns] = X[:, c : c + m], U[:, c : c + m], V[:, c * ns : (c + m) * ns]
            out = call(Xc, Uc, pv, Vc, W)
            Y[:, c : c + m], dY[:, c * ns : (c + m) * ns] = out[0][:, :m], out[1][:, : m * ns]
        return Y, dY.T.reshape(n, ns, ny)
    return run


def _check_memory(model, rec: Record, ns: int) -> None:
    """Refuse a record whose trajectories and sensitivities would not fit in memory."""
    need = rec.n * model.nx * (ns + 2) * 8 + rec.n * len(rec.channels) * (ns + 2) * 8 * 2
    limit = available_bytes()
    if need > limit:
        raise IdentificationError(f"{rec.path}: {rec.n} samples x {model.nx} states x {ns} free parameters need "
                                  f"about {need / 1e9:.3g} GB for the sensitivities, above the {limit / 1e9:.3g} GB "
                                  f"this machine allows one fit; use a shorter record or fewer samples")


def marginal(J, n: int) -> np.ndarray:
    """The Jacobian's first ``n`` columns with the directions of the others (the
    estimated initial states, nuisance parameters) projected out: its Gram matrix is
    the parameters' Fisher information with the initial states estimated alongside
    (the Schur complement), so the intervals include what the unknown start costs."""
    if J.shape[1] == n:
        return J
    Jt, Jx = J[:, :n], J[:, n:]
    return Jt - Jx @ np.linalg.lstsq(Jx, Jt, rcond=1e-12)[0]


def given_model(model, params: Parameters, variants: dict | None) -> Model:
    """The model of ``params`` and ``variants``: the one the caller built (checked to be
    that model), or built here.

    Parameters
    ----------
    model : Model or None
        The caller's model.
    params : Parameters
        The parameter set.
    variants : dict or None
        Variant overrides.
    """
    if model is None:
        return build_model(params, variants)
    from ..model.components import validate_variants

    instance(model, Model, "model", IdentificationError, " (from build_model)")
    same = np.array_equal(model.params.vector(), params.vector(), equal_nan=True)  # the model keeps a copy
    if not same or dict(model.variants) != validate_variants({**params.variants, **(variants or {})}):
        raise IdentificationError("model: not the model of these parameters and variants "
                                  "(build_model(params, variants))")
    return model


def x0_states(model, estimate_x0) -> tuple:
    """The states whose initial values are estimated: none (False), the states with a
    role in :data:`X0_ROLES` (True), or the names given (checked)."""
    if estimate_x0 is False or estimate_x0 is None:
        return ()
    if estimate_x0 is True:
        return tuple(n for n, s in model.state_info.items() if set(s.roles) & set(X0_ROLES)
                     or ("controller_integral" in s.roles and s.loop not in (None, "current")))
    names = [s.strip() for s in estimate_x0.split(",")] if isinstance(estimate_x0, str) else list(estimate_x0)
    for n in names:
        if n not in model.states:
            raise IdentificationError(f"--estimate-x0 {n}: not a state of the model{nearest(n, model.states)}")
    if not names or len(set(names)) < len(names):
        raise IdentificationError("--estimate-x0: name each state once")
    return tuple(names)
