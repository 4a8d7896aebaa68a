"""Direct collocation (Radau IIA) of a move's dynamics on the shooting grid: the
transcription of a stiff configuration (module docs: :mod:`ema_casadi.optimal`; the
equations: :mod:`ema_casadi.optimisation`, whose ``collocation`` this binds to a move),
and the continuation through widened switches that its solve starts with.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..optimisation import DEGREE
from ..optimisation import collocation as layer_collocation

__all__ = ["WIDENED", "WARM", "collocation", "widened"]

#: The continuation's first, smoother solves, in turn: the model's smooth switches at the
#: widths its parts declare (the ``switch_width`` policy; on the reference the screw's
#: efficiency switch over the transmitted power, 0.1 W: 8 mrad/s of shaft speed against
#: 15 kN, a rate of 10^5 1/s at rest, widened to 10 W, then 1 W). At the model's own width
#: the NLP under load has several optima a few 1e-4 apart in the braking, and which one
#: IPOPT reaches from the ECU's step follows the rounding (the BLAS kernel, the barrier's
#: start: 0.11496 ... 0.11662 s for 10 mm against 15 kN); from the widened optima every
#: start tried reached the same one (0.1149842 s).
WIDENED = ("wider", "wide")
#: IPOPT's warm start from the widened problem's optimum (primal and multipliers): the
#: barrier's start and the slacks' push, beside the optimiser's own warm-start settings.
WARM = {"mu_init": 1e-4, "warm_start_slack_bound_push": 1e-9}


def collocation(prob, opti, Xs, C, dts, scale: np.ndarray, guess: dict) -> tuple:
    """The collocation equations of every interval of a move (the layer's
    :func:`~ema_casadi.optimisation.collocation` with the move's rates, quadrature and
    guess): (X_next, cost, points), the states the polynomial ends each interval at
    (nx x N), the quadrature summed (0 without one) and, per collocation point, (X_r, Y_r)
    for the caller's limits and rest conditions.

    The equations hold for the states the shooting makes continuous; a memory state at
    rest on its signal (``Model.rest_states``) is not integrated: the caller holds it at
    its signal at the nodes and at the collocation points.

    Parameters
    ----------
    prob : Problem
        The problem (its model, grid and rate function :meth:`Problem._rates`).
    opti : casadi.Opti
        The NLP the collocation states and equations go into.
    Xs : MX
        The scaled node states (nx x N + 1).
    C : MX
        The controls (nc x N).
    dts : MX
        The intervals' lengths (1 x N, s).
    scale : ndarray
        The states' full scales.
    guess : dict
        The initial guess (:func:`~ema_casadi.optimal.initial_guess`: ``T``, ``ecu``).
    """
    m = prob.model
    power = prob._power_outputs()
    T = guess["T"] if prob.objective == "time" else prob.duration
    res, fr = guess["ecu"], prob.fractions()

    def start(tau):  # the collocation states' guess: the ECU's step (the guess's run) at their times
        t = T * (fr[:-1] + np.diff(fr) * tau)
        return np.array([np.interp(t, res.t, res[n]) for n in m.states])

    def integrand(y):
        return sum(y[m.yindex(n), :] for n in power)

    X_next, q, pts = layer_collocation(opti, prob._rates, Xs, C, dts, scale, free=_free(prob),
                                       integrand=integrand if power else None, start=start, degree=DEGREE)
    return X_next, ca.sum2(q) if power else 0, pts


def widened(prob) -> list:
    """The parameter vectors of the continuation's first solves (:data:`WIDENED`: each
    declared width wider than the model's own, in turn); [] where the model declares none."""
    names = prob.model.param_names
    out = []
    for value in WIDENED:
        p = np.array(prob.p, float)
        for n, w in prob.model.small_signal(switch_width=value).items():
            i = names.index(n)
            p[i] = w if 0 < p[i] < w else p[i]
        if not np.array_equal(p, prob.p):
            out.append(p)
    return out


def _free(prob) -> list:
    """The states the collocation equations integrate (not a memory state at rest on its signal)."""
    rest_on = prob.model.rest_states(prob.p)
    return [i for i, n in enumerate(prob.model.states) if n not in rest_on]
