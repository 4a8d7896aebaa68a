"""``optimal_move``: the problem, its solution, the ECU's own step and the replay."""

from __future__ import annotations

import math

import numpy as np

from ..model.assembly import Model
from ..signals import Signal
from ..simulation import RunFailed, simulate, step_response_metrics
from ._envelope import check_capacity
from ._errors import Infeasible, Unresolved
from ._problem import BINDING, INTERVALS, Problem, _margins, check_request, solve
from ._result import STAIR, OptimalMove
from ._shaping import shape_command

__all__ = ["optimal_move", "replay_window", "settling_time"]

#: A replay's peak within this fraction above its limit is on it (the FOC's clip at the voltage circle
#: lands there to floating-point rounding).
ROUNDING = 1e-9


def optimal_move(model: Model, move: float, *, load: float = 0.0, objective: str = "time",
                 duration: float | None = None, start: float = 0.0, through: str = "drive",
                 intervals: int = INTERVALS, field_weakening: bool = False, replay: bool = True,
                 zoh: bool = False, method: str = "auto") -> OptimalMove:
    """The optimal move of the actuator within the limits its parts declare.

    Direct multiple shooting (:func:`~ema_casadi.simulation.interval_function`, RK4
    substeps inside RK4's stability limit, exact derivatives) or, where the RK4 chain
    would be too long for the exact Hessian (a stiff configuration: under load), direct
    collocation (Radau IIA of degree 3 on the same grid), on the model's smooth
    variant (:meth:`~ema_casadi.model.assembly.Model.smooth`: smooth friction, the
    averaged bridge, smooth limits) with the backlash closed, solved by IPOPT. The
    constraints are the model's operating limits
    (:meth:`~ema_casadi.model.assembly.Model.operating_limits`: the current limit, the
    voltage circle, the stroke, the rated rod speed, the rated temperatures), at every
    node; the move starts at rest at the operating point of ``start`` under ``load`` and
    ends at rest at ``start + move``.

    Parameters
    ----------
    model : Model
        The actuator (from :func:`~ema_casadi.model.assembly.build_model`).
    move : float
        The move (m), signed.
    load : float
        Constant external rod force (N), positive pushes the rod in.
    objective : {"time", "energy", "heat"}
        Minimise the move's duration, the energy drawn from the DC link, or the heat
        into the winding (J); ``energy`` and ``heat`` need ``duration``.
    duration : float, optional
        The move's duration (s) for ``energy`` and ``heat``.
    start : float
        Start position of the rod (m).
    through : {"drive", "ecu"}
        The control: ``drive``, the innermost loop's held outputs (the motor voltages):
        the drive's capability; ``ecu``, the rod command with the cascade in the loop:
        a command profile for the real ECU.
    intervals : int
        Shooting intervals (a cosine-clustered grid for ``time``, uniform otherwise).
    field_weakening : bool
        Lift the drive strategy's limits (the FOC's i_d >= 0): the physical bound with
        field weakening, above the commissioned drive's.
    replay : bool
        Replay the command profile in the full model (:attr:`OptimalMove.replay`) and
        run the ECU's own step of the same size beside it.
    zoh : bool
        Replay with the sampled ECU (RK4 at the simulation's step).
    method : {"auto", "shooting", "collocation"}
        The transcription (``through="drive"``): ``auto`` shoots where intervals x RK4
        substeps is at most :data:`~ema_casadi.optimal._problem.EXPAND_LIMIT` (400) and
        collocates above (docs: optimal-control, *Transcription*).

    Returns
    -------
    OptimalMove
        The optimum, its command profile, the ECU's step and the replay.

    Raises
    ------
    OptimalError
        A request that cannot be a move (checked before any work).
    Infeasible
        IPOPT found no move within the limits (the message names the binding one).
    Unresolved
        With ``replay``: an optimum that does not answer the question (a minimum time
        slower than the ECU's own step: too few ``intervals``; a move the closed loop
        does not resolve: too small a ``move``); the message names the fix.
    """
    move, load, objective, duration, start, through, intervals = check_request(
        model, move, load, objective, duration, start, through, intervals, method)
    prob = Problem(model, move, load, objective, duration, start, through, intervals, bool(field_weakening),
                   method=method)
    if load * move > 0:  # the load opposes the move: can the drive move against it at all?
        check_capacity(prob)
    if duration is not None:
        _check_duration(prob)
    if through == "ecu":
        sol = shape_command(prob)
        sol["margins"] = _margins(prob, sol["X"], sol["Y"])
    else:
        sol = solve(prob)
    m = prob.model
    cost = sol["cost"]
    controls = {(m.holds[i].name if through == "drive" else m.inputs[i]): sol["C"][j]
                for j, i in enumerate(prob.controls)}
    res = OptimalMove(
        objective=objective, through=through, move=move, load=load, start=start, duration=sol["T"], cost=cost,
        t=sol["t"], states=dict(zip(m.states, sol["X"], strict=True)),
        outputs=dict(zip(m.outputs, sol["Y"], strict=True)), controls=controls, limits=prob.limits,
        margins=sol["margins"], binding=[k for k, v in sol["margins"].items() if v < BINDING],
        profile=sol.get("profile"),
        ipopt={"solver": "grid + bounded search" if through == "ecu" else "IPOPT",
               "status": sol["status"], "iterations": sol["iterations"], "solve_time_s": sol["solve_time_s"],
               "setup_time_s": sol["setup_time_s"], "intervals": intervals, "substeps": sol["substeps"],
               "method": sol.get("method", "shaping"),
               "solver_warnings": sol["warnings"],
               **({k: sol[k] for k in ("overshoot", "t_return")} if through == "ecu" else {})},
        variants=dict(m.variants), rod=prob.rod, command=prob.cmd, _units=m.units,
        rating_signals={r.name: r.signals for r in prob.ratings},
    )
    if replay:
        _replay(model, res, zoh)
        check_resolved(model, res)
    return res


#: The band of the settling times the checks compare (a fraction of the move).
BAND = 0.02


def check_resolved(model: Model, res: OptimalMove) -> None:
    """:class:`Unresolved` where the replayed optimum does not answer the question.

    * The ECU's own step of the move never enters the 2 % band: the closed loop does
      not resolve a move this small (the rod position sensor's step, friction); the
      message gives where the loop leaves the rod and the move whose band is twice that.
    * A minimum-time move through the drive is slower than the ECU's own step (the
      drive with the voltages free can always do what its ECU does): the grid is too
      coarse for the move; the message asks for twice the intervals, at least the
      default.
    * A minimum-time move whose replay never enters the band: no answer to replay.

    Parameters
    ----------
    model : Model
        The model the move was solved and replayed on.
    res : OptimalMove
        The replayed optimum (:attr:`OptimalMove.replay_check` set).
    """
    from ..signals import format_quantity

    size = format_quantity(abs(res.move), "m")
    settle = res.ecu_step["settling_time_s"]
    if not math.isfinite(settle):
        # where the loop leaves the rod (friction, the position sensor's step): the last fifth of the step
        step = res.ecu_step["result"]
        rest = float(np.abs(step[model.output_with("rod_position")][step.t >= 0.8 * step.t[-1]]
                            - (res.start + res.move)).max())
        raise Unresolved(f"move {size}: below what the closed loop resolves: the ECU's own step of this size rests "
                         f"{format_quantity(rest, 'm')} from the target, outside its 2 % band "
                         f"({format_quantity(BAND * abs(res.move), 'm')}); give a move of at least "
                         f"{format_quantity(2 * rest / BAND, 'm')} (a band of twice that)")
    if res.objective != "time":
        return
    N = res.ipopt["intervals"]
    if res.through == "drive" and res.duration > settle:
        raise Unresolved(f"intervals {N}: too coarse for a {size} move: its minimum time {res.duration:.4g} s is "
                         f"slower than the ECU's own step ({settle:.4g} s into the 2 % band); give intervals "
                         f"{max(2 * N, INTERVALS)} or more")
    replayed = (res.replay_check or {}).get("settling_time_s")
    if replayed is not None and not math.isfinite(replayed):
        raise Unresolved(f"move {size}: the optimum's command profile, replayed in the full model, never enters "
                         f"the 2 % band (the ECU's own step does, after {settle:.4g} s)")


def _check_duration(prob: Problem) -> None:
    """A fixed duration below the minimum time: refused with the minimum time (a
    minimum-time solve, so after some work, but before anything is written)."""
    from ._errors import OptimalError

    fastest = Problem(prob.full, prob.move, prob.load, "time", None, prob.start, prob.through, prob.N,
                      prob.field_weakening, method=prob.method)
    try:
        T_min = solve(fastest)["T"]
    except Infeasible:
        return
    if prob.duration < T_min:
        raise OptimalError(f"duration {prob.duration:g} s: below the minimum time of this move, {T_min:.5g} s")


def replay_window(res: OptimalMove, settle: float) -> float:
    """The replay's length (s): the move's duration for energy and heat (their
    comparison is over that window), else 1.5 x the longer of the move and the ECU's step.

    Parameters
    ----------
    res : OptimalMove
        The optimum.
    settle : float
        The ECU's step's 2 % settling time (s).
    """
    if res.objective != "time":
        return res.duration
    return 1.5 * max(res.duration, settle if math.isfinite(settle) else res.duration)


def settling_time(model: Model, sim, start: float, move: float, band: float = 0.02) -> float:
    """2 % settling time (s) of the rod position of a run of a move ``start -> start + move``.

    Parameters
    ----------
    model : Model
        The model the run is of.
    sim : SimResult
        The run.
    start, move : float
        The move's start and length (m).
    band : float
        The band, a fraction of the move.
    """
    y = (sim[model.output_with("rod_position")] - start) / move
    return step_response_metrics(sim.t, y, band)["settling_time_s"]


def _replay(model: Model, res: OptimalMove, zoh: bool) -> None:
    """The ECU's own step and the command profile, both in the full model."""
    load_name = model.input_with("load")
    kw = {"from_trim": True, "zoh": zoh, "dt_out": 1e-4}
    t_step = max(res.duration * 3, 0.1)
    # at the start at t = 0 (the trim), the step STAIR later
    step_cmd = Signal.step(res.start, 0.0) + Signal.step(res.move, STAIR)
    step = simulate(model, t_step, inputs={res.command: step_cmd, load_name: res.load}, **kw)
    settle = settling_time(model, step, res.start, res.move)
    window = replay_window(res, settle)
    if window < t_step and res.objective != "time":
        step = simulate(model, window, inputs={res.command: step_cmd, load_name: res.load}, **kw)
    res.ecu_step = {"settling_time_s": settle, "t": step.t, "rod": step[model.output_with("rod_position")],
                    "result": step}
    try:
        sim = simulate(model, window, inputs={res.command: res.command_signal(), load_name: res.load}, **kw)
    except RunFailed as exc:
        res.replay_check = {"failed": exc.reason}
        return
    res.replay = sim
    res.replay_check = _check(model, res, sim, settle)


def _peak(r, s) -> float:
    """A rating's extreme over a run (rows: its signals)."""
    if r.sense == "norm":
        return float(np.sqrt((s**2).sum(0)).max())
    return float(s[0].max()) if r.sense == "max" else float(s[0].min())


def _check(model: Model, res: OptimalMove, sim, settle_step: float) -> dict:
    """Per rating, the replay's peak against the limit; the settling time; the energies."""
    P = model.pdict()
    out: dict = {"ratings": {}}
    step = res.ecu_step["result"]
    for r in model.ratings:
        if not all(n in sim.columns() for n in r.signals):
            continue
        lim = float(r.limit(P))
        peak, peak_step = (_peak(r, np.array([run[n] for n in r.signals])) for run in (sim, step))
        within = peak <= lim * (1 + ROUNDING) if r.sense != "min" else peak >= lim - ROUNDING * abs(lim)
        # role "strategy": how the ECU runs its drive (i_d = 0 commanded), not a limit of the actuator; the
        # replay's signal is what the ECU's loops make of it (its FOC's voltage clip lets i_d follow a little)
        out["ratings"][r.name] = {"peak": peak, "limit": lim, "unit": r.unit, "within": bool(within),
                                  "role": r.role, "ratio": peak / lim if lim else None, "ecu_step_peak": peak_step}
    out["settling_time_s"] = settling_time(model, sim, res.start, res.move)
    out["ecu_step_settling_time_s"] = settle_step
    power = model.output_with("electrical_power")
    E, E_step = sim.energies(), res.ecu_step["result"].energies() if "result" in res.ecu_step else {}
    out["window_s"] = float(sim.t[-1])
    out["link_energy_J"] = E.get(power)
    out["ecu_step_link_energy_J"] = E_step.get(power) if float(res.ecu_step["t"][-1]) == float(sim.t[-1]) else None
    heat = model.heat_outputs("winding")
    out["winding_heat_J"] = sum(E[n] for n in heat if n in E)
    return out
