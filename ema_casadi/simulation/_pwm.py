"""Carrier-synchronous simulation of a switched model (a PWM bridge).

One compiled step advances one carrier period T = 1/f_sw: the ECU samples at its start
(and at the valley T/2 for double update: the current loop at 2 f_sw), the model's
``schedule`` gives the sub-intervals of each half period in closed form from the duty
cycles (four per half: the three legs' edges sorted), and each sub-interval, whose leg
states are constant, is integrated with k = ceil(D/dt) equal RK4 steps of the smooth
dynamics ``f_switched`` (D its length, k chosen at run time by a ``conditional``).
The integrator thus steps exactly to every switching instant: the result does not
depend on the step size beyond the smooth dynamics' RK4 error, and the power and loss
outputs are integrated as quadratures in the same steps
(:meth:`~ema_casadi.simulation.SimResult.energies` is exact where a trapezoid over
samples of switched powers is not).

The step is rolled out like the RK4 rollout (:mod:`._rk4`): ``fold`` over ``k`` periods
per kept sample, ``mapaccum`` over the samples of a chunk, compiled and cached with
:func:`~ema_casadi._util._compiled.compile_keyed`. Without ``dt_out`` every sub-interval is
kept (``resolve``): its start, its states and its leg states, for plots of the switched
waveforms (a step plot, ``steps-post``).

Inputs are interpolated linearly within the period between their values at its ends;
the ECU's loops sample at the half-period boundary at or after each of their instants.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import casadi as ca
import numpy as np

from .._util._compiled import BufferCall, compile_keyed
from .._util._interrupts import check as check_interrupt
from ..model.assembly import Model
from ._envelope import RunFailed, monitor_for
from ._inputs import _initial_projection, input_matrix
from ._result import SimResult, SimulationError, _result, progress_bar
from ._rk4 import _flags, _rk4

__all__ = ["PERIODS_PER_CALL", "energy_outputs", "pwm_period_function", "check_switched", "simulate_pwm"]

#: Carrier periods per compiled call (bounds the input buffers of a chunk).
PERIODS_PER_CALL = 4000
_WHOLE = 1e-9
_SOURCE = Path(__file__).read_bytes()


def energy_outputs(model: Model) -> tuple[str, ...]:
    """The outputs whose quadratures are energies: every loss and power output."""
    return model.outputs_of("loss") + model.outputs_of("power")


def quadrature_outputs(model: Model) -> tuple[str, ...]:
    """The outputs integrated as quadratures: :func:`energy_outputs`, and the DC-link
    current ``i_dc`` (its charge), so that its carrier-period average is written too
    (V_dc times it is then the average power drawn)."""
    return energy_outputs(model) + (("i_dc",) if "i_dc" in model.outputs else ())


def _update(model: Model, pv) -> bool:
    """Double update (ECU at peak and valley) when the current loop samples at 2 f_sw,
    single when at f_sw; other rates are refused."""
    names = model.param_names
    f_carrier = pv[names.index(model.carrier)]
    inner = list(model.loops.values())[-1]
    ratio = pv[names.index(inner.rate)] / f_carrier
    if abs(ratio - 1) < 1e-9:
        return False
    if abs(ratio - 2) < 1e-9:
        return True
    raise SimulationError(f"the {inner.name} loop samples at {inner.rate} = {pv[names.index(inner.rate)]:g} Hz; "
                          f"the PWM bridge needs {model.carrier} = {f_carrier:g} Hz (single update) or twice it "
                          f"(double update)")


def _substep(model: Model, qi) -> ca.Function:
    """One RK4 step of the smooth dynamics with the switched values fixed:
    ``(z, U2, tau, h, T, hold, s, p) -> z_next``, ``z`` = [x, quadratures]; the hybrid
    map applied after it as in the RK4 rollout."""
    nx = model.nx
    z = ca.SX.sym("z", nx + len(qi))
    U2 = ca.SX.sym("U2", model.nu, 2)
    tau, h, T = ca.SX.sym("tau"), ca.SX.sym("h"), ca.SX.sym("T")
    hold = ca.SX.sym("hold", len(model.holds))
    s = ca.SX.sym("s", len(model.switched))
    p = ca.SX.sym("p", len(model.param_names))

    def u_at(t):
        return U2[:, 0] + (U2[:, 1] - U2[:, 0]) * (t / T)

    def rhs(zz, stage):
        dx, y = model.f_switched(zz[:nx], u_at(tau + (0, 0.5, 1)[stage] * h), p, hold, s)
        return ca.vertcat(dx, y[qi])

    stages = [] if model.hybrid else None
    z_next = _rk4(rhs, z, h, stages)
    if model.hybrid:
        x = z_next[:nx]
        for zs in [z, *stages]:
            x, _ = model.project(zs[:nx], x, u_at(tau + h), p)
        z_next = ca.vertcat(x, z_next[nx:])
    opts = {"cse": True}
    return ca.Function("pwm_substep", [z, U2, tau, h, T, hold, s, p], [z_next],
                       ["z", "U2", "tau", "h", "T", "hold", "s", "p"], ["z_next"], opts)


def _steps(sub: ca.Function, n: int) -> ca.Function:
    """``(z, U2, tau0, D, T, hold, s, p) -> z_next``: a sub-interval of length D in k
    equal RK4 steps, k = ceil(D / hmax) chosen at run time among 0..n (a ``conditional``:
    only the chosen case runs), so short sub-intervals cost few steps."""
    z = ca.MX.sym("z", sub.size1_in(0))
    U2 = ca.MX.sym("U2", *sub.size_in(1))
    tau0, D, T = ca.MX.sym("tau0"), ca.MX.sym("D"), ca.MX.sym("T")
    hold, s, p = (ca.MX.sym(sub.name_in(i), sub.size1_in(i)) for i in (5, 6, 7))
    args = [z, U2, tau0, D, T, hold, s, p]
    cases = [ca.Function("pwm_steps0", args, [z])]
    for k in range(1, n + 1):
        h = D / k
        fk = sub.fold(k) if k > 1 else sub
        cases.append(ca.Function(f"pwm_steps{k}", args,
                                 [fk(z, U2, tau0 + h * ca.DM(np.arange(k)).T, h, T, hold, s, p)]))
    return ca.Function.conditional("pwm_steps", cases[:-1], cases[-1])


def pwm_period_function(model: Model, n: int, double: bool, resolve: bool = False) -> ca.Function:
    """One carrier period ``(xa, U2, F2, p, hmax) -> xa_next`` (with ``resolve`` also the
    augmented state at the start of each sub-interval, their lengths and switched values).

    ``xa`` = [x, held controller outputs, quadratures of :func:`quadrature_outputs`];
    ``U2`` the inputs at the period's start and end (interpolated linearly in between);
    ``F2`` the loop flags at its start and at T/2 (used with ``double``); ``hmax`` the
    longest RK4 step. Each sub-interval of length D takes ceil(D / hmax) equal steps (at
    most ``n``). The RK4 step is one Function called for every sub-interval, so the
    generated code holds it once.

    Parameters
    ----------
    model : Model
        A switched model (``model.schedule`` not None).
    n : int
        Most RK4 steps of a sub-interval (the longest, T/2, needs ceil(T/2 / hmax)).
    double : bool
        Double update: the ECU samples at T/2 too and the second half follows its
        new references.
    resolve : bool
        Also return the sub-interval starts.
    """
    nx, nh = model.nx, len(model.holds)
    qi = [model.yindex(n_) for n_ in quadrature_outputs(model)]
    steps_of = _steps(_substep(model, qi), n)
    xa = ca.MX.sym("x", nx + nh + len(qi))
    hmax = ca.MX.sym("hmax")
    U2 = ca.MX.sym("U2", model.nu, 2)
    F2 = ca.MX.sym("F2", len(model.loops), 2)
    p = ca.MX.sym("p", len(model.param_names))
    T = 1 / p[model.param_names.index(model.carrier)]
    x, hold, q = xa[:nx], xa[nx : nx + nh], xa[nx + nh :]
    starts, lengths, values = [], [], []
    tau = 0
    D = S = None
    for half in (0, 1):
        if half == 0 or double:
            u_s = U2[:, 0] + (U2[:, 1] - U2[:, 0]) * (tau / T)
            x, hold = model.sample(x, u_s, p, hold, F2[:, half])
            D, S = model.schedule(x, u_s, p, hold)
        n_sub = 4
        for j in range(n_sub):
            s = S[:, half * n_sub + j]
            starts.append(ca.vertcat(x, hold, q))
            d = D[half, j]
            lengths.append(d)
            values.append(s)
            k = ca.fmin(n, ca.ceil(d / hmax - 1e-9))
            z = steps_of(k, ca.vertcat(x, q), U2, tau, d, T, hold, s, p)
            x, q = z[:nx], z[nx:]
            tau = tau + d
    out = [ca.vertcat(x, hold, q)]
    names = ["x_next"]
    if resolve:
        out += [ca.horzcat(*starts), ca.horzcat(*lengths), ca.horzcat(*values)]
        names += ["X_sub", "D_sub", "S_sub"]
    return ca.Function("pwm_period", [xa, U2, F2, p, hmax], out, ["x", "U2", "F2", "p", "hmax"], names)


def _rollout(model: Model, n: int, double: bool, k: int, M: int, resolve: bool, jit: bool):
    key = ("pwm_rollout", n, double, k, M, resolve, jit)
    if key not in model.cache:
        name = f"pwm_{'dbl_' if double else ''}{'res_' if resolve else ''}{n}n{k}x{M}"
        functions = (model.f_switched, model.schedule, model.sample, model.project)
        parts = [_SOURCE, name, *(g.serialize() for g in functions)]
        Fc, info = compile_keyed(name, parts, lambda: _build(model, n, double, k, M, resolve, name), jit)
        model.cache[key] = (BufferCall(Fc), info)
    return model.cache[key]


def _build(model, n, double, k, M, resolve, name):
    step = pwm_period_function(model, n, double, resolve)
    if resolve:
        roll = step.mapaccum("roll", M)
    else:
        roll = (step.fold(k) if k > 1 else step).mapaccum("roll", M)
    nxa = step.size1_in(0)
    x0 = ca.MX.sym("x0", nxa)
    U = ca.MX.sym("U", model.nu, 2 * k * M)
    F = ca.MX.sym("F", len(model.loops), 2 * k * M)
    p = ca.MX.sym("p", len(model.param_names))
    hmax = ca.MX.sym("hmax")
    out = roll(x0, U, F, p, hmax)
    out = list(out) if isinstance(out, (list, tuple)) else [out]
    names = ["X", "X_sub", "D_sub", "S_sub"][: len(out)]
    return ca.Function(name, [x0, U, F, p, hmax], out, ["x0", "U", "F", "p", "hmax"], names)


def check_switched(model: Model, pv, t_end: float, error: type = SimulationError, label: str = "t_end") -> None:
    """Refuse (``error``, one line) a switched run whose ``t_end`` is not a whole number
    of carrier periods or whose current loop is not synchronous with the carrier.

    Parameters
    ----------
    model : Model
        A switched model.
    pv : array_like
        Its parameter vector.
    t_end : float
        End time (s).
    error : type
        The exception raised.
    label : str
        The name of ``t_end`` in the message (``--t-end``).
    """
    try:
        _Grid(model, pv, t_end, 1e-5, None)
    except SimulationError as exc:
        text = str(exc)
        raise error(label + text[len("t_end"):] if text.startswith("t_end") else text) from None


class _Grid:
    """The carrier grid of a run: periods, periods per kept sample, RK4 steps per
    sub-interval, update mode."""

    def __init__(self, model, pv, t_end, dt, dt_out):
        f_carrier = pv[model.param_names.index(model.carrier)]
        self.T = 1 / f_carrier
        periods = t_end * f_carrier
        self.periods = round(periods)
        if self.periods < 1 or abs(self.periods - periods) > _WHOLE * max(periods, 1):
            raise SimulationError(f"t_end {t_end:g} s is not a whole number of carrier periods 1/{model.carrier} = "
                                  f"{self.T * 1e6:g} us ({periods:.6g}); the switched model steps period by period")
        self.resolve = dt_out is None
        k = 1 if dt_out is None else max(1, round(dt_out * f_carrier))
        self.k = math.gcd(min(k, self.periods), self.periods)
        self.k_req = min(k, self.periods)
        self.n = max(1, math.ceil(0.5 * self.T / dt - 1e-9))
        self.hmax = dt
        self.double = _update(model, pv)


def simulate_pwm(model: Model, t_end, sig, pv, x0, dt, dt_out, jit, progress) -> SimResult:
    """The carrier-synchronous run (see the module docstring); ``dt`` bounds the RK4
    step in every sub-interval (a sub-interval of length D takes ceil(D/dt) steps),
    ``dt_out`` is rounded to whole carrier periods (None: every sub-interval kept)."""
    g = _Grid(model, pv, t_end, dt, dt_out)
    nx, nh = model.nx, len(model.holds)
    names_q = quadrature_outputs(model)
    monitor = monitor_for(model, pv)
    x0, _ = _initial_projection(model, sig, pv, x0)
    bad = monitor.first([0.0], x0, None, input_matrix(model, sig, [0.0]))
    if bad is not None:
        raise RunFailed(bad.what, 0.0, None)
    n_out = g.periods // g.k
    M = max(1, min(n_out, PERIODS_PER_CALL // g.k))
    F, cinfo = _rollout(model, g.n, g.double, g.k, M, g.resolve, jit)
    rates = [pv[model.param_names.index(lp.rate)] for lp in model.loops.values()]
    xa = np.concatenate([x0, np.zeros(nh), np.zeros(len(names_q))])
    t_comp = time.perf_counter()
    T_chunks, X_chunks, S_chunks = [], [], []
    Q_end = np.zeros(len(names_q))
    for c0 in range(0, n_out, M):
        check_interrupt()
        periods = np.arange(c0 * g.k, (c0 + M) * g.k)
        t0 = periods * g.T
        U = input_matrix(model, sig, np.column_stack([t0, t0 + g.T]).ravel())
        half = g.T / 2 if g.double else g.T
        Fl = np.empty((len(rates), 2 * len(t0)))
        Fl[:, 0::2] = _flags(t0, half, rates)
        Fl[:, 1::2] = _flags(t0 + g.T / 2, g.T / 2, rates) if g.double else 0.0
        out = F(xa, U, Fl, pv, g.hmax)
        m = min(M, n_out - c0)
        if g.resolve:
            Xs, Ds, Ss = out[1], out[2], out[3]
            n_sub = Ds.shape[1] // M
            offsets = np.concatenate([np.zeros((M, 1)), np.cumsum(Ds.reshape(M, n_sub), 1)[:, :-1]], 1)
            ts = (t0[:m, None] + offsets[:m]).ravel()
            T_chunks.append(ts)
            X_chunks.append(Xs[:, : m * n_sub])
            S_chunks.append(Ss[:, : m * n_sub])
        else:
            T_chunks.append((np.arange(c0, c0 + m) + 1) * g.k * g.T)
            X_chunks.append(out[0][:, :m])
        xa = out[0][:, m - 1]
        Q_end = xa[nx + nh :]
        ends = out[0][:, :m]
        bad = monitor.first((np.arange(c0, c0 + m) + 1) * g.k * g.T, ends[:nx], None,
                            U[:, 1 :: 2 * g.k][:, :m])
        if bad is not None:
            raise RunFailed(bad.what, bad.time, None)
        progress_bar(min(1.0, (c0 + m) / n_out), progress)
    if g.resolve:
        t = np.append(np.concatenate(T_chunks), t_end)
        Xa = np.column_stack([*X_chunks, xa])
        S = np.column_stack([*S_chunks, S_chunks[-1][:, -1:]])
    else:
        t = np.concatenate([[0.0], *T_chunks])
        Xa = np.column_stack([np.concatenate([x0, np.zeros(nh + len(names_q))]), *X_chunks])
        S = None
    return _finish(model, sig, pv, g, t, Xa, S, names_q, Q_end, cinfo, t_comp, jit)


_CHUNK = 1024


def _outputs(model, X, U, pv, H, S, jit):
    """The outputs of ``f_switched`` at many samples: a compiled map over chunks."""
    key = ("pwm_outputs", jit)
    if key not in model.cache:
        f = model.f_switched
        args = [ca.MX.sym(f.name_in(i), f.size1_in(i), _CHUNK if i != 2 else 1) for i in range(f.n_in())]
        F = ca.Function("pwm_outputs", args, [f.map(_CHUNK)(*args)[1]])
        parts = [_SOURCE, "pwm_outputs", f.serialize()]
        model.cache[key] = BufferCall(compile_keyed("pwm_outputs", parts, lambda: F, jit)[0])
    call = model.cache[key]
    n = X.shape[1]
    Y = np.empty((model.ny, n))
    for c in range(0, n, _CHUNK):
        m = min(_CHUNK, n - c)
        pad = [np.zeros((A.shape[0], _CHUNK)) for A in (X, U, H, S)]
        for P_, A in zip(pad, (X, U, H, S), strict=True):
            P_[:, :m] = A[:, c : c + m]
        Y[:, c : c + m] = call(pad[0], pad[1], pv, pad[2], pad[3])[0][:, :m]
    return Y


def _finish(model, sig, pv, g, t, Xa, S, names_q, Q_end, cinfo, t_comp, jit):
    """Outputs at the kept samples (``f_switched`` with the leg states of the sub-interval
    that starts there; at a period end without ``resolve``, of the one that ends there),
    the quadratures as columns ``E_<output>`` in ``info``."""
    nx, nh = model.nx, len(model.holds)
    X, H = Xa[:nx], Xa[nx : nx + nh]
    U = input_matrix(model, sig, t)
    if S is None:
        D, Sp = model.schedule(X[:, 0], U[:, 0], pv, H[:, 0])
        s_end = np.asarray(Sp)[:, -1]
        S = np.repeat(s_end[:, None], len(t), 1)
    Y = _outputs(model, X, U, pv, H, S, jit)
    if not g.resolve:  # at t = 0 the ECU has not sampled yet: the continuous law
        Y[:, 0] = np.asarray(model.f(X[:, 0], U[:, 0], pv)[1]).ravel()
    info = {"status": "completed", "carrier_periods": g.periods, "rk4_max_per_subinterval": g.n,
            "update": "double" if g.double else "single", "compute_time": time.perf_counter() - t_comp,
            "energies": {n: float(q) for n, q in zip(names_q, Q_end, strict=True) if n in energy_outputs(model)},
            "switched": True,
            # the running integrals at the kept samples (window energies: differences)
            "energy_series": {n: Xa[nx + nh + i].copy() for i, n in enumerate(names_q)},
            "dt_out": None if g.resolve else g.k_req * g.T, "zoh": True, **cinfo}
    res = _result(model, sig, t, X, Y, info)
    if not g.resolve and g.k_req != g.k:
        keep = np.nonzero((np.arange(len(t)) * g.k) % g.k_req == 0)[0]
        keep = np.union1d(keep, [len(t) - 1])
        info["energy_series"] = {n: v[keep] for n, v in info["energy_series"].items()}
        res = SimResult(t=res.t[keep], inputs={k: v[keep] for k, v in res.inputs.items()},
                        outputs={k: v[keep] for k, v in res.outputs.items()},
                        states={k: v[keep] for k, v in res.states.items()}, info=info, unit_table=res.unit_table,
                        kinds=res.kinds, roles=res.roles)
    if not g.resolve:
        _window_averages(res)
    return res


def _window_averages(res: SimResult) -> None:
    """Replace every power and loss output (and the DC-link current) of a run kept at
    whole carrier periods by its
    average over the window that ends at each sample, (E_k - E_(k-1)) / (t_k - t_(k-1))
    from the run's own quadratures (row 0: the first window's average), so that the
    samples sum to the energy: sum_k P_k (t_k - t_(k-1)) = E exactly. Sampled at the
    carrier instants (the zero vector) the instantaneous values are the least
    representative of the period; they are kept in ``info["instantaneous"]``
    (:meth:`~ema_casadi.simulation.SimResult.with_instantaneous` adds them as columns)."""
    series = res.info["energy_series"]
    inst = {}
    for name, E in series.items():
        if name not in res.outputs or len(res.t) < 2:
            continue
        avg = np.diff(E) / np.diff(res.t)
        inst[name] = res.outputs[name].copy()
        res.outputs[name] = np.concatenate([avg[:1], avg])
    res.info["instantaneous"] = inst
    res.info["power_columns"] = "carrier-period averages over the window ending at each sample"
