"""Pitch responses of the aircraft loop with the nonlinear EMA: theta_cmd steps and a
vertical 1-cosine gust (docs: aircraft)."""

from __future__ import annotations

import math

import numpy as np

from ..linearisation import OperatingPoint
from ..model.assembly import Model
from ..signals import Signal, constant
from ..simulation import simulate, step_response_metrics
from ._conditions import condition_overrides

__all__ = ["one_minus_cosine", "pitch_step", "gust_response", "RESPONSE_SIGNALS"]

#: Roles of the signals a response reports (those the model has), under the model's names:
#: pitch attitude, rate and angle of attack, load factor, elevator and its command, the
#: rod command and position, the surface load on the rod, the motor current.
RESPONSE_SIGNALS = ("pitch_attitude", "pitch_rate", "angle_of_attack", "load_factor", "elevator", "elevator_command",
                    "rod_command", "rod_position", "surface_load", "motor_current")


def one_minus_cosine(amplitude: float, duration: float, t0: float = 1.0, points: int = 200) -> Signal:
    """A discrete 1-cosine gust: (amplitude/2)(1 - cos(2 pi (t - t0)/duration)) for
    t0 <= t <= t0 + duration, zero elsewhere (a table, linear between ``points`` samples).

    Parameters
    ----------
    amplitude : float
        Peak gust velocity (m/s, up positive).
    duration : float
        Gust length in time, 2H/V for a gradient distance H (s).
    t0 : float
        Start (s).
    points : int
        Table samples over the gust.
    """
    t = np.linspace(0.0, duration, points)
    v = 0.5 * amplitude * (1 - np.cos(2 * math.pi * t / duration))
    return Signal.table(t0 + t, v)  # held at 0 before and after


def _params(model: Model, condition: str, overrides: dict):
    """The run's parameters: the condition's, then the overrides (an unknown name is a TypeError)."""
    return model.p(**{**condition_overrides(condition), **overrides})


def _run(model: Model, op: OperatingPoint, p, t_end: float, dt: float, dt_out: float, zoh: bool, **signals):
    """The nonlinear run from the trim (real friction and backlash, loops closed)."""
    fixed = {n: float(op.u[model.inputs.index(n)]) for n in op.policy.get("trim_free", {})}
    fixed.update(signals)
    res = simulate(model, t_end, dt=dt, dt_out=dt_out, p=p, x0=op.x, zoh=zoh, **fixed)
    shown = [n for role in RESPONSE_SIGNALS for n in model.signals_with(role)]
    return {"t": res.t, **{n: np.asarray(res[n]) for n in dict.fromkeys(shown)},
            "wall_time_s": res.info["wall_time"]}


def pitch_step(model: Model, op: OperatingPoint, condition: str = "cruise_sl", step: float = math.radians(1.0), *,
               t_end: float = 20.0, t_step: float = 1.0, dt: float = 1e-4, dt_out: float = 1e-2, zoh: bool = False,
               **overrides) -> dict:
    """theta_cmd step from the trim; the series and the step metrics of theta.

    Parameters
    ----------
    model : Model
    op : OperatingPoint
        The trim (:func:`~ema_casadi.aircraft.aircraft_point`).
    condition : str
        The flight condition the trim was made at.
    step : float
        Attitude step (rad).
    t_end, t_step, dt, dt_out : float
        Run length, step time, RK4 step, kept sample spacing (s).
    zoh : bool
        Sampled flight-control computer (80 Hz) and ECU.
    **overrides : float
        Flat parameter values (SI), e.g. ``B`` or ``K_i_x``.
    """
    p = _params(model, condition, overrides)
    att, theta = model.input_with("attitude_command"), model.signal_with("pitch_attitude")
    th0 = float(op.u[model.inputs.index(att)])
    out = _run(model, op, p, t_end, dt, dt_out, zoh, **{att: Signal.step(step, t_step) + constant(th0)})
    on = out["t"] >= t_step
    out["metrics"] = None
    if on.sum() > 1:
        th_start = float(out[theta][np.argmax(on)])
        out["metrics"] = step_response_metrics(out["t"][on] - t_step, (out[theta][on] - th_start) / step)
    return out


def gust_response(model: Model, op: OperatingPoint, condition: str = "cruise_sl", amplitude: float = 5.0,
                  duration: float = 1.0, *, t_end: float = 20.0, t0: float = 1.0, dt: float = 1e-4,
                  dt_out: float = 1e-2, zoh: bool = False, **overrides) -> dict:
    """Response to a vertical 1-cosine gust from the trim; the series and the peaks.

    Parameters
    ----------
    model : Model
    op : OperatingPoint
        The trim.
    condition : str
        Its flight condition.
    amplitude, duration, t0 : float
        Gust peak (m/s), length (s) and start (s).
    t_end, dt, dt_out : float
        Run length, RK4 step, kept sample spacing (s).
    zoh : bool
        Sampled flight-control computer and ECU.
    **overrides : float
        Flat parameter values (SI).
    """
    p = _params(model, condition, overrides)
    att = model.input_with("attitude_command")
    th0 = float(op.u[model.inputs.index(att)])
    out = _run(model, op, p, t_end, dt, dt_out, zoh,
               **{model.input_with("gust"): one_minus_cosine(amplitude, duration, t0), att: th0})
    theta, n_z, F_surf = (model.signal_with(r) for r in ("pitch_attitude", "load_factor", "surface_load"))
    out["peaks"] = {"theta_dev_rad": float(np.max(np.abs(out[theta] - op.state(theta)))),
                    "n_z_dev": float(np.max(np.abs(out[n_z] - op.output(n_z)))),
                    "F_surf_rod_max_N": float(np.max(np.abs(out[F_surf])))}
    return out
