"""The performance envelope: the top rod speed against each load and the largest force
held, by steady-state NLPs on the drive level; the minimum move time over distance by
minimum-time moves; at given soak temperatures (the ambient input of a thermal network)."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from .._util._checks import integer
from .._util._parallel import check_main_guard
from .._util._tasks import process_map
from ..model.assembly import Model, build_model
from ..optimisation import solve_ipopt
from ._errors import Infeasible, OptimalError
from ._problem import Problem, _margins, solve
from ._request import MAX_INTERVALS

__all__ = ["performance_envelope", "Envelope", "check_capacity", "CREEP"]

#: A steady speed against a load below this fraction of the rated rod speed is no move: the creep of the
#: smooth counterpart's screw lock (a blend; the self-locking screw itself stands still), e.g. 3.9 um/s
#: against 49 kN on the reference, where K_t I_max eta 2 pi/p = 48.9 kN is all the motor drives.
CREEP = 1e-3


@dataclass
class Envelope:
    """The performance envelope (:func:`performance_envelope`).

    Attributes
    ----------
    temperatures : list
        Soak temperatures (degC; None: the parameter set's resistance and flux).
    loads : ndarray
        Loads opposing the move (N).
    top_speed : dict
        Temperature -> top rod speed (m/s) against each load (nan where not held).
    largest_force : dict
        Temperature -> the largest load held at standstill (N).
    distances : ndarray
        Move distances (m).
    min_time : dict
        Temperature -> the minimum move time (s) at no load over the distances.
    wall_time_s : float
        The whole computation (s).
    status : dict
        (temperature, load) -> IPOPT's status of that steady state.
    """

    temperatures: list
    loads: np.ndarray
    top_speed: dict
    largest_force: dict
    distances: np.ndarray
    min_time: dict
    wall_time_s: float = 0.0
    status: dict = field(default_factory=dict)

    def as_dict(self) -> dict:
        """The envelope as JSON can hold it."""
        key = [str(t) for t in self.temperatures]
        return {"temperatures": self.temperatures, "loads_N": self.loads, "distances_m": self.distances,
                "top_speed_m_s": dict(zip(key, self.top_speed.values(), strict=True)),
                "largest_force_N": dict(zip(key, self.largest_force.values(), strict=True)),
                "min_time_s": dict(zip(key, self.min_time.values(), strict=True)), "wall_time_s": self.wall_time_s}

    def plot(self, path=None):
        """The figure: the top rod speed against the load (the largest load held marked)
        and the minimum move time against the distance, per soak temperature; a
        matplotlib Figure (written to ``path`` if given).

        Parameters
        ----------
        path : str or Path, optional
            A .png file to write.
        """
        from ..plots._optimal import plot_envelope

        return plot_envelope(self, path)


def _steady(prob: Problem, speed: float | None, direction: float = 1.0, full: bool = False):
    """Steady state on the drive level at the given rod speed (None: maximise it in
    ``direction``, +1 outward), or at standstill maximising the load (speed 0 with
    ``prob.load`` None). Returns (the optimum, IPOPT's status), with ``full`` also the
    margins of the ratings at the last iterate."""
    m = prob.model
    opti = ca.Opti()
    scale = np.maximum(m.full_scale(prob.p), 1e-6)
    xs = opti.variable(m.nx)
    x = ca.diag(scale) @ xs
    c_scale = prob._control_scale()
    cs = opti.variable(len(prob.controls))
    c = ca.diag(c_scale) @ cs
    free_load = prob.load is None
    F = opti.variable() if free_load else prob.load
    u0 = ca.MX(m.u(prob.p, **{prob.cmd: 0.0, prob.load_input: 0.0, **prob.extra}))
    u0[m.inputs.index(prob.load_input)] = F
    h = ca.MX.zeros(len(m.holds))
    for j, i in enumerate(prob.controls):
        h[i] = c[j]
    xdot, y = m.f_held(x, u0, prob.p, h)
    travel = m.travel(prob.p)
    rest = m.rest_states(prob.p)
    v = prob._signal(m.output_with("rod_velocity"), x, y)
    for i, n in enumerate(m.states):
        roles = m.state_info[n].roles
        if n in travel or n in rest:
            opti.subject_to(xs[i] == 0)  # at the centre (the rate is the speed)
        elif "temperature" in roles:  # soaked at the ambient (the envelope), else at the start's
            soak = getattr(prob, "extra_temperature", None)
            opti.subject_to(x[i] == (soak if soak is not None else prob.start_state()[i]))
        elif "controller_integral" not in roles:
            opti.subject_to(xdot[i] / scale[i] == 0)
    for r in prob.ratings:
        if r.name == "stroke" or any(n in m.states and "temperature" in m.state_info[n].roles for n in r.signals):
            continue
        s = [prob._signal(n, x, y) for n in r.signals]
        lim = prob.limits[r.name]
        if r.sense == "norm":
            opti.subject_to(sum(q**2 for q in s) / lim**2 <= 1)
        elif r.sense == "max":
            opti.subject_to(s[0] <= lim)
        else:
            opti.subject_to(s[0] >= lim)
    v_ref = prob.limits.get("rod_speed", 0.1)
    if free_load:
        opti.subject_to(v == 0)
        opti.minimize(F / 1e4)  # the largest load pushing the rod in, held: F < 0 is held out
        opti.set_initial(F, -1e3)
    else:
        opti.subject_to(direction * v >= 0)
        opti.minimize(-direction * v / v_ref)
        opti.set_initial(xs, np.where(np.isin(np.arange(m.nx), [m.index(n) for n in m.states_with("shaft_speed")]),
                                      0.5, 0.0))
    res = solve_ipopt(opti, {"max_iter": 300, "tol": 1e-9}, expand=True)
    val, status = res.value, res.status
    best = float(val(-F if free_load else v)) if res.success else np.nan
    if not full:
        return best, status
    X, Y = np.asarray(val(x), float).reshape(-1, 1), np.asarray(val(y), float).reshape(-1, 1)
    return best, status, _margins(prob, X, Y)


def check_capacity(prob: Problem) -> None:
    """Raise :class:`Infeasible` when the drive cannot move the rod against ``prob.load``
    at all: the steady state of the largest rod speed in the move's direction within
    the ratings (the envelope's NLP, a fraction of a second) has none. The message names
    the rating the last iterate sits furthest beyond (or nearest to).

    Parameters
    ----------
    prob : Problem
        A move whose load opposes it (``load`` and ``move`` of one sign).
    """
    probe = Problem(prob.full, prob.move, prob.load, "time", None, prob.start, "drive", 4, prob.field_weakening,
                    prob.extra)
    v, status, margins = _steady(probe, None, direction=float(np.sign(prob.move)), full=True)
    if status == "Solve_Succeeded" and abs(v) > CREEP * probe.limits.get("rod_speed", 1.0):
        return
    worst = min(margins, key=margins.get)
    r = next(r for r in probe.ratings if r.name == worst)
    raise Infeasible(f"no move within the limits: against {prob.load / 1e3:g} kN the rod does not move (the "
                     f"largest steady speed {v * 1e3:.3g} mm/s, IPOPT {status}); the binding limit is the "
                     f"{r.what} ({r.why} = {probe.limits[r.name]:.4g} {r.unit})")


def _steady_item(model: Model, T, ambient, loads) -> tuple:
    """(top speeds against ``loads``, the largest load held, statuses) at soak ``T``."""
    extra = {} if T is None else {ambient: T}
    speeds, status = [], {}
    for F in loads:
        # the load opposes the outward move: it pushes the rod in (+)
        prob = Problem(model, 1e-3, float(F), "time", None, 0.0, "drive", 4, False, extra)
        prob.extra_temperature = T
        v, st = _steady(prob, None)
        # the smooth lock's creep against a load the motor cannot drive is no speed
        speeds.append(0.0 if v < CREEP * prob.limits.get("rod_speed", 1.0) else v)
        status[(T, float(F))] = st
    prob = Problem(model, 1e-3, 0.0, "time", None, 0.0, "drive", 4, False, extra)
    prob.load, prob.extra_temperature = None, T
    largest, _ = _steady(prob, 0.0)
    return np.array(speeds), largest, status


def _move_item(model: Model, T, ambient, d, intervals) -> tuple:
    """(the minimum time of a ``d`` move at no load, or nan; its failure or None) at soak ``T``."""
    extra = {} if T is None else {ambient: T}
    try:
        return solve(Problem(model, float(d), 0.0, "time", None, 0.0, "drive", intervals, False, extra))["T"], None
    except Infeasible as exc:
        return np.nan, str(exc)


def _item(args) -> tuple:
    """One item of the envelope in a worker process: the model built again from its
    parameters and variants (the same model)."""
    params, variants, kind, rest = args
    model = build_model(params, variants)
    return _steady_item(model, *rest) if kind == "steady" else _move_item(model, *rest)


def performance_envelope(model: Model, loads=None, distances=None, temperatures=None,
                         intervals: int = 30, jobs: int = 1) -> Envelope:
    """The performance envelope of the drive within its operating limits.

    Parameters
    ----------
    model : Model
        The actuator.
    loads : array_like, optional
        Loads opposing the move (N, >= 0); default 10 from 0 to 0.9 x the load the screw
        holds (the model's ``held_load``).
    distances : array_like, optional
        Move distances (m) for the minimum time; default 1, 2, 5, 10, 20 mm.
    temperatures : array_like, optional
        Soak temperatures (degC), for a model with an ambient-temperature input (a thermal
        network); default 20 and 20 K below the lowest rated node there, else the parameter set.
    intervals : int
        Shooting intervals of each minimum-time move.
    jobs : int
        Worker processes (the steady states of each temperature, and each move, are
        independent NLPs; a script needs a main guard above 1). The answers do not depend
        on it: each item is the same computation on the same model.
    """
    t0 = time.perf_counter()
    for role in ("command", "load"):  # the envelope's moves command the rod against its load
        model.needs_input(role, "the performance envelope of the rod", OptimalError)
    held = model.envelope_limits().get("held_load", np.inf)
    loads = np.linspace(0.0, 0.9 * held, 10) if loads is None else np.asarray(loads, float)
    distances = np.array([1e-3, 2e-3, 5e-3, 10e-3, 20e-3]) if distances is None else np.asarray(distances, float)
    ambient = model.inputs_with("ambient_temperature")
    if temperatures is None:
        # 20 degC and 20 K below the lowest rated node (every node soaks at the ambient)
        rated = [v for r, v in zip(model.ratings, model.operating_limits().values(), strict=True)
                 if any(n in model.states and "temperature" in model.state_info[n].roles for n in r.signals)]
        temperatures = [20.0, min(rated) - 20.0] if ambient and rated else [None]
    temperatures = list(temperatures)
    if any(t is not None for t in temperatures) and not ambient:
        raise OptimalError("temperatures: the model has no ambient-temperature input (choose a thermal network)")
    if np.any(loads < 0) or np.any(np.abs(loads) > held):
        raise OptimalError(f"loads: between 0 and the {held / 1e3:.4g} kN the screw holds")
    if not np.all(np.isfinite(distances)) or np.any(distances <= 0):
        raise OptimalError(f"distances: finite and above 0 (m), got {distances.tolist()}")
    stroke = model.operating_limits().get("stroke", np.inf)  # each move starts at 0
    if np.any(distances > stroke):
        raise OptimalError(f"distances: {distances.max() * 1e3:g} mm from 0 is beyond the stroke +-{stroke * 1e3:g} mm")
    bad = [t for t in temperatures if t is not None and not (np.isfinite(t) and t > -273.15)]
    if bad:
        raise OptimalError(f"temperatures: finite and above absolute zero (-273.15 degC), got {bad[0]}")
    intervals = integer(intervals, "intervals", OptimalError, minimum=4)
    if intervals > MAX_INTERVALS:
        raise OptimalError(f"intervals {intervals}: above the limit of {MAX_INTERVALS}")
    jobs = integer(jobs, "jobs", OptimalError, minimum=1)
    amb = ambient[0] if ambient else None
    items = [("steady", (T, amb, loads)) for T in temperatures]
    items += [("move", (T, amb, float(d), intervals)) for T in temperatures for d in distances]
    if jobs > 1:
        check_main_guard(OptimalError, f"performance_envelope(jobs={jobs})")
        got = process_map(_item, [(model.params, model.variants, k, rest) for k, rest in items], jobs)
    else:
        got = [_steady_item(model, *rest) if k == "steady" else _move_item(model, *rest) for k, rest in items]
    top, largest, tmin, status = {}, {}, {}, {}
    for (kind, rest), out in zip(items, got, strict=True):
        T = rest[0]
        if kind == "steady":
            top[T], largest[T] = out[0], out[1]
            status.update(out[2])
        else:
            tmin.setdefault(T, []).append(out[0])
            if out[1] is not None:
                status[(T, rest[2])] = out[1]
    tmin = {T: np.array(v) for T, v in tmin.items()}
    return Envelope(temperatures=temperatures, loads=loads, top_speed=top, largest_force=largest, distances=distances,
                    min_time=tmin, wall_time_s=time.perf_counter() - t0, status=status)
