"""The Opti problem of one tuning request (:class:`TuningProblem`), solved by IPOPT."""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from ..frequency import bandwidth, closed_loop
from ..linearisation import LinearizationError, jacobian_function, operating_point
from ..model.assembly import Model
from ..model.params import Parameters
from ..optimisation import solve_ipopt
from ._callbacks import spectral_abscissa
from ._cascade import (
    OUTER_OPEN,
    dense_checks,
    gap_start,
    noise_gain_bound,
    noise_group,
    open_grid,
    outer_open_groups,
    separation_groups,
)
from ._closed_loop import _LOOP_ORDER, _ClosedLoop
from ._constraints import (
    _SHARED,
    _bandwidth_groups,
    _dense_minima,
    _eigenvalue_group,
    _Group,
    _limit_groups,
    _loop_groups,
    _overshoot_group,
    ecu_limits,
)
from ._inspect import _Inspection
from ._kernels import _sensitivity_function, _soft_min, _step_states
from ._requirements import Requirements, TuneError, _goal, _load_label, _request
from ._scaling import _GainScaling

_EFFORT = 1e-3           # weight of the effort term sum(theta^2)
#: Exact-penalty weight of the constraint slacks (elastic mode). The constraints are
#: scaled to O(1) near their boundary (log ratios, or bounded ratios that do not flatten
#: where the objective pushes: a flat penalty would let the objective win); their
#: multipliers at a solution are far below this.
_PENALTY = 1e3
#: IPOPT's ``theta_max_fact``: its filter rejects every trial point whose constraint
#: violation (1-norm) exceeds this times max(1, violation at the start). The start is
#: always a feasible point of the elastic problem (the slacks start at the start's
#: violations), so the iterates stay within this violation of the feasible set.
#: IPOPT's default (1e4) let a long Newton step (the Hessian is the 2e-3 of the effort
#: term when no constraint is active) leave the feasible set by 1.5 (summed) on the
#: one-load reference problem, to where the margin measures sit at their floor (no
#: restoring gradient). Measured on 28 tunes (every variant from the reference gains,
#: one and three loads; eight from gains x 0.2): 0.1, 0.3 and 1 all succeed with the
#: same optima, in 1410, 1311 and 1245 iterations (the old formulation: 1769, and the
#: one-load reference tune failed); 0.3 keeps a margin below the failing step and
#: takes the fewest iterations from gains x 0.2 over 0/15/30 kN (44, was 52).
_THETA_MAX = 0.3
#: a normalised constraint (soft minimum of a group) at or above -_FEAS_TOL holds
_FEAS_TOL = 1e-6


class TuningProblem(_Inspection):
    """The Opti problem for one model, set of free gains, load cases and requirements
    (the formulation: :mod:`ema_casadi.tuning`).

    Only the closed loop is linearised: with every loop closed, the response of a
    loop's measurement to its own injection is S - 1, S = 1/(1 + L) the loop's
    sensitivity (the controller sees measurement + injection), so one factorisation
    per frequency gives all three loop transfers, and T = 1 - S_x is x_rod/x_cmd.

    Parameters
    ----------
    model : Model
        The assembled model.
    params : Parameters
        Parameter set; its gains are the reference that scales the variables.
    free : sequence of str, optional
        Gains to tune (default :func:`~ema_casadi.tuning.default_free`).
    loads : sequence of float
        Load cases f_ext (N).
    requirements : Requirements, optional
        What every load case must meet (default :class:`Requirements`).
    objective : {"bandwidth", "tracking"}
        Maximise the worst-case -3 dB frequency, or minimise the worst-case integrated
        squared error of the step.
    start : dict, optional
        Start values of free gains (SI; default the set's).
    freqs : array_like, optional
        Frequency grid (Hz) of the robustness constraints (default 0.5 Hz - 10 kHz,
        14 per decade).

    Attributes
    ----------
    cases : list of OperatingPoint
        The trimmed operating point of each load case (at the start gains).
    groups : list
        The constraint groups (``kind``, ``loads`` in N, ``loop``, ``freqs`` in Hz),
        load cases with equal linear dynamics sharing one.
    freqs : ndarray
        The frequency grid (Hz).
    model, params, free, requirements
        As given (``free`` and ``requirements`` completed with their defaults).
    """

    def __init__(self, model: Model, params: Parameters, free=None, loads=(0.0,),
                 requirements: Requirements | None = None, objective: str = "bandwidth",
                 start: dict | None = None, freqs=None):
        req = _goal(requirements, objective)
        free, loads, start, freqs = _request(model, params, free, loads, start, freqs)
        self.model, self.params, self.free, self.requirements = model, params, free, req
        self._names = list(model.param_names)
        self._ref = params.as_dict()
        self._limits = ecu_limits(model, params.vector())
        self.freqs = freqs
        self._callbacks = []
        self.cases = self._trim(loads, params.vector(**start))
        self._opti = ca.Opti()
        self._scaling = _GainScaling(self._opti, free, self._ref, start)
        self.groups: list[_Group] = []
        self._signatures: dict = {}
        self._trajectories: list = []
        self._case_step: list[int] = []
        self._bandwidth_variable(objective)
        self._gap_variables()
        self._loop = _ClosedLoop(model, jacobian_function(model), self._scaling, self.cases)
        self._S = _sensitivity_function(len(self._loop.keep), 3)
        self._S1 = _sensitivity_function(len(self._loop.keep), 1)
        self._S_grid = self._S.map(len(self.freqs))
        ise = [e for e in (self._add_case(op) for op in self.cases) if e is not None]
        self._objective(objective, ise)

    def _trim(self, loads, p_start) -> list:
        cases = []
        for F in loads:
            try:
                cases.append(operating_point(self.model, f_ext=F, p=p_start))
            except LinearizationError as exc:
                raise TuneError(f"load case {_load_label(F)}: {exc}") from None
        return cases

    def _bandwidth_variable(self, objective: str) -> None:
        """f_b (Hz) = 10 exp(fb_log), the worst case's -3 dB frequency, for ``bandwidth``."""
        self._fb = None
        if objective == "bandwidth":
            opti = self._opti
            self._fb_log = opti.variable()
            self._fb = 10.0 * ca.exp(self._fb_log)  # Hz
            opti.subject_to(opti.bounded(math.log(1e-4), self._fb_log, math.log(1e3)))
            self._fb_log0 = math.log(self._initial_bandwidth() / 10.0)
            opti.set_initial(self._fb_log, self._fb_log0)

    def _gap_variables(self) -> None:
        """g_k (Hz) = 10 exp(zeta_k): between each pair of neighbouring loops (outer loops
        open) the frequency that the outer loop's crossover lies below g_k / sqrt(s) and
        the inner one's above g_k sqrt(s) (separation s); started at the geometric mean of
        the start's crossovers."""
        self._zeta, self._zeta0 = ca.MX.sym("unused_zeta", 0), np.zeros(0)
        if self.requirements.separation <= 0:
            return
        g0 = gap_start(self.model, self.cases[0])
        self._zeta = self._opti.variable(len(g0))
        self._zeta0 = np.log(np.array(g0) / 10.0)
        self._opti.subject_to(self._opti.bounded(math.log(1e-3), self._zeta, math.log(1e3)))
        self._opti.set_initial(self._zeta, self._zeta0)

    def _initial_bandwidth(self) -> float:
        fb = min(bandwidth(closed_loop(self.model, op), f_min=0.01, f_max=1e4) for op in self.cases)
        return fb if math.isfinite(fb) else 10.0

    def _objective(self, objective: str, ise: list) -> None:
        """Elastic constraints and the cost: each group may be relaxed by a slack at an
        exact-penalty cost, so an infeasible request still converges, to the least
        violation, and the groups whose slack is left positive are the ones that cannot
        be met."""
        opti, theta = self._opti, self._scaling.theta
        self._g = ca.vertcat(*[_soft_min(grp.expr) for grp in self.groups])
        self._group_function = ca.Function("groups", [theta, self._fb_sym, self._zeta], [self._g])
        # the start is a feasible point of the elastic problem: each slack starts at its
        # group's violation there (zero for a feasible start)
        self.start_values = np.atleast_1d(np.array(opti.debug.value(self._g, opti.initial()), float).ravel())
        self._slack = opti.variable(len(self.groups))
        opti.subject_to(self._slack >= 0)
        opti.set_initial(self._slack, np.maximum(0.0, -self.start_values))
        for i in range(len(self.groups)):
            opti.subject_to(self._g[i] + self._slack[i] >= 0)
        logs = [theta[i] for i, ls in enumerate(self._scaling.log_scaled) if ls]
        effort = _EFFORT * ca.sumsqr(ca.vertcat(*logs)) if logs else 0
        worst_ise = ca.mmax(ca.vertcat(*ise)) if len(ise) > 1 else ise[0]
        self._J_main = -self._fb_log if objective == "bandwidth" else worst_ise
        self._J_function = ca.Function("main_objective", [theta, self._fb_sym, self._zeta], [self._J_main])
        opti.minimize(self._J_main + effort + _PENALTY * ca.sum1(self._slack))
        self._iterates: list = []

    @property
    def _fb_sym(self):  # the bandwidth variable's symbol (a stand-in without the bandwidth objective)
        return self._fb_log if self._fb is not None else self.__dict__.setdefault("_fb_dummy", ca.MX.sym("unused"))

    def _record(self, _iteration, dv) -> None:
        """Keep every IPOPT iterate (theta, fb_log, zeta) for :meth:`feasible_iterates`
        (``dv``: the iterate's value of an expression)."""
        fb_log = float(dv(self._fb_log)) if self._fb is not None else 0.0
        zeta = np.atleast_1d(np.array(dv(self._zeta), float).ravel()) if self._zeta.numel() else self._zeta0
        self._iterates.append((np.atleast_1d(np.array(dv(self._scaling.theta), float).ravel()), fb_log, zeta))

    @property
    def start_feasible(self) -> bool:
        """Every constraint group holds at the start gains (optimiser's model)."""
        return bool(np.all(self.start_values >= -_FEAS_TOL))

    def _same(self, key: str, exprs) -> int | None:
        """Index of an earlier load case whose ``exprs`` (MX of the gains) are numerically
        equal at the start gains and at random gains, else None (and remember these).

        Under the small-signal policy the linear dynamics at rest do not depend on the
        load (only the operating current and voltage do), so the frequency-domain
        constraints and the step's state trajectory are built once for all loads."""
        theta0 = self._scaling.theta0
        f = ca.Function("signature", [self._scaling.theta], [ca.veccat(*exprs)])
        rng = np.random.default_rng(1)
        sig = np.concatenate([np.array(f(t)).ravel() for t in (theta0, theta0 + rng.uniform(-1, 1, len(theta0)))])
        seen = self._signatures.setdefault(key, [])
        for j, other in seen:
            if np.allclose(sig, other, rtol=1e-12, atol=0):
                return j
        seen.append((len(seen), sig))
        return None

    def _share(self, kinds, case: int, F: float) -> None:
        """Let the groups of these kinds built for ``case`` stand for load F too."""
        for grp in self.groups:
            if grp.kind in kinds and grp.case == case:
                grp.loads.append(F)

    def _add_case(self, op):
        """The constraint groups of one load case; returns its step's ISE (None when an
        earlier case has the same rod response)."""
        req, F = self.requirements, op.f_ext
        A, loop_matrices, (b, Cs, ds) = self._loop.matrices(op)
        Ak = loop_matrices[0]
        A_eig = A[self._loop.keep_eig, self._loop.keep_eig]
        opened = {loop: self._loop.matrices(op, OUTER_OPEN[loop])[1] for loop in _LOOP_ORDER if OUTER_OPEN[loop]}
        noise = self._loop.noise_matrices(op)
        j = self._same("frequency", [A_eig, *loop_matrices, *sum(opened.values(), ()), *(noise or ())])
        if j is not None:
            self._share(_SHARED, j, F)
        else:
            self._frequency_groups(op, len(self._signatures["frequency"]) - 1, A_eig, loop_matrices, opened, noise)
        j = self._same("step", [Ak, b])
        if j is None:
            self._trajectories.append(_step_states(Ak, b, req.step, req.t_step, self._loop.A_norm))
            j = len(self._trajectories) - 1
        self._case_step.append(j)
        X, t = self._trajectories[j]
        k = self._same("rod", [Ak, b, Cs[0, :], ds[0]])
        if k is not None:  # same rod response as an earlier load case: its overshoot group
            self._share(("overshoot",), k, F)
            ise = None
        else:
            grp, ise = _overshoot_group(X, t, Cs[0, :], ds[0], req, F, len(self._signatures["rod"]) - 1)
            self.groups.append(grp)
        limited = tuple(self.model.output_with(r) for r in ("motor_current", "d_voltage", "q_voltage"))
        self.groups.extend(_limit_groups(op, X, Cs[1:, :], ds[1:], req, ecu_limits(self.model, op.p), limited))
        return ise

    def _frequency_groups(self, op, case, A_eig, loop_matrices, opened, noise):
        """Margin disks, ECU-rate ceilings, bandwidth and eigenvalue constraints; the
        cascade's (outer loops open: margins, unconditional stability, separation) and
        the noise bound."""
        req, F = self.requirements, op.f_ext
        w = (2 * np.pi * self.freqs).reshape(1, -1)
        G = self._S_grid(*loop_matrices, w)  # 2 x 3N
        self.groups.extend(_loop_groups(G, self.freqs, req, self._limits, F, case))
        G_open = {"position": (G, self.freqs)}
        for loop, m in opened.items():
            f = open_grid(loop, self.freqs)
            G_open[loop] = (self._S.map(len(f))(*m, (2 * np.pi * f).reshape(1, -1)), f)
        self.groups.extend(outer_open_groups(G_open, req, F, case))
        if self._zeta.numel():
            cfg = {"position": loop_matrices} | opened
            self.groups.extend(separation_groups(self._S, cfg, 10.0 * ca.exp(self._zeta), req, F, case))
        bound = noise_gain_bound(req, self._limits)
        if noise is not None and bound is not None:
            self.groups.append(noise_group(self._S1, noise, self.freqs, bound, F, case))
        self.groups.extend(_bandwidth_groups(self._S, loop_matrices, self._fb, self.freqs, req, F, case))
        cb = spectral_abscissa(A_eig.shape[0], f"spectral_abscissa_{len(self._callbacks)}")
        self._callbacks.append(cb)  # keep the callback alive as long as the problem
        self.groups.append(_eigenvalue_group(cb(A_eig), req, F, case))

    def solve(self, max_iter: int = 200, hessian: str = "exact", warm: tuple | None = None) -> dict:
        """Solve by IPOPT.

        Parameters
        ----------
        max_iter : int
            IPOPT iteration limit.
        hessian : {"exact", "limited-memory"}
            Exact (AD) Hessian or L-BFGS.
        warm : tuple, optional
            (x, lam_g) of a previous solve of a problem of the same structure (the
            constraints are aggregated per group, so a refined grid keeps it).

        Returns
        -------
        dict
            ``gains`` (SI, by name), ``stats`` (IPOPT's), ``wall`` (s), ``warm`` (for a
            next solve), ``groups`` (per group: ``kind``, ``loads``, ``loop``, ``min``,
            ``slack``, ``at_hz``), ``objective`` (the main cost: -log(f_b / 10 Hz) or the
            worst-case normalised ISE) and ``f_b`` (Hz, or None).
        """
        if hessian not in ("exact", "limited-memory"):
            raise TuneError(f"hessian '{hessian}' unknown; choose exact or limited-memory")
        # detect_simple_bounds (simple_bounds): the gain, bandwidth, gap and slack bounds reach
        # IPOPT as variable bounds (Opti passes every constraint as a row of g otherwise), so
        # the iterates never leave them and the slacks (started on their bound 0) stay >= 0
        res = solve_ipopt(self._opti, self._ipopt_options(max_iter, hessian, warm), simple_bounds=True,
                          warm=warm, on_iteration=self._record)
        out = self._read_solution(res.value)
        out.update(stats=res.stats, wall=res.wall_s, warm=res.warm)
        return out

    @staticmethod
    def _ipopt_options(max_iter, hessian, warm) -> dict:
        # mu_init 1e-2 instead of 0.1: the start is usually feasible or nearly so, and a
        # smaller initial barrier halves the iterations on the reference problem; from a
        # warm start (the optimiser's own warm-start settings added) 1e-6
        return {"max_iter": int(max_iter), "hessian_approximation": hessian, "tol": 1e-6, "acceptable_tol": 1e-4,
                "mu_init": 1e-2 if warm is None else 1e-6, "theta_max_fact": _THETA_MAX}

    def _read_solution(self, val) -> dict:
        theta = np.atleast_1d(np.array(val(self._scaling.theta), float).ravel())
        # an interior point stops ~1e-8 inside a bound: a linear gain (K_i_x) there is 0
        theta = np.where(~np.array(self._scaling.log_scaled) & (theta < 1e-6), 0.0, theta)
        gains = self._scaling.values(theta)
        slack = np.atleast_1d(np.array(val(self._slack), float).ravel())
        groups = self._group_rows([np.atleast_1d(np.array(val(grp.expr), float).ravel()) for grp in self.groups], slack)
        return {"gains": dict(zip(self.free, map(float, gains), strict=False)),
                "groups": groups, "objective": float(val(self._J_main)),
                "f_b": float(val(self._fb)) if self._fb is not None else None}

    def _group_rows(self, values, slack) -> list[dict]:
        """Per group: ``kind``, ``loads``, ``loop``, ``min`` (smallest normalised value),
        ``slack`` and ``at_hz`` (where the smallest value is, for grid groups)."""
        rows = []
        for grp, v, sl in zip(self.groups, values, slack, strict=False):
            j = int(np.argmin(v))
            rows.append({"kind": grp.kind, "loads": list(grp.loads), "loop": grp.loop, "min": float(v[j]),
                         "slack": float(sl), "at_hz": float(grp.freqs[j]) if grp.freqs is not None else None})
        return rows

    def groups_at(self, gains: dict, f_b: float | None = None, zeta=None) -> list[dict]:
        """The constraint groups (as ``groups`` of :meth:`solve`, no slack) at these gains.

        Parameters
        ----------
        gains : dict
            Values of the free gains (SI, by name).
        f_b : float, optional
            Value (Hz) of the bandwidth variable (``bandwidth`` objective; default the
            start's, the -3 dB frequency at the start gains).
        zeta : array_like, optional
            The gap variables log(g_k / 10 Hz) of the separation (default the start's).
        """
        theta = self._scaling.theta_of(gains)
        fb_log = math.log(f_b / 10.0) if f_b is not None else (self._fb_log0 if self._fb is not None else 0.0)
        zeta = self._zeta0 if zeta is None else np.asarray(zeta, float)
        exprs = [grp.expr for grp in self.groups]
        f = ca.Function("group_values", [self._scaling.theta, self._fb_sym, self._zeta], exprs)
        values = [np.atleast_1d(np.array(v, float).ravel()) for v in f(theta, fb_log, zeta)] if len(exprs) > 1 else \
            [np.atleast_1d(np.array(f(theta, fb_log, zeta), float).ravel())]
        return self._group_rows(values, np.zeros(len(self.groups)))

    def main_objective(self, gains: dict, f_b: float | None = None) -> float:
        """The main cost (as ``objective`` of :meth:`solve`) at these gains: for
        ``bandwidth`` -log(f_b / 10 Hz), for ``tracking`` the worst-case normalised ISE.

        Parameters
        ----------
        gains : dict
            Values of the free gains (SI, by name).
        f_b : float, optional
            Bandwidth (Hz) for the ``bandwidth`` objective (default the start's).
        """
        theta = self._scaling.theta_of(gains)
        fb_log = math.log(f_b / 10.0) if f_b is not None else (self._fb_log0 if self._fb is not None else 0.0)
        return float(self._J_function(theta, fb_log, self._zeta0))

    @property
    def start_bandwidth(self) -> float | None:
        """The start's worst-case -3 dB frequency (Hz; the bandwidth variable's start), or None."""
        return 10.0 * math.exp(self._fb_log0) if self._fb is not None else None

    def feasible_iterates(self, iterates=None) -> list[dict]:
        """The IPOPT iterates at which every constraint group of this problem holds with
        no slack (optimiser's model), best main objective first.

        Parameters
        ----------
        iterates : list, optional
            (theta, fb_log, zeta) of iterates (default those of this problem's solves).

        Returns
        -------
        list of dict
            ``gains`` (SI, by name), ``objective`` (the main cost, as in :meth:`solve`),
            ``f_b`` (Hz, or None) and ``zeta`` (the separation's gap variables).
        """
        out = []
        for theta, fb_log, zeta in (self._iterates if iterates is None else iterates):
            g = np.array(self._group_function(theta, fb_log, zeta), float).ravel()
            if not np.all(np.isfinite(g)) or np.any(g < -_FEAS_TOL):
                continue
            out.append({"gains": dict(zip(self.free, map(float, self._scaling.values(theta)), strict=False)),
                        "objective": float(self._J_function(theta, fb_log, zeta)), "zeta": zeta,
                        "f_b": 10.0 * math.exp(fb_log) if self._fb is not None else None})
        return sorted(out, key=lambda c: c["objective"])

    @property
    def iterates(self) -> list:
        """(theta, fb_log, zeta) of every IPOPT iterate of this problem's solves."""
        return list(self._iterates)

    def grid_gaps(self, gains: dict, per_decade: int = 100) -> np.ndarray:
        """Frequencies (Hz) where a margin disk or ECU-rate constraint, checked on a grid
        ``per_decade`` times denser than the decade, is violated between the points of
        the optimisation grid (one per local minimum below zero).

        Parameters
        ----------
        gains : dict
            Values of the free gains (SI, by name).
        per_decade : int
            Points per decade of the dense check.
        """
        theta = self._scaling.theta_of(gains)
        f = np.logspace(math.log10(self.freqs[0]), math.log10(self.freqs[-1]),
                        int(per_decade * math.log10(self.freqs[-1] / self.freqs[0])) + 1)
        out = []
        for case in range(len(self.cases)):
            for loop, S in self._sensitivities(case, f, theta).items():
                out.extend(_dense_minima(f, 1 / S - 1, self.requirements, self._limits, loop))
            L_open = {loop: (1 / self._sensitivities(case, open_grid(loop, f), theta, OUTER_OPEN[loop])[loop] - 1,
                             open_grid(loop, f)) for loop in _LOOP_ORDER}
            out.extend(dense_checks(L_open, self.requirements))
            out.extend(self._noise_gaps(case, f, theta))
        new = [x for x in out if np.min(np.abs(np.log(self.freqs / x))) > 1e-6]
        return np.unique(np.array(new))

    def _noise_gaps(self, case: int, f: np.ndarray, theta: np.ndarray) -> list[float]:
        """Frequencies (Hz) of local maxima of |i_cmd / n_x| above the noise bound on f."""
        bound, noise = noise_gain_bound(self.requirements, self._limits), self._loop.noise_matrices(self.cases[case])
        if bound is None or noise is None:
            return []
        H = self._S1.map(len(f))(*noise, (2 * np.pi * f).reshape(1, -1))
        H = np.array(ca.Function("noise", [self._scaling.theta], [H])(theta))
        h = np.abs(H[0] + 1j * H[1])
        high = (h > bound) & (h >= np.r_[-np.inf, h[:-1]]) & (h >= np.r_[h[1:], -np.inf])
        return f[high].tolist()

    def _sensitivities(self, case: int, f: np.ndarray, theta: np.ndarray, opened=()) -> dict:
        _, loop_matrices, _ = self._loop.matrices(self.cases[case], opened)
        G = self._S.map(len(f))(*loop_matrices, (2 * np.pi * f).reshape(1, -1))
        G = np.array(ca.Function("dense", [self._scaling.theta], [G])(theta))
        return {loop: 1 + G[0, j::3] + 1j * G[1, j::3] for j, loop in enumerate(_LOOP_ORDER)}
