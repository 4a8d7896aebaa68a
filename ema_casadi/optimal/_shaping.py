"""Command shaping through the ECU (``through="ecu"``): the rod command that brings the
rod into the target's 2 % band soonest with the cascade in the loop.

The command is an overshoot-and-return profile: from the start the command sits
``overshoot`` x the move beyond the target (the position loop's speed command stays at
its rate limit longer than a step's, whose proportional tail creeps into the band),
and at ``t_return`` it steps back to the target (the speed loop brakes at its current
limit). The two parameters are found on the smooth variant by a grid over both and a
bounded scalar search on ``t_return`` for the best overshoot, the objective the 2 %
settling time of the run itself (the same function the replay is judged by).

Why not the multiple-shooting NLP of the drive level: the FOC's voltage limit is the
hard linear-SVPWM circle in every variant (``fmin(1, v_lim/|v|)``), and every fast move
through the cascade drives its current loop into it (a current step of 5 A already asks
for more than the circle). IPOPT on that non-smooth chain stalled at a local
infeasibility of the continuity constraints (10 mm: 85 iterations, 4e-3) or ran into the
iteration limit; the settling time of a run is what the acceptance judges, and a
derivative-free search over a two-parameter command is robust to the kink.
"""

from __future__ import annotations

import math
import time

import numpy as np
from scipy.optimize import minimize_scalar

from ..signals import Signal
from ..simulation import simulate, step_response_metrics
from ._problem import Problem
from ._result import STAIR

__all__ = ["shape_command", "OVERSHOOTS", "BAND"]

#: The overshoots tried (fractions of the move beyond the target), within the stroke.
OVERSHOOTS = (0.05, 0.1, 0.2, 0.5)
#: The settling band the command is shaped for (a fraction of the move).
BAND = 0.02
#: Output spacing of the runs the search judges, as a fraction of the ECU step's settling time.
SPACING = 1 / 2000


def _profile(prob: Problem, overshoot: float, t_return: float) -> tuple[np.ndarray, np.ndarray]:
    hi = prob.target + overshoot * prob.move
    return (np.array([0.0, STAIR, t_return, t_return + STAIR]),
            np.array([prob.start, hi, hi, prob.target]))


def _run(prob: Problem, x0, t_end, dt_out, profile):
    return simulate(prob.model, t_end, p=prob.p, x0=x0, dt_out=dt_out,
                    inputs={prob.cmd: Signal.table(*profile), prob.load_input: prob.load, **prob.extra})


def _settle(prob: Problem, res) -> float:
    y = (res[prob.model.output_with("rod_position")] - prob.start) / prob.move
    return step_response_metrics(res.t, y, BAND)["settling_time_s"]


def shape_command(prob: Problem) -> dict:
    """The shaped command of ``prob`` (``through="ecu"``, ``objective="time"``): the raw
    solution as :func:`~ema_casadi.optimal.solve` returns it (``T`` the 2 % settling time
    on the smooth variant, ``X``, ``Y`` the run's states and outputs at ``t``, ``C`` the
    command on each output interval, ``profile`` the command's table rows).

    Parameters
    ----------
    prob : Problem
        The problem (its smooth model, start, target, load).
    """
    t0 = time.perf_counter()
    x0 = prob.start_state()
    t_try = 0.05
    for _ in range(8):  # a window the ECU's own step settles in, with room after it
        step = prob._ecu_step(t_try, x0)
        settle = _settle(prob, step)
        if math.isfinite(settle) and settle < 0.7 * t_try:
            break
        t_try *= 2
    t_end = t_try
    dt_out = settle * SPACING
    stroke = prob.limits["stroke"]
    room = (stroke - abs(prob.target)) / abs(prob.move) if abs(prob.target) < stroke else 0.0
    overshoots = [a for a in OVERSHOOTS if a <= room] or [room]
    evals = 0

    def cost(a, t1):
        nonlocal evals
        evals += 1
        return _settle(prob, _run(prob, x0, t_end, dt_out, _profile(prob, a, t1)))

    setup = time.perf_counter() - t0
    grid = np.linspace(0.3, 1.0, 15) * settle
    trials = [(cost(a, t1), a, t1) for a in overshoots for t1 in grid]
    best, a, t1 = min(trials)
    # refine the return time around the best grid point for that overshoot
    h = grid[1] - grid[0]
    opt = minimize_scalar(lambda s: cost(a, s), bounds=(max(t1 - h, STAIR * 10), t1 + h), method="bounded",
                          options={"xatol": dt_out})
    if opt.fun < best:
        best, t1 = float(opt.fun), float(opt.x)
    profile = _profile(prob, a, t1)
    res = _run(prob, x0, t_end, t_end / 400, profile)  # the optimum kept on 400 intervals
    m = prob.model
    X = np.array([res[n] for n in m.states])
    Y = np.array([res[n] for n in m.outputs])
    C = np.interp(res.t[:-1], profile[0], profile[1])[None, :]
    status = "Shaped" if best < settle else "No_Better_Than_Step"
    return {"T": best, "X": X, "C": C, "Y": Y, "t": res.t, "status": status, "iterations": evals,
            "solve_time_s": time.perf_counter() - t0 - setup, "setup_time_s": setup, "cost": best, "warnings": 0,
            "x0": x0, "substeps": None, "profile": profile, "overshoot": a, "t_return": t1,
            "smooth_step_settling_time_s": settle}
