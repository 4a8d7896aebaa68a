"""Gain tuning of the cascade by nonlinear optimisation (docs: tune).

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

*The cascade* (each loop with its outer loops open: the velocity loop with the
position loop open, the current loop with both open; the position loop as above), the
classic view of a cascade design, in which each loop must stand on its own:

- ``cascade_margin``: the same exclusion disk as the loop-at-a-time margins.
- ``unconditional``: wherever |L| >= 10^(-GM/20), L stays out of its second quadrant
  (Re L < 0 < Im L, past -180 deg). L reaches it only by crossing the negative real
  axis, so every phase crossover then has |L| <= 10^(-GM/20): the gain may rise by GM
  and there is no crossover where it may only fall (no gain-reduction margin to
  report: the loop is unconditionally stable).
- ``separation`` (``separation`` s, default 3): between each pair of neighbouring
  loops a gap frequency g_k (a decision variable, started at the geometric mean of the
  start's crossovers) with the outer loop's |L| <= 1 over 1.5 decades from g_k/sqrt(s)
  and the inner loop's |L| >= 1 over 1.5 decades up to g_k sqrt(s): the inner loop's
  crossover is at least s times the outer one's. (A pointwise form - "wherever the
  outer |L| >= 1 at f, the inner |L| >= 1 at s f" - needed a smoothed maximum whose
  curvature stalled IPOPT: Infeasible_Problem_Detected on the dc/rigid/hybrid/PI
  variant over three loads; the gap variables converge there.)

*Noise* (``sensor_noise``, ``command_noise``): the closed-loop response of the
current command i_cmd to the position loop's injection, where position-sensor noise
enters, at most command_noise I_max / sensor_noise on the grid (default 0.005 x 24 A /
1 um = 1.2e5 A/m; the reference gains use 2.5e4 A/m, the proportional path K_x K_p_w
2 pi/p): bandwidth bought with the proportional gains costs current-command activity.

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

The start is a feasible point of this problem: each slack starts at its group's
violation at the start gains (zero when the start meets every constraint, as the
reference gains do), and IPOPT's filter is told to reject every trial point whose
constraint violation (1-norm) exceeds 0.3 (``theta_max_fact``; IPOPT's default allows
1e4). Without that bound the one-load reference problem (0 kN) failed from its
feasible start: with no constraint active the Lagrangian's Hessian is only the effort
term's 2e-3 I (-log f_b is linear in its variable), so the Newton step is set by the
linearised constraints and was long; at iteration 12 IPOPT's filter accepted a trial
point (K_x and K_p_w up by e^1.7 and e^1.4 from the start, K_p_i and K_i_i down by
e^2.5 and e^2.1) that left the feasible set by 0.57 in the max-norm, 1.5 summed
(position, velocity and current margins, overshoot and current all violated). There
and in the next 15 iterations the margin measures of the velocity and current loops
sat at or near their floor (-0.224, at L = -1.48 inside the disk, where the measure's
gradient is zero), so the linearised constraints gave no direction that restores them;
the restoration phase ended on a point with slack and the tune reported "infeasible".
With three load cases the 30 kN current limit (13.2 A of 24 A held; the step's current
grows with K_x K_p_w, whatever K_p_i) becomes active at the same stage and the
iterates stayed within 0.1 of feasibility (max-norm); at 0 kN only the voltage bounds
K_x K_p_w, and the optimiser meets it by lowering the current-loop gains until the
current-loop margin, strongly nonlinear in them, stops it.

Safety net (:func:`tune`): from a start that the verification passes, gains worse
than the start or an "infeasible" answer are never returned. If IPOPT does not
converge, converges with slack, or to gains that fail the verification or are worse
than the start (worst-case -3 dB frequency, or ISE), the result is the best of the
iterates that meet every constraint of the optimiser and pass the verification, no
worse than the start, or else the start itself (:attr:`TuneResult.fallback`), with a
message saying so.

Objectives
----------
The default objective is ``bandwidth`` under every requirement above (margins both
ways, the cascade's unconditional margins and separation, the noise bound, limits and
overshoot on the step): the fastest position response whose loops a reviewer can read
one at a time. ``bandwidth``: maximise f_b, a variable with |T(j 2 pi f_b)| >= 1/sqrt(2) in every
load case: the worst case's -3 dB frequency (as long as |T| stays above -3 dB below
it, which the margin and overshoot constraints keep; the verification measures the
true -3 dB frequency). ``tracking``: minimise the worst case's integrated squared
error of the step (normalised by the step and 10 ms). Both add an effort term,
1e-3 sum(log(gain/reference)^2): a pure bandwidth or squared-error objective drives
gains to their bounds (measured).

Gains are scaled logarithmically, ``gain = reference * exp(theta)`` within
``reference * [1/100, 100]``; ``K_i_x`` may start at zero and is scaled linearly
(``K_x^2/4 * theta``, theta in [0, 100]).

Verification
------------
:func:`verify` re-trims and re-linearises with the tuned gains
(:mod:`ema_casadi.linearisation`) and takes the toolkit's margins
(:func:`ema_casadi.frequency.margins`) of every loop transfer (crossovers searched in
0.01 Hz - 100 kHz; PM is the smallest angular distance of L to -1, GM counted in both
directions), the sensitivity peak, the closed-loop eigenvalues and -3 dB bandwidth and
a linear step response (exact discretisation); :func:`step_metrics` simulates a nonlinear step on the
full model. A tune succeeds only when IPOPT converged with no slack left and this check
passes (or, from a verified-feasible start, when the safety net's gains pass it and
are no worse than the start).

Modules
-------
``_requirements`` (what is asked: :class:`Requirements`, :func:`exclusion_disk`, the
tunable gains), ``_kernels`` (numeric building blocks: sensitivities, matrix
exponential, soft minimum), ``_callbacks`` (the spectral abscissa with its gradient),
``_scaling`` (gains as decision variables), ``_closed_loop`` (the reduced, balanced
closed loop as a function of the gains), ``_constraints`` (the constraint groups),
``_cascade`` (the cascade's groups and the noise bound), ``_inspect`` (reading the
problem back),
``_problem`` (:class:`TuningProblem`, the Opti problem), ``_solve`` (:func:`tune`,
:class:`TuneResult`), ``_report`` (texts), ``_verify`` (:func:`verify`,
:func:`step_metrics`), ``_figures`` (:func:`plot_tuning`, drawn in ``plots``).
"""

from ._callbacks import spectral_abscissa
from ._figures import cascade_bode_figure, plot_tuning
from ._problem import TuningProblem
from ._report import describe_constraint
from ._requirements import (
    GAINS,
    OBJECTIVES,
    Requirements,
    TuneError,
    default_free,
    exclusion_disk,
    scaled_gains,
)
from ._solve import TuneResult, tune
from ._verify import step_metrics, verify

__all__ = [
    "GAINS", "OBJECTIVES", "TuneError", "Requirements", "TuneResult", "tune", "verify",
    "step_metrics", "scaled_gains", "default_free", "exclusion_disk", "plot_tuning", "cascade_bode_figure",
    "describe_constraint", "TuningProblem", "spectral_abscissa",
]
