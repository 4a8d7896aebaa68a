"""Fixed-step RK4 rolled out in compiled chunks (``fold`` + ``mapaccum``), with the
sampled ECU and the hybrid stick-entry map inside the step (see the package docstring)."""

from __future__ import annotations

import math
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import casadi as ca
import numpy as np

from .._util._compiled import BufferCall, compile_function, compile_keyed
from .._util._interrupts import check as check_interrupt
from ..model.assembly import Model
from ._envelope import RunFailed, monitor_for
from ._inputs import _initial_projection, input_matrix
from ._native import native_outputs, native_rollout
from ._result import _result, progress_bar

STEPS_PER_CALL = 20000


def _rk4(fx, x, h, stages=None):
    """Classical RK4 step; the intermediate stage states are appended to ``stages``."""
    k1 = fx(x, 0)
    x2 = x + h / 2 * k1
    k2 = fx(x2, 1)
    x3 = x + h / 2 * k2
    k3 = fx(x3, 1)
    x4 = x + h * k3
    k4 = fx(x4, 2)
    if stages is not None:
        stages += [x2, x3, x4]
    return x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


def rk4_step_function(model: Model, zoh: bool = False, count_modes: bool = False, split: bool = False) -> ca.Function:
    """One RK4 step ``(x, U, flags, p, h) -> x_next``.

    ``U`` holds the inputs at t, t+h/2 and t+h in its three columns. With ``zoh`` the
    state is augmented with the held controller outputs (``model.holds``) and
    ``flags`` (one per loop of ``model.loops``) say which loops sample at the start of
    this step.

    With ``split`` (and ``zoh``) the loops sample inside the step, at ``t + theta h``
    (``theta`` the last entry of ``flags``, in [0, 1)): RK4 over ``theta h`` with the
    old holds, the ECU update there, RK4 over the rest with the new ones; ``U`` then
    holds five columns, the inputs at t, t + theta h/2, t + theta h, t + theta h +
    (1 - theta) h/2 and t + h. So each loop samples at its own instants whatever the
    step (as the switched bridge steps to its switching instants).

    With hybrid friction the step ends with the model's discrete stick-entry map
    ``model.project`` (the mode is evaluated once per step, inside the compiled step).
    A zero crossing of the contact velocity is sought between the step's end and each
    of its start and stage states: on the light rod of the elastic screw, sliding
    friction can reverse the velocity within a stage (F_r h / M >> eps), and a step
    whose start and end velocities share a sign can still have passed through zero;
    without this test RK4 at 1e-4 s found spurious sliding cycles (the rod "sliding"
    at -0.8 mm/s while its position repeated every five steps).
    With ``count_modes`` the (augmented) state carries two more entries at its end:
    the stick flag after the step and the running number of stick/slip switches.

    Parameters
    ----------
    model : Model
        The assembled model.
    zoh : bool
        Sampled ECU: augment the state with the held controller outputs.
    count_modes : bool
        Carry the stick flag and the switch count in the state (hybrid friction).
    split : bool
        Sampled ECU: the loops sample inside the step, at its fraction ``theta``.
    """
    nx, nu = model.nx, model.nu
    split = bool(split and zoh)
    nh = len(model.holds) if zoh else 0
    nc = 2 if count_modes else 0
    nl = len(model.loops)
    xa = ca.SX.sym("x", nx + nh + nc)
    U3 = ca.SX.sym("U3", nu, 5 if split else 3)
    flags = ca.SX.sym("flags", nl + (1 if split else 0))
    p = ca.SX.sym("p", len(model.param_names))
    h = ca.SX.sym("h")
    stages = [] if model.hybrid else None
    if split:
        theta, hold0 = flags[nl], xa[nx : nx + nh]
        starts = [xa[:nx]]
        xm = _rk4(lambda z, j: model.f_held(z, U3[:, j], p, hold0)[0], xa[:nx], theta * h, stages)
        x, hold = model.sample(xm, U3[:, 2], p, hold0, flags[:nl])
        starts.append(x)
        x_next = _rk4(lambda z, j: model.f_held(z, U3[:, 2 + j], p, hold)[0], x, (1 - theta) * h, stages)
    elif zoh:
        x, hold = model.sample(xa[:nx], U3[:, 0], p, xa[nx : nx + nh], flags)
        starts = [x]
        x_next = _rk4(lambda z, j: model.f_held(z, U3[:, j], p, hold)[0], x, h, stages)
    else:
        x = xa[: nx + nh]
        starts = [x]
        x_next = _rk4(lambda z, j: model.f(z, U3[:, j], p)[0], x, h, stages)
    stick = ca.SX(0)
    if model.hybrid:
        # chained: once a test zeroes the velocity the next ones see it in the band and
        # keep it zeroed (the force test does not depend on the velocity)
        for z in [*starts, *stages]:
            x_next, stick = model.project(z, x_next, U3[:, -1], p)
    out = [x_next]
    if zoh:
        out.append(hold)
    if count_modes:
        stick_prev, n_switch = xa[nx + nh], xa[nx + nh + 1]
        out += [stick, n_switch + ca.fabs(stick - stick_prev)]
    # the stick tests repeat the contact-force expression: merge common subexpressions
    opts = {"cse": True} if model.hybrid else {}
    return ca.Function("rk4_step", [xa, U3, flags, p, h], [ca.vertcat(*out)], ["x", "U3", "flags", "p", "h"],
                       ["x_next"], opts)


def _outputs_only(f: ca.Function) -> ca.Function:
    """``f`` without its state derivative: the outputs y alone (a kept sample costs
    about one step less)."""
    args = f.sx_in()
    return ca.Function(f"{f.name()}_y", args, [f(*args)[1]], f.name_in(), ["y"])


def _rollout(model: Model, zoh: bool, k: int, M: int, jit: bool, split: bool = False):
    """Compiled chunk: M outputs, each after k RK4 steps. Cached per model/options.

    Hybrid models count their mode switches inside the rollout (``count_modes``);
    ``split``: the sampled ECU updates inside the steps (:func:`rk4_step_function`)."""
    count = model.hybrid
    key = ("rollout", zoh, k, M, jit, split)
    if key not in model.cache:
        name = f"rollout_{'zoh_' if zoh else ''}{'split_' if split else ''}{'hyb_' if count else ''}{k}x{M}"
        functions = (model.f, model.f_held, model.sample, model.project)
        parts = [_SOURCE, name, *(g.serialize() for g in functions if g is not None)]
        native, info = (None, {})
        if jit:  # the C loop around the generated step (same numbers, no per-step copies)
            step = rk4_step_function(model, zoh, count, split)
            native, info = native_rollout(model, step, _outputs_only(model.f_held if zoh else model.f), k, M, parts)
        if native is None:
            Fc, info = compile_keyed(name, parts, lambda: _build_rollout(model, zoh, count, k, M, name, split), jit)
            native = BufferCall(Fc)
        model.cache[key] = (native, info)
    return model.cache[key]


#: This module's code determines the generated rollouts: part of their cache key.
_SOURCE = Path(__file__).read_bytes()


def _build_rollout(model: Model, zoh: bool, count: bool, k: int, M: int, name: str, split: bool = False) -> ca.Function:
    """The compiled chunk: M outputs, each after k RK4 steps (``fold`` of the step),
    stacked by ``mapaccum``; the outputs at the kept samples in the same call."""
    step = rk4_step_function(model, zoh, count, split)
    blk = step.fold(k) if k > 1 else step
    roll = blk.mapaccum("rollout", M)
    nxa, ncol = step.size1_in(0), step.size2_in(1)
    x0 = ca.MX.sym("x0", nxa)
    U = ca.MX.sym("U", model.nu, ncol * k * M)
    Fl = ca.MX.sym("F", step.size1_in(2), k * M)
    p = ca.MX.sym("p", len(model.param_names))
    h = ca.MX.sym("h")
    X = roll(x0, U, Fl, p, h)
    u_at = U[:, ca.Slice(ncol * k - 1, ncol * k * M, ncol * k)]  # input at the end of each block
    nh = len(model.holds) if zoh else 0
    if zoh:
        Y = _outputs_only(model.f_held).map(M)(X[: model.nx, :], u_at, p, X[model.nx : model.nx + nh, :])
    else:
        Y = _outputs_only(model.f).map(M)(X[: model.nx, :], u_at, p)
    return ca.Function(name, [x0, U, Fl, p, h], [X, Y], ["x0", "U", "flags", "p", "h"], ["X", "Y"])




_MAP_CHUNK = 1024
_FEW = 8


def outputs_at(model: Model, X: np.ndarray, U: np.ndarray, p: np.ndarray, jit: bool = True,
               out: np.ndarray | None = None) -> np.ndarray:
    """Model outputs y (ny x n) at states X (nx x n) and inputs U (nu x n).

    Parameters
    ----------
    model : Model
        The assembled model.
    X : ndarray
        States (SI), one column per sample.
    U : ndarray
        Inputs (SI), one column per sample.
    p : ndarray
        Parameter vector (SI).
    jit : bool
        Compile the mapped output function to native code (cached on disk).
    out : ndarray, optional
        Where to write y (ny x n; returned); a new array by default.
    """
    key = ("outputs_map", jit)
    if key not in model.cache:
        # the outputs alone, by a C loop over the arrays in place (CasADi's map repeats the
        # parameters per column: on two actuators 4 MB per 1024 columns)
        y = _outputs_only(model.f)
        native = native_outputs(model, y) if jit else None
        model.cache[key] = native or BufferCall(compile_function(y.map("outputs_map", "serial", _MAP_CHUNK, [2], []),
                                                                 jit)[0])
    call = model.cache[key]
    n = X.shape[1]
    Y = np.empty((model.ny, n)) if out is None else out
    if n <= _FEW:  # a few samples: the plain call beats a compiled 4096-column map
        for i in range(n):
            Y[:, i] = np.asarray(model.f(X[:, i], U[:, i], p)[1]).ravel()
        return Y
    if not isinstance(call, BufferCall):
        return call(X, U, p, Y)
    Xc = np.empty((model.nx, _MAP_CHUNK), order="F")  # column-major, as the compiled map reads them
    Uc = np.empty((model.nu, _MAP_CHUNK), order="F")
    for c in range(0, n, _MAP_CHUNK):
        m = min(_MAP_CHUNK, n - c)
        Xc[:, :m], Uc[:, :m] = X[:, c : c + m], U[:, c : c + m]
        Xc[:, m:], Uc[:, m:] = 0.0, 0.0  # the last chunk's spare columns (their outputs unused)
        Y[:, c : c + m] = call.view(Xc, Uc, p)[0][:, :m]
    return Y


def _flags(t: np.ndarray, dt: float, rates) -> np.ndarray:
    """1 where a loop's sampling instant n/f_s falls in [t, t + dt)."""
    out = np.empty((len(rates), len(t)))
    for j, fs in enumerate(rates):
        n_end = np.ceil((t + dt) * fs - 1e-9)
        n_start = np.ceil(t * fs - 1e-9)
        out[j] = (n_end > n_start).astype(float)
    return out


def _split_flags(t: np.ndarray, dt: float, rates) -> np.ndarray:
    """The flags of the split step (:func:`rk4_step_function`): per loop 1 where its
    sampling instant n/f_s falls in [t, t + dt), and last the instant's fraction theta
    of the step (the loops that sample in one step share the instant:
    :func:`sampling_split` checked that)."""
    out = np.zeros((len(rates) + 1, len(t)))
    for j, fs in enumerate(rates):
        first = np.ceil(t * fs - 1e-9) / fs  # the loop's first instant at or after t
        inside = first < t + dt - 1e-9 * dt
        out[j] = inside
        out[-1] = np.where(inside, np.clip((first - t) / dt, 0.0, 1.0), out[-1])
    return out


def _whole(x: float) -> bool:
    return abs(x - round(x)) <= 1e-6 * max(1.0, abs(x))


def sampling_split(model: Model, dt: float, pv, error: type = ValueError, label: str = "dt") -> bool:
    """Whether a sampled-ECU run at step ``dt`` splits its steps at the sampling
    instants: False when ``dt`` divides every loop's sample period (each instant is a
    step's start), True otherwise. Refused (``error``) when one step would hold two
    different instants: ``dt`` longer than the fastest period, or loops whose periods
    are not whole multiples of the fastest one (their instants would not coincide).

    Parameters
    ----------
    model : Model
        The model.
    dt : float
        The RK4 step (s).
    pv : ndarray
        Its parameter vector (the loops' rates).
    error : type
        The exception raised.
    label : str
        The step's name in the message.
    """
    periods = {n: 1.0 / float(pv[model.param_names.index(lp.rate)]) for n, lp in model.loops.items()}
    if not periods or all(_whole(T / dt) for T in periods.values()):
        return False
    name, fastest = min(periods.items(), key=lambda kv: kv[1])
    if dt > fastest * (1 + 1e-9):
        raise error(f"{label} {dt:g} s is longer than the {name} loop's sample period {fastest * 1e6:g} us; a step "
                    f"holds one sampling instant at most")
    odd = [n for n, T in periods.items() if not _whole(T / fastest)]
    if odd:
        raise error(f"{label} {dt:g} s does not divide the sample periods, and the {odd[0]} loop's period "
                    f"{periods[odd[0]] * 1e6:g} us is not a whole number of the {name} loop's {fastest * 1e6:g} us: "
                    "a step could hold two instants; choose a step that divides every period")
    return True


def _prefetched(make, keys):
    """``(key, make(key))`` for each key, the next one made in a helper thread while the
    caller works on the current one. The compiled rollout releases the GIL, so on a
    long run the NumPy input sampling (about a fifth of the time of a 20000-step chunk)
    runs on the second core; the values are the same as made in line."""
    keys = list(keys)
    if len(keys) < 3:
        for key in keys:
            yield key, make(key)
        return
    pool = ThreadPoolExecutor(1, thread_name_prefix="ema-inputs")
    try:
        nxt = pool.submit(make, keys[0])
        for i, key in enumerate(keys):
            value = nxt.result()
            if i + 1 < len(keys):
                nxt = pool.submit(make, keys[i + 1])
            yield key, value
    finally:
        pool.shutdown(wait=False, cancel_futures=True)


def _simulate_rk4(model, t_end, sig, pv, x0, dt, zoh, k, jit, progress, split=False):
    n_steps = int(math.ceil(t_end / dt - 1e-9))
    n_out = int(math.ceil(n_steps / k))
    M = max(1, min(n_out, STEPS_PER_CALL // k))
    monitor = monitor_for(model, pv)
    x0, stick0 = _initial_projection(model, sig, pv, x0)
    bad = monitor.first([0.0], x0, None, input_matrix(model, sig, [0.0]))
    if bad is not None:  # before the rollout is compiled
        raise RunFailed(bad.what, 0.0, None)
    F, cinfo = _rollout(model, zoh, k, M, jit, split)
    ncol = 5 if split else 3
    nh = len(model.holds) if zoh else 0
    counter = [stick0, 0.0] if model.hybrid else []
    xa = np.concatenate([x0, np.zeros(nh), counter])
    rates = [pv[model.param_names.index(loop.rate)] for loop in model.loops.values()]
    X_out = np.empty((len(xa), n_out))
    Y_out = np.empty((model.ny, n_out))
    t_compute = time.perf_counter()

    def result(n):
        """The run's first n kept samples after t = 0 as a SimResult."""
        t_out = np.arange(n + 1) * k * dt
        X_all = np.column_stack([x0, X_out[: model.nx, :n]])
        # outputs at t = 0 from the continuous law (the ECU has not sampled yet)
        y0 = outputs_at(model, x0[:, None], input_matrix(model, sig, [0.0]), pv, jit)
        Y_all = np.column_stack([y0, Y_out[:, :n]])
        info = {"status": "completed", "dt": dt, "steps": min(n_steps, n * k), "decimate": k,
                "compute_time": time.perf_counter() - t_compute, "zoh": zoh, "split_samples": split, **cinfo}
        if model.hybrid:
            # the mode decided inside each step (identical to the rule in f except at
            # the instant of a band crossing) and the switches counted at every step
            Y_all[model.yindex(model.output_with("stuck"))] = np.concatenate([[stick0], X_out[model.nx + nh, :n]])
            info["mode_switches"] = int(round(X_out[model.nx + nh + 1, n - 1])) if n else 0
        return _result(model, sig, t_out, X_all, Y_all, info)

    def inputs(c0):
        """The chunk's inputs at t, t + h/2, t + h of each step (column-major, as the
        compiled call reads them) and the sampling flags."""
        t = np.arange(c0 * k, (c0 + M) * k) * dt
        if split:  # t, t + theta h/2, t + theta h, t + theta h + (1 - theta) h/2, t + h
            Fl = _split_flags(t, dt, rates)
            th = Fl[-1][:, None]
            t3 = (t[:, None] + np.hstack([0 * th, th / 2, th, (1 + th) / 2, 1 + 0 * th]) * dt).ravel()
        else:
            t3 = (t[:, None] + np.array([0, 0.5, 1.0]) * dt).ravel()
            Fl = _flags(t, dt, rates) if zoh else np.zeros((len(rates), len(t)))
        return np.asfortranarray(input_matrix(model, sig, t3)), Fl

    chunks = _prefetched(inputs, range(0, n_out, M))
    for c0, (U, Fl) in chunks:
        check_interrupt()
        Xc, Yc = F(xa, U, Fl, pv, dt)
        m = min(M, n_out - c0)
        X_out[:, c0 : c0 + m] = Xc[:, :m]
        Y_out[:, c0 : c0 + m] = Yc[:, :m]
        # inputs at the kept samples: the end of each block of k steps
        bad = monitor.first((np.arange(c0, c0 + m) + 1) * k * dt, Xc[: model.nx, :m], Yc[:, :m],
                            U[:, ncol * k - 1 :: ncol * k][:, :m])
        if bad is not None:
            what = bad.what
            if what.startswith("non-finite") and (bad.finite_before or c0 > 0):
                # from inside the envelope to non-finite within one kept sample: RK4 unstable
                what += f" right after a sample inside the envelope (RK4 step dt = {dt:g} s: too long?)"
            chunks.close()  # the helper thread ends now, not when the traceback is dropped
            raise RunFailed(what, bad.time, result(c0 + bad.index + 1))
        xa = Xc[:, -1]
        progress_bar(min(1.0, (c0 + m) / n_out), progress)
    return result(n_out)
