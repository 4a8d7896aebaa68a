"""The optimal-control problem of one move, by direct multiple shooting or, where the
RK4 chain would be too long for the exact Hessian, by direct collocation (module docs:
:mod:`ema_casadi.optimal`; the collocation equations: :mod:`._collocation`)."""

from __future__ import annotations

import math
import time

import casadi as ca
import numpy as np

from .._util import _interrupts
from ..linearisation import operating_point
from ..model.assembly import Model
from ..optimisation import continuity, multiple_shooting, solve_ipopt
from ..signals import Signal
from ..simulation import captured_stderr, interval_function, jacobian_step_limit, simulate, step_response_metrics
from ._collocation import WARM, collocation, widened
from ._errors import Infeasible
from ._request import LEVELS, METHODS, OBJECTIVES, check_method, check_request

__all__ = ["OBJECTIVES", "LEVELS", "METHODS", "INTERVALS", "Problem", "solve", "rk4_substeps", "initial_guess",
           "check_request"]

#: Shooting intervals of a move (default).
INTERVALS = 40
#: RK4 substeps are kept at this fraction of RK4's stability limit on the interval's
#: modes (:func:`~ema_casadi.simulation.jacobian_step_limit`).
STABILITY_FRACTION = 0.5
#: Substeps in all (intervals x substeps) up to which the shooting NLP is expanded to SX with its exact
#: Hessian; above it ``auto`` collocates (a shooting asked for keeps the chain as MX calls with a
#: quasi-Newton Hessian: 10 mm against 15 kN, 40 x 695 substeps, 90 iterations, 120 s).
EXPAND_LIMIT = 400
#: A limit counts as binding where the optimum sits within this fraction of it.
BINDING = 1e-3
#: Node spacing: the share of a cosine (Chebyshev) grid in the shooting grid of a
#: minimum-time move, whose current and voltage transients sit at its two ends (the
#: rest is uniform); energy and heat moves use a uniform grid.
CLUSTER = 0.8
#: States an optimal move ends at rest in: their rates are zero at the last node.
_REST_ROLES = ("shaft_speed", "rod_velocity", "contact_velocity")


def rk4_substeps(model: Model, x: np.ndarray, u: np.ndarray, p: np.ndarray, dt: float, held_h=None) -> int:
    """RK4 substeps for an interval ``dt`` (s) from RK4's stability limit on the
    Jacobian's eigenvalues at the state ``x`` (each along its own direction,
    :func:`~ema_casadi.simulation.jacobian_step_limit`): substeps of at most
    STABILITY_FRACTION x that limit.

    Parameters
    ----------
    model : Model
        The model.
    x, u, p : ndarray
        State, inputs and parameters (SI) where the Jacobian is taken.
    dt : float
        The interval (s).
    held_h : ndarray, optional
        Held controller outputs: the Jacobian of ``f_held`` (default: of ``f``).
    """
    xs = ca.SX.sym("x", model.nx)
    f = model.f_held(xs, u, p, held_h)[0] if held_h is not None else model.f(xs, u, p)[0]
    A = np.array(ca.Function("A", [xs], [ca.jacobian(f, xs)])(x))
    return max(1, math.ceil(dt / (STABILITY_FRACTION * jacobian_step_limit(A)) - 1e-12))


class Problem:
    """One move's optimal-control problem on the smooth variant of a model (what a peer
    tool is given to solve the same problem: ``model``, ``p``, :meth:`start_state`,
    :meth:`fractions`, :meth:`build`).

    Parameters
    ----------
    model : Model
        The actuator; the problem is built on its smooth variant (attribute ``model``)
        with the backlash closed (attribute ``p``, the parameter vector).
    move, load, start : float
        The move (m), the constant load (N), the start position (m).
    objective : str
        One of :data:`OBJECTIVES`.
    duration : float or None
        The fixed duration (s) of an energy or heat move.
    through : str
        One of :data:`LEVELS`.
    intervals : int
        Shooting intervals.
    field_weakening : bool
        Lift the drive-strategy ratings.
    inputs : dict, optional
        Other constant inputs by name or role (``ambient_temperature``: degC).
    method : str
        One of :data:`METHODS`; the one used is attribute ``method`` after :meth:`build`.
    """

    def __init__(self, model: Model, move: float, load: float, objective: str, duration: float | None,
                 start: float, through: str, intervals: int, field_weakening: bool, inputs: dict | None = None,
                 method: str = "auto"):
        self.method, self.substeps = check_method(method), None
        self.p_nlp, self._building = None, False  # the parameters as the NLP's (Opti) parameter: build()
        self.full, self.move, self.load, self.objective = model, move, load, objective
        self.duration, self.start, self.through, self.N = duration, start, through, intervals
        self.field_weakening = field_weakening
        smooth = model.smooth()
        self.model = smooth
        # the backlash closed (the model's small-signal policy): a dead zone has no derivative in its gap
        self.p = smooth.p(**smooth.small_signal(backlash="off"))
        self.cmd = smooth.input_with("command")
        self.load_input = smooth.input_with("load")
        self.extra = {smooth.input_name(k): float(v) for k, v in (inputs or {}).items()}
        self.ratings = [r for r in smooth.ratings if field_weakening is False or r.role != "strategy"]
        self.ratings = [r for r in self.ratings if all(s in smooth.states or s in smooth.outputs for s in r.signals)]
        self.limits = {r.name: float(r.limit(smooth.pdict(self.p))) for r in self.ratings}
        stroke = next(r for r in self.ratings if r.name == "stroke")
        self.rod = stroke.signals[0]  # the rod's mechanical position: the signal the stroke limits
        self.target = start + move
        if through == "drive":
            inner = list(smooth.loops)[-1]
            self.controls = [i for i, h in enumerate(smooth.holds) if h.loop == inner]
        else:
            self.controls = [smooth.inputs.index(self.cmd)]

    def fractions(self) -> np.ndarray:
        """The nodes as fractions of the move's duration (0 ... 1)."""
        k = np.arange(self.N + 1) / self.N
        beta = CLUSTER if self.objective == "time" else 0.0
        return (1 - beta) * k + beta * (1 - np.cos(np.pi * k)) / 2

    # -- the signals ----------------------------------------------------------------
    def _signal(self, name, x, y):
        """A state's or output's row of x or y."""
        if name in self.model.states:
            return x[self.model.index(name), :]
        return y[self.model.yindex(name), :]

    # -- the start, the guess --------------------------------------------------------
    def start_state(self) -> np.ndarray:
        op = operating_point(self.model, p=self.p,
                             inputs={self.cmd: self.start, self.load_input: self.load, **self.extra})
        return np.asarray(op.x, float)

    def _ecu_step(self, t_end: float, x0: np.ndarray):
        """The ECU's own step response on the smooth model (the guess) as a SimResult."""
        return simulate(self.model, t_end, p=self.p, x0=x0, dt_out=t_end / 400,
                        inputs={self.cmd: Signal.step(self.target, 0.0) if self.move else self.target,
                                self.load_input: self.load, **self.extra})

    # -- the NLP -----------------------------------------------------------------------
    def _inputs(self, C):
        """(U, H): the model inputs and held outputs of every interval (columns) for the
        controls C (rows: the controls, columns: the intervals)."""
        n = C.shape[1]
        u0 = self._u0()
        U = ca.repmat(ca.MX(u0), 1, n)
        H = ca.MX.zeros(len(self.model.holds), n)
        for j, i in enumerate(self.controls):
            if self.through == "drive":
                H[i, :] = C[j, :]
            else:
                U[i, :] = C[j, :]
        return U, H

    def _u0(self) -> np.ndarray:
        return self.model.u(self.p, **{self.load_input: self.load, self.cmd: self.target, **self.extra})

    def _rates(self, X, C):
        """(xdot, y) at the columns of X with the controls of the columns of C."""
        U, H = self._inputs(C)
        n = X.shape[1]
        P = ca.repmat(self.p_nlp if self._building else ca.MX(self.p), 1, n)
        if self.through == "drive":
            return self.model.f_held.map(n)(X, U, P, H)
        return self.model.f.map(n)(X, U, P)

    def build(self, x0: np.ndarray, guess) -> tuple:
        """The NLP in CasADi's Opti: (opti, Xs, Cs, T, scale, c_scale), the scaled states
        (nx x N+1) and controls (nc x N), the duration and the scales. The transcription
        (attribute ``method``) is resolved here: :data:`METHODS`.

        Parameters
        ----------
        x0 : ndarray
            The start state (:meth:`start_state`).
        guess : dict
            The initial guess (``T``, ``X``, ``C``, ``cost_scale``), from :func:`initial_guess`.
        """
        m, N = self.model, self.N
        opti = ca.Opti()
        self.substeps = self._substeps(x0, guess)
        if self.method == "auto":
            self.method = "shooting" if self.N * self.substeps <= EXPAND_LIMIT else "collocation"
        if self.method == "collocation":  # the parameters an Opti parameter: solve() widens a switch first
            self.p_nlp, self._building = opti.parameter(len(self.p)), True
            opti.set_value(self.p_nlp, self.p)
        scale = np.maximum(m.full_scale(self.p), 1e-6)
        Xs = opti.variable(m.nx, N + 1)
        X = ca.diag(scale) @ Xs
        c_scale = self._control_scale()
        Cs = opti.variable(len(self.controls), N)
        C = ca.diag(c_scale) @ Cs
        if self.objective == "time":
            T = opti.variable()
            opti.subject_to(opti.bounded(0.05 * guess["T"], T, 20 * guess["T"]))
            opti.set_initial(T, guess["T"])
        else:
            T = self.duration
        dts = T * ca.DM(np.diff(self.fractions())).T
        X_next, cost, inner = self._dynamics(opti, x0, guess, Xs, X, C, dts, scale)
        opti.subject_to(Xs[:, 0] == x0 / scale)
        # continuity, but a memory state at rest on its signal (the play with the gap closed) is that signal
        rest_on = m.rest_states(self.p)
        free = [i for i, n in enumerate(m.states) if n not in rest_on]
        continuity(opti, Xs, X_next, scale, free)
        # the limits at both ends of every interval, with its control (both transcriptions: the same NLP but
        # for the dynamics); the memory states at rest at the nodes and at the collocation points
        _, Y0 = self._rates(X[:, :-1], C)
        _, Y1 = self._rates(X[:, 1:], C)
        for Xn, Yn in [(X[:, 1:], Y1), *inner]:
            self._hold(opti, Xn, Yn, rest_on, scale)
        for Xn, Yn in ((X[:, :-1], Y0), (X[:, 1:], Y1)):
            self._constrain(opti, Xn, Yn)
        self._end(opti, Xs, X, C, scale, guess["T"], rest_on)
        opti.minimize(T / guess["T"] if self.objective == "time" else cost / guess["cost_scale"])
        opti.set_initial(Xs, guess["X"] / scale[:, None])
        opti.set_initial(Cs, guess["C"] / c_scale[:, None])
        self.cost, self._building = cost, False
        return opti, Xs, Cs, T, scale, c_scale

    def _dynamics(self, opti, x0, guess, Xs, X, C, dts, scale) -> tuple:
        """(X_next, cost, points): every interval's end state (nx x N), the cost's quadrature
        and the collocation points' (X, Y) (none for the shooting)."""
        if self.method == "collocation":
            return collocation(self, opti, Xs, C, dts, scale, guess)
        F = interval_function(self.model, held=self.through == "drive", substeps=self.substeps,
                              quadrature=self._power_outputs())
        U, H = self._inputs(C)
        P = ca.repmat(ca.MX(self.p), 1, self.N)
        out = multiple_shooting(F, X, U, P, H, dts) if self.through == "drive" else multiple_shooting(F, X, U, P, dts)
        return (out[0], ca.sum2(out[1]), []) if self._power_outputs() else (out, 0, [])

    def _hold(self, opti, X, Y, rest_on, scale) -> None:
        """A memory state at rest on its signal is that signal at the columns of X, Y."""
        for n, sig in rest_on.items():
            i = self.model.index(n)
            opti.subject_to(ca.vec(X[i, :] - self._signal(sig, X, Y)) / scale[i] == 0)

    def _end(self, opti, Xs, X, C, scale, T_guess, rest_on) -> None:
        """The end: at the target, at rest, every rate but the temperatures' (and the held
        controller integrals') zero; a rate the speeds at rest make zero already (the shaft
        angle's, the shaft speed) not again (:meth:`_kinematic`)."""
        m, N = self.model, self.N
        xdot, y = self._rates(X[:, N], C[:, N - 1])
        opti.subject_to(self._signal(self.rod, X[:, N], y) == self.target)
        held = self.through == "drive"
        rates, rest = [], []
        implied = self._kinematic()
        for i, n in enumerate(m.states):
            roles = m.state_info[n].roles
            if "temperature" in roles or (held and "controller_integral" in roles) or n in rest_on:
                continue
            if i not in implied:
                rates.append(xdot[i] / (scale[i] / T_guess))
            if set(roles) & set(_REST_ROLES):
                rest.append(Xs[i, N])
        opti.subject_to(ca.vertcat(*rates, *rest) == 0)

    def _kinematic(self) -> set:
        """States whose rate is a function of the resting states (shaft speed, rod and
        contact velocities) alone, zero where they are (a position's rate, its speed):
        their rate's end condition would repeat the speeds' (a rank-deficient Jacobian,
        whose multipliers IPOPT's least-squares start leaves to the BLAS kernel's rounding)."""
        m = self.model
        xs, us, hs = ca.SX.sym("x", m.nx), ca.SX.sym("u", m.nu), ca.SX.sym("h", len(m.holds))
        xdot = m.f_held(xs, us, self.p, hs)[0] if self.through == "drive" else m.f(xs, us, self.p)[0]
        at_rest = [i for i, n in enumerate(m.states) if set(m.state_info[n].roles) & set(_REST_ROLES)]
        zero = ca.Function("xdot", [xs, us, hs], [xdot])(np.zeros(m.nx), self._u0(), np.zeros(len(m.holds)))
        out = set()
        for i in range(m.nx):
            dx, du, dh = (np.array(ca.which_depends(xdot[i], v, 1, False)) for v in (xs, us, hs))
            if dx.any() and not du.any() and not dh.any() and set(np.flatnonzero(dx)) <= set(at_rest) \
                    and float(zero[i]) == 0.0:
                out.add(i)
        return out

    def _control_scale(self) -> np.ndarray:
        if self.through == "drive":
            return np.full(len(self.controls), self.limits.get("voltage", 1.0))
        return np.array([self.limits["stroke"]])

    def _power_outputs(self) -> tuple:
        if self.objective == "energy":
            return (self.model.output_with("electrical_power"),)
        if self.objective == "heat":
            return self.model.heat_outputs("winding")
        return ()

    def _constrain(self, opti, X, Y):
        """Every rating at the columns of X (states) and Y (outputs)."""
        for r in self.ratings:
            sig = [self._signal(n, X, Y) for n in r.signals]
            lim = self.limits[r.name]
            if r.sense == "norm":
                opti.subject_to(ca.vec(sum(v**2 for v in sig) / lim**2) <= 1)
            elif r.sense == "max":
                opti.subject_to(ca.vec(sig[0]) <= lim)
            else:
                opti.subject_to(ca.vec(sig[0]) >= lim)

    def _substeps(self, x0, guess) -> int:
        """RK4 substeps per interval within half RK4's stability limit at the start and at
        the guess's middle node (:func:`rk4_substeps`, the longest interval, twice)."""
        held = self.through == "drive"
        h0 = np.zeros(len(self.model.holds)) if held else None
        u0 = self._u0()
        dt_max = (guess["T"] if self.objective == "time" else self.duration) * np.diff(self.fractions()).max()
        return max(rk4_substeps(self.model, x, u0, self.p, 2 * dt_max, h0) for x in (x0, guess["X"][:, self.N // 2]))


def initial_guess(prob: Problem, x0: np.ndarray) -> dict:
    """Initial guess from the ECU's own step response: its 2 % settling time (or the
    given duration) and its states and controls resampled on the shooting grid.

    Parameters
    ----------
    prob : Problem
        The problem.
    x0 : ndarray
        The start state.
    """
    m = prob.model
    t_try = max(prob.duration or 0.0, 0.05)
    for _ in range(6):
        res = prob._ecu_step(t_try, x0)
        y = (res[m.output_with("rod_position")] - prob.start) / prob.move if prob.move else None
        settle = step_response_metrics(res.t, y)["settling_time_s"] if prob.move else 0.0
        if math.isfinite(settle) and (prob.duration is None or settle <= t_try):
            break
        t_try *= 2
    # the ECU's step that never reaches the band (a load it cannot move against): its whole window
    T = prob.duration if prob.duration is not None else max(settle if math.isfinite(settle) else t_try, 1e-3)
    tk = T * prob.fractions()
    X = np.array([np.interp(tk, res.t, res[n]) for n in m.states])
    if prob.through == "drive":
        holds = [m.holds[i].name for i in prob.controls]
        C = np.array([np.interp(tk[:-1], res.t, res[n]) if n in res.outputs else np.zeros(prob.N) for n in holds])
    else:
        C = np.full((1, prob.N), prob.target)
    ref = 1.0
    power = prob._power_outputs()
    if power:
        ref = max(abs(float(np.trapezoid(sum(res[n] for n in power), res.t))), 1e-6)
    return {"T": T, "X": X, "C": C, "cost_scale": ref, "ecu": res, "ecu_settle": settle}


def solve(prob: Problem, *, max_iter: int = 500, tol: float = 1e-8) -> dict:
    """Solve the problem; returns the raw solution (grid, states, controls, outputs, IPOPT's
    statistics). Raises :class:`Infeasible` naming the limit that binds where IPOPT stops.
    In the ``ema`` process it runs in a forked child, so that SIGINT/SIGTERM end it at
    once even while CasADi builds the NLP's derivatives (``_interrupts.interruptible``).

    Parameters
    ----------
    prob : Problem
        The problem.
    max_iter : int
        IPOPT's iteration limit.
    tol : float
        IPOPT's convergence tolerance.
    """
    return _interrupts.interruptible(_solve, prob, max_iter, tol)


def _solve(prob: Problem, max_iter: int, tol: float) -> dict:
    """:func:`solve` in this process.

    Parameters
    ----------
    prob : Problem
        The problem.
    max_iter : int
        IPOPT's iteration limit.
    tol : float
        IPOPT's convergence tolerance.
    """
    t0 = time.perf_counter()
    x0 = prob.start_state()
    guess = initial_guess(prob, x0)
    opti, Xs, Cs, T, scale, c_scale = prob.build(x0, guess)
    # collocation and a short RK4 chain expanded to SX with the exact Hessian; a long chain of substeps
    # (a shooting asked for) kept as calls (MX) with a quasi-Newton Hessian (the exact one is slow)
    small = prob.method == "collocation" or prob.N * prob.substeps <= EXPAND_LIMIT
    # the monotone barrier from mu 1e-2 (the guess is near-feasible): on the reference 10 mm minimum time 28
    # iterations against the adaptive strategy's 241 (the same optimum to 2e-7), field weakening converges there
    # (adaptive: Restoration_Failed), energy 39 against 48
    ipopt = {"print_level": 0, "max_iter": max_iter, "tol": tol, "mu_strategy": "monotone", "mu_init": 1e-2}
    if not small:
        ipopt["hessian_approximation"] = "limited-memory"
    # where the monotone barrier stops short (20 mm soaked at 20 degC with the thermal network: a local
    # infeasibility), the adaptive one from the same guess
    strategies = (ipopt, {**ipopt, "mu_strategy": "adaptive", "mu_init": 0.1})
    t_setup = time.perf_counter() - t0
    # CasADi's warnings of NaN trial points in IPOPT's line search (the solver steps back) kept
    # off stderr: counted in the result instead
    with captured_stderr() as messages:
        stages, ok = [], False
        # collocation: the switches widened first (smoother problems), each optimum the next one's warm start
        warm = None
        for p in [*widened(prob), prob.p] if prob.method == "collocation" else []:
            opti.set_value(prob.p_nlp, p)
            res = solve_ipopt(opti, {**ipopt, **WARM} if warm else strategies, expand=small, warm=warm)
            stats, ok, val = res.stats, res.success, res.value
            stages.append(res.iterations)
            if not ok:
                break
            warm = res.warm
        if stages and not ok:  # from the guess at the model's own width
            opti, Xs, Cs, T, scale, c_scale = prob.build(x0, guess)
        if not ok:
            res = solve_ipopt(opti, strategies, expand=small)
            stats, ok, val = res.stats, res.success, res.value
            stages.append(res.iterations)
    X = np.asarray(val(Xs)).reshape(prob.model.nx, -1) * scale[:, None]
    C = np.asarray(val(Cs)).reshape(len(prob.controls), -1) * c_scale[:, None]
    Tv = float(val(T)) if prob.objective == "time" else float(T)
    cost = Tv if prob.objective == "time" else float(val(prob.cost))
    out = {"T": Tv, "X": X, "C": C, "t": Tv * prob.fractions(), "status": stats["return_status"],
           "iterations": sum(stages), "stages": stages, "solve_time_s": time.perf_counter() - t0 - t_setup,
           "setup_time_s": t_setup, "cost": cost,
           "warnings": messages.getvalue().count("WARNING"), "guess": guess, "x0": x0, "substeps": prob.substeps,
           "method": prob.method}
    out["Y"] = _outputs(prob, X, C)
    out["margins"] = _margins(prob, X, out["Y"])
    if not ok:
        worst = min(out["margins"].items(), key=lambda kv: kv[1])
        r = next(r for r in prob.ratings if r.name == worst[0])
        raise Infeasible(f"no move found: IPOPT stopped with {stats['return_status']} after "
                         f"{stats['iter_count']} iterations; the binding limit is the {r.what} ({r.why} = "
                         f"{prob.limits[r.name]:.4g} {r.unit})", out)
    return out


def _outputs(prob: Problem, X, C) -> np.ndarray:
    """Outputs at the nodes (node k with the control of interval k, the last with the last)."""
    Cn = np.hstack([C, C[:, -1:]])
    _, Y = prob._rates(ca.DM(X), ca.DM(Cn))
    return np.asarray(ca.evalf(Y))


def _margins(prob: Problem, X, Y) -> dict:
    """Per rating, the smallest margin along the nodes: 1 - value/limit (0: on the limit)."""
    out = {}
    for r in prob.ratings:
        s = np.array([X[prob.model.index(n)] if n in prob.model.states else Y[prob.model.yindex(n)]
                      for n in r.signals])
        lim = prob.limits[r.name]
        if r.sense == "norm":
            out[r.name] = float(1 - np.sqrt((s**2).sum(0)).max() / lim)
        elif r.sense == "max":
            out[r.name] = float(1 - s[0].max() / lim) if lim else float(-s[0].max())
        else:
            out[r.name] = float(s[0].min() - lim)
    return out
