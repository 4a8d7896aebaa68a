"""Shooting transcriptions of a trajectory and what every transcription shares: scaled
node states, continuity, the parameters as decision variables, and :func:`transcribe`,
which builds one of the three (module docs: :mod:`ema_casadi.optimisation`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from ._collocation import DEGREE, collocation

__all__ = ["METHODS", "Transcription", "transcribe", "multiple_shooting", "single_shooting", "continuity",
           "decision_parameters"]

#: The transcriptions of :func:`transcribe`.
METHODS = ("single", "multiple", "collocation")


def multiple_shooting(interval: ca.Function, X, *args):
    """Every interval's end state (nx x N): ``interval`` mapped over the N intervals
    from the node states X[:, :-1] (physical), each of ``args`` with N columns (inputs,
    parameters, interval lengths, in ``interval``'s order after the state).

    Parameters
    ----------
    interval : casadi.Function
        One interval, ``F(x, *args) -> x_next`` (or ``(x_next, q)`` with a quadrature),
        e.g. :func:`ema_casadi.simulation.interval_function`.
    X : MX
        The node states (nx x N + 1; the last column is not used).
    *args
        The interval's other inputs, N columns each.
    """
    N = X.shape[1] - 1
    return interval.map(N)(X[:, :-1], *args)


def single_shooting(interval: ca.Function, x0, *args):
    """The states at the N + 1 nodes (nx x N + 1) of one rollout from ``x0``: the chain
    of ``interval`` over the N intervals (``args`` with N columns each, as
    :func:`multiple_shooting`; a quadrature output, if any, is dropped).

    Parameters
    ----------
    interval : casadi.Function
        One interval, ``F(x, *args) -> x_next``.
    x0 : MX or DM
        The start state.
    *args
        The interval's other inputs, N columns each.
    """
    N = args[0].shape[1] if args else 0
    x, cols = x0, [x0]
    for k in range(N):
        out = interval(x, *(a[:, k] for a in args))
        x = out[0] if isinstance(out, (tuple, list)) else out
        cols.append(x)
    return ca.horzcat(*cols)


def continuity(opti: ca.Opti, Xs, X_next, scale: np.ndarray, rows=None) -> None:
    """The continuity constraints Xs[:, k+1] = X_next[:, k] / scale (the rows ``rows``,
    default all), in the states' full scales.

    Parameters
    ----------
    opti : casadi.Opti
        The NLP.
    Xs : MX
        Scaled node states (nx x N + 1).
    X_next : MX
        Every interval's end state (nx x N, physical).
    scale : ndarray
        The states' full scales.
    rows : sequence of int, optional
        The states made continuous (default all).
    """
    rows = list(range(Xs.shape[0])) if rows is None else list(rows)
    opti.subject_to(ca.vec(Xs[rows, 1:] - ca.diag(1 / scale[rows]) @ X_next[rows, :]) == 0)


def decision_parameters(opti: ca.Opti, p0, free, *, log=None, lower=None, upper=None) -> tuple:
    """The parameter vector with the entries ``free`` as decision variables:
    (p, z), ``p`` the full vector (MX) and ``z`` the variables, started at ``p0``; an
    entry in log scale (``log[i]`` True, positive values) is ``p0 exp(z)``, else
    ``p0 (1 + z)`` (z = 0 at the start: relative units either way).

    Parameters
    ----------
    opti : casadi.Opti
        The NLP.
    p0 : array_like
        The parameter vector (SI): the start of the free entries and the value of the others.
    free : sequence of int
        Indices of the entries estimated.
    log : sequence of bool, optional
        Per free entry, log scale (default: where p0 > 0).
    lower, upper : array_like, optional
        Bounds of the free entries (SI; default none).
    """
    p0 = np.asarray(p0, float)
    free = list(free)
    log = [p0[i] > 0 for i in free] if log is None else list(log)
    z = opti.variable(len(free))
    opti.set_initial(z, 0.0)
    entries = [ca.MX(float(v)) for v in p0]
    for j, i in enumerate(free):
        entries[i] = p0[i] * ca.exp(z[j]) if log[j] else p0[i] * (1 + z[j])
        lo = None if lower is None else lower[j]
        hi = None if upper is None else upper[j]
        if lo is not None and np.isfinite(lo):
            opti.subject_to(entries[i] >= lo)
        if hi is not None and np.isfinite(hi):
            opti.subject_to(entries[i] <= hi)
    return ca.vertcat(*entries), z


@dataclass
class Transcription:
    """A trajectory transcribed into an Opti problem (:func:`transcribe`).

    Attributes
    ----------
    method : str
        One of :data:`METHODS`.
    X : MX
        The node states (nx x N + 1, physical): expressions of the decision variables.
    Xs : MX or None
        The scaled node states' decision variables (None for single shooting: the nodes
        are the rollout's).
    quadrature : MX or 0
        The integrand's integral over each interval (1 x N).
    points : list
        Per collocation point, (X_r, Y_r) in every interval (collocation only).
    """

    method: str
    X: ca.MX
    Xs: ca.MX | None
    quadrature: object = 0
    points: list = field(default_factory=list)


def transcribe(opti: ca.Opti, method: str, *, x0, guess, scale, U, dts, rates=None, interval=None,
               interval_args=(), free=None, fixed_start: bool = True, integrand=None, degree: int = DEGREE
               ) -> Transcription:
    """Transcribe a trajectory's dynamics into ``opti`` by single shooting, multiple
    shooting or Radau collocation (the choice rule: :mod:`ema_casadi.optimisation`).

    Parameters
    ----------
    opti : casadi.Opti
        The NLP.
    method : {"single", "multiple", "collocation"}
        The transcription.
    x0 : array_like or MX
        The start state (physical): the first node (fixed where ``fixed_start``, else
        only the first node's guess).
    guess : ndarray
        Node states' initial guess (nx x N + 1, physical): measured channels where they
        are measured, a simulation elsewhere.
    scale : ndarray
        The states' full scales (the decision variables are states / scale).
    U : MX or DM
        Inputs (or controls) of every interval, N columns (for ``rates``).
    dts : MX or DM
        The intervals' lengths (1 x N, s).
    rates : callable, optional
        ``rates(X, U) -> (xdot, y)`` (collocation).
    interval : casadi.Function, optional
        One interval ``F(x, *interval_args) -> x_next`` (shooting).
    interval_args : tuple
        The interval's other inputs, N columns each (shooting).
    free : sequence of int, optional
        The states continuity and collocation apply to (default all).
    fixed_start : bool
        The first node equals ``x0`` (else it is free, started at the guess).
    integrand : callable, optional
        ``integrand(y) -> 1 x cols`` (collocation's quadrature).
    degree : int
        Collocation points per interval.
    """
    if method not in METHODS:
        raise ValueError(f"method '{method}' unknown; choose one of {', '.join(METHODS)}")
    scale = np.asarray(scale, float)
    guess = np.asarray(guess, float)
    nx, N = guess.shape[0], guess.shape[1] - 1
    if method == "single":
        start = x0 if isinstance(x0, ca.MX) else ca.DM(np.asarray(x0, float))
        return Transcription(method, single_shooting(interval, start, *interval_args), None)
    Xs = opti.variable(nx, N + 1)
    X = ca.diag(scale) @ Xs
    opti.set_initial(Xs, guess / scale[:, None])
    if fixed_start:
        opti.subject_to(Xs[:, 0] == x0 / scale)
    if method == "multiple":
        X_next = multiple_shooting(interval, X, *interval_args)
        X_next = X_next[0] if isinstance(X_next, (tuple, list)) else X_next
        continuity(opti, Xs, X_next, scale, free)
        return Transcription(method, X, Xs)
    def start(t):  # the guess between the nodes: linear
        return guess[:, :-1] + t * np.diff(guess, axis=1)

    X_next, q, pts = collocation(opti, rates, Xs, U, dts, scale, free=free, integrand=integrand, start=start,
                                 degree=degree)
    continuity(opti, Xs, X_next, scale, free)
    return Transcription(method, X, Xs, q, pts)
