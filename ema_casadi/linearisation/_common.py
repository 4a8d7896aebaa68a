"""Shared by trim and linearisation: errors, loop names, policies, the AD Jacobians."""

from __future__ import annotations

import casadi as ca
import numpy as np

from .._util._errors import InputError
from ..model.assembly import Model
from ..model.components import PART_CLASSES, POLICIES

#: Loop name -> (closure flag, injection input, fed-back measurement), outer to inner:
#: every loop a registered part declares (a model has its own in ``model.loops``).
LOOPS = {
    lp.name: (lp.flag, lp.injection, lp.measured)
    for cls in PART_CLASSES for lp in cls.loops
}
#: Small-signal policies (the parts declare what each value sets)
FRICTION_POLICIES = POLICIES["friction"]
BACKLASH_POLICIES = POLICIES["backlash"]
OUTER = ("closed", "open")

# saturation limits are lifted by this factor while solving the trim
_LIFT = 1e6

class LinearizationError(InputError, ValueError):
    """A linearisation request cannot be served (bad option, unsupported variant)."""


class OperatingPointError(LinearizationError):
    """No operating point exists or none was found; the one-line message names the
    limit that is exceeded and the numbers."""


def signal_outputs(model: Model) -> tuple[str, ...]:
    """Outputs that are signals (not powers, energies or the stick flag): the default
    outputs of a linear model.

    Parameters
    ----------
    model : Model
        The assembled model (its parts declare each output's kind).
    """
    return model.outputs_of("signal")


def jacobian_function(model: Model) -> ca.Function:
    """``J(x, u, p) -> (xdot, y, A, B, C, D)``: the model and its exact AD Jacobians.

    Built once per model and cached on it (a call costs tens of microseconds).

    Parameters
    ----------
    model : Model
        The assembled model.
    """
    J = model.cache.get("jacobians")
    if J is None:
        x = ca.SX.sym("x", model.nx)
        u = ca.SX.sym("u", model.nu)
        p = ca.SX.sym("p", len(model.param_names))
        xdot, y = model.f(x, u, p)
        J = ca.Function(
            "ema_jacobians", [x, u, p],
            [xdot, y, ca.jacobian(xdot, x), ca.jacobian(xdot, u), ca.jacobian(y, x), ca.jacobian(y, u)],
            ["x", "u", "p"], ["xdot", "y", "A", "B", "C", "D"],
        )
        model.cache["jacobians"] = J
    return J


def _eval(model, x, u, p):
    return [np.array(v) for v in jacobian_function(model)(x, u, p)]
