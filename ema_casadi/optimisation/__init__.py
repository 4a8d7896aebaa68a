"""The optimisation layer: one IPOPT wrapper, one least-squares path, and the
transcriptions of a trajectory on the compiled model (docs: architecture).

Every analysis that optimises uses it: gain tuning, optimal moves and the performance
envelope, experiment design, identification, trim and periodic orbits. It sits below
the analyses and imports only the model and the shared helpers: a caller binds its
model's functions (rates, the interval integrator of
:func:`ema_casadi.simulation.interval_function`) and hands them in.

IPOPT
-----
:func:`solve_ipopt` ``(opti, ipopt=(), *, expand=False, simple_bounds=False, warm=None,
on_iteration=None) -> IpoptResult`` solves a ``casadi.Opti`` problem:

- ``ipopt``: IPOPT's options without the ``ipopt.`` prefix, or a sequence of option
  sets tried in turn until one converges (a fallback chain). :data:`BASE_OPTIONS` (no
  output, MUMPS) are always added; nothing in them depends on the machine. A path that
  stays the same on every OpenBLAS kernel comes from the formulation: bounds passed as
  bounds (``simple_bounds=True``: IPOPT's iterates never leave them), constraints scaled
  to O(1), no rank-deficient rows, and the barrier settings each caller measured.
- ``warm=(x, lam_g)`` (:attr:`IpoptResult.warm` of a previous solve of the same
  structure): set as the initial values, :data:`WARM_START` added to each option set
  (the caller picks ``mu_init``).
- ``on_iteration(k, value)`` after every iteration (``value(expr)``: the iterate's value).
- Interrupts: SIGINT/SIGTERM stop IPOPT at the end of the iteration it is in (Python's
  signal handlers cannot run while IPOPT holds the interpreter; the wrapper's
  per-iteration callback asks the flag the ``ema`` command's handler sets, and raises),
  and the interrupt is raised again after the solve.
- :class:`IpoptResult`: ``success``, ``status``, ``iterations``, ``value(expr)``, ``x``,
  ``lam_g``, ``stats``, ``log`` (per iteration ``obj``, ``inf_pr``, ``inf_du``, ``mu``,
  ...), ``attempts`` (status and iterations per option set), ``wall_s``, ``warm``.

No module outside this package creates an IPOPT solver (``tests/meta/test_architecture.py``).

Least squares
-------------
:func:`levenberg_marquardt` ``(evaluate, z0, lo, hi, max_evaluations, cost_tol=COST_TOL)``
minimises 1/2 |r(z)|^2 in a box with the exact Jacobian (``evaluate(z) -> (r, J)``),
bounded per-component steps and a statistical stop (the Gauss-Newton step predicts a
decrease below ``cost_tol``); returns ``z``, ``r``, ``J``, ``cost``, ``converged``,
``message``, ``evaluations``. :func:`gauss_newton_decrease` is that prediction;
:func:`newton_step` the minimum-norm Newton step of a square or over-determined system
r(z) = 0 (the trim's and the periodic orbit's Newton iterations use it).

Transcriptions
--------------
:func:`transcribe` ``(opti, method, *, x0, guess, scale, U, dts, rates=None,
interval=None, interval_args=(), free=None, fixed_start=True, integrand=None) ->
Transcription`` puts a trajectory's dynamics into an Opti problem by

- ``single``: one rollout of ``interval`` from x0 (:func:`single_shooting`): the fewest
  variables; the states are functions of everything before them;
- ``multiple``: node states (scaled by ``scale``) as variables, ``interval`` mapped over
  the intervals (:func:`multiple_shooting`) and :func:`continuity` constraints;
- ``collocation``: node and Radau IIA collocation states as variables, the rate
  function ``rates(X, U) -> (xdot, y)`` at every point (:func:`collocation`), with an
  optional quadrature of an output (``integrand``).

Path constraints go on :attr:`Transcription.X` and, for collocation, on
:attr:`Transcription.points`; the parameters become decision variables with
:func:`decision_parameters` (relative units, log scale for positive ones) bound into
the caller's ``rates``/``interval_args``; the node states' guess (``guess``) is the
caller's: measured channels where measured, a simulation elsewhere.

The choice rule (measured in ``benchmarks/bench_transcriptions.py``; table in the
architecture docs):

- **collocation** where the model is stiff for RK4 at the interval length (intervals x
  substeps above 400, ``optimal.EXPAND_LIMIT``: the loaded move, 0.67 s against 19 s by
  shooting) and where the start may be far off (an oscillator's three parameters from
  starts x0.25 ... x4: 4 of 4 reached); its grid must resolve the dynamics (0.6 % bias
  at 25 ms intervals there);
- **multiple** shooting where the RK4 chain is short (the unloaded move) and for an
  accurate answer near a good start (3 of 4 far starts, 0.02 % error);
- **single** shooting for few unknowns from a good start (2 of 4 far starts).
"""

from ._collocation import DEGREE, SCHEME, coefficients, collocation, points
from ._ipopt import BASE_OPTIONS, SUCCESS, WARM_START, IpoptResult, solve_ipopt
from ._lsq import COST_TOL, STEP0, STEP_TOL, gauss_newton_decrease, levenberg_marquardt, newton_step
from ._shooting import (
    METHODS,
    Transcription,
    continuity,
    decision_parameters,
    multiple_shooting,
    single_shooting,
    transcribe,
)

__all__ = ["solve_ipopt", "IpoptResult", "BASE_OPTIONS", "WARM_START", "SUCCESS",
           "levenberg_marquardt", "gauss_newton_decrease", "newton_step", "COST_TOL", "STEP_TOL", "STEP0",
           "transcribe", "Transcription", "METHODS", "multiple_shooting", "single_shooting", "continuity",
           "decision_parameters", "collocation", "coefficients", "points", "DEGREE", "SCHEME"]
