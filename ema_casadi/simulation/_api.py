"""``simulate()``: validate the request, plan the output grid, refuse work the machine
cannot do, build the input signals, run a solver.

Output grid (no sample past the end, docs: reliability): samples at 0, dt_out, 2 dt_out, ... and
at ``t_end`` itself; when dt_out does not divide t_end the last interval is shorter
(t_end 0.25 s with dt_out 0.1 s gives 0, 0.1, 0.2, 0.25 s), and a dt_out longer than
t_end gives the two samples 0 and t_end. RK4 takes fixed steps, so for ``rk4`` t_end
must be a whole number of steps dt and dt_out a whole number of steps (refused
otherwise, with the numbers). The rollout is run at a decimation that divides both the
sample spacing and the number of steps, at most :data:`~ema_casadi.simulation.STEPS_PER_CALL`
steps per kept sample, and thinned to the requested grid: a large dt_out/dt costs
nothing extra. ``cvodes`` integrates the whole intervals and then the last, shorter one;
``rosenbrock`` interpolates every sample, the shorter last one included.

Limits (module constants, checked before anything is built):

:data:`MAX_STEPS`
    RK4 steps of one run (t_end/dt).
:data:`MAX_RESULT_BYTES`
    Kept samples x signals x 8 bytes of the result (the peak memory of a run, with
    the rollout buffers and a CSV being written, is about three times this).
:data:`RK4_SECONDS_PER_STEP`
    The measured cost of one compiled RK4 step, for the time estimate in messages.
"""

from __future__ import annotations

import math
import time
import warnings
from typing import TYPE_CHECKING

import numpy as np

from .._util._checks import describe, instance, integer, number, size_text, vector
from ..model.assembly import Model
from ..model.components import SIGNAL_KEYS
from ..model.params import Parameters
from ._choice import ATOL, RTOL, _chosen, choose_solver, tolerances, trimmed_start
from ._cvodes import _simulate_cvodes, _simulate_cvodes_hybrid
from ._envelope import RunFailed
from ._inputs import check_effect, check_inputs, input_signals
from ._pwm import simulate_pwm
from ._result import SimResult, SimulationError, step_corrections
from ._rk4 import STEPS_PER_CALL, _simulate_rk4
from ._rosenbrock import _simulate_rosenbrock, library
from ._steplimit import default_step, fixed_step, step_check

if TYPE_CHECKING:
    from ..signals import Signal

SOLVERS = ("auto", "rk4", "cvodes", "rosenbrock")

#: Spacing of the kept samples without ``dt_out`` or ``decimate`` (s); for rk4 the
#: nearest whole number of steps (at least one), for a switched model whole carrier periods.
DT_OUT = 1e-4
#: Most RK4 steps one run may take (about 12 min at :data:`RK4_SECONDS_PER_STEP`).
MAX_STEPS = 10**9
#: Largest result (kept samples x signals x 8 bytes) one run may build: 1 GiB.
MAX_RESULT_BYTES = 2**30
#: Wall time of one compiled RK4 step (s), measured on the reference model (pmsm,
#: elastic, smooth friction; 0.64 us decimated, 1.2 us with every step kept) on a
#: 2-core x86-64 machine: the basis of the time estimate in a refusal.
RK4_SECONDS_PER_STEP = 0.7e-6

#: Relative slack when a time must be a whole number of steps or samples.
_WHOLE = 1e-9


def simulate(
    model: Model,
    t_end: float,
    x_cmd: Signal | float | str | None = None,
    f_ext: Signal | float | str | None = None,
    eta: Signal | float | str | None = None,
    *,
    inputs: dict | None = None,
    dt: float | None = None, solver: str = "auto",
    params: Parameters | None = None, p: np.ndarray | None = None,
    x0: np.ndarray | None = None, from_trim: bool = False, zoh: bool = False,
    decimate: int | None = None, dt_out: float | None = None,
    rtol: float | None = None, atol: float | None = None, event_tol: float = 1e-7,
    jit: bool = True, progress: bool = False, check_step: bool = True,
    **signals,
) -> SimResult:
    """Simulate ``model`` from 0 to ``t_end`` (s): samples at 0, ``dt_out``, 2 ``dt_out``,
    ... and at ``t_end``. Every argument is checked first (:class:`SimulationError`, or
    :class:`~ema_casadi.signals.SignalError` for a signal, naming it; a run above
    :data:`MAX_STEPS` or :data:`MAX_RESULT_BYTES` is refused with the estimate).

    Parameters
    ----------
    model : Model
        From :func:`~ema_casadi.model.assembly.build_model`.
    t_end : float
        End time (s); for ``rk4`` a whole number of steps ``dt``.
    x_cmd, f_ext, eta : Signal, float or str
        Rod command (m), external force (N, + pushes the rod in), screw efficiency (-);
        None: the input's default (0 m, 0 N, the set's eta; no x_cmd behind an airframe).
        Conveniences for ``inputs={"command": ..., "load": ..., "efficiency": ...}``.
    inputs : dict, optional
        Input name or role (``model.input_info``, :data:`~ema_casadi.model.components.INPUT_ROLES`:
        ``"load"``, ``"ambient_temperature"``, ...) -> value: the way to drive a model whose
        command or load is another signal without naming it.
    **signals : Signal, float or str
        Any other model input by name (``model.inputs``, e.g. ``d_x``), strings in its
        quantity's unit; undriven inputs take their declared default.
    dt : float, optional
        RK4 step (s); default 1e-5 s, or inside RK4's stability limit (:func:`~ema_casadi.simulation.default_step`).
    solver : {"auto", "rk4", "cvodes", "rosenbrock"}
        ``auto`` (default): ``rosenbrock`` (compiled RODAS4; ``cvodes`` without a C
        compiler) at :data:`AUTO_RTOL`, :data:`AUTO_ATOL` on a continuous model, ``rk4``
        where it switches or sticks (hybrid friction, ``zoh``, a PWM bridge); what ran
        and its tolerance: ``info["solver"]``, ``info["tolerance"]``.
    params, p : Parameters or array, optional
        Parameter values (default: the model's set); ``p`` is the raw vector.
    x0 : array, optional
        Initial state, one value per ``model.states`` (default: at rest, all zero).
    from_trim : bool
        Start at the operating point of the inputs' values at t = 0 (a load present
        from the start does not knock the rod back); not with ``x0``.
    zoh : bool
        Sampled ECU at its rates (rk4 only).
    decimate, dt_out : int or float, optional
        Keep every ``decimate``-th step (1: all), or a sample every ``dt_out`` s (rk4: a
        whole number of steps); default every :data:`DT_OUT` (1e-4 s).
    rtol, atol : float, optional
        Tolerances of the variable-step solvers; default :data:`AUTO_RTOL`,
        :data:`AUTO_ATOL` for ``auto``, else :data:`RTOL`, :data:`ATOL`.
    event_tol : float
        cvodes with hybrid friction: switching instants located to this time (s).
    jit : bool
        Compile the rollout to native code (cached on disk).
    progress : bool
        Progress bar on stderr.
    check_step : bool
        rk4: warn (:class:`StepLimitWarning`) above RK4's stability limit (:func:`rk4_step_limit`, in
        ``info["tolerance"]["dt_max"]``) at the run's parameters and largest load; False: checked once.
    """
    instance(model, Model, "model", SimulationError, " (from build_model)")
    (solver, why), requested, (rtol, atol) = choose_solver(model, solver, zoh), solver, tolerances(solver, rtol, atol)
    if from_trim and x0 is not None:
        raise SimulationError("give x0 or from_trim, not both")
    if dt is None:  # inside RK4's stability limit (simulation/_steplimit.py)
        dt = default_step(model, t_end, lambda: (_given(model, x_cmd, f_ext, eta, inputs, signals), _values(
            model, params, p, x0)[0]), zoh or bool(model.switched), dt_out, solver == "rk4" or bool(model.switched))
    if model.switched:  # a PWM bridge: the carrier-synchronous stepper (module _pwm)
        given = _given(model, x_cmd, f_ext, eta, inputs, signals)
        res = _run_switched(model, t_end, given, dt, solver, params, p, x0, dt_out, decimate, jit, progress, from_trim)
        return _chosen(res, requested, why, rtol, atol)
    plan = check_run(model, t_end, dt=dt, dt_out=dt_out, decimate=decimate, solver=solver, zoh=zoh,
                     event_tol=event_tol, rtol=rtol, atol=atol)
    pv, x0 = _values(model, params, p, x0)
    step = plan.dt if solver == "rk4" else plan.spacing
    sig = _checked_inputs(model, _given(model, x_cmd, f_ext, eta, inputs, signals), pv, plan.t_end,
                          {f"{'dt' if solver == 'rk4' else 'dt_out'} {step:g} s": step})
    split, limit = fixed_step(model, plan.dt, sig, pv, zoh, plan.t_end, check_step) if solver == "rk4" else (0, 0)
    if from_trim:
        x0 = trimmed_start(model, sig, pv)
    run, used = _runner(model, solver, plan, sig, pv, x0, (zoh, split), bool(jit), bool(progress), rtol, atol,
                        event_tol)
    res = _chosen(_timed(model, solver, plan.t_end, run, used=used), requested, why, rtol, atol)
    if limit:
        res.info["tolerance"]["dt_max"] = limit.dt_max
    return step_corrections(model, sig, pv, res, zoh)


def _checked_inputs(model, given, pv, t_end, sampling) -> dict:
    """The run's input signals, checked: each given one read by the model, in its range,
    within the envelope, below the Nyquist rate of ``sampling`` (label -> interval, s)."""
    sig = input_signals(model, given, pv, t_end)
    check_effect(model, given, pv)
    check_inputs(model, _driven(model, sig), t_end, sampling)
    return sig


def _driven(model, sig) -> dict:
    """The signals a user drives (not the seeded noise, held at its loop's rate)."""
    return {n: s for n, s in sig.items() if model.input_info[n].noise is None}


def _given(model, x_cmd, f_ext, eta, inputs, signals) -> dict:
    """The inputs given, by name (those not given take their declared defaults; any
    other keyword is checked against the model's inputs); ``inputs`` by name or role.
    An input given twice is refused."""
    from ..model import AssemblyError

    # the conveniences drive the input of their role (a model without one: refused by that key's name below)
    given = {(model.inputs_with(role) or (SIGNAL_KEYS[role],))[0]: value
             for role, value in (("command", x_cmd), ("load", f_ext), ("efficiency", eta)) if value is not None}
    given.update(signals)
    if inputs is not None and not isinstance(inputs, dict):
        raise SimulationError(f"inputs: expected a dict name or role -> value, got {describe(inputs)}")
    for key, value in (inputs or {}).items():
        try:
            name = model.input_name(key)
        except AssemblyError as exc:
            raise SimulationError(f"inputs: {exc}") from None
        if name in given:
            raise SimulationError(f"inputs: '{key}' drives {name}, which is already given")
        given[name] = value
    return given


def _runner(model, solver, plan, sig, pv, x0, zoh, jit, progress, rtol, atol, event_tol):
    """(the run of the solver as a function of no arguments, the solver that runs)."""
    if solver == "rosenbrock" and library(model)[0] is None:
        warnings.warn("solver rosenbrock needs a C compiler: running cvodes instead", stacklevel=4)
        solver = "cvodes"
    return _run_of(model, solver, plan, sig, pv, x0, zoh, jit, progress, rtol, atol, event_tol), solver


def _run_of(model, solver, plan, sig, pv, x0, zoh, jit, progress, rtol, atol, event_tol):
    if solver == "rk4":
        return lambda: _run_rk4(model, plan, sig, pv, x0, zoh, jit, progress)
    if solver == "rosenbrock":
        return lambda: _simulate_rosenbrock(model, plan.t_end, plan.spacing, plan._tail() > 0, sig, pv, x0, rtol,
                                            atol, progress)
    return lambda: _run_cvodes(model, plan, sig, pv, x0, rtol, atol, event_tol, progress)


def _timed(model, solver, t_end, run, **info) -> SimResult:
    """``run()`` with its wall time and the run's facts in ``info``."""
    t_wall = time.perf_counter()
    res = run()
    res.info.update(wall_time=time.perf_counter() - t_wall, solver=info.pop("used", solver),
                    variants=dict(model.variants), t_end=t_end, **info)
    return res


def _run_switched(model, t_end, given, dt, solver, params, p, x0, dt_out, decimate, jit, progress,
                  from_trim=False) -> SimResult:
    """A switched model runs carrier period by period (``simulation/_pwm.py``): solver
    rk4 only (its ``dt`` bounds the RK4 step inside a sub-interval), the ECU always
    sampled, ``dt_out`` (default :data:`DT_OUT`) rounded to whole carrier periods
    (``decimate=1``: every sub-interval)."""
    if solver != "rk4":
        raise SimulationError(f"solver '{solver}': the model switches ({', '.join(model.switched)}); it runs with "
                              f"solver rk4, which steps to every switching instant")
    if decimate is not None and (decimate != 1 or dt_out is not None):
        raise SimulationError("decimate: a switched model keeps samples by dt_out (whole carrier periods), or "
                              "every sub-interval with decimate=1")
    dt_out = None if decimate == 1 else (DT_OUT if dt_out is None else dt_out)
    check_run(model, t_end, dt=dt, dt_out=dt_out, solver="cvodes")  # types, values, result size
    pv, x0 = _values(model, params, p, x0)
    sig = _checked_inputs(model, given, pv, float(t_end), {f"dt {float(dt):g} s": float(dt)})
    step_check(model, float(dt), sig, pv, True, float(t_end))
    if from_trim:
        x0 = trimmed_start(model, sig, pv)
    out = None if dt_out is None else float(dt_out)
    return _timed(model, solver, float(t_end), lambda: simulate_pwm(model, float(t_end), sig, pv, x0, float(dt), out,
                                                                    bool(jit), bool(progress)), dt=float(dt))


def _values(model: Model, params, p, x0) -> tuple[np.ndarray, np.ndarray]:
    """The checked parameter vector and initial state of a run."""
    if params is not None:
        instance(params, Parameters, "params", SimulationError, " (from load_parameters)")
    if p is not None:
        pv = vector(p, "p", SimulationError, len(model.param_names), " (the model's parameter vector)")
    else:
        pv = model.p(params)
    if x0 is None:
        return pv, model.x0()
    return pv, vector(x0, "x0", SimulationError, model.nx, f" (one per state: {', '.join(model.states)})")


class _Plan:
    """The checked request: end time, step, sample spacing, and for rk4 the numbers of
    steps (``n_steps``), steps per sample (``k``) and the rollout's decimation (``k_run``)."""

    def __init__(self, t_end, dt, spacing, n_steps=None, k=None, k_run=None):
        self.t_end, self.dt, self.spacing = t_end, dt, spacing
        self.n_steps, self.k, self.k_run = n_steps, k, k_run

    @property
    def samples(self) -> int:
        """Samples of the result (0 and t_end included)."""
        if self.k is not None:
            return -(-self.n_steps // self.k) + 1
        return _whole_intervals(self.t_end, self.spacing) + 1 + (self._tail() > 0)

    @property
    def kept(self) -> int:
        """Samples the run holds before thinning (rk4: at the rollout's decimation)."""
        return self.n_steps // self.k_run + 1 if self.k_run is not None else self.samples

    def _tail(self) -> float:
        n = _whole_intervals(self.t_end, self.spacing)
        r = self.t_end - n * self.spacing
        return r if r > _WHOLE * self.spacing else 0.0


def _whole_intervals(t_end: float, spacing: float) -> int:
    """Whole intervals of ``spacing`` in [0, t_end] (round-off tolerated)."""
    return int(math.floor(t_end / spacing * (1 + _WHOLE)))


def _steps_in(length: float, dt: float):
    """``length / dt`` as an int if it is whole (round-off tolerated), else None."""
    n = round(length / dt)
    return n if n >= 1 and abs(n * dt - length) <= _WHOLE * max(length, dt) else None


def _largest_divisor(n: int, cap: int) -> int:
    """Largest divisor of ``n`` that is at most ``cap``."""
    if n <= cap:
        return n
    best = 1
    for d in range(1, math.isqrt(n) + 1):
        if n % d == 0:
            if d <= cap:
                best = max(best, d)
            if n // d <= cap:
                best = max(best, n // d)
    return best


def check_run(model: Model, t_end, *, dt=1e-5, dt_out=None, decimate=None, solver="auto", zoh=False,
              event_tol=1e-7, rtol=RTOL, atol=ATOL, labels: dict | None = None, error: type = SimulationError):
    """Check a simulation request and plan its output grid, before anything is built.

    Raises ``error`` with one line naming the argument (by its name in ``labels``, e.g.
    ``{"dt_out": "--dt-out"}`` for the command line): a bad type or value, a t_end or
    dt_out that is not a whole number of RK4 steps, or a run above :data:`MAX_STEPS`
    or :data:`MAX_RESULT_BYTES` (with the estimate and the limit).

    Parameters
    ----------
    model : Model
        The model to run (its signal count sizes the result).
    t_end, dt, dt_out, decimate, solver, zoh, event_tol, rtol, atol
        As in :func:`simulate`.
    labels : dict, optional
        Argument name -> the name to show in messages.
    error : type
        The exception raised.

    Returns
    -------
    object
        The plan (private): end time, step, sample spacing, step counts.
    """
    labels = labels or {}

    def lab(name):
        return labels.get(name, name)

    if not isinstance(solver, str) or solver not in SOLVERS:
        raise error(f"{lab('solver')} '{solver}' unknown; choose one of {', '.join(SOLVERS)}")
    solver = choose_solver(model, solver, zoh)[0]
    t_end = _seconds(t_end, lab("t_end"), error)
    dt = _seconds(dt, lab("dt"), error)
    if dt_out is not None:
        dt_out = _seconds(dt_out, lab("dt_out"), error)
    elif decimate is None:  # the default spacing: DT_OUT, for rk4 in whole steps
        dt_out = dt * max(1, round(DT_OUT / dt)) if solver == "rk4" else DT_OUT
    if decimate is not None:
        decimate = integer(decimate, lab("decimate"), error, minimum=1)
        if dt_out is not None:
            raise error(f"give {lab('decimate')} or {lab('dt_out')}, not both")
    event_tol = _seconds(event_tol, lab("event_tol"), error)
    for name, val in (("rtol", rtol), ("atol", atol)):
        number(val, lab(name), error, positive=True)
    if zoh and solver != "rk4":
        raise error(f"{lab('zoh')} (sampled ECU) needs solver rk4")
    if solver == "rosenbrock" and model.hybrid:
        raise error(f"{lab('solver')} rosenbrock does not handle hybrid (stick-slip) friction, a hybrid system "
                    "with mode switches: use cvodes (switching instants located) or rk4")
    n_signals = model.nu + model.ny + model.nx
    if solver == "rk4":
        plan = _rk4_plan(t_end, dt, dt_out, decimate, lab, error)
    else:
        spacing = dt_out if dt_out is not None else dt * (decimate or 1)
        spacing_label = lab("dt_out") if dt_out is not None else lab("dt")
        if t_end / spacing > MAX_RESULT_BYTES:  # before counting samples as an int
            raise error(_too_big(t_end / spacing, n_signals, lab("t_end"), t_end, spacing_label, spacing))
        plan = _Plan(t_end, dt, min(spacing, t_end))
    kept = plan.kept
    if kept * n_signals * 8 > MAX_RESULT_BYTES:
        if dt_out is not None or solver != "rk4":
            spacing_label, spacing = lab("dt_out") if dt_out is not None else lab("dt"), plan.spacing
        else:
            spacing_label, spacing = lab("dt"), dt
        note = f" (kept every {plan.k_run} steps so that the samples end at t_end)" if kept > plan.samples else ""
        raise error(_too_big(kept, n_signals, lab("t_end"), t_end, spacing_label, spacing, note))
    return plan


def _rk4_plan(t_end, dt, dt_out, decimate, lab, error) -> _Plan:
    """The fixed-step plan: whole numbers of steps, at most MAX_STEPS."""
    if dt > t_end:
        raise error(f"{lab('dt')} ({dt:g} s) is longer than {lab('t_end')} ({t_end:g} s)")
    steps = t_end / dt
    if steps > MAX_STEPS:
        raise error(f"{lab('t_end')} {t_end:g} s / {lab('dt')} {dt:g} s = {steps:.3g} RK4 steps, "
                    f"about {_duration(steps * RK4_SECONDS_PER_STEP)} at {RK4_SECONDS_PER_STEP * 1e6:g} us "
                    f"per step (measured); the limit is {MAX_STEPS:.0e} steps (MAX_STEPS)")
    n_steps = _steps_in(t_end, dt)
    if n_steps is None:
        raise error(f"{lab('t_end')} {t_end:g} s is not a whole number of RK4 steps {lab('dt')} {dt:g} s "
                    f"({steps:.6g}); choose a {lab('dt')} that divides {lab('t_end')}")
    if decimate is not None:
        k = decimate
    elif dt_out is not None:
        k = _steps_in(dt_out, dt)
        if k is None:
            raise error(f"{lab('dt_out')} {dt_out:g} s is not a whole number of RK4 steps {lab('dt')} {dt:g} s "
                        f"({dt_out / dt:.6g}); the samples fall on steps")
    else:
        k = 1
    k = min(k, n_steps)
    k_run = _largest_divisor(math.gcd(k, n_steps), STEPS_PER_CALL)
    return _Plan(t_end, dt, k * dt, n_steps, k, k_run)


def _too_big(samples, n_signals, t_label, t_end, spacing_label, spacing, note="") -> str:
    size = samples * n_signals * 8
    return (f"{t_label} {t_end:g} s with {spacing_label} {spacing:g} s: {samples:.3g} samples{note} x {n_signals} "
            f"signals x 8 B = {size_text(size)}, above the limit of {size_text(MAX_RESULT_BYTES)} (MAX_RESULT_BYTES); "
            f"use a longer {spacing_label} or a shorter {t_label}")


def _seconds(value, label, error) -> float:
    try:
        return number(value, label, error, unit="s", positive=True)
    except error:
        raise error(f"{label} must be a positive finite number of seconds, got {_shown(value)}") from None


def _shown(value) -> str:
    return repr(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else describe(value)


def _duration(s: float) -> str:
    for unit, size in (("years", 3.15e7), ("days", 86400), ("h", 3600), ("min", 60)):
        if s >= size:
            return f"{s / size:.3g} {unit}"
    return f"{s:.3g} s"


# -- running the plan ----------------------------------------------------------------
def _run_rk4(model, plan: _Plan, sig, pv, x0, zoh, jit, progress) -> SimResult:
    """The rollout at decimation ``k_run`` over ``n_steps``, thinned to every k-th step
    plus the last one; ``zoh`` is (sampled ECU, steps split at its instants)."""
    res = _simulate_rk4(model, plan.n_steps * plan.dt, sig, pv, x0, plan.dt, zoh[0], plan.k_run, jit, progress, zoh[1])
    if plan.k_run != plan.k:
        steps = np.arange(len(res.t)) * plan.k_run
        keep = np.nonzero((steps % plan.k == 0) | (steps == plan.n_steps))[0]
        res = _thin(res, keep)
    res.t[-1] = plan.t_end  # the same instant, without the round-off of n dt
    res.info.update(decimate=plan.k, dt_out=plan.spacing)
    return res


def _thin(res: SimResult, keep: np.ndarray) -> SimResult:
    return SimResult(t=res.t[keep], inputs={k: v[keep] for k, v in res.inputs.items()},
                     outputs={k: v[keep] for k, v in res.outputs.items()},
                     states={k: v[keep] for k, v in res.states.items()}, info=res.info, unit_table=res.unit_table,
                     kinds=res.kinds, roles=res.roles)


def _run_cvodes(model, plan: _Plan, sig, pv, x0, rtol, atol, event_tol, progress) -> SimResult:
    """The whole intervals of dt_out, then the last, shorter one from where they ended."""

    def run(t_end, signals, x_start, spacing):
        if model.hybrid:
            return _simulate_cvodes_hybrid(model, t_end, signals, pv, x_start, spacing, rtol, atol, event_tol,
                                           progress)
        return _simulate_cvodes(model, t_end, signals, pv, x_start, spacing, rtol, atol, progress)

    n = _whole_intervals(plan.t_end, plan.spacing)  # >= 1: the spacing is at most t_end
    t_full, tail = n * plan.spacing, plan._tail()
    if not tail:
        res = run(t_full, sig, x0, plan.spacing)
        res.t[-1] = plan.t_end
        res.info["dt_out"] = plan.spacing
        return res
    head = run(t_full, sig, x0, plan.spacing)
    x_end = np.array([head.states[s][-1] for s in model.states])
    shifted = {name: s.shifted(t_full) for name, s in sig.items()}
    try:
        last = run(tail, shifted, x_end, tail)
    except RunFailed as exc:  # its time from the start of the run; the result up to the tail
        raise RunFailed(exc.what, t_full + exc.time, head) from None
    t = np.append(head.t, plan.t_end)
    info = dict(head.info)
    for key in ("steps", "integrator_calls", "compute_time", "mode_switches"):
        if key in info:
            info[key] = info[key] + last.info.get(key, 0)
    if "switch_times" in info:
        info["switch_times"] = np.concatenate([info["switch_times"], np.asarray(last.info["switch_times"]) + t_full])
    info.update(dt_out=plan.spacing, restarts_at=[t_full])
    return SimResult(
        t=t, inputs={name: s(t) for name, s in sig.items()},
        outputs={k: np.append(v, last.outputs[k][-1]) for k, v in head.outputs.items()},
        states={k: np.append(v, last.states[k][-1]) for k, v in head.states.items()},
        info=info, unit_table=head.unit_table, kinds=head.kinds, roles=head.roles,
    )

