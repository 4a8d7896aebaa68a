"""The aircraft loop at the actuator-command break: ideal and linearised-EMA loop
transfers, margins (frequency.margins) and the equivalent time delay (docs: aircraft)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .._util._notebook import Summarised
from ..frequency import freqresp, margins
from ..linearisation import LinearModel, OperatingPoint, flight_point, linear_model, loop_model
from ..model.assembly import Model
from ._conditions import condition_overrides

__all__ = ["aircraft_point", "ideal_loop", "ema_loop", "equivalent_delay", "aircraft_margins", "AircraftMargins",
           "DELAY_BAND_RAD_S"]

#: Band of the equivalent-system match (rad/s), MIL-STD-1797A: 0.1 to 10 rad/s.
DELAY_BAND_RAD_S = (0.1, 10.0)
#: Crossover search window of the aircraft loop (Hz).
F_WINDOW = (1e-3, 200.0)


def aircraft_point(model: Model, condition: str = "cruise_sl", **overrides) -> OperatingPoint:
    """Trim of the whole loop at a flight condition (:data:`~ema_casadi.aircraft.CONDITIONS`).

    Parameters
    ----------
    model : Model
        A model with an airframe.
    condition : str
        Flight condition name.
    **overrides : float
        Further flat parameter values (SI), e.g. ``B=1e-4``.
    """
    p = model.p(**{**condition_overrides(condition), **overrides})
    return flight_point(model, p=p)


def _airframe_states(model: Model) -> list[int]:
    names = [s.name for part in model.parts if part.family == "airframe" for s in part.states]
    return [model.index(n) for n in names]


def ema_loop(model: Model, op: OperatingPoint) -> LinearModel:
    """L(s) at the actuator command with the linearised EMA (``loop_model`` of ``aircraft``).

    Parameters
    ----------
    model : Model
    op : OperatingPoint
        From :func:`aircraft_point`.
    """
    return loop_model(model, "aircraft", op)


def ideal_loop(model: Model, op: OperatingPoint) -> LinearModel:
    """L(s) at the actuator command with an ideal actuator: the rod at x_cmd exactly.

    From the same Jacobian: the airframe block A_aa, driven through the columns of the
    actuator's position-like states at one metre of rod travel (what an ideal rod
    standing at x_cmd means for every state the airframe reads).

    Parameters
    ----------
    model : Model
    op : OperatingPoint
        From :func:`aircraft_point`.
    """
    brk = model.loops["aircraft"]  # the loop break: its injection and the law's rod command
    lin = linear_model(model, op, open_loops=["aircraft"], inputs=[brk.injection], outputs=[brk.measured])
    ia = _airframe_states(model)
    ie = [i for i in range(model.nx) if i not in ia]
    travel = model.travel(op.p)
    t = np.array([1.0 / travel[model.states[i]] if model.states[i] in travel else 0.0 for i in ie])
    A = lin.A[np.ix_(ia, ia)]
    b = lin.A[np.ix_(ia, ie)] @ t
    c = lin.C[0, ia]
    d = float(lin.C[0, ie] @ t)
    return LinearModel(A=A, B=b[:, None], C=-c[None, :], D=np.array([[-d]]),
                       states=tuple(model.states[i] for i in ia), inputs=(model.output_with("rod_position"),),
                       outputs=(f"-{brk.measured}",),
                       op=op, name="L_aircraft_ideal", open_loops=("aircraft",))


def equivalent_delay(L_ideal, L_ema, band=DELAY_BAND_RAD_S, points: int = 100,
                     f_crossover: float | None = None) -> dict:
    """The time delay the actuator adds, phase-matched (MIL-STD-1797A equivalent system).

    The actuator's effect is T(jw) = L_ema/L_ideal; its phase is fitted by -w tau in the
    least-squares sense over ``band`` (log-spaced), and also matched at the ideal
    loop's gain crossover.

    Parameters
    ----------
    L_ideal, L_ema : LinearModel
        The two loop transfers.
    band : (float, float)
        Fit band (rad/s).
    points : int
        Log-spaced frequencies in the band.
    f_crossover : float, optional
        The ideal loop's gain crossover (Hz), when already known (default: from its margins).
    """
    w = np.geomspace(band[0], band[1], points)
    T = freqresp(L_ema, w / (2 * math.pi))[0, 0] / freqresp(L_ideal, w / (2 * math.pi))[0, 0]
    phi = np.unwrap(np.angle(T))
    tau = float(-(w @ phi) / (w @ w))
    gain_db = 20 * np.log10(np.abs(T))
    fit_err = float(np.degrees(np.max(np.abs(phi + w * tau))))
    out = {"tau_s": tau, "band_rad_s": list(band), "max_fit_error_deg": fit_err,
           "gain_db_min": float(gain_db.min()), "gain_db_max": float(gain_db.max())}
    fc = margins(L_ideal, f_min=F_WINDOW[0], f_max=F_WINDOW[1]).f_gc_hz if f_crossover is None else f_crossover
    if fc is not None:
        Tc = freqresp(L_ema, [fc])[0, 0, 0] / freqresp(L_ideal, [fc])[0, 0, 0]
        out.update(tau_at_crossover_s=float(-np.angle(Tc) / (2 * math.pi * fc)), f_crossover_hz=fc)
    return out


@dataclass(repr=False)
class AircraftMargins(Summarised):
    """Margins at the actuator-command break, ideal actuator and linearised EMA.

    Parameters
    ----------
    condition : str
        The flight condition.
    ideal, ema : LoopMargins
        Margins with an ideal actuator and with the linearised EMA.
    delay : dict
        The EMA's equivalent delay (:func:`equivalent_delay`).
    trim : dict
        Trim values: the free inputs, delta_e (deg), x_cmd (m), the surface load on the rod (N).
    """

    condition: str
    ideal: object
    ema: object
    delay: dict
    trim: dict = field(default_factory=dict)

    def _facts(self) -> dict:
        def m(x):
            return f"GM {x.gm_db:.3g} dB, PM {x.pm_deg:.3g} deg"

        return {"condition": self.condition, "ideal": m(self.ideal), "ema": m(self.ema),
                "delay": f"{self.delay.get('tau_s', float('nan')) * 1e3:.3g} ms"}

    def as_dict(self) -> dict:
        return {"condition": self.condition, "trim": self.trim, "ideal": self.ideal.as_dict(),
                "ema": self.ema.as_dict(), "delay": self.delay}


def aircraft_margins(model: Model, condition: str = "cruise_sl", op: OperatingPoint | None = None,
                     **overrides) -> AircraftMargins:
    """Trim, both loop transfers, their margins and the EMA's equivalent delay.

    Parameters
    ----------
    model : Model
        A model with an airframe.
    condition : str
        Flight condition (:data:`~ema_casadi.aircraft.CONDITIONS`).
    op : OperatingPoint, optional
        A trim already made (then ``condition`` is a label).
    **overrides : float
        Flat parameter values (SI) on top of the condition's.
    """
    op = op if op is not None else aircraft_point(model, condition, **overrides)
    Li, Le = ideal_loop(model, op), ema_loop(model, op)
    mi = margins(Li, f_min=F_WINDOW[0], f_max=F_WINDOW[1], loop="aircraft (ideal actuator)")
    me = margins(Le, f_min=F_WINDOW[0], f_max=F_WINDOW[1], loop="aircraft (EMA)")
    trim = {**op.policy.get("trim_free", {}), "delta_e_deg": math.degrees(op.output(model.output_with("elevator"))),
            "x_cmd_m": op.x_cmd, "F_surf_rod_N": op.output(model.output_with("surface_load"))}
    return AircraftMargins(condition, mi, me, equivalent_delay(Li, Le, f_crossover=mi.f_gc_hz), trim)
