"""Running a mission on the full model: compiled RK4 at the hybrid-friction step,
block by block (progress, envelope checks), the kept samples reduced to the signals a
mission reports."""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from .._util._errors import RunError
from ..model.assembly import Model, build_model
from ..model.components import SIGNAL_KEYS, node_outflow
from ..model.params import Parameters
from ..simulation import (
    STEPS_PER_CALL,
    RunFailed,
    SimulationError,
    check_run,
    choose_solver,
    inside_limit,
    progress_bar,
    simulate,
    trimmed_start,
)
from ._profile import MISSION_VARIANTS, Mission, MissionError, load_mission
from ._result import MissionResult

__all__ = ["MissionFailed", "run_mission", "KEPT", "FULL_DT", "FAST_DT", "HEAT_RESIDUAL_TOL"]

#: The full model's largest step (s): the hybrid friction's (docs: friction-and-endstops);
#: a mission without ``dt`` runs at the largest step inside RK4's stability limit at its
#: largest load and at most this (:func:`~ema_casadi.simulation.inside_limit`).
FULL_DT = 1e-4
#: The fast path's step (s): the same model at twice the step. On the reference mission
#: its temperatures differ from the full model's by at most 0.16 K (docs: missions);
#: RK4 stays stable (the 1.42 kHz drive-train mode at |lambda h| = 1.8 < 2.8).
FAST_DT = 2e-4

#: Largest relative residual of the heat balance (losses = stored + to ambient) a
#: mission may report: the reference mission closes to 0.05 % (README "Missions"), a
#: 5 s mission to 3 % (the sampling of the losses' first seconds); 10 % is no answer.
HEAT_RESIDUAL_TOL = 0.1

#: Roles of the signals kept besides the losses, the temperature states and the heat flows
#: (the result knows them by role: :attr:`MissionResult.names`).
KEPT = ("command", "rod_position", "load", "ambient_temperature", "motor_current", "winding_resistance",
        "magnet_flux", "screw_efficiency", "electrical_power", "load_power", "ambient_heat", "thermal_energy",
        "stored_energy")


#: The input roles a mission segment drives (its keys: :data:`~ema_casadi.model.components.SIGNAL_KEYS`).
SEGMENT_ROLES = ("command", "load", "ambient_temperature")


class MissionFailed(RunError, RuntimeError):
    """The run left the physical envelope or the integration failed (not a converged answer)."""


def _model(params: Parameters, mission: Mission, variants: dict | None) -> Model:
    v = {**MISSION_VARIANTS, **mission.variants, **(variants or {})}
    model = build_model(params, v)
    if not model.states_with("temperature"):
        raise MissionError(f"{mission.source}: a mission needs the thermal network: variant thermal = lumped "
                           f"(got thermal = {model.variants.get('thermal')})")
    return model


def _rod_travel(model: Model) -> str:
    """The signal whose rate is the rod velocity v_rod (P_load = f_ext v_rod): the rod
    position state, or the nut position where that state is a play operator's output
    (the rigid screw's rod moves with the nut)."""
    rod = model.state_with("rod_position")
    return model.output_with("nut_position") if "play" in model.state_info[rod].roles else rod


def _blocks(t_total: float, dt: float, dt_out: float, block: float) -> list[tuple[float, float]]:
    """(start, length) of the simulated blocks: whole numbers of output samples, each at
    least one compiled chunk long (so every block reuses the same compiled rollout)."""
    n_total = int(math.ceil(t_total / dt_out - 1e-9))
    k = int(round(dt_out / dt))
    n_min = max(1, int(math.ceil(STEPS_PER_CALL / k)))
    n_blk = max(n_min, int(round(block / dt_out)))
    edges = list(range(0, n_total, n_blk)) + [n_total]
    if len(edges) > 2 and edges[-1] - edges[-2] < n_min:
        del edges[-2]  # a short last block joins the one before
    return [(a * dt_out, (b - a) * dt_out) for a, b in zip(edges, edges[1:], strict=False)]


def _progress(enabled: bool, frac: float, t: float, run: Mission, seg: str, T_w: float, wall: float) -> None:
    progress_bar(frac, enabled, "mission", f"{t:6.0f}/{run.duration:.0f} s  {seg[:18]:18s}  T_w {T_w:6.1f} degC  "
                                           f"{wall:5.1f} s")


def run_mission(params: Parameters, mission: Mission | str | Path, variants: dict | None = None, *,
                dt: float | None = None, dt_out: float = 0.01, block: float = 60.0, progress: bool = False,
                jit: bool = True, solver: str = "auto", from_trim: bool = False) -> MissionResult:
    """Run a mission on the full model (compiled RK4, every step at ``dt``).

    The mission is simulated in blocks of about ``block`` seconds of mission time, each
    continuing from the state where the previous one ended (the same trajectory as one
    long run); after each block the run is checked against the physical envelope and the
    progress is drawn on stderr.

    Parameters
    ----------
    params : Parameters
        The parameter set.
    mission : Mission, str or Path
        A mission, or its TOML file.
    variants : dict, optional
        Variant choices over the mission file's ``[model]`` table and the mission
        defaults (thermal = lumped, friction = hybrid, iron_loss = on).
    dt : float, optional
        RK4 step (s); default the largest step at most :data:`FULL_DT` (1e-4 s, the
        hybrid friction's step) inside RK4's stability limit on the mission's model at
        its largest load that divides ``dt_out``; :data:`FAST_DT`
        (2e-4 s) for the fast path.
    dt_out : float
        Spacing of the kept samples (s), a multiple of ``dt``; the energies are
        integrated from them.
    block : float
        Mission time per simulation call (s): the progress granularity.
    progress : bool
        Draw a progress line on stderr.
    jit : bool
        Compile the model to native code (cached on disk).
    solver : {"auto", "rk4", "rosenbrock", "cvodes"}
        As in :func:`~ema_casadi.simulation.simulate`; ``auto`` runs the compiled RK4 on
        the mission's model (hybrid friction sticks) and the compiled RODAS4 when the
        variants make it continuous. The choice is in ``info["solver"]``.
    from_trim : bool
        Start the mechanics and electrics at the operating point of the first
        segment's command and load (temperatures at the mission's start value).
    """
    if not isinstance(mission, Mission):
        mission = load_mission(mission, params)
    model = _model(params, mission, variants)
    if dt is None and all(isinstance(v, (int, float)) and math.isfinite(v) and v > 0 for v in (dt_out, block)):
        dt = _default_dt(model, mission, dt_out, block)
    for name, val in (("dt", dt), ("dt_out", dt_out), ("block", block)):
        if not (isinstance(val, (int, float)) and math.isfinite(val) and val > 0):
            raise MissionError(f"{name} must be a positive number of seconds, got {val!r}")
    k = dt_out / dt
    if abs(k - round(k)) > 1e-9 * k:
        raise MissionError(f"dt_out ({dt_out} s) must be a whole multiple of dt ({dt} s)")
    _check_size(model, mission, dt, dt_out, block)
    temps = model.states_with("temperature")
    losses = model.outputs_of("loss")
    heat = tuple(n for n in model.outputs if n.startswith("P_heat_"))
    nodes = {n: model.state_info[n].node for n in temps if model.state_info[n].node is not None}
    flows = tuple(node_outflow(node.name) for node in nodes.values())
    x_mech = _rod_travel(model)
    names = {role: model.signal_with(role) for role in KEPT}
    keep = tuple(dict.fromkeys((*temps, *losses, *heat, *flows, *names.values(), x_mech)))
    wall0 = time.perf_counter()
    t, series, info = _simulate_blocks(model, mission, keep, _blocks(mission.duration, dt, dt_out, block),
                                       dt=dt, dt_out=dt_out, jit=jit, progress=progress, solver=solver,
                                       from_trim=from_trim)
    series["x_mech"] = series[x_mech]
    info.update(wall_time=time.perf_counter() - wall0, variants=dict(model.variants), model=str(params.source))
    res = MissionResult(
        mission=mission, t=t, series=series, units={n: model.units.get(n, "") for n in keep}, losses=losses,
        owners={o: part.family for part in model.parts for o in (d.name for d in part.outputs) if o in losses},
        nodes={n: nodes[n].name if n in nodes else n for n in temps},
        capacity={n: float(node.capacity(model.pdict())) for n, node in nodes.items()},
        heat_of={n: node for part in model.parts for n, node in part.heat.items() if n in losses},
        P=model.pdict(), info=info, names=names)
    residual = res.heat_balance()["relative_residual"]
    if not abs(residual) <= HEAT_RESIDUAL_TOL:  # NaN too: heat not conserved is no answer
        raise MissionFailed(f"{mission.source}: the heat balance does not close: residual {100 * residual:+.3g} % "
                            f"of the losses, beyond the {100 * HEAT_RESIDUAL_TOL:g} % tolerance (HEAT_RESIDUAL_TOL)")
    return res


def _default_dt(model: Model, mission: Mission, dt_out: float, block: float) -> float:
    """A mission's RK4 step without ``dt`` (s): the largest step at most :data:`FULL_DT`
    under 0.8 x RK4's stability limit on ``model`` at the largest load of the mission
    and of each of its blocks (each block's run checks its own), dividing ``dt_out``
    where one does (:func:`~ema_casadi.simulation.inside_limit`).

    Parameters
    ----------
    model : Model
        The mission's model.
    mission : Mission
        The mission (its command, load and cavity temperature).
    dt_out, block : float
        The spacing of the kept samples and the mission time per block (s).
    """
    sig = {model.input_with(role): mission.signal(SIGNAL_KEYS[role]) for role in SEGMENT_ROLES}
    dt, last = inside_limit(model, sig, mission.duration, False, FULL_DT, (dt_out,)), None
    while dt != last:  # the blocks depend on the step (whole compiled chunks): until they agree
        last = dt
        for t0, length in _blocks(mission.duration, last, dt_out, block):
            shifted = {n: s.shifted(t0) for n, s in sig.items()}
            dt = min(dt, inside_limit(model, shifted, length, False, FULL_DT, (dt_out,)))
    return dt


def _check_size(model: Model, mission: Mission, dt: float, dt_out: float, block: float) -> None:
    """Before anything is built, a mistake (not a failed run): a segment too short to be
    sampled, a run above the simulation's step or memory limits (with the estimate)."""
    short = [s for s in mission.segments if s.duration < dt_out]
    if short:
        raise MissionError(f"{mission.source}: segment '{short[0].name}' lasts {short[0].duration:g} s, shorter than "
                           f"the sample spacing dt_out {dt_out:g} s: it would not be resolved")
    check_run(model, sum(n for _, n in _blocks(mission.duration, dt, dt_out, block)), dt=dt, dt_out=dt_out,
              labels={"t_end": f"{mission.source}: the mission's {mission.duration:g} s", "dt": "dt",
                      "dt_out": "dt_out"}, error=MissionError)


def _simulate_blocks(model: Model, mission: Mission, keep: tuple, blocks: list, *, dt: float, dt_out: float,
                     jit: bool, progress: bool, solver: str = "auto", from_trim: bool = False):
    """The blocks one after the other, each from where the previous one ended; the kept
    signals concatenated. Returns (t, series, info)."""
    temps = model.states_with("temperature")
    x = model.x0()
    for n in temps:
        x[model.index(n)] = mission.T_start
    sig = {model.input_with(role): mission.signal(SIGNAL_KEYS[role]) for role in SEGMENT_ROLES}
    if from_trim:
        x = trimmed_start(model, sig, model.p(), x)
    used, why = choose_solver(model, solver)
    chunks = {n: [] for n in keep}
    times, steps, switches, compile_time = [], 0, 0, 0.0
    wall0 = time.perf_counter()
    seg_names = [s.name for s in mission.segments]
    _progress(progress, 0.0, 0.0, mission, seg_names[0], mission.T_start, 0.0)
    for b, (t0, length) in enumerate(blocks):
        try:
            res = simulate(model, length, dt=dt, dt_out=dt_out, solver=used, x0=x, jit=jit,
                           **{n: s.shifted(t0) for n, s in sig.items()})
        except RunFailed as exc:  # the physical-envelope monitor of simulate()
            raise MissionFailed(f"{mission.source}: the run failed: {exc.what} at t = {t0 + exc.time:.6g} s") from None
        except SimulationError as exc:
            raise MissionFailed(f"{mission.source}: the run failed at {t0:.0f}...{t0 + length:.0f} s: {exc}") from None
        first = 0 if b == 0 else 1  # each block starts where the previous one ended
        times.append(t0 + res.t[first:])
        for n in keep:
            chunks[n].append(np.asarray(res[n], float)[first:])
        x = np.array([res.states[n][-1] for n in model.states])
        # RK4 steps; a switched (PWM) run counts carrier periods instead
        steps += res.info.get("steps") or res.info.get("carrier_periods", 0)
        switches += res.info.get("mode_switches") or 0
        if b == 0:  # the rollout is compiled (or loaded) once, by the first block
            compile_time = res.info.get("compile_time", 0.0)
        t_now = t0 + length
        seg = seg_names[min(int(np.searchsorted(mission.starts, t_now, side="right")) - 1, len(seg_names) - 1)]
        _progress(progress, (b + 1) / len(blocks), t_now, mission, seg, float(x[model.index(temps[0])]),
                  time.perf_counter() - wall0)
    info = {"solver": used, "solver_reason": why, "from_trim": from_trim, "dt": dt, "dt_out": dt_out,
            "steps": steps, "mode_switches": switches, "blocks": len(blocks),
            "compile_time": compile_time, "switched": bool(model.switched)}
    return np.concatenate(times), {n: np.concatenate(chunks[n]) for n in keep}, info
