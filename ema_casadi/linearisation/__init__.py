"""Operating points and exact linearisation (docs: linearise-margins).

An operating point (trim) is a state ``x`` at which the model is at rest for given
inputs: ``f(x, u, p) = 0`` with ``u = (x_cmd, f_ext, eta, 0, 0, 0)``. Optionally the
rod moves at a constant velocity ``v_rod``; the point is then a relative equilibrium
(every derivative zero except the positions', which move at ``v_rod``; the model only
sees position differences, so the linearisation does not depend on where along the
path it is taken). The trim is solved on the model itself by Newton's method with the
CasADi AD Jacobian.

The linear model is the exact AD Jacobian ``A, B, C, D`` of the same CasADi Function at
that point, returned as :class:`LinearModel` (NumPy, no python-control import) or as a
named ``control.StateSpace`` (:func:`linearize`).

Small-signal policy for the non-smooth elements
-----------------------------------------------
Each is handled through the parameter vector (the model is never rebuilt):

``backlash="off"`` (default)
    ``B = 0``: the dead-zone spring and the play operator are written so that B = 0
    gives slope exactly 1, so the drive train is linear. ``"keep"`` leaves ``B``; at
    an unloaded point the rod then sits inside the gap and is *decoupled* from the
    screw in the linear model (a warning says so); under load the screw is preloaded
    on one flank and the result equals ``"off"``.
``friction="off"`` (default)
    Coulomb-type friction is left out of the small-signal model: seal and thrust-bearing
    friction ``F_seal = C_bear = 0`` (viscous ``c_v`` and ``b_m`` stay), the hybrid
    variant's stick band is closed (``eps = 0``, so the hybrid model linearises exactly
    like the smooth one), and the screw-nut efficiency switch - itself a load-dependent
    Coulomb friction - is frozen at its operating-point value ``g`` (the model is
    evaluated with ``eta = 1/g`` and ``eta_inv = g``, which makes the blend constant;
    the ``eta`` input's column is taken from the unfrozen model). Without this, the
    efficiency blend linearised at standstill under 30 kN adds ~660 N m s/rad of
    fictitious shaft damping (the motor's own b_m is 2e-4). At a moving operating point the Coulomb force is then
    absent from the trim too (use ``"smooth"`` to keep it).
``friction="smooth"``
    Linearise the smooth friction law and the efficiency blend as they are. At rest
    the result depends on the smoothing velocity ``v_s`` (slope F_r/v_s, ~1.5e6 N s/m
    with the reference set) and on the blend width; a warning says so. Not available
    for the hybrid variant (its Karnopp law has no meaningful slope).
``quantisation="off"`` (always: the policy's default)
    The real sensors' quantisation steps are 0 (``Part.small_signal``), so the linear
    model keeps a sensor's gain, lag and sample delay and leaves its quantisation (and
    its noise inputs, 0 by default) to the time-domain analyses.
Saturations (rate limit, current limit, voltage circle) must be inactive at the
point: the trim is solved with the limits lifted and then checked against them, so a
load above what the current limit can hold, or a speed above the rate or voltage
limit, raises :class:`OperatingPointError` naming the limit and the numbers.

Loop breaks (the paper's "Gain = 1" block)
------------------------------------------
Every loop's feedback is ``loop_flag * measurement + d`` (flags in the parameter
vector, injections ``d_x, d_w, d_i`` among the inputs). Opening a loop sets its flag
to 0 and its injection to the measurement's operating-point value, so the controller
sees the same signals and the Jacobian is taken at the same point. The loop transfer
at a break is ``L(s) = -G_{d -> measurement}(s)`` (negative-feedback convention: the
closed loop is L/(1+L)).
"""

from ._common import (
    BACKLASH_POLICIES,
    FRICTION_POLICIES,
    LOOPS,
    OUTER,
    LinearizationError,
    OperatingPointError,
    jacobian_function,
    signal_outputs,
)
from ._flight import flight_point
from ._linear import LinearModel, linear_model, linearize, loop_model, loop_transfer
from ._trim import REQUEST_KEYS, OperatingPoint, operating_point, small_signal_point

__all__ = [
    "LOOPS", "OUTER", "FRICTION_POLICIES", "BACKLASH_POLICIES", "LinearizationError", "OperatingPointError",
    "OperatingPoint", "LinearModel", "operating_point", "linear_model", "linearize", "loop_model",
    "loop_transfer", "signal_outputs", "jacobian_function", "flight_point", "small_signal_point", "REQUEST_KEYS",
]
