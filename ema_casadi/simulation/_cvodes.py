"""Variable-step CVODES (BDF) runs, and the hybrid wrapper that locates stick/slip
switches itself (see the package docstring)."""

from __future__ import annotations

import math
import time

import casadi as ca
import numpy as np

from .._util._compiled import BufferCall
from .._util._interrupts import check as check_interrupt
from ._envelope import GaveUp, RunFailed, captured_stderr, integrator_failure, monitor_for
from ._inputs import _initial_projection, input_matrix
from ._result import _result, progress_bar
from ._rk4 import outputs_at

_INTEGRATORS_MAX = 64

#: Highest BDF order CVODES may use. BDF3 is A(86 deg)-stable, BDF4 only A(73 deg):
#: the drive-train mode (1.42 kHz, zeta 0.28) sits 73.7 deg from the negative real
#: axis, just outside BDF4's stability wedge, so orders 4-5 cost rejected steps and
#: order cuts. Capped at 3, the reference scenario needs ~30 % fewer steps for the
#: same rod-position accuracy (0.05 um: 1007 steps instead of 1435).
BDF_MAX_ORDER = 3


def _segment_integrator(model, sig, a: float, tout: np.ndarray, rtol: float, atol: float) -> BufferCall:
    """CVODES over [a, tout[-1]] with the signals as expressions of t, cached: the
    parameters are an input, so a sweep or an optimiser re-running one scenario with
    other values reuses the integrator (creating one costs ~2 ms)."""
    cache = model.cache.setdefault("cvodes", {})
    key = (tuple(sig.items()), a, len(tout), float(tout[0]), float(tout[-1]), rtol, atol)
    if key not in cache:
        x = ca.SX.sym("x", model.nx)
        p = ca.SX.sym("p", len(model.param_names))
        t = ca.SX.sym("t")
        u = ca.SX.zeros(model.nu)
        for name, s in sig.items():
            u[model.inputs.index(name)] = s.sym(t)
        dae = {"x": x, "p": p, "t": t, "ode": model.f(x, u, p)[0]}
        opts = {"abstol": atol, "reltol": rtol, "max_num_steps": 10**7, "max_order": BDF_MAX_ORDER}
        if len(cache) >= _INTEGRATORS_MAX:
            cache.pop(next(iter(cache)))
        cache[key] = BufferCall(ca.integrator("F", "cvodes", dae, a, [float(v) for v in tout], opts))
    return cache[key]


def _call(F, args, to_time=None, t_default=0.0):
    """Call a CVODES integrator; an integrator failure becomes ``(what, time)`` in the
    raised :class:`GaveUp`, with CasADi's printout kept off the terminal."""
    with captured_stderr() as log:
        try:
            return F(*args)
        except RuntimeError as exc:
            check_interrupt()  # CasADi turns an interrupt inside the call into a RuntimeError
            raise GaveUp(*integrator_failure(exc, log.getvalue(), to_time, t_default)) from None


def _check_inputs(monitor, model, sig, grid, X, Y):
    """The inputs over the whole output grid against the envelope, before integrating
    (they are known up front: a load the actuator cannot take fails at its time)."""
    U = input_matrix(model, sig, grid)
    bad = monitor.first(grid, None, None, U)
    if bad is not None:
        raise RunFailed(bad.what, bad.time, None)
    return U


def _check(monitor, model, sig, pv, grid, X, Y, U, i0, i1):
    """States of samples i0..i1-1 against the envelope (cheap: no model call). On a
    violation the outputs up to it are computed and checked too, so the earliest reason
    wins, and RunFailed is raised with the run up to the failure."""
    if i1 <= i0:
        return
    bad = monitor.first(grid[i0:i1], X[:, i0:i1])
    if bad is not None:
        _outputs(monitor, model, sig, pv, grid, X, Y, U, i0 + bad.index + 1)
        raise RunFailed(bad.what, bad.time, _partial(model, sig, grid, X, Y, i0 + bad.index + 1))


def _outputs(monitor, model, sig, pv, grid, X, Y, U, n):
    """Outputs of the first n samples into Y (one mapped call), checked against the
    envelope; RunFailed at the first violation."""
    outputs_at(model, X[:, :n], U[:, :n], pv, out=Y[:, :n])
    bad = monitor.first(grid[:n], None, Y[:, :n])  # the states were checked as they came
    if bad is not None:
        raise RunFailed(bad.what, bad.time, _partial(model, sig, grid, X, Y, bad.index + 1))


def _partial(model, sig, grid, X, Y, n):
    """The run's first n samples (outputs already computed) as a SimResult."""
    return _result(model, sig, grid[:n], X[:, :n], Y[:, :n], {})


def _simulate_cvodes(model, t_end, sig, pv, x0, dt_out, rtol, atol, progress):
    n_out = int(math.ceil(t_end / dt_out - 1e-9))
    grid = np.arange(n_out + 1) * dt_out
    cuts = [b for s in sig.values() for b in s.breakpoints() if 0 < b < grid[-1]]
    edges = sorted({0.0, float(grid[-1]), *cuts})
    X = np.empty((model.nx, len(grid)))
    Y = np.empty((model.ny, len(grid)))
    X[:, 0] = x0
    xc = np.asarray(x0, float)
    monitor = monitor_for(model, pv)
    U = _check_inputs(monitor, model, sig, grid, X, Y)
    _check(monitor, model, sig, pv, grid, X, Y, U, 0, 1)
    steps, done = 0, 1
    t_compute = time.perf_counter()
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        check_interrupt()
        inside = np.nonzero((grid > a + 1e-12) & (grid <= b + 1e-12))[0]
        tout = grid[inside]
        if not len(tout) or abs(tout[-1] - b) > 1e-12:
            tout = np.append(tout, b)
        F = _segment_integrator(model, sig, a, tout, rtol, atol)
        try:
            xf = _call(F, (xc, np.zeros((0, 1)), pv, np.zeros((0, len(tout))), *[np.zeros((0, 1))] * 3),
                       t_default=a)[0]
        except GaveUp as exc:
            raise RunFailed(exc.what, exc.time, _partial(model, sig, grid, X, Y, done)) from None
        steps += int(F.stats().get("nsteps", 0))
        X[:, inside] = xf[:, : len(inside)]
        if len(inside):
            _check(monitor, model, sig, pv, grid, X, Y, U, done, inside[-1] + 1)
            done = inside[-1] + 1
        xc = xf[:, -1]
        progress_bar(b / edges[-1], progress)
    _outputs(monitor, model, sig, pv, grid, X, Y, U, len(grid))
    info = {"status": "completed", "dt_out": dt_out, "steps": steps, "compute_time": time.perf_counter() - t_compute,
            "compiled": False, "compile_time": 0.0, "rtol": rtol, "atol": atol}
    return _result(model, sig, grid, X, Y, info)


# ---------------------------------------------------------------------------------
# Variable step with hybrid friction: own event location around CVODES.
#
# CasADi's integrator events are experimental and failed on this model in trials
# (CV_ILL_INPUT), so the switching is handled here. CVODES integrates the continuous
# f over chunks of output intervals, with two quadratures: the time spent with the
# stick condition of f holding and the time spent without it. Once stuck, f keeps the
# contact velocity constant, so "the stick condition has held since t" is monotone in
# t until breakaway, and a chunk whose quadrature of the *other* mode is positive
# contains a switch. The switch is bracketed between output times and the bracket is
# shrunk to ``event_tol`` by re-integrating from its left end (``_locate_switch``); at
# the bracket's right end the model's ``project`` map is applied (velocity 0 on
# entering stick) and the integrator restarts. Because the quadratures see the whole
# interval, switches are found whatever the output spacing; only a visit to the other
# mode that begins and ends between two of CVODES's internal steps can go unseen.
_CHUNK_SECONDS = 2e-2  # integrated per CVODES call between checks (s)
_MAX_CHUNK = 2048


def _hybrid_integrators(model, sig, rtol, atol):
    """``get(n)``: a time-scaled CVODES integrator ``(x0, [p; t0; H]) -> (X, Q)`` with
    outputs at t0 + H k/n, k = 1..n, and the quadratures [time stuck, time not stuck]
    from t0 (built on first use, cached); and ``mode(x, u, p)``, the stick flag of f."""
    x = ca.SX.sym("x", model.nx)
    p = ca.SX.sym("p", len(model.param_names))
    t0, H, tau = ca.SX.sym("t0"), ca.SX.sym("H"), ca.SX.sym("tau")
    u = ca.SX.zeros(model.nu)
    for name, s in sig.items():
        u[model.inputs.index(name)] = s.sym(t0 + H * tau)
    xdot, y = model.f(x, u, p)
    k_stick = model.yindex(model.output_with("stuck"))
    stick = y[k_stick]
    dae = {"x": x, "p": ca.vertcat(p, t0, H), "t": tau, "ode": H * xdot, "quad": H * ca.vertcat(stick, 1 - stick)}
    opts = {"abstol": atol, "reltol": rtol, "max_num_steps": 10**7}
    cache = {}

    def get(n):
        if n not in cache:
            cache[n] = BufferCall(ca.integrator(f"F{n}", "cvodes", dae, 0.0, [(k + 1) / n for k in range(n)], opts))
        return cache[n]

    uu = ca.SX.sym("u", model.nu)
    mode = ca.Function("mode", [x, uu, p], [model.f(x, uu, p)[1][k_stick]])
    return get, mode


def _locate_switch(integrate, F1, stuck, t_l, x_l, t_r, x_r, q_r, tol):
    """Shrink the bracket (t_l: no switch yet, t_r: switched) to width <= tol (s).

    ``q_r`` is the time spent in the other mode over [t_l, t_r]; since the new mode
    persists under the continuous f, t_r - q_r estimates the switching instant. Each
    trial integrates from the left end to just past the estimate (or just before it,
    once the right end sits within tol/2 of it); a trial that fails to halve the
    bracket is followed by a bisection step (safeguard). Typically 2-4 integrations.
    Returns (t_l, x_l, t_r, x_r)."""
    halved = True
    while t_r - t_l > tol:
        w = t_r - t_l
        t_est = t_r - q_r
        if halved:
            t_m = t_est + 0.25 * tol if q_r > 0.5 * tol else t_est - 0.25 * tol
            t_m = min(max(t_m, t_l + 0.25 * tol), t_r - 0.25 * tol)
        else:
            t_m = 0.5 * (t_l + t_r)
        x_m, q = integrate(F1, x_l, t_l, t_m - t_l, 1)
        q_m = (q[1] if stuck else q[0])[0]
        if q_m > 0:
            t_r, x_r, q_r = t_m, x_m, q_m
        else:
            t_l, x_l = t_m, x_m[:, 0]  # q_r is unchanged: nothing of it lay in [t_l, t_m]
        halved = (t_r - t_l) <= 0.5 * w
    return t_l, x_l, t_r, x_r


def _hybrid_grid(sig, t_end, dt_out):
    """Output grid, samples per integrator call (a power of two, so that partial chunks
    before a breakpoint or the end are covered by few distinct integrators), the
    signals' breakpoints."""
    n_out = int(math.ceil(t_end / dt_out - 1e-9))
    grid = np.arange(n_out + 1) * dt_out
    K = 2 ** int(math.log2(min(_MAX_CHUNK, max(1.0, _CHUNK_SECONDS / dt_out))))
    cuts = sorted({b for s in sig.values() for b in s.breakpoints() if 0 < b < grid[-1]})
    return n_out, grid, K, cuts


def _simulate_cvodes_hybrid(model, t_end, sig, pv, x0, dt_out, rtol, atol, event_tol, progress):
    n_out, grid, K, cuts = _hybrid_grid(sig, t_end, dt_out)
    get_integrator, mode_fn = _hybrid_integrators(model, sig, rtol, atol)
    F1 = get_integrator(1)
    nz = np.zeros((0, 1))
    stats = {"steps": 0, "calls": 0}

    def integrate(F, x, t0, H, n):
        try:
            out = _call(F, (x, nz, np.concatenate([pv, [t0, H]]), np.zeros((0, n)), nz, nz, nz),
                        lambda tau: t0 + H * tau, t0)
        except GaveUp as exc:
            raise RunFailed(exc.what, exc.time, _partial(model, sig, grid, X, Y, gi)) from None
        stats["steps"] += int(F.stats().get("nsteps", 0))
        stats["calls"] += 1
        return out[0], out[2]  # xf (nx x n), qf (2 x n)

    def stuck_at(x, t):
        return bool(float(mode_fn(x, input_matrix(model, sig, [t])[:, 0], pv)) > 0.5)

    x0, _ = _initial_projection(model, sig, pv, x0)
    X = np.empty((model.nx, len(grid)))
    Y = np.empty((model.ny, len(grid)))
    X[:, 0] = x0
    x, t, gi = x0, 0.0, 1  # state, time, index of the next output sample
    monitor = monitor_for(model, pv)
    U = _check_inputs(monitor, model, sig, grid, X, Y)
    _check(monitor, model, sig, pv, grid, X, Y, U, 0, 1)
    stuck = stuck_at(x, t)
    switch_times = []
    t_compute = time.perf_counter()
    while gi <= n_out:
        check_interrupt()
        g_start = gi
        b_next = next((c for c in cuts if c > t + 1e-12), math.inf)
        on_grid = abs(t - grid[gi - 1]) <= 1e-12 * max(1.0, t)
        if on_grid:
            n_fit = int(np.searchsorted(grid[gi : gi + K], b_next + 1e-12))  # samples before b_next
            n = 2 ** int(math.log2(n_fit)) if n_fit else 0
        if on_grid and n:
            ends = grid[gi : gi + n]
            Xs, Q = integrate(get_integrator(n), x, t, ends[-1] - t, n)
        else:
            ends = np.array([min(grid[gi], b_next)])
            Xs, Q = integrate(F1, x, t, ends[0] - t, 1)
        other = Q[1] if stuck else Q[0]
        hits = np.nonzero(other > 0)[0]
        j = hits[0] if len(hits) else len(ends)
        # accept the samples before the first switch
        for k in range(j):
            if abs(ends[k] - grid[gi]) <= 1e-12 * max(1.0, ends[k]):
                X[:, gi] = Xs[:, k]
                gi += 1
        if j == len(ends):
            x, t = Xs[:, -1], float(ends[-1])
        else:
            t_l, x_l = (float(ends[j - 1]), Xs[:, j - 1]) if j > 0 else (t, x)
            t_r = float(ends[j])
            x_r, q = integrate(F1, x_l, t_l, t_r - t_l, 1)
            q_r = (q[1] if stuck else q[0])[0]
            if q_r > 0:  # confirmed from the bracket's left end
                t_l, x_l, t_r, x_r = _locate_switch(integrate, F1, stuck, t_l, x_l, t_r, x_r, q_r, event_tol)
                x_r = np.asarray(model.project(x_l, x_r[:, 0], input_matrix(model, sig, [t_r])[:, 0], pv)[0], float)
                new = stuck_at(x_r, t_r)
                if new != stuck:
                    switch_times.append(t_r)
                stuck = new
            x, t = np.asarray(x_r, float).ravel(), t_r
            if abs(t - grid[gi]) <= 1e-12 * max(1.0, t):
                X[:, gi] = x
                gi += 1
        _check(monitor, model, sig, pv, grid, X, Y, U, g_start, gi)
        progress_bar(min(1.0, t / grid[-1]), progress)
    _outputs(monitor, model, sig, pv, grid, X, Y, U, len(grid))
    info = {"status": "completed", "dt_out": dt_out, "steps": stats["steps"], "integrator_calls": stats["calls"],
            "compute_time": time.perf_counter() - t_compute, "compiled": False, "compile_time": 0.0,
            "rtol": rtol, "atol": atol, "event_tol": event_tol,
            "mode_switches": len(switch_times), "switch_times": np.array(switch_times)}
    return _result(model, sig, grid, X, Y, info)
