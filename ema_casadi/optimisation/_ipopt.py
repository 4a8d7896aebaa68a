"""The one IPOPT wrapper: an Opti problem solved with the project's settings, a fallback
chain of option sets, a warm start, the iteration log and a stop between iterations on
SIGINT/SIGTERM (module docs: :mod:`ema_casadi.optimisation`)."""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from .._util import _interrupts

__all__ = ["IpoptResult", "solve_ipopt", "BASE_OPTIONS", "WARM_START", "SUCCESS"]

#: The settings every solve gets (the caller's options may not change them): no banner,
#: no output, no timing print; MUMPS, IPOPT's default linear solver, named so that a build
#: with another default does not change the paths. Nothing here depends on the machine.
#: What keeps a path the same on every OpenBLAS kernel is the formulation (bounds passed
#: as bounds: ``simple_bounds``; well-scaled constraints; no rank-deficient rows), and the
#: options a caller measured for its problem (``mu_init``, ``theta_max_fact``, ...).
BASE_OPTIONS = {"sb": "yes", "print_level": 0, "linear_solver": "mumps"}
#: IPOPT's warm start from a previous solution's primal and dual values (``warm``): the
#: start is not pushed back into the interior. The barrier's start (``mu_init``) is the
#: caller's: how close the previous solution is to this one's is the caller's knowledge.
WARM_START = {"warm_start_init_point": "yes", "warm_start_bound_push": 1e-9, "warm_start_mult_bound_push": 1e-9}
#: IPOPT's return statuses that count as converged.
SUCCESS = ("Solve_Succeeded", "Solved_To_Acceptable_Level")


@dataclass
class IpoptResult:
    """The outcome of :func:`solve_ipopt`.

    Attributes
    ----------
    success : bool
        IPOPT converged (a status in :data:`SUCCESS`) with the last option set tried.
    status : str
        IPOPT's return status (``Solve_Succeeded``, ``Maximum_Iterations_Exceeded``, ...).
    iterations : int
        IPOPT's iterations of the last option set tried.
    value : callable
        ``value(expr)``: an expression of the Opti problem at the solution (at the last
        iterate where IPOPT did not converge).
    x, lam_g : ndarray
        The decision variables and the constraints' multipliers (``warm`` of a next solve).
    stats : dict
        IPOPT's statistics (CasADi's ``stats()``) of the last option set tried.
    log : dict
        The iteration log: per iteration ``obj``, ``inf_pr``, ``inf_du``, ``mu``,
        ``d_norm``, ``alpha_pr``, ``alpha_du``, ``regularization_size`` (lists).
    attempts : list of dict
        Per option set tried, in turn: ``status`` and ``iterations``.
    wall_s : float
        Wall time of the solves (s).
    """

    success: bool
    status: str
    iterations: int
    value: Callable
    x: np.ndarray
    lam_g: np.ndarray
    stats: dict
    log: dict = field(default_factory=dict)
    attempts: list = field(default_factory=list)
    wall_s: float = 0.0

    @property
    def warm(self) -> tuple:
        """(x, lam_g): the ``warm`` argument of a next solve of a problem of the same structure."""
        return self.x, self.lam_g


class _Hook:
    """The per-iteration callback: the interrupt flag first, then the caller's hook.

    Python runs a signal handler only between bytecodes of the main thread, never while
    IPOPT holds the interpreter in C++: the handler of :mod:`ema_casadi._util._interrupts`
    records the signal (and raises, which CasADi swallows where it happens inside a
    function evaluation). This hook runs once per IPOPT iteration, asks that flag, and
    raises; CasADi turns an exception in the callback into IPOPT's
    ``User_Requested_Stop``, and :func:`solve_ipopt` raises it again after the solve."""

    def __init__(self, opti: ca.Opti, on_iteration: Callable | None):
        self.opti, self.on_iteration, self.raised = opti, on_iteration, None

    def __call__(self, iteration) -> None:
        try:
            _interrupts.check()
            if self.on_iteration is not None:
                self.on_iteration(int(iteration), self.opti.debug.value)
        except BaseException as exc:  # noqa: BLE001 - kept, raised again after IPOPT stops
            self.raised = exc
            raise


def _options(ipopt: Mapping, expand: bool, simple_bounds: bool) -> tuple[dict, dict]:
    unknown = [k for k in ipopt if k.startswith("ipopt.")]
    if unknown:
        raise ValueError(f"ipopt options without the 'ipopt.' prefix: {unknown}")
    plugin = {"print_time": False, "expand": bool(expand), "detect_simple_bounds": bool(simple_bounds)}
    return plugin, {**dict(ipopt), **BASE_OPTIONS}


def solve_ipopt(opti: ca.Opti, ipopt: Mapping | Sequence[Mapping] = (), *, expand: bool = False,
                simple_bounds: bool = False, warm: tuple | None = None, on_iteration: Callable | None = None
                ) -> IpoptResult:
    """Solve an Opti problem by IPOPT.

    Parameters
    ----------
    opti : casadi.Opti
        The problem (variables, constraints, objective, initial values set).
    ipopt : dict or sequence of dict
        IPOPT's options (names without the ``ipopt.`` prefix: ``max_iter``, ``tol``,
        ``mu_strategy``, ...), or a fallback chain: option sets tried in turn, each from
        the same initial values, until one converges. :data:`BASE_OPTIONS` are added.
    expand : bool
        Expand the problem to SX (faster evaluations; the exact Hessian of a long chain
        of calls is cheaper kept as MX).
    simple_bounds : bool
        Pass constraints on a single variable (``opti.bounded(lo, x, hi)``, ``x >= 0``)
        to IPOPT as variable bounds, which its iterates never leave (Opti passes every
        constraint as a row of g otherwise).
    warm : tuple, optional
        (x, lam_g) of a solve of a problem of the same structure (:attr:`IpoptResult.warm`):
        set as the initial values, with :data:`WARM_START` added to every option set.
    on_iteration : callable, optional
        ``on_iteration(k, value)`` after every IPOPT iteration, ``value(expr)`` the
        iterate's value of an expression. What it raises stops IPOPT and is raised again.

    Returns
    -------
    IpoptResult

    Raises
    ------
    RuntimeError
        CasADi's error where the problem cannot be built or evaluated (not a solver failure).
    KeyboardInterrupt, ema_casadi._util._interrupts.Interrupted
        SIGINT/SIGTERM arrived during the solve: IPOPT stopped at the end of its iteration.
    """
    chain = [ipopt] if isinstance(ipopt, Mapping) else list(ipopt) or [{}]
    if warm is not None:
        opti.set_initial(opti.x, warm[0])
        opti.set_initial(opti.lam_g, warm[1])
        chain = [{**WARM_START, **o} for o in chain]
    hook = _Hook(opti, on_iteration)
    opti.callback(hook)
    attempts, t0 = [], time.perf_counter()
    for options in chain:
        opti.solver("ipopt", *_options(options, expand, simple_bounds))
        try:
            sol = opti.solve()
            value, ok = sol.value, True
        except RuntimeError:
            if hook.raised is not None:
                raise hook.raised from None
            try:
                opti.stats()
            except RuntimeError:
                raise  # not a solver failure: an error building or evaluating the problem
            value, ok = opti.debug.value, False
        _interrupts.check()
        stats = opti.stats()
        attempts.append({"status": stats["return_status"], "iterations": int(stats["iter_count"])})
        if ok:
            break
    return IpoptResult(success=ok, status=stats["return_status"], iterations=int(stats["iter_count"]),
                       value=value, x=_vector(value(opti.x)), lam_g=_vector(value(opti.lam_g)), stats=stats,
                       log=dict(stats.get("iterations", {})), attempts=attempts, wall_s=time.perf_counter() - t0)


def _vector(v) -> np.ndarray:
    return np.atleast_1d(np.array(v, float).ravel())
