"""Time simulation of an assembled model (docs: simulate).

Three solvers share the model's one CasADi Function; ``solver="auto"`` (the default)
picks ``rosenbrock`` for a continuous model and ``rk4`` where the model switches or
sticks (hybrid friction, the sampled ECU, a PWM bridge), and records the choice and
its tolerance in ``info`` (``solver``, ``solver_reason``, ``tolerance``):

``rk4``
    Fixed-step classical Runge-Kutta, rolled out inside one compiled call per chunk
    (``fold`` of the step for output decimation, ``mapaccum`` over the outputs of a
    chunk): no Python per step. Input signals are sampled in NumPy at each step's
    t, t + h/2 and t + h and passed in, so one compiled rollout serves every signal,
    parameter value and step size. Optional zero-order-hold (ZOH) execution of the
    ECU at its sample rates: each loop updates at the start of the step that holds
    its sampling instant when dt divides every loop's sample period, else in a step
    split at the instant (RK4 up to it, the update, RK4 on), so each loop samples at
    its own instants at any dt. A step above RK4's stability limit on the model
    (``rk4_step_limit``: the fastest eigenvalues of the Jacobian at rest and held
    under the run's largest load) is warned (``StepLimitWarning``).
``cvodes``
    Variable-step BDF (SUNDIALS CVODES through ``casadi.integrator``) on the
    continuous model with the signals as CasADi expressions of t; the run is split
    at the signals' breakpoints (steps, starts) and the integrator restarted there.
``rosenbrock``
    Variable-step RODAS4 (order 4, L-stable, embedded error estimate) with its whole
    step-size loop in C (``_c/rosenbrock.c``) around CasADi-generated f, df/dx and
    df/du u', built once per model and cached on disk; the signals are evaluated in
    C, steps land on their breakpoints, samples come from Hermite interpolation.
    About 3x fewer steps than CVODES at equal accuracy and ~2.5 us per step instead
    of ~5 us. Continuous models only (hybrid friction is refused).

Memory stays bounded by output decimation: only every ``decimate``-th step (or
every ``dt_out``) is kept, and the inputs are generated chunk by chunk.

Hybrid (stick-slip) friction is a hybrid system, and both solvers wrap it:

- ``rk4``: the mode logic lives inside the compiled step. The continuous ``f`` holds
  a stuck rod (zero acceleration); after each step ``model.project`` resets the
  contact velocity to 0 when the rod entered the dead band, or its velocity changed
  sign between the step's start or stage states and its end, with the stick condition
  holding. Switching instants are thus resolved to one step. The stick flag and the
  number of stick/slip switches ride along as two extra rollout states, so
  ``info["mode_switches"]`` counts every switch, whatever the output decimation.
- ``cvodes``: CasADi's integrator events are experimental and failed on this model
  (CV_ILL_INPUT), so the wrapper owns the switching logic: CVODES integrates the
  continuous ``f`` with quadratures of the time spent stuck / not stuck; a chunk
  whose quadrature of the other mode is positive holds a switch, which is bracketed
  and shrunk (quadrature estimate, bisection safeguard) to ``event_tol`` (default
  1e-7 s) by re-integrating from the last accepted state; ``model.project`` is applied
  at the located instant and the integrator restarted. ``info`` holds
  ``mode_switches`` and ``switch_times``.

Every run is checked against the model's physical envelope
(:meth:`~ema_casadi.model.assembly.Model.envelope`, ``_envelope``): after every rollout chunk
(RK4) or integrator segment (CVODES) the kept samples of every bounded state, output
and input are compared with their bounds, and checked to be finite. A run that leaves
the envelope, goes non-finite or whose integrator gives up raises :class:`RunFailed`
with the reason, the time and the result up to the failure (``info["status"]`` is
"failed" there, "completed" on a run that finished). The chunk loops also
honour an interrupt (:mod:`ema_casadi._util._interrupts`) between chunks.
"""


from ._api import DT_OUT, MAX_STEPS, SOLVERS, check_run, simulate
from ._choice import AUTO_ATOL, AUTO_RTOL, choose_solver, trimmed_start
from ._cvodes import BDF_MAX_ORDER
from ._envelope import AnalysisFailed, GaveUp, Monitor, RunFailed, captured_stderr, integrator_failure
from ._inputs import (
    as_signal,
    check_effect,
    check_inputs,
    check_value_range,
    input_matrix,
    input_signals,
    noise_signal,
)
from ._interval import interval_function
from ._pwm import check_switched
from ._result import SimResult, SimulationError, hunting_metrics, progress_bar, step_response_metrics
from ._rk4 import STEPS_PER_CALL, outputs_at, rk4_step_function, sampling_split
from ._sensitivity import REPLAY_LIMIT, forward_sensitivities, sensitivity_library
from ._steplimit import (
    DT_DEFAULT,
    DT_MARGIN,
    RK4_REAL_REACH,
    StepLimit,
    StepLimitWarning,
    default_step,
    inside_limit,
    jacobian_step_limit,
    mode_step_limit,
    peak_load,
    rk4_growth,
    rk4_reach,
    rk4_step_limit,
    sample_periods,
    step_check,
)

__all__ = [
    "simulate", "SimResult", "SOLVERS", "DT_OUT", "MAX_STEPS", "AUTO_RTOL", "AUTO_ATOL", "choose_solver",
    "SimulationError", "RunFailed", "AnalysisFailed", "Monitor", "rk4_step_function",
    "step_response_metrics", "hunting_metrics",
    "progress_bar", "outputs_at", "STEPS_PER_CALL", "BDF_MAX_ORDER", "noise_signal", "interval_function",
    # the interfaces other packages build on: request checks, inputs, the start, integrator failures
    "check_run", "check_inputs", "check_value_range", "check_effect", "check_switched", "trimmed_start",
    "as_signal", "input_signals", "input_matrix",
    "GaveUp", "captured_stderr", "integrator_failure",
    "forward_sensitivities", "sensitivity_library", "REPLAY_LIMIT",
    # RK4's stability limit and the ECU's sample instants
    "rk4_step_limit", "StepLimit", "StepLimitWarning", "rk4_reach", "rk4_growth", "RK4_REAL_REACH", "step_check",
    "default_step", "inside_limit", "DT_DEFAULT", "DT_MARGIN", "mode_step_limit", "jacobian_step_limit",
    "sampling_split", "sample_periods", "peak_load",
]
