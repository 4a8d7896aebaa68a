"""The sine-stream driver: request checks, variant set, initial states, the task list
and the result arrays (method: :mod:`ema_casadi.sinestream`)."""

from __future__ import annotations

import itertools
import math
import time
from types import SimpleNamespace
from typing import TYPE_CHECKING

import casadi as ca
import numpy as np

from .._util._checks import describe, instance, vector
from .._util._parallel import check_main_guard
from ..linearisation import small_signal_point
from ..model.assembly import Model
from ..model.components import validate_variants
from ..model.params import Parameters
from ..simulation import Monitor
from ._backends import BACKENDS, Grid, _cores, point_costs, run_points, worth_processes
from ._kernels import _failed, _Settle, _stepper
from ._parse import _as_axis, check_grid
from ._result import FreqRespError, FreqResponse

if TYPE_CHECKING:
    from numpy.typing import ArrayLike


def sine_stream(
    params: Parameters, amplitudes: ArrayLike, freqs: ArrayLike, loads: ArrayLike = (0.0,),
    variants: dict | list | None = None, *,
    p: np.ndarray | None = None, samples: int = 64, tol_db: float = 0.01, tol_deg: float = 0.1,
    max_periods: int = 60, rtol: float = 1e-6, atol: float = 1e-9, hybrid_dt: float = 5e-5,
    jobs: int | None = None, backend: str = "processes", scheduler: str | None = None, progress: bool = False,
    keep: bool = False,
) -> FreqResponse:
    """Sine-stream frequency response of the nonlinear model x_rod / x_cmd.

    Parameters
    ----------
    params : Parameters
        Parameter set (its variants are the defaults).
    amplitudes : sequence of float
        Command amplitudes A (m).
    freqs : sequence of float
        Frequencies (Hz); sorted ascending in the result.
    loads : sequence of float
        Constant external forces F_ext (N, positive pushes the rod in).
    variants : dict, optional
        One variant choice (``{"screw": "rigid"}``) or several, label -> choice
        (``{"elastic": {"screw": "elastic"}, "rigid": {"screw": "rigid"}}``).
    p : ndarray, optional
        Raw parameter vector (default ``params.vector()``), e.g. with overrides.
    samples : int
        Output samples per period K (even, >= 8).
    tol_db, tol_deg : float
        Settling tolerances on the first harmonic (dB, deg); see :mod:`ema_casadi.sinestream`.
    max_periods : int
        Periods after which an unsettled point is reported as not converged.
    rtol, atol : float
        CVODES tolerances (rtol -; atol in the states' SI units).
    hybrid_dt : float
        Largest RK4 step for hybrid-friction points (s); on the reference set 1e-4 s
        and 2e-5 s gave gains within 1e-3 dB of each other.
    jobs : int, optional
        Local workers (default: the number of cores); 1 runs in this thread.
    backend : {"processes", "threads"}
        The local pool. Processes scale with the cores: ``jobs - 1`` of them and this
        process, which computes while they start; a grid too small to pay for their
        start-up runs in this thread. They are started by spawn and import the main
        script again, so a script must call ``sine_stream`` under
        ``if __name__ == "__main__":`` (refused with :class:`FreqRespError` otherwise,
        before any point runs). Threads share this process (no start-up) but Python's
        lock serialises the work between the integrator calls (about 8 % of it).
    scheduler : str, optional
        Address of a Dask distributed scheduler (``tcp://host:port``); needs the
        optional ``dask[distributed]`` and ema_casadi on the workers.
    progress : bool
        Progress bar on stderr.
    keep : bool
        Keep the x_rod and i_q samples of every simulated period.

    Returns
    -------
    FreqResponse
    """
    t_wall = time.perf_counter()
    instance(params, Parameters, "params", FreqRespError,
             " (from load_parameters; sine_stream builds its own models: pass variants=model.variants)")
    amplitudes = _as_axis(amplitudes, "amplitudes", "m")
    freqs = np.unique(_as_axis(freqs, "freqs", "Hz"))
    loads = _as_axis(loads, "loads", "N", positive=False)
    _check_options(samples, max_periods, tol_db, tol_deg, rtol, atol, hybrid_dt, jobs)
    if scheduler is not None and not (isinstance(scheduler, str) and "://" in scheduler):
        raise FreqRespError(f"scheduler: expected an address like tcp://host:8786, got {describe(scheduler)}")
    if backend not in BACKENDS:
        raise FreqRespError(f"backend: expected one of {', '.join(BACKENDS)}, got {describe(backend)}")
    vset = _variant_set(params, variants)
    check_grid({"variants": len(vset), "loads": len(loads), "amplitudes": len(amplitudes), "freqs": len(freqs)},
               max_periods, jobs or _cores())
    pv = _param_vector(params, p)
    n_jobs = 1 if scheduler else (jobs or _cores())
    settle = _Settle(tol_db, tol_deg, max_periods)
    build = (samples, rtol, atol, hybrid_dt)
    x0s, rho = _starts(params, vset, build, pv, loads, amplitudes, freqs)
    grid = Grid(params, tuple(vset.values()), build, settle, keep, pv, loads, amplitudes, freqs, x0s)
    held = _beyond_hold(vset, pv, loads)  # no response to measure: failed points, not numbers
    todo = [i for i in x0s if i[:2] not in held]
    costs = point_costs(grid, {i: rho[i] for i in todo})
    if backend == "processes" and n_jobs > 1:
        if not worth_processes(costs):  # a small grid: this thread ends it before a worker has started
            n_jobs = 1
        else:
            check_main_guard(FreqRespError, f"sine_stream(jobs={n_jobs})")
    results, timing = run_points(grid, todo, costs, jobs=n_jobs, backend=backend, scheduler=scheduler,
                                 progress=progress) if todo else ({}, {})
    results.update({i: _failed(0, held[i[:2]]) for i in x0s if i[:2] in held})
    shape = (len(vset), len(loads), len(amplitudes), len(freqs))
    data, samples_out, failed = _collect(results, shape, keep)
    info = _info(settle, build, None if scheduler else n_jobs, scheduler, len(x0s), data, failed, freqs)
    info["backend"] = "dask" if scheduler else (backend if n_jobs > 1 else "serial")
    info["timing"] = _timing(timing, shape)
    info["wall_time"] = time.perf_counter() - t_wall
    axes = {"variant": list(vset), "load": loads, "amplitude": amplitudes, "frequency": freqs}
    return FreqResponse(axes=axes, data=data, variants=vset, info=info, samples=samples_out)


def _beyond_hold(vset: dict, pv, loads) -> dict:
    """(variant index, load index) -> the reason, for loads above what the variant's
    actuator holds at standstill: the envelope limit ``held_load`` its parts declare."""
    from ..model.components import parts_for

    names = Parameters.names()  # the shared values lead the vector of a model of several actuators
    P = SimpleNamespace(**dict(zip(names, np.asarray(pv, float)[:len(names)], strict=True)))
    out = {}
    for iv, v in enumerate(vset.values()):
        held = [float(part.limits["held_load"](P)) for part in parts_for(v)[0] if "held_load" in part.limits]
        F = max(held, default=math.inf)
        out.update({(iv, il): f"load {load / 1e3:.4g} kN is above the {F / 1e3:.3g} kN the actuator holds at "
                               "standstill at its current limit: the actuator cannot hold the load, no response "
                               "to measure" for il, load in enumerate(loads) if abs(load) > F})
    return out


def _check_options(samples, max_periods, tol_db, tol_deg, rtol, atol, hybrid_dt, jobs) -> None:
    """One-line FreqRespError for the first bad numeric option."""
    if not (isinstance(samples, int) and samples >= 8 and samples % 2 == 0):
        raise FreqRespError(f"samples: expected an even integer >= 8, got {samples!r}")
    if not (isinstance(max_periods, int) and max_periods >= 3):
        raise FreqRespError(f"max_periods: expected an integer >= 3, got {max_periods!r}")
    for name, v in (("tol_db", tol_db), ("tol_deg", tol_deg), ("rtol", rtol), ("atol", atol), ("hybrid_dt", hybrid_dt)):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v > 0):
            raise FreqRespError(f"{name}: expected a positive number, got {describe(v)}")
    if jobs is not None and (not isinstance(jobs, int) or jobs < 1):
        raise FreqRespError(f"jobs: expected a positive integer, got {jobs!r}")


def _param_vector(params: Parameters, p) -> np.ndarray:
    """The raw parameter vector: ``p`` if given (checked), else the set's defaults."""
    if p is None:
        return params.vector()
    return vector(p, "p", FreqRespError, len(params.vector()), " (the parameter vector)")


def _variant_set(params: Parameters, variants) -> dict:
    """Normalise ``variants`` to label -> complete variant dict."""
    if variants is None:
        return {"model": validate_variants(params.variants)}
    if isinstance(variants, dict) and all(isinstance(v, str) for v in variants.values()):
        full = dict(params.variants)
        full.update(variants)
        full = validate_variants(full)
        base = validate_variants(params.variants)
        diff = [f"{k}={v}" for k, v in full.items() if base[k] != v]
        return {";".join(diff) or "model": full}
    if isinstance(variants, dict):
        out = {}
        for label, v in variants.items():
            if v is not None and not isinstance(v, dict):
                raise FreqRespError(f"variants: '{label}' must map to a dict of variant choices, got {describe(v)}")
            full = dict(params.variants)
            full.update(v or {})
            out[str(label)] = validate_variants(full)
        return out
    raise FreqRespError("variants: expected a dict of variant choices or a dict label -> dict")


def _starts(params, vset, build, pv, loads, amplitudes, freqs) -> tuple[dict, dict]:
    """Every point's starting state and its linear rod speed demand over the rate limit
    (the cost estimate's input), each index (variant, load, amplitude, frequency) -> value."""
    x0s, rho = {}, {}
    for iv, v in enumerate(vset.values()):
        model, step = _stepper(v, params, *build)
        x0, r = _initial_states(model, step, pv, loads, amplitudes, freqs)
        for il, ia, jf in itertools.product(range(len(loads)), range(len(amplitudes)), range(len(freqs))):
            x0s[iv, il, ia, jf], rho[iv, il, ia, jf] = x0[il, ia, jf], r[il, ia, jf]
    return x0s, rho


def _initial_states(model: Model, step, p, loads, amplitudes, freqs) -> tuple[dict, dict]:
    """(i_load, i_amplitude, i_frequency) -> starting state (package docstring), and ->
    the linear response's rod speed amplitude over the rate limit (-)."""
    nx = model.nx
    x = ca.SX.sym("x", nx)
    u = ca.SX.sym("u", model.nu)
    pp = ca.SX.sym("p", len(model.param_names))
    xdot = model.f(x, u, pp)[0]
    ju = model.inputs.index(model.input_with("command"))
    jac = ca.Function("lin_jacobians", [x, u, pp], [ca.jacobian(xdot, x), ca.jacobian(xdot, u)[:, ju]])
    rate_limit = model.limit_values(p)["rod_speed"]
    # the rod's own travel: its position state, or the shaft angle where the rod
    # position is a play (the rigid screw)
    travel = model.travel(p)
    rods = [n for n in model.states_with("rod_position") if n not in model.states_with("play")]
    rod = rods[0] if rods else model.state_with("shaft_angle")
    j_rod, per_unit = model.index(rod), travel[rod]
    monitor = Monitor(model, p)
    out, rho = {}, {}
    for il, load in enumerate(loads):
        # at rest under the load: 1 s with the command held at zero
        x_rest, _ = step(np.zeros(nx), np.r_[p, 0.0, 1.0, load])
        if not np.all(np.isfinite(x_rest)):
            x_rest = np.zeros(nx)
        # the small-signal model there: Coulomb friction and backlash off, the blends frozen
        uu, p_lin = small_signal_point(model, model.u(p, f_ext=load), p)
        Ja, Jb = (np.asarray(m, float) for m in jac(x_rest, uu, p_lin))
        Jb = Jb.ravel()
        for jf, f in enumerate(freqs):
            w = 2 * np.pi * f
            try:
                Xc = np.linalg.solve(1j * w * np.eye(nx) - Ja, Jb)
            except np.linalg.LinAlgError:
                Xc = np.zeros(nx, complex)
            # rod speed amplitude of the linear response per unit command amplitude
            g_rod = abs(Xc[j_rod]) * per_unit
            for ia, A in enumerate(amplitudes):
                rho[il, ia, jf] = w * g_rod * A / rate_limit
                scale = A * min(1.0, rate_limit / max(w * g_rod * A, 1e-300))
                guess = x_rest + scale * Xc.imag
                # a guess outside the physical envelope (the linearised hybrid rod is
                # stuck: its "response" drives the currents far beyond I_max) would
                # start the run in garbage: start at rest instead
                out[il, ia, jf] = x_rest if monitor.first([0.0], guess) is not None else guess
    return out, rho


def _collect(results: dict, shape: tuple, keep: bool):
    """Point dicts -> (data arrays of :data:`FIELDS`, kept samples or None, failed count)."""
    H = np.full(shape, np.nan, complex)
    I = np.full(shape, np.nan, complex)
    data = {k: np.full(shape, np.nan) for k in ("distortion", "i_q_distortion", "x_offset")}
    periods = np.zeros(shape, int)
    conv = np.zeros(shape, bool)
    status = np.full(shape, "", object)
    reason = np.full(shape, "", object)
    samples_out = {} if keep else None
    failed = 0
    for idx, r in results.items():
        H[idx], I[idx] = r["H"], r["I"]
        for k in data:
            data[k][idx] = r[k]
        periods[idx], conv[idx] = r["periods"], r["converged"]
        status[idx], reason[idx] = r["status"], r["reason"]
        failed += bool(r["failed"])
        if keep and "samples" in r:
            samples_out[idx] = r["samples"]
    data = {
        "gain_db": 20 * np.log10(np.abs(H)),
        "phase_deg": _unwrap_deg(np.degrees(np.angle(H))),
        "distortion": data["distortion"],
        "i_q_amp": np.abs(I),
        "i_q_phase_deg": _unwrap_deg(np.degrees(np.angle(I))),
        "i_q_distortion": data["i_q_distortion"],
        "x_offset": data["x_offset"],
        "periods": periods,
        "converged": conv,
        "status": status,
        "reason": reason,
    }
    return data, samples_out, failed


def _info(settle: _Settle, build: tuple, jobs, scheduler, points: int, data: dict, failed: int, freqs) -> dict:
    """Options and counts of a run (the caller adds ``wall_time``)."""
    samples, rtol, atol, _ = build
    periods, conv = data["periods"], data["converged"]
    return {
        "samples_per_period": samples, "tol_db": settle.tol_db, "tol_deg": settle.tol_deg,
        "max_periods": settle.max_periods, "rtol": rtol, "atol": atol, "jobs": jobs, "scheduler": scheduler,
        "points": points, "not_converged": int((~conv).sum()), "failed": failed,
        "periods_total": int(periods.sum()),
        "simulated_time": float(np.sum(periods / freqs[None, None, None, :])),
    }


def _timing(timing: dict, shape: tuple) -> dict:
    """The run's timings: ``point_seconds`` (CPU seconds of each point's periods, NaN for
    points not run, shaped like the data), ``point_cost`` (its estimated cost, in periods
    of the CVODES map, the same shape), ``task_seconds`` (of each task's points),
    ``build_seconds`` (period maps built in the workers), ``worker_cpu`` (each worker
    process's CPU seconds: its start-up where it started for this call, what it spent
    on this call, start-up included, and its points), ``points_here`` (CPU seconds of
    the points run in this process) and the task engine's plan
    (``tasks``, ``seconds_per_cost``, ``pool_start_seconds``, ``first_task_seconds``)."""
    out = dict(timing)
    for key in ("point_seconds", "point_cost"):
        values = np.full(shape, np.nan)
        for idx, s in timing.get(key, {}).items():
            values[idx] = s
        out[key] = values
    out.setdefault("task_seconds", [])
    out.setdefault("worker_cpu", [])
    return out


def _unwrap_deg(phase: np.ndarray) -> np.ndarray:
    """Unwrap along the last (frequency) axis, skipping failed (NaN) points."""
    out = np.array(phase, float)
    flat = out.reshape(-1, out.shape[-1])
    for row in flat:
        ok = np.isfinite(row)
        if ok.any():
            row[ok] = np.degrees(np.unwrap(np.radians(row[ok])))
    return out
