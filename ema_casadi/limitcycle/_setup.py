"""Where a describing-function analysis starts, per loop break, and its confirming run.

``position``: the actuator at rest (the model's initial state), the break signal x_rod;
confirmed by a 1 mm command step held (the hunting study's scenario). ``aircraft``: the
whole loop trimmed at a flight condition (:func:`~ema_casadi.aircraft.aircraft_point`),
the break at the actuator command; confirmed by a return-to-trim attitude pulse (+0.5 deg
from 1 s to 3 s, then the trim command again), so that the run settles into its cycle
about the operating point the describing function is computed at.
"""

from __future__ import annotations

import math

import numpy as np

from ..model.assembly import Model
from ..signals import Signal
from ..simulation import simulate
from ._df import cycle_of

__all__ = ["LOOP_SETUPS", "setup", "confirm_cycle"]

LOOP_SETUPS = ("position", "aircraft")


def _position(model: Model, p, condition):
    def confirm(t_end, dt, **held):
        cmd = model.input_with("command")
        return simulate(model, t_end, dt=dt, dt_out=max(dt, 1e-4), p=p, **{cmd: Signal.step(1e-3, 0.01), **held})

    return {"p": p, "x0": model.x0(), "inputs": {}, "meas0": 0.0, "confirm": confirm,
            "signal": model.output_with("rod_position")}


def _aircraft(model: Model, p, condition):
    from ..aircraft import aircraft_point, condition_overrides

    names = list(model.param_names)
    base = model.p(**condition_overrides(condition))
    given = {n: float(v) for n, v, b in zip(names, p, model.p(), strict=True) if v != b}
    pv = base.copy()
    for n, v in given.items():
        pv[names.index(n)] = v
    op = aircraft_point(model, condition, **given)
    inputs = {n: float(op.u[model.inputs.index(n)]) for n in op.policy["trim_free"]}
    meas0 = op.output(model.output_with("law_command"))

    def confirm(t_end, dt, **held):
        att = model.input_with("attitude_command")
        th0, kick = inputs[att], math.radians(0.5)
        pulse = Signal.step(th0, 0.0) + Signal.step(kick, 1.0) + Signal.step(-kick, 3.0)
        return simulate(model, t_end, dt=dt, dt_out=max(dt, 1e-3), p=pv, x0=op.x, **{**inputs, **held, att: pulse})

    return {"p": pv, "x0": op.x, "inputs": inputs, "meas0": meas0, "confirm": confirm,
            "signal": model.output_with("rod_command"), "op": op}


def setup(model: Model, loop: str, p=None, condition: str = "cruise_sl") -> dict:
    """Parameter vector, initial state, fixed inputs, the break signal's operating value,
    ``confirm(t_end, dt, **inputs) -> SimResult`` (the closed-loop run, other inputs held
    at the values given) and ``signal`` (the name of
    the break signal in it) for a loop.

    Parameters
    ----------
    model : Model
    loop : {"position", "aircraft"}
    p : ndarray, optional
        Parameter vector (default the model's); for ``aircraft`` its values differing
        from the model's are applied on top of the flight condition.
    condition : str
        Flight condition (``aircraft``).
    """
    fn = {"position": _position, "aircraft": _aircraft}[loop]
    return fn(model, model.p() if p is None else np.asarray(p, float), condition)


def confirm_cycle(s: dict, t_end: float, dt: float) -> dict:
    """The confirming closed-loop run, measured over its second half (:func:`cycle_of`).

    Parameters
    ----------
    s : dict
        From :func:`setup`.
    t_end, dt : float
        Run length and RK4 step (s).
    """
    res = s["confirm"](t_end, dt)
    return cycle_of(res.t, np.asarray(res[s["signal"]]), t_end / 2)
