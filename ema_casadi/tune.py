"""Gain tuning of the cascade by nonlinear optimisation (SPEC §4.6).

The free gains (any of ``K_x``, ``K_i_x``, ``K_p_w``, ``T_i_w``, ``K_p_i``, ``K_i_i``)
are decision variables of one CasADi ``Opti`` problem solved by IPOPT. Every quantity
in it is a symbolic function of the gains through the model itself: the parameter
vector ``p`` of the assembled ``model.f`` carries the gains, and the exact AD Jacobian
``A(p), B(p), C(p), D(p)`` of ``model.f`` at each load case's operating point
(:func:`ema_casadi.linearisation.jacobian_function`) feeds the frequency and step
responses below, so IPOPT gets exact first and second derivatives (except the second
derivative of the eigenvalue bound, taken as zero).

Load cases and the linearisation
--------------------------------
Each load case is an operating point at rest, ``x_cmd = 0``, ``f_ext = F``, under the
toolkit's small-signal policy (:mod:`ema_casadi.linearisation`): backlash off, Coulomb-type
friction off, the screw-nut efficiency switch frozen at its operating-point value. The
trim does not depend on the gains (each integrator holds its loop's output at rest:
``z_w = i_q``, ``z_q = v_q``; the position error is zero), so it is solved once per load
case and the Jacobian taken there as a function of the gains; the verification
re-trims with the tuned gains. Under this policy the load leaves the linear dynamics
unchanged (at rest the frozen efficiency is the switch's midpoint for every load, and
the FOC decoupling cancels the i_q-dependent terms); what it changes is the operating
current and voltage, the headroom to the limits during a step: that is where the
worst case bites (at 30 kN the holding current is 13.2 A of 24 A). Load cases with
numerically equal linearisations share their frequency-domain constraints and the
step's state trajectory.

Loop transfers from the closed loop
-----------------------------------
Each loop is broken with the other loops closed (``L = -G_{d -> measurement}`` with the
loop's flag at 0, as :func:`ema_casadi.linearisation.loop_model`). With every loop closed
the controller sees measurement + injection, so the closed-loop response of a loop's
measurement to its own injection is ``S - 1`` with ``S = 1/(1 + L)``: one closed-loop
Jacobian and one factorisation per frequency give all three loops' sensitivities, and
``T = 1 - S_x`` is x_rod/x_cmd. The response ``C (jwI - A)^-1 B`` is computed in real
arithmetic, ``(jwI - A)^-1 = (A^2 + w^2 I)^-1 (-A - jw I)``, on the states the
injections reach (the decoupled d-axis current loop drops out) after a diagonal
balancing of A (its SI entries span 1e-3 ... 1e8, which A^2 would square past double
precision).

Constraints (every load case)
-----------------------------
*Margins, per loop*, on a log frequency grid (0.5 Hz - 10 kHz, 14 per decade): L stays
outside an exclusion disk (centre ``-c``, radius ``R``, :func:`exclusion_disk`):

- ``gm_db`` and ``pm_deg`` (default): the disk through ``-10^(-GM/20)`` and the points
  ``-e^(+-j PM)`` of the unit circle. Outside it, every phase crossover has
  |L| <= 10^(-GM/20) (the gain may rise by GM) or lies left of the disk (it may fall
  by at least 20 log10(c + R)), and every gain crossover is at least PM away from -1.
  GM = 6 dB, PM = 45 deg: c = 1.82, R = 1.32, i.e. [-3.13, -0.5] on the negative axis
  (lower GM 9.9 dB). When cos(PM) <= 10^(-GM/20) no disk passes through both; then the
  disk through the PM points centred at ``-1/cos(PM)``, radius ``tan(PM)``, which
  contains the GM point.
- ``ms``: the sensitivity peak, |1 + L| >= 1/Ms (c = 1, R = 1/Ms), which implies an
  upward GM of 20 log10(Ms/(Ms-1)), a downward one of 20 log10(1 + 1/Ms) and
  PM >= 2 asin(1/(2 Ms)).

The grid is refined where needed (exchange method): after a solve the constraints
are checked at 100 frequencies per decade and the frequencies of violations between
grid points added; the problem is re-solved, warm started (at most 3 solves).

*ECU rate*: the linearisation is continuous, without the ECU's sample-and-hold delay,
so each loop's gain is kept below 1 above its sample rate / ``rate_ratio`` (default
10: 200 Hz position, 800 Hz velocity, 1.6 kHz current loop).

*Step response* of the closed loop to a step of ``step`` metres (exact discretisation
by matrix exponential, Pade with scaling and squaring, on a time grid of 8 segments of
40 samples whose spacing doubles per segment, 20 us first): overshoot of x_rod <=
``overshoot``; the q-current (operating value + response) within +-I_max; the
voltage |v_dq| inside the SVPWM circle k_v V_dc/sqrt(3). The step is the size of
command the loops must follow without touching a limit (default 0.1 mm: the
proportional path K_p_i K_p_w K_x (2 pi/p) puts a voltage step on the winding at once;
the reference gains reach the voltage limit at about 0.2 mm).

*Eigenvalues*: the spectral abscissa of the closed loop <= -sigma, through a callback
with its analytic gradient (eigenvector sensitivity).

*Bandwidth*: optionally |T| >= 1/sqrt(2) up to ``bandwidth_min_hz``.

Each group of grid or sample constraints enters as one constraint on its
Kreisselmeier-Steinhauser soft minimum (conservative by at most 0.002 in the
normalised units), and every such constraint is elastic: a slack at an exact-penalty
cost may relax it. A feasible request ends with all slacks zero; an infeasible one
still converges, to the least-violating gains, and the groups left with slack are
named (:attr:`TuneResult.violations`).

Objectives
----------
``bandwidth``: maximise f_b, a variable with |T(j 2 pi f_b)| >= 1/sqrt(2) in every
load case: the worst case's -3 dB frequency (as long as |T| stays above -3 dB below
it, which the margin and overshoot constraints keep; the verification measures the
true -3 dB frequency). ``tracking``: minimise the worst case's integrated squared
error of the step (normalised by the step and 10 ms). Both add an effort term,
1e-3 sum(log(gain/reference)^2): a pure bandwidth or squared-error objective drives
gains to their bounds (STACK_NOTES).

Gains are scaled logarithmically, ``gain = reference * exp(theta)`` within
``reference * [1/100, 100]``; ``K_i_x`` may start at zero and is scaled linearly
(``K_x^2/4 * theta``, theta in [0, 100]).

Verification
------------
:func:`verify` re-trims and re-linearises with the tuned gains
(:mod:`ema_casadi.linearisation`) and takes python-control's ``stability_margins`` of
every loop transfer (crossovers outside 0.01 Hz - 100 kHz dropped; PM is the smallest
angular distance of L to -1, GM counted in both directions, as
:class:`ema_casadi.frequency.LoopMargins` does), the closed-loop eigenvalues and
-3 dB bandwidth and a python-control step response; :func:`step_metrics` simulates a
nonlinear step on the full model. A tune succeeds only when IPOPT converged with no
slack left and this check passes.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import casadi as ca
import numpy as np

from .assembly import Model, build_model
from .linearisation import LOOPS, LinearizationError, jacobian_function, operating_point
from .params import Parameters
from .simulation import step_response_metrics

__all__ = [
    "GAINS", "OBJECTIVES", "TuneError", "Requirements", "TuneResult", "tune", "verify",
    "step_metrics", "scaled_gains", "default_free", "exclusion_disk", "plot_tuning",
    "describe_constraint",
]

#: Tunable gains (flat parameter names, SPEC §3 symbols).
GAINS = ("K_x", "K_i_x", "K_p_w", "T_i_w", "K_p_i", "K_i_i")
OBJECTIVES = ("bandwidth", "tracking")
#: ECU sample-rate parameter of each loop.
_RATE = {"position": "f_s_x", "velocity": "f_s_w", "current": "f_s_i"}
_EFFORT = 1e-3           # weight of the effort term sum(theta^2)
_BOUND = 100.0           # gains within reference * [1/_BOUND, _BOUND]
_SEG, _NSEG = 40, 8      # step grid: _NSEG segments of _SEG samples, spacing doubling
_FEAS_TOL = 1e-6         # a normalised constraint below -_FEAS_TOL is violated
#: Sharpness of the soft minimum that aggregates each constraint group (a grid of
#: frequencies or time samples) into one constraint. One constraint per group lets
#: the worst point move along the grid without IPOPT's barrier stalling on many
#: nearly active neighbours (measured on the three-load reference problem, before the
#: elastic slacks: 163 iterations with every point a constraint, 35 aggregated); the
#: bound is conservative by at most log(321)/rho = 0.002 in the normalised units.
_KS_RHO = 3000.0
#: Exact-penalty weight of the constraint slacks (elastic mode). The constraints are
#: scaled to O(1) near their boundary (log ratios, or bounded ratios that do not flatten
#: where the objective pushes: a flat penalty would let the objective win); their
#: multipliers at a solution are far below this.
_PENALTY = 1e3
#: At most this many solves: after each, frequencies where a dense (100 per decade)
#: check of the margin constraints fails are added to the grid (exchange method).
_ROUNDS = 3
_ACTIVE = 1e-2           # a group with its smallest normalised value below this is active


class TuneError(ValueError):
    """A tuning request cannot be served (unknown gain, bad requirement, a load the
    actuator cannot hold). The one-line message names the option."""


@dataclass(frozen=True)
class Requirements:
    """What the tuned loops must satisfy, in every load case.

    Attributes
    ----------
    gm_db : float
        Gain margin of every loop (dB), either direction.
    pm_deg : float
        Phase margin of every loop (deg).
    ms : float or None
        If given, the sensitivity-peak bound |1 + L| >= 1/ms replaces the GM/PM disk;
        the verification then checks the peak and the margins it implies
        (:meth:`margin_targets`).
    overshoot : float
        Largest overshoot of x_rod in the step response (fraction, 0.05 = 5 %).
    bandwidth_min_hz : float or None
        Closed-loop x_rod/x_cmd at least -3 dB up to this frequency (Hz).
    sigma : float
        Closed-loop eigenvalues left of -sigma (1/s).
    step : float
        Step amplitude (m) of the response that must stay inside the current and
        voltage limits.
    t_step : float
        Horizon of the step response (s).
    rate_ratio : float
        Loop gain below 1 above (ECU sample rate)/rate_ratio; 0 switches it off.
    """

    gm_db: float = 6.0
    pm_deg: float = 45.0
    ms: float | None = None
    overshoot: float = 0.05
    bandwidth_min_hz: float | None = None
    sigma: float = 0.0
    step: float = 1e-4
    t_step: float = 0.2
    rate_ratio: float = 10.0

    def check(self) -> None:
        """Raise :class:`TuneError` naming the first invalid field."""
        def bad(name, what):
            raise TuneError(f"{name} must be {what}, got {getattr(self, name)!r}")

        for name in ("gm_db", "pm_deg", "overshoot", "sigma", "rate_ratio"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                bad(name, "a non-negative number")
        if self.gm_db <= 0:
            bad("gm_db", "positive (dB)")
        if not 0 < self.pm_deg < 90:
            bad("pm_deg", "between 0 and 90 deg")
        if self.ms is not None and not (math.isfinite(self.ms) and self.ms > 1):
            bad("ms", "a number above 1")
        if self.bandwidth_min_hz is not None and not (math.isfinite(self.bandwidth_min_hz) and self.bandwidth_min_hz > 0):
            bad("bandwidth_min_hz", "a positive frequency (Hz)")
        for name in ("step", "t_step"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                bad(name, "positive")
        if 0 < self.rate_ratio < 1:
            bad("rate_ratio", "0 (off) or at least 1")

    def margin_targets(self) -> tuple[float, float]:
        """(GM dB, PM deg) every loop must reach: the requested ones, or with ``ms`` the
        ones the sensitivity bound implies, 20 log10(Ms/(Ms-1)) and 2 asin(1/(2 Ms))."""
        if self.ms is None:
            return self.gm_db, self.pm_deg
        return 20 * math.log10(self.ms / (self.ms - 1)), math.degrees(2 * math.asin(1 / (2 * self.ms)))

    def as_dict(self) -> dict:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


def exclusion_disk(req: Requirements) -> tuple[float, float]:
    """Centre -c and radius R of the disk the loop transfer must stay out of.

    See the module docstring: the disk through -10^(-GM/20) and -e^(+-j PM), or the
    sensitivity disk (c = 1, R = 1/Ms) when ``req.ms`` is given.
    """
    if req.ms is not None:
        return 1.0, 1.0 / req.ms
    a = 10 ** (-req.gm_db / 20)
    cphi = math.cos(math.radians(req.pm_deg))
    if cphi > a:
        c = (1 - a * a) / (2 * (cphi - a))
    else:
        c = 1 / cphi
    return c, math.sqrt(c * c - 2 * c * cphi + 1)


def default_free(model: Model) -> tuple[str, ...]:
    """All gains that act in this variant (``K_i_x`` only with the PI position loop)."""
    return tuple(g for g in GAINS if g != "K_i_x" or model.variants.get("controller") == "PI")


def scaled_gains(params: Parameters, factor: float, free=None) -> dict[str, float]:
    """Gains ``factor`` times the set's: K_x, K_i_x, K_p_w, K_p_i, K_i_i scale, the speed
    loop's integral time T_i_w stays (so its integral gain K_p_w/T_i_w scales too)."""
    d = params.as_dict()
    names = [g for g in GAINS if free is None or g in free]
    return {g: d[g] if g == "T_i_w" else factor * d[g] for g in names}


def _load_label(f: float) -> str:
    return f"{f / 1e3:g} kN"


# -------------------------------------------------------------------------------
class _SpectralAbscissa(ca.Callback):
    """max Re(eig(A)) of a dense n x n matrix, with its analytic gradient
    d alpha / dA_ij = Re(conj(w_i) v_j / (w^H v)) (v, w right/left eigenvectors)."""

    def __init__(self, n: int, name: str = "spectral_abscissa"):
        ca.Callback.__init__(self)
        self.n = n
        self._jac = None
        self.construct(name, {"enable_fd": False})

    def get_n_in(self):
        return 1

    def get_n_out(self):
        return 1

    def get_sparsity_in(self, i):
        return ca.Sparsity.dense(self.n, self.n)

    def get_sparsity_out(self, i):
        return ca.Sparsity.dense(1, 1)

    def eval(self, arg):
        return [float(np.max(np.linalg.eigvals(np.array(arg[0])).real))]

    def has_jacobian(self):
        return True

    def get_jacobian(self, name, inames, onames, opts):
        self._jac = _SpectralAbscissaGradient(self.n, name, inames, onames)
        return self._jac


class _SpectralAbscissaGradient(ca.Callback):
    def __init__(self, n, name, inames, onames):
        ca.Callback.__init__(self)
        self.n = n
        self._zero = None
        self._inames, self._onames = list(inames), list(onames)
        self.construct(name, {"enable_fd": False})

    def get_name_in(self, i):
        return self._inames[i]

    def get_name_out(self, i):
        return self._onames[i]

    def get_n_in(self):
        return 2

    def get_n_out(self):
        return 1

    def get_sparsity_in(self, i):
        return ca.Sparsity.dense(self.n, self.n) if i == 0 else ca.Sparsity.dense(1, 1)

    def get_sparsity_out(self, i):
        return ca.Sparsity.dense(1, self.n * self.n)

    def eval(self, arg):
        import scipy.linalg

        A = np.array(arg[0])
        lam, vl, vr = scipy.linalg.eig(A, left=True, right=True)
        k = int(np.argmax(lam.real))
        v, w = vr[:, k], vl[:, k]
        G = np.real(np.outer(np.conj(w), v) / (np.conj(w) @ v))
        return [G.reshape(1, -1, order="F")]

    def has_jacobian(self):
        return True

    def get_jacobian(self, name, inames, onames, opts):
        # second derivative of the spectral abscissa neglected (documented)
        ins = [ca.MX.sym(n, self.sparsity_in(i)) for i, n in enumerate(self.name_in())]
        ins.append(ca.MX.sym("out", self.sparsity_out(0)))
        nn = self.n * self.n
        self._zero = ca.Function(name, ins, [ca.MX(nn, nn), ca.MX(nn, 1)], inames, onames)
        return self._zero


def _sensitivity_function(n: int, m: int) -> ca.Function:
    """(A, B, C, D, w) -> [Re; Im] (2 x m) of the diagonal of C (jwI - A)^-1 B + D
    (n states, m input/output pairs), in real arithmetic:
    (jwI - A)^-1 = (A^2 + w^2 I)^-1 (-A - jw I), one factorisation for all m."""
    A = ca.SX.sym("A", n, n)
    B = ca.SX.sym("B", n, m)
    C = ca.SX.sym("C", m, n)
    D = ca.SX.sym("D", m)
    w = ca.SX.sym("w")
    Y = ca.solve(A @ A + w**2 * ca.SX.eye(n), ca.horzcat(-A @ B, -w * B))
    re = ca.vertcat(*[C[j, :] @ Y[:, j] + D[j] for j in range(m)])
    im = ca.vertcat(*[C[j, :] @ Y[:, m + j] for j in range(m)])
    return ca.Function("closed_loop_diagonal", [A, B, C, D, w], [ca.horzcat(re, im).T])


def _expm_step(A, b, h: float, squarings: int):
    """Exact discretisation over h of x' = A x + b (constant input): (Ad, bd) from the
    matrix exponential of [[A, b], [0, 0]] h by (6,6) Pade with scaling and squaring."""
    n = A.shape[0]
    M = ca.vertcat(ca.horzcat(A, b), ca.DM.zeros(1, n + 1)) * (h / 2**squarings)
    q = 6
    coef = [1.0]
    for k in range(1, q + 1):
        coef.append(coef[-1] * (q - k + 1) / (k * (2 * q - k + 1)))
    P = ca.DM.eye(n + 1)
    N = coef[0] * P
    D = coef[0] * P
    for k in range(1, q + 1):
        P = P @ M
        N = N + coef[k] * P
        D = D + (-1) ** k * coef[k] * P
    E = ca.solve(D, N)
    for _ in range(squarings):
        E = E @ E
    return E[:n, :n], E[:n, n]


def _soft_min(g):
    """Kreisselmeier-Steinhauser lower bound of min(g): -log(sum(exp(-rho g)))/rho,
    within log(len(g))/rho of the minimum (shifted by min(g) against overflow; the
    shift's derivative cancels exactly)."""
    if g.shape[0] == 1:
        return g
    m = ca.mmin(g)
    return m - ca.log(ca.sum1(ca.exp(-_KS_RHO * (g - m)))) / _KS_RHO


def _reachable(A: np.ndarray, B: np.ndarray) -> list[int]:
    """States reachable from the inputs through the non-zero pattern of A (graph search)."""
    seen = set(np.nonzero(np.any(B != 0, axis=1))[0].tolist())
    todo = list(seen)
    while todo:
        j = todo.pop()
        for i in np.nonzero(A[:, j] != 0)[0].tolist():
            if i not in seen:
                seen.add(i)
                todo.append(i)
    return sorted(seen)


# -------------------------------------------------------------------------------
_LOOP_ORDER = tuple(LOOPS)  # position, velocity, current


@dataclass
class _Group:
    """One named block of normalised constraints ``expr >= 0``."""

    kind: str        # "margin", "rate", "bandwidth", "bandwidth_min", "overshoot", "current", "voltage", "eigenvalue"
    loads: list      # load cases (N) it stands for
    loop: str | None
    expr: ca.MX
    freqs: np.ndarray | None = None
    case: int = -1   # index of the distinct linearisation it was built for


#: constraint kinds that depend only on the linear dynamics (shared by equal load cases)
_SHARED = ("margin", "rate", "bandwidth", "bandwidth_min", "eigenvalue")


class _Problem:
    """The Opti problem for one model, set of free gains, load cases and requirements.

    Only the closed loop is linearised: with every loop closed, the response of a
    loop's measurement to its own injection is S - 1, S = 1/(1 + L) the loop's
    sensitivity (the controller sees measurement + injection), so one factorisation
    per frequency gives all three loop transfers, and T = 1 - S_x is x_rod/x_cmd.
    """

    def __init__(self, model, params, free, loads, req, objective, start, freqs):
        self.model, self.params, self.free, self.req = model, params, tuple(free), req
        self.names = list(model.param_names)
        self.ref = params.as_dict()
        self.jac = jacobian_function(model)
        self.freqs = np.asarray(freqs, float)
        self._callbacks = []
        p_start = params.vector(**start)
        self.cases = []
        for F in loads:
            try:
                op = operating_point(model, f_ext=F, p=p_start)
            except LinearizationError as exc:
                raise TuneError(f"load case {_load_label(F)}: {exc}") from None
            self.cases.append(op)

        self.opti = opti = ca.Opti()
        self._variables(start)
        self.groups: list[_Group] = []
        self._signatures: dict = {}
        self._trajectories: list = []
        self.fb = None
        if objective == "bandwidth":
            self.fb_log = opti.variable()
            self.fb = 10.0 * ca.exp(self.fb_log)  # Hz
            opti.subject_to(opti.bounded(math.log(1e-4), self.fb_log, math.log(1e3)))
            opti.set_initial(self.fb_log, math.log(self._initial_bandwidth() / 10.0))
        self._reduce()
        self.S = _sensitivity_function(len(self.keep), 3)
        self.S_grid = self.S.map(len(self.freqs))
        ise = [e for e in (self._add_case(op) for op in self.cases) if e is not None]
        # elastic constraints: each group may be relaxed by a slack at an exact-penalty
        # cost, so an infeasible request still converges, to the least violation, and the
        # groups whose slack is left positive are the ones that cannot be met
        self.slack = opti.variable(len(self.groups))
        opti.subject_to(self.slack >= 0)
        opti.set_initial(self.slack, 0)
        for i, grp in enumerate(self.groups):
            opti.subject_to(_soft_min(grp.expr) + self.slack[i] >= 0)
        logs = [self.theta[i] for i, ls in enumerate(self.log_scaled) if ls]
        effort = _EFFORT * ca.sumsqr(ca.vertcat(*logs)) if logs else 0
        self.J_main = -self.fb_log if objective == "bandwidth" else (ca.mmax(ca.vertcat(*ise)) if len(ise) > 1 else ise[0])
        opti.minimize(self.J_main + effort + _PENALTY * ca.sum1(self.slack))

    # -- variables ----------------------------------------------------------------
    def _variables(self, start):
        """theta: gain = reference * exp(theta); K_i_x from zero: gain = scale * theta."""
        opti, ref = self.opti, self.ref
        self.theta = opti.variable(len(self.free))
        self.log_scaled, exprs, theta0 = [], [], []
        for i, g in enumerate(self.free):
            if g == "K_i_x" and ref[g] == 0.0:
                s = ref["K_x"] ** 2 / 4  # PI zero at K_x/4: the natural size of K_i_x
                self.log_scaled.append(False)
                exprs.append(s * self.theta[i])
                theta0.append(start[g] / s)
                opti.subject_to(opti.bounded(0, self.theta[i], _BOUND))
                continue
            for what, v in (("reference", ref[g]), ("start", start[g])):
                if v <= 0:
                    raise TuneError(f"{what} value of {g} must be positive, got {v}")
            self.log_scaled.append(True)
            exprs.append(ref[g] * ca.exp(self.theta[i]))
            theta0.append(math.log(start[g] / ref[g]))
            opti.subject_to(opti.bounded(-math.log(_BOUND), self.theta[i], math.log(_BOUND)))
        self.gains = ca.vertcat(*exprs)
        self.theta0 = np.array(theta0)
        opti.set_initial(self.theta, self.theta0)

    def _p(self, base: np.ndarray) -> ca.MX:
        entries = [ca.MX(float(v)) for v in base]
        for i, g in enumerate(self.free):
            entries[self.names.index(g)] = self.gains[i]
        return ca.vertcat(*entries)

    # -- model pieces -----------------------------------------------------------
    def _io(self):
        m = self.model
        ins = [m.inputs.index(LOOPS[k][1]) for k in _LOOP_ORDER] + [m.inputs.index("x_cmd")]
        outs = [m.outputs.index(LOOPS[k][2]) for k in _LOOP_ORDER] + [m.outputs.index(n) for n in ("v_d", "v_q")]
        return ins, outs

    def _reduce(self):
        """States kept in the frequency and step responses: those the injections and the
        command reach through A (e.g. the decoupled d-axis current loop is not), the
        pattern taken at the start gains and at random gains. The eigenvalue constraint
        keeps every state with a non-zero column (not the rigid screw's free shaft angle)."""
        rng = np.random.default_rng(0)
        ins, _ = self._io()
        pattern_A, pattern_B = 0, 0
        for k in range(2):
            for op in self.cases:
                p = op.p_lin.copy()
                if k:  # random gains, none zero (a zero gain hides the states it drives)
                    th = self.theta0 + rng.uniform(-1, 1, len(self.theta0))
                    th = np.where(self.log_scaled, th, np.abs(th) + 0.5)
                    gains = np.array(ca.Function("g", [self.theta], [self.gains])(th)).ravel()
                    for g, v in zip(self.free, gains):
                        p[self.names.index(g)] = v
                _, _, A, B, _, _ = (np.array(v) for v in self.jac(op.x, op.u_lin, p))
                pattern_A = pattern_A + np.abs(A)
                pattern_B = pattern_B + np.abs(B[:, ins])
        self.keep = k = _reachable(pattern_A, pattern_B)
        self.keep_eig = [j for j in range(pattern_A.shape[0]) if np.any(pattern_A[:, j] != 0)]
        # Diagonal similarity T^-1 A T balancing A (the entries span 1e-3 ... 1e8 in SI
        # units, which (A^2 + w^2 I) would square beyond double precision); balanced on
        # the summed magnitudes at the start and random gains.
        import scipy.linalg

        Ak = pattern_A[np.ix_(k, k)]
        _, (scale, _) = scipy.linalg.matrix_balance(Ak, permute=False, separate=True)
        self.scale = scale
        self.A_norm = float(np.linalg.norm(Ak * (1 / scale)[:, None] * scale[None, :], 1))

    def _closed_loop(self, op):
        """Balanced, reduced closed-loop matrices at ``op`` as functions of the gains:
        (A, B3, C3, D3) for the three loop injections/measurements (diagonal of D3),
        and (b, Cs, ds) for the command x_cmd and the outputs x_rod, i_q, v_d, v_q."""
        _, _, A, B, C, D = self.jac(op.x, op.u_lin, self._p(op.p_lin))
        ins, outs = self._io()
        k, s = self.keep, self.scale
        Ak = A[k, k] * ca.DM(np.outer(1 / s, s))  # T^-1 A T, T = diag(s)
        Bk = B[k, :] * ca.DM(np.outer(1 / s, np.ones(B.shape[1])))
        Ck = C[:, k] * ca.DM(np.outer(np.ones(C.shape[0]), s))
        B3 = ca.horzcat(*[Bk[:, i] for i in ins[:3]])
        C3 = ca.vertcat(*[Ck[o, :] for o in outs[:3]])
        D3 = ca.vertcat(*[D[outs[j], ins[j]] for j in range(3)])
        rows = [outs[0], outs[2], outs[3], outs[4]]  # x_rod, i_q, v_d, v_q
        Cs = ca.vertcat(*[Ck[o, :] for o in rows])
        ds = ca.vertcat(*[D[o, ins[3]] for o in rows])
        return A, (Ak, B3, C3, D3), (Bk[:, ins[3]], Cs, ds)

    def _same(self, key: str, exprs) -> int | None:
        """Index of an earlier load case whose ``exprs`` (MX of the gains) are numerically
        equal at the start gains and at random gains, else None (and remember these).

        Under the small-signal policy the linear dynamics at rest do not depend on the
        load (only the operating current and voltage do), so the frequency-domain
        constraints and the step's state trajectory are built once for all loads."""
        f = ca.Function("signature", [self.theta], [ca.veccat(*exprs)])
        rng = np.random.default_rng(1)
        sig = np.concatenate([np.array(f(t)).ravel() for t in (self.theta0, self.theta0 + rng.uniform(-1, 1, len(self.theta0)))])
        seen = self._signatures.setdefault(key, [])
        for j, other in seen:
            if np.allclose(sig, other, rtol=1e-12, atol=0):
                return j
        seen.append((len(seen), sig))
        return None

    def _add_case(self, op):
        req, F = self.req, op.f_ext
        A, (Ak, B3, C3, D3), (b, Cs, ds) = self._closed_loop(op)
        A_eig = A[self.keep_eig, self.keep_eig]
        j = self._same("frequency", [A_eig, Ak, B3, C3, D3])
        if j is not None:
            for grp in self.groups:
                if grp.kind in _SHARED and grp.case == j:
                    grp.loads.append(F)
        else:
            self._frequency_groups(op, len(self._signatures["frequency"]) - 1, A_eig, Ak, B3, C3, D3)
        j = self._same("step", [Ak, b])
        if j is None:
            self._trajectories.append(self._step_states(Ak, b))
            j = len(self._trajectories) - 1
        X, t = self._trajectories[j]
        k = self._same("x_rod", [Ak, b, Cs[0, :], ds[0]])
        if k is not None:  # same rod response as an earlier load case: its overshoot group
            for grp in self.groups:
                if grp.kind == "overshoot" and grp.case == k:
                    grp.loads.append(F)
            ise = None
        else:
            x_rod = (Cs[0, :] @ X) / req.step + ds[0]
            self.groups.append(_Group("overshoot", [F], None, (1 + req.overshoot - x_rod).T, None,
                                      len(self._signatures["x_rod"]) - 1))
            e2 = (x_rod - 1) ** 2
            ise = ca.sum2((e2[:, :-1] + e2[:, 1:]) * ca.DM(np.diff(t)).T) / 2 / 0.01
        self._limit_groups(op, X, Cs[1:, :], ds[1:])
        return ise

    def _frequency_groups(self, op, case, A_eig, Ak, B3, C3, D3):
        """Margin disks, ECU-rate ceilings, bandwidth and eigenvalue constraints."""
        req, F = self.req, op.f_ext
        G = self.S_grid(Ak, B3, C3, D3, (2 * np.pi * self.freqs).reshape(1, -1))  # 2 x 3N
        c, R = exclusion_disk(req)
        for j, loop in enumerate(_LOOP_ORDER):
            Sr, Si = 1 + G[0, j::3], G[1, j::3]  # S_j = 1 + G_jj
            s2 = Sr**2 + Si**2
            l2 = (1 - Sr) ** 2 + Si**2  # |1 - S|^2 = |L|^2 |S|^2
            u2 = (1 + (c - 1) * Sr) ** 2 + ((c - 1) * Si) ** 2  # |1 + (c-1) S|^2 = |L + c|^2 |S|^2
            # (|L + c|^2 - R^2) / (|L|^2 + c^2 + R^2), in [-1, 2] whatever the disk
            self.groups.append(_Group("margin", [F], loop, ((u2 - R**2 * s2) / (l2 + (c**2 + R**2) * s2)).T,
                                      self.freqs, case))
            if req.rate_ratio > 0:
                sel = np.nonzero(self.freqs >= self.ref[_RATE[loop]] / req.rate_ratio)[0]
                if len(sel):  # -log|L|^2 >= 0
                    self.groups.append(_Group("rate", [F], loop, ca.log(s2[sel] / l2[sel]).T, self.freqs[sel], case))

        def t_half(w_rad):  # x_rod/x_cmd = T = 1 - S_x = -G_xx: log(2 |T|^2) >= 0
            g = self.S.map(w_rad.shape[1])(Ak, B3, C3, D3, w_rad)
            return ca.log(2 * (g[0, 0::3] ** 2 + g[1, 0::3] ** 2)).T

        if self.fb is not None:
            self.groups.append(_Group("bandwidth", [F], "position", t_half(2 * np.pi * self.fb), None, case))
        if req.bandwidth_min_hz is not None:
            fm = req.bandwidth_min_hz
            fs = np.r_[self.freqs[(self.freqs >= fm / 10) & (self.freqs < fm)], fm]
            self.groups.append(_Group("bandwidth_min", [F], "position", t_half((2 * np.pi * fs).reshape(1, -1)), fs, case))
        cb = _SpectralAbscissa(A_eig.shape[0], f"spectral_abscissa_{len(self._callbacks)}")
        self._callbacks.append(cb)  # keep the callback alive as long as the problem
        excess = -req.sigma - cb(A_eig)  # >= 0 required (1/s)
        self.groups.append(_Group("eigenvalue", [F], None, ca.asinh(excess / max(1.0, req.sigma)), None, case))

    def _step_states(self, A, b):
        """Closed-loop state response to a step of req.step metres from rest, exact at the
        samples (matrix exponential), on a grid of _NSEG segments of _SEG samples whose
        spacing doubles per segment. Returns (X, t), X's first column at t = 0+."""
        req = self.req
        n = A.shape[0]
        h0 = req.t_step / (_SEG * (2**_NSEG - 1))
        # the norm grows with the gains: allow for 16x (4 extra squarings cost little)
        squarings = max(0, int(math.ceil(math.log2(max(self.A_norm * h0, 1e-300) / 0.5)))) + 4
        Ad, bd = _expm_step(A, b * req.step, h0, squarings)
        xs, Ads, bds = ca.MX.sym("x", n), ca.MX.sym("Ad", n, n), ca.MX.sym("bd", n)
        roll = ca.Function("lin_step", [xs, Ads, bds], [Ads @ xs + bds]).mapaccum("lin_roll", _SEG)
        x, X, t, h, tk = ca.MX.zeros(n), [ca.MX.zeros(n)], [0.0], h0, 0.0
        for _ in range(_NSEG):
            Xs = roll(x, Ad, bd)
            X.append(Xs)
            t.extend(tk + h * np.arange(1, _SEG + 1))
            tk += h * _SEG
            x = Xs[:, -1]
            bd = Ad @ bd + bd  # doubling the step: x(2h) = Ad (Ad x + bd) + bd
            Ad = Ad @ Ad
            h *= 2
        return ca.horzcat(*X), np.array(t)

    def _limit_groups(self, op, X, Cs, ds):
        """Current and voltage limits along the step (rows of Cs/ds: i_q, v_d, v_q;
        operating values added)."""
        req, F = self.req, op.f_ext
        Y = Cs @ X + ca.repmat(ds * req.step, 1, X.shape[1])
        i_q = op.output("i_q") + Y[0, :]
        v_d, v_q = op.output("v_d") + Y[1, :], op.output("v_q") + Y[2, :]
        pv = dict(zip(self.names, op.p))
        v_lim = pv["k_v"] * pv["V_dc"] / math.sqrt(3)
        r_i = (i_q / pv["I_max"]) ** 2
        r_v = (v_d**2 + v_q**2) / v_lim**2
        self.groups.append(_Group("current", [F], None, ca.log((1 + 1e-3) / (r_i + 1e-3)).T))
        self.groups.append(_Group("voltage", [F], None, ca.log((1 + 1e-3) / (r_v + 1e-3)).T))

    def _initial_bandwidth(self) -> float:
        from .frequency import bandwidth, closed_loop

        fb = min(bandwidth(closed_loop(self.model, op), f_min=0.01, f_max=1e4) for op in self.cases)
        return fb if math.isfinite(fb) else 10.0

    # -- solve --------------------------------------------------------------------
    def solve(self, max_iter: int, hessian: str, warm: tuple | None = None):
        """IPOPT; ``warm`` = (x, lam_g) of a previous solve of a problem of the same
        structure (the constraints are aggregated per group, so a refined grid keeps it)."""
        # mu_init 1e-2 instead of 0.1: the start is usually feasible or nearly so, and a
        # smaller initial barrier halves the iterations on the reference problem
        opts = {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes",
                "ipopt.max_iter": int(max_iter), "ipopt.hessian_approximation": hessian,
                "ipopt.tol": 1e-6, "ipopt.acceptable_tol": 1e-4, "ipopt.mu_init": 1e-2}
        if warm is not None:
            self.opti.set_initial(self.opti.x, warm[0])
            self.opti.set_initial(self.opti.lam_g, warm[1])
            opts.update({"ipopt.warm_start_init_point": "yes", "ipopt.mu_init": 1e-6,
                         "ipopt.warm_start_bound_push": 1e-9, "ipopt.warm_start_mult_bound_push": 1e-9})
        self.opti.solver("ipopt", opts)
        t0 = time.perf_counter()
        try:
            val = self.opti.solve().value
        except RuntimeError:
            try:
                self.opti.stats()
            except RuntimeError:
                raise  # not a solver failure: an error building or evaluating the problem
            val = self.opti.debug.value
        wall = time.perf_counter() - t0
        stats = self.opti.stats()
        theta = np.atleast_1d(np.array(val(self.theta), float).ravel())
        # an interior point stops ~1e-8 inside a bound: a linear gain (K_i_x) there is 0
        theta = np.where(~np.array(self.log_scaled) & (theta < 1e-6), 0.0, theta)
        gains = np.array(ca.Function("gains", [self.theta], [self.gains])(theta), float).ravel()
        groups = []
        slack = np.atleast_1d(np.array(val(self.slack), float).ravel())
        for grp, sl in zip(self.groups, slack):
            v = np.atleast_1d(np.array(val(grp.expr), float).ravel())
            j = int(np.argmin(v))
            groups.append({"kind": grp.kind, "loads": list(grp.loads), "loop": grp.loop, "min": float(v[j]),
                           "slack": float(sl),
                           "at_hz": float(grp.freqs[j]) if grp.freqs is not None else None})
        x_lam = (np.array(val(self.opti.x), float).ravel(), np.array(val(self.opti.lam_g), float).ravel())
        return {"gains": dict(zip(self.free, map(float, gains))), "stats": stats, "wall": wall, "warm": x_lam,
                "groups": groups, "objective": float(val(self.J_main)),
                "f_b": float(val(self.fb)) if self.fb is not None else None}


    def grid_gaps(self, gains: dict, per_decade: int = 100) -> np.ndarray:
        """Frequencies (Hz) where a margin disk or ECU-rate constraint, checked on a grid
        ``per_decade`` times denser than the decade, is violated between the points of
        the optimisation grid (one per local minimum below zero)."""
        theta = np.array([math.log(gains[g] / self.ref[g]) if ls else gains[g] / (self.ref["K_x"] ** 2 / 4)
                          for g, ls in zip(self.free, self.log_scaled)])
        f = np.logspace(math.log10(self.freqs[0]), math.log10(self.freqs[-1]),
                        int(per_decade * math.log10(self.freqs[-1] / self.freqs[0])) + 1)
        c, R = exclusion_disk(self.req)
        out = []
        for op in self.cases:
            _, (Ak, B3, C3, D3), _ = self._closed_loop(op)
            G = np.array(ca.Function("dense", [self.theta], [self.S.map(len(f))(Ak, B3, C3, D3, (2 * np.pi * f).reshape(1, -1))])(theta))
            for j, loop in enumerate(_LOOP_ORDER):
                S = 1 + G[0, j::3] + 1j * G[1, j::3]
                L = 1 / S - 1
                checks = [np.abs(L + c) ** 2 - R**2]
                if self.req.rate_ratio > 0:
                    checks.append(np.where(f >= self.ref[_RATE[loop]] / self.req.rate_ratio, 1 - np.abs(L) ** 2, 1.0))
                for m in checks:
                    low = (m < 0) & (m <= np.r_[np.inf, m[:-1]]) & (m <= np.r_[m[1:], np.inf])
                    out.extend(f[low].tolist())
        new = [x for x in out if np.min(np.abs(np.log(self.freqs / x))) > 1e-6]
        return np.unique(np.array(new))


# -------------------------------------------------------------------------------
@dataclass
class TuneResult:
    """Outcome of :func:`tune`.

    Attributes
    ----------
    success : bool
        IPOPT converged and the independent verification meets every requirement.
    status : str
        IPOPT's return status (e.g. ``Solve_Succeeded``).
    iterations : int
        IPOPT iterations, summed over the rounds.
    rounds : int
        Solves: after each, frequencies where a dense check finds a margin constraint
        violated between grid points are added to the grid (at most 3).
    solve_time, build_time : float
        Wall times (s) of IPOPT and of building the problems.
    n_freqs : int
        Frequencies in the final grid.
    objective : str
        ``bandwidth`` or ``tracking``.
    objective_value : float
        Worst-case -3 dB frequency f_b (Hz) for ``bandwidth``; the normalised ISE for
        ``tracking``.
    gains_before, gains_after : dict
        Free gains at the start and at the solution (SI).
    loads : list of float
        Load cases (N).
    requirements : Requirements
    violations : list of dict
        Constraint groups violated at the returned point (optimiser's model): ``kind``,
        ``loads``, ``loop``, ``min`` (smallest normalised value, >= 0 is met), ``slack``
        (elastic relaxation left), ``at_hz``.
    active : list of dict
        Constraint groups met with almost no slack (what limits the design), same keys.
    verification_before, verification_after : dict
        :func:`verify` at the start and at the result (fresh linearisation, python-control).
    params : Parameters
        The parameter set with the tuned gains.
    message : str
        One line: what happened, naming a violated constraint if any.
    """

    success: bool
    status: str
    iterations: int
    rounds: int
    solve_time: float
    build_time: float
    n_freqs: int
    objective: str
    objective_value: float
    gains_before: dict
    gains_after: dict
    loads: list
    requirements: Requirements
    violations: list
    active: list
    verification_before: dict
    verification_after: dict
    params: Parameters
    message: str
    variants: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        """JSON-ready summary (SI units; frequencies in Hz)."""
        return {
            "success": self.success, "status": self.status, "iterations": self.iterations,
            "rounds": self.rounds, "solve_time_s": self.solve_time, "build_time_s": self.build_time,
            "n_freqs": self.n_freqs,
            "objective": self.objective, "objective_value": self.objective_value,
            "gains_before": self.gains_before, "gains_after": self.gains_after,
            "loads_N": self.loads, "requirements": self.requirements.as_dict(),
            "violations": self.violations, "active": self.active, "message": self.message, "variants": self.variants,
            "before": self.verification_before, "after": self.verification_after,
        }

    def write(self, path) -> Path:
        """Parameter file with the tuned gains (atomic)."""
        g = ", ".join(f"{k} = {v:.6g}" for k, v in self.gains_after.items())
        header = (f"Tuned by ema tune ({self.objective}; IPOPT {self.status}, {self.iterations} iterations)\n"
                  f"loads {', '.join(_load_label(f) for f in self.loads)}; {g}")
        return self.params.to_toml(path, header=header)


def tune(
    params: Parameters,
    variants: dict | None = None,
    *,
    free=None,
    loads=(0.0,),
    objective: str = "bandwidth",
    requirements: Requirements | None = None,
    start: dict | None = None,
    freqs=None,
    max_iter: int = 200,
    hessian: str = "exact",
    verify_step: float = 1e-3,
    model: Model | None = None,
) -> TuneResult:
    """Tune the cascade's gains by IPOPT (module docstring for the formulation).

    Parameters
    ----------
    params : Parameters
        Parameter set; its gains are the reference that scales the variables.
    variants : dict, optional
        Model variants (default the set's own).
    free : sequence of str, optional
        Gains to tune (default :func:`default_free`); the others keep their values.
    loads : sequence of float
        Load cases f_ext (N); the worst case must meet every requirement.
    objective : {"bandwidth", "tracking"}
    requirements : Requirements, optional
    start : dict, optional
        Start values of free gains (default the set's).
    freqs : array_like, optional
        Frequency grid (Hz) of the robustness constraints (default 0.5 Hz - 10 kHz,
        25 per decade).
    max_iter : int
        IPOPT iteration limit.
    hessian : {"exact", "limited-memory"}
    verify_step : float
        Amplitude (m) of the nonlinear step simulated before and after (0 skips it).
    model : Model, optional
        An already built model for ``params``/``variants``.
    """
    req = requirements or Requirements()
    req.check()
    if objective not in OBJECTIVES:
        raise TuneError(f"objective '{objective}' unknown; choose one of {', '.join(OBJECTIVES)}")
    if hessian not in ("exact", "limited-memory"):
        raise TuneError(f"hessian '{hessian}' unknown; choose exact or limited-memory")
    if model is None:
        model = build_model(params, variants)
    free = tuple(default_free(model) if free is None else free)
    if not free:
        raise TuneError("no free gain: name at least one of " + ", ".join(GAINS))
    for g in free:
        if g not in GAINS:
            import difflib

            near = difflib.get_close_matches(g, GAINS, n=1)
            raise TuneError(f"'{g}' is not a tunable gain{f' (did you mean {near[0]!r}?)' if near else ''}; "
                            f"choose from {', '.join(GAINS)}")
        if g == "K_i_x" and model.variants.get("controller") != "PI":
            raise TuneError("K_i_x acts only with the PI position loop (variant controller=PI)")
    if len(set(free)) != len(free):
        raise TuneError("a gain is named twice in free")
    loads = [float(f) for f in loads]
    if not loads or not all(math.isfinite(f) for f in loads):
        raise TuneError("loads must be one or more finite forces (N)")
    d = params.as_dict()
    start = {g: float(d[g]) for g in free} | {k: float(v) for k, v in (start or {}).items() if k in free}
    for k in start:
        if not math.isfinite(start[k]) or start[k] < 0:
            raise TuneError(f"start value of {k} must be a non-negative number, got {start[k]}")
    freqs = np.logspace(math.log10(0.5), 4, 61) if freqs is None else np.asarray(freqs, float)

    t0 = time.perf_counter()
    iterations, solve_time, rounds, warm = 0, 0.0, 0, None
    for rounds in range(1, _ROUNDS + 1):
        prob = _Problem(model, params, free, loads, req, objective, start, freqs)
        out = prob.solve(max_iter, hessian, warm)
        iterations += int(out["stats"].get("iter_count", 0))
        solve_time += out["wall"]
        relaxed = any(g["slack"] > _FEAS_TOL for g in out["groups"])
        gaps = prob.grid_gaps(out["gains"]) if out["stats"].get("success") and not relaxed else []
        if not len(gaps):
            break
        # semi-infinite constraints: add the frequencies where the dense check fails, re-solve
        freqs = np.sort(np.r_[freqs, gaps])
        warm = out["warm"]
    build_time = time.perf_counter() - t0 - solve_time
    stats = out["stats"]
    status = str(stats.get("return_status", "unknown"))
    converged = bool(stats.get("success", False)) and status in ("Solve_Succeeded", "Solved_To_Acceptable_Level")
    tuned = params.replace(**out["gains"])
    violations = [g for g in out["groups"] if g["slack"] > _FEAS_TOL or g["min"] < -_FEAS_TOL]
    active = [g for g in out["groups"] if g not in violations and g["min"] < _ACTIVE]

    before_gains = dict(start)
    ver_before = verify(model, params.replace(**before_gains), loads, req, nonlinear_step=verify_step)
    ver_after = verify(model, tuned, loads, req, nonlinear_step=verify_step)
    success = converged and not violations and ver_after["meets"]
    message = _message(converged, status, violations, ver_after, req)
    value = out["f_b"] if objective == "bandwidth" else out["objective"]
    return TuneResult(
        success=success, status=status, iterations=iterations, rounds=rounds,
        solve_time=solve_time, build_time=build_time, n_freqs=len(freqs), objective=objective, objective_value=value,
        gains_before=before_gains, gains_after=out["gains"], loads=loads, requirements=req,
        violations=violations, active=active, verification_before=ver_before, verification_after=ver_after,
        params=tuned, message=message, variants=dict(model.variants),
    )


def _loads_text(loads) -> str:
    return ", ".join(f"{f / 1e3:g}" for f in loads) + " kN"


def describe_constraint(v: dict, req: Requirements | None = None) -> str:
    """One-line text of a constraint group (an entry of :attr:`TuneResult.violations` or
    ``active``), with the requirement's numbers when ``req`` is given."""
    r = req or Requirements()
    if r.ms is not None:
        margin = f"sensitivity peak Ms <= {r.ms:g}"
    else:
        margin = f"margins GM >= {r.gm_db:g} dB / PM >= {r.pm_deg:g} deg"
    text = {
        "margin": margin,
        "rate": f"loop gain below 1 above the ECU sample rate / {r.rate_ratio:g}",
        "bandwidth": "bandwidth (objective)",
        "bandwidth_min": f"bandwidth >= {r.bandwidth_min_hz:g} Hz" if r.bandwidth_min_hz else "minimum bandwidth",
        "overshoot": f"step overshoot <= {100 * r.overshoot:g} %",
        "current": f"current limit on a {r.step * 1e3:g} mm step",
        "voltage": f"voltage limit on a {r.step * 1e3:g} mm step",
        "eigenvalue": f"closed-loop eigenvalues left of -{r.sigma:g} 1/s",
    }.get(v["kind"], v["kind"])
    where = f"{v['loop']} loop, " if v.get("loop") and v["kind"] in ("margin", "rate") else ""
    at = f" near {v['at_hz']:.3g} Hz" if v.get("at_hz") else ""
    return f"{text} ({where}{_loads_text(v['loads'])}{at})"


def _message(converged, status, violations, ver, req) -> str:
    if converged and not violations and ver["meets"]:
        return f"tuned: IPOPT {status}; every requirement met in every load case (verified)"
    fails = ver.get("failures", [])
    if violations:
        worst = sorted(violations, key=lambda v: -max(v["slack"], -v["min"]))[:2]
        text = ("infeasible request: no gains meet every constraint; the least-violating gains "
                f"(IPOPT {status}) still break the " + " and the ".join(describe_constraint(v, req) for v in worst))
        return text + (f"; e.g. {fails[0]}" if fails else "")
    if not converged:
        return f"tuning failed: IPOPT {status}" + (f"; at the last point {fails[0]}" if fails else "")
    return (f"tuning failed: IPOPT {status}, but the independent check finds " + "; ".join(fails[:3]))


# -------------------------------------------------------------------------------
def _ct_margins(L, f_lo=1e-2, f_hi=1e5) -> dict:
    """python-control margins of a SISO loop transfer, crossovers outside [f_lo, f_hi] Hz
    (the spurious ones near 0 Hz and ~1e9 Hz) dropped.

    Returns ``gm_db`` (signed, the smallest in magnitude: positive = the gain may rise
    by that much, negative = fall), ``f_pc_hz``, ``gm_up_db`` / ``gm_down_db`` (the
    smallest rise / fall, inf if none), ``pm_deg`` (smallest angular distance of L to
    -1 at a gain crossover) and ``f_gc_hz``."""
    import warnings

    import control as ct

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # NaNs from its root polishing
        gm, pm, _sm, wpc, wgc, _wms = ct.stability_margins(L, returnall=True)
    gm, pm, wpc, wgc = (np.atleast_1d(np.asarray(v, float)) for v in (gm, pm, wpc, wgc))
    fpc, fgc = wpc / (2 * np.pi), wgc / (2 * np.pi)
    sel = (fpc >= f_lo) & (fpc <= f_hi) & np.isfinite(gm) & (gm > 0)
    gm_db, fpc = 20 * np.log10(gm[sel]), fpc[sel]
    out = {"gm_db": math.inf, "f_pc_hz": None, "gm_up_db": math.inf, "gm_down_db": math.inf,
           "pm_deg": math.inf, "f_gc_hz": None}
    if gm_db.size:
        j = int(np.argmin(np.abs(gm_db)))
        out.update(gm_db=float(gm_db[j]), f_pc_hz=float(fpc[j]))
        up, down = gm_db[gm_db > 0], -gm_db[gm_db <= 0]
        out.update(gm_up_db=float(up.min()) if up.size else math.inf,
                   gm_down_db=float(down.min()) if down.size else math.inf)
    sel = (fgc >= f_lo) & (fgc <= f_hi) & np.isfinite(pm)
    pms = np.abs((pm[sel] + 180) % 360 - 180)
    if pms.size:
        j = int(np.argmin(pms))
        out.update(pm_deg=float(pms[j]), f_gc_hz=float(fgc[sel][j]))
    return out


def _linear_step(model, op, amp, t_end):
    """Closed-loop linear step (python-control) of amp metres: overshoot, 2 % settling
    time, peak |i_q| and |v_dq| including the operating values."""
    import control as ct

    from .linearisation import linear_model

    outs = ["x_rod", "i_q", "v_d", "v_q"]
    lin = linear_model(model, op, inputs=["x_cmd"], outputs=outs)
    keep = [i for i in range(lin.A.shape[0]) if np.any(lin.A[:, i] != 0) or np.any(lin.C[:, i] != 0)]
    sys = ct.ss(lin.A[np.ix_(keep, keep)], lin.B[keep], lin.C[:, keep], lin.D)
    t = np.linspace(0.0, t_end, int(round(t_end / 2e-5)) + 1)  # 20 us: resolves the current peak
    r = ct.forced_response(sys, t, np.full_like(t, amp))
    y = np.atleast_2d(r.outputs)
    x = y[0] / amp
    i_q = op.output("i_q") + y[1]
    v = np.hypot(op.output("v_d") + y[2], op.output("v_q") + y[3])
    m = step_response_metrics(t, x)
    return {"overshoot": m["overshoot"], "settling_time_s": m["settling_time_s"],
            "i_q_peak_A": float(np.max(np.abs(i_q))), "v_dq_peak_V": float(np.max(v))}


def verify(model: Model, params: Parameters, loads=(0.0,), requirements: Requirements | None = None,
           nonlinear_step: float = 0.0) -> dict:
    """Check a gain set independently of the optimiser.

    For every load case a fresh trim and AD linearisation with these gains
    (:mod:`ema_casadi.linearisation`); per loop, python-control ``stability_margins`` of
    the loop transfer (crossovers outside 0.01 Hz - 100 kHz dropped; GM is the signed
    one of smallest magnitude, PM the smallest angular distance to -1) and the
    closed-loop stability; the closed-loop -3 dB bandwidth and the linear step
    (python-control) with its peaks of current and voltage. Optionally a nonlinear
    step simulation (:func:`step_metrics`) at no load.

    Returns a dict: ``loads`` (per load label: ``loops`` -> gm_db, f_pc_hz, pm_deg,
    f_gc_hz, stable; ``bandwidth_hz``, ``spectral_abscissa``, ``step``), ``worst``
    (smallest |GM|, PM, bandwidth over all), ``meets`` (bool), ``failures`` (list of
    one-line texts) and ``nonlinear_step`` (or None).
    """
    from .frequency import bandwidth, closed_loop
    from .linearisation import linear_model, loop_transfer

    import control as ct

    req = requirements or Requirements()
    gm_up, pm_req = req.margin_targets()
    # a lower gain margin (crossing left of -1): GM itself, or 1 + 1/Ms under |1 + L| >= 1/Ms
    gm_down = gm_up if req.ms is None else 20 * math.log10(1 + 1 / req.ms)
    f_ms = np.logspace(-2, 5, 701)  # 100 per decade for the sensitivity peak
    p = params.vector()
    pv = dict(zip(model.param_names, p))
    I_max, v_lim = pv["I_max"], pv["k_v"] * pv["V_dc"] / math.sqrt(3)
    out, failures = {}, []
    worst = {"gm_db": math.inf, "pm_deg": math.inf, "ms": 0.0, "bandwidth_hz": math.inf}
    for F in loads:
        label = _load_label(F)
        try:
            op = operating_point(model, f_ext=F, p=p)
        except LinearizationError as exc:
            failures.append(f"{label}: {exc}")
            continue
        loops = {}
        for name in LOOPS:
            L = loop_transfer(model, name, op)
            m = _ct_margins(L)
            m["ms"] = float(np.max(np.abs(1 / (1 + ct.frequency_response(L, 2 * np.pi * f_ms).complex.ravel()))))
            loops[name] = m
            worst["gm_db"] = min(worst["gm_db"], abs(m["gm_db"]))
            worst["pm_deg"] = min(worst["pm_deg"], m["pm_deg"])
            worst["ms"] = max(worst["ms"], m["ms"])
            where = f"{name} loop at {label}"
            if m["gm_up_db"] < gm_up - 1e-6:
                failures.append(f"{where}: GM +{m['gm_up_db']:.2f} dB < {gm_up:.3g} dB required")
            if m["gm_down_db"] < gm_down - 1e-6:
                failures.append(f"{where}: GM -{m['gm_down_db']:.2f} dB (gain may fall only that much) "
                                f"< {gm_down:.3g} dB required")
            if m["pm_deg"] < pm_req - 1e-6:
                failures.append(f"{where}: PM {m['pm_deg']:.2f} deg < {pm_req:.3g} deg required")
            if req.ms is not None and m["ms"] > req.ms * (1 + 1e-3):
                failures.append(f"{where}: sensitivity peak {m['ms']:.4g} > Ms = {req.ms:g}")
        A = linear_model(model, op, inputs=["x_cmd"], outputs=["x_rod"]).A
        keep = [i for i in range(A.shape[0]) if np.any(A[:, i] != 0)]
        alpha = float(np.max(np.linalg.eigvals(A[np.ix_(keep, keep)]).real))
        stable = alpha < 0
        for v in loops.values():
            v["stable"] = stable
        if not alpha <= -req.sigma + 1e-9 * max(1.0, abs(alpha)):
            failures.append(f"{label}: closed-loop eigenvalue at Re = {alpha:.4g} 1/s, right of -sigma = {-req.sigma:g}")
        bw = bandwidth(closed_loop(model, op), f_min=0.01, f_max=1e4)
        worst["bandwidth_hz"] = min(worst["bandwidth_hz"], bw)
        if req.bandwidth_min_hz is not None and bw < req.bandwidth_min_hz * (1 - 1e-6):
            failures.append(f"{label}: bandwidth {bw:.3g} Hz < {req.bandwidth_min_hz:g} Hz required")
        st = _linear_step(model, op, req.step, req.t_step)
        if st["overshoot"] > req.overshoot + 1e-4:
            failures.append(f"{label}: linear step overshoot {100 * st['overshoot']:.2f} % > {100 * req.overshoot:g} %")
        if st["i_q_peak_A"] > I_max * (1 + 1e-4):
            failures.append(f"{label}: current peak {st['i_q_peak_A']:.3g} A > I_max {I_max:g} A on a "
                            f"{req.step * 1e3:g} mm step")
        if st["v_dq_peak_V"] > v_lim * (1 + 1e-4):
            failures.append(f"{label}: voltage peak {st['v_dq_peak_V']:.4g} V > {v_lim:.4g} V on a "
                            f"{req.step * 1e3:g} mm step")
        out[label] = {"f_ext_N": F, "loops": loops, "bandwidth_hz": bw, "spectral_abscissa": alpha,
                      "stable": stable, "step": st}
    nl = step_metrics(model, params, nonlinear_step) if nonlinear_step else None
    return {"loads": out, "worst": worst, "meets": not failures, "failures": failures, "nonlinear_step": nl}


def step_metrics(model: Model, params: Parameters, amp: float = 1e-3, *, f_ext: float = 0.0,
                 t_end: float = 0.4, t0: float = 0.01, band: float = 0.02) -> dict:
    """Nonlinear step simulation (full model: friction, backlash, limits; CVODES) from
    rest under the load (trimmed, screw against the loaded flank of the backlash).

    Parameters
    ----------
    amp : float
        Step amplitude (m) at ``t0`` (s).
    f_ext : float
        Constant external force (N).
    t_end : float
        End time (s).
    band : float
        Settling band (fraction of amp).

    Returns a dict: ``overshoot`` (fraction), ``settling_time_s`` (from the step; inf if
    it has not settled by t_end), ``rise_time_s`` (10-90 %), ``i_q_peak_A``,
    ``v_dq_peak_V``, ``x_final_m``, and the series ``t``, ``x_rod``, ``i_q`` for plots.
    """
    import warnings

    from .signals import Signal
    from .simulation import simulate

    pv = params.vector()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "inside the backlash gap" at no load: expected here
        # at rest under the load, the nut against the loaded flank of the gap
        x0 = operating_point(model, f_ext=f_ext, backlash="keep", p=pv).x
    res = simulate(model, t_end, x_cmd=Signal.step(amp, t0), f_ext=f_ext, p=pv, x0=x0,
                   solver="cvodes", dt=1e-4, dt_out=1e-4, rtol=1e-7, atol=1e-10)
    t, x = res.t, res["x_rod"]
    # relative to the rest position before the step (a load compresses the screw)
    x0 = float(np.interp(t0, t, x))
    after = t >= t0
    m = step_response_metrics(t[after] - t0, (x[after] - x0) / amp, band)
    return {
        "amp_m": amp, "f_ext_N": f_ext,
        "overshoot": m["overshoot"],
        "settling_time_s": m["settling_time_s"],
        "rise_time_s": m["rise_time_s"],
        "i_q_peak_A": float(np.max(np.abs(res["i_q"]))),
        "v_dq_peak_V": float(np.max(np.hypot(res["v_d"], res["v_q"]))),
        "x_final_m": float(x[-1]),
        "t": t, "x_rod": x, "i_q": res["i_q"],
    }


# -------------------------------------------------------------------------------
def plot_tuning(result: TuneResult, model: Model, params_before: Parameters, folder,
                reference: Parameters | None = None) -> list:
    """Bode plots (closed loop x_rod/x_cmd and the three loop transfers, first load case)
    and the nonlinear step (no load) before and after, optionally with a reference gain
    set; PNGs ``tune_bode.png`` and ``tune_step.png`` written atomically into ``folder``.
    Returns the paths."""
    from pathlib import Path

    from .frequency import bode, closed_loop, frequency_grid
    from .linearisation import loop_model
    from .plotting import save

    import matplotlib.pyplot as plt

    folder = Path(folder)
    f = frequency_grid(0.1, 1e4, 60)
    F = result.loads[0]
    sets = {"before": (params_before, "--"), "after": (result.params, "-")}
    if reference is not None:
        sets["reference"] = (reference, ":")
    fig, ax = plt.subplots(2, 4, figsize=(17, 7), sharex=True)
    titles = ["closed loop x_rod/x_cmd"] + [f"L, {n} loop (others closed)" for n in LOOPS]
    for lbl, (ps, ls) in sets.items():
        op = operating_point(model, f_ext=F, p=ps.vector())
        systems = [closed_loop(model, op)] + [loop_model(model, n, op) for n in LOOPS]
        for j, sys_ in enumerate(systems):
            b = bode(sys_, f)
            ax[0, j].semilogx(f, b["mag_db"], ls, label=lbl)
            ax[1, j].semilogx(f, b["phase_deg"], ls, label=lbl)
    for j, ttl in enumerate(titles):
        ax[0, j].set_title(ttl, fontsize=9)
        ax[0, j].axhline(-3 if j == 0 else 0, color="k", lw=0.6)
        ax[1, j].set_xlabel("frequency (Hz)")
        for a in ax[:, j]:
            a.grid(True, which="both", alpha=0.3)
    ax[0, 0].set_ylabel("magnitude (dB)")
    ax[1, 0].set_ylabel("phase (deg)")
    ax[0, 0].legend(fontsize=8)
    fig.suptitle(f"gain tuning ({result.objective}), linearised at {_load_label(F)}", fontsize=10)
    fig.tight_layout()
    paths = [save(fig, folder / "tune_bode.png")]

    fig, ax = plt.subplots(2, 1, figsize=(8, 7), sharex=True)
    amp = None
    for lbl, (ps, ls) in sets.items():
        key = {"before": "verification_before", "after": "verification_after"}.get(lbl)
        nl = getattr(result, key).get("nonlinear_step") if key else None
        if nl is None:
            amp = amp or next((getattr(result, k)["nonlinear_step"]["amp_m"] for k in
                               ("verification_after", "verification_before") if getattr(result, k).get("nonlinear_step")), 1e-3)
            nl = step_metrics(model, ps, amp)
        amp = nl["amp_m"]
        ax[0].plot(nl["t"], nl["x_rod"] * 1e3, ls,
                   label=f"{lbl}: overshoot {100 * nl['overshoot']:.1f} %, settles {1e3 * nl['settling_time_s']:.1f} ms")
        ax[1].plot(nl["t"], nl["i_q"], ls, label=lbl)
    ax[0].set_ylabel("x_rod (mm)")
    ax[1].set_ylabel("i_q (A)")
    ax[1].set_xlabel("time (s)")
    for a in ax:
        a.grid(True, alpha=0.3)
        a.legend(fontsize=8)
    ax[0].set_title(f"nonlinear {amp * 1e3:g} mm step (full model, no load)", fontsize=10)
    fig.tight_layout()
    paths.append(save(fig, folder / "tune_step.png"))
    return paths
