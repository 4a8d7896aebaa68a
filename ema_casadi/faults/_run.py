"""Running the fault cases on one model, and the healthy runs through the sweep engine."""

from __future__ import annotations

import math
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from .._util._checks import describe, integer
from .._util._resources import REFERENCE_FAULTS, packaged_file
from ..model.params import Parameters
from ._result import FaultResult
from ._spec import FaultError, FaultSpec, load_faults, parse_faults

__all__ = ["run_faults", "healthy_runs", "DEFAULT_FAULTS", "HEALTHY_TOLERANCE"]

#: The reference fault file (packaged; ``models/faults_reference.toml`` in the repository).
DEFAULT_FAULTS = REFERENCE_FAULTS
#: Relative tolerance (uniform, +-) on friction and stiffness in the healthy runs.
HEALTHY_TOLERANCE = 0.05


def _spec(params, faults, variants) -> FaultSpec:
    if isinstance(faults, FaultSpec):
        return faults
    if faults is None:
        faults = packaged_file(REFERENCE_FAULTS)
    if not isinstance(params, Parameters):
        raise FaultError(f"params: expected Parameters (from load_parameters), got {describe(params)}")
    if isinstance(faults, dict):
        return parse_faults(faults, params, "<faults>", variants)
    if isinstance(faults, (str, Path)):
        return load_faults(faults, params, variants)
    raise FaultError(f"faults: expected a fault file, a dict or a FaultSpec, got {describe(faults)}")


def _start(model, spec: FaultSpec):
    """(parameter vector, initial state or None, fixed inputs): the aircraft loop starts
    from the trim of the whole loop at its flight condition, its attitude command on
    top of the trim's."""
    sc = spec.scenario
    # the scenario's signals by the role they drive; one the model lacks (a segment's cavity
    # temperature without the thermal network) is left out
    sig = {model.input_with(role): v for role, v in sc["signals"].items() if model.inputs_with(role)}
    if sc["condition"] is None:
        return model.p(), None, sig
    from ..aircraft import aircraft_point, condition_overrides
    from ..signals import constant

    pv = model.p(**condition_overrides(sc["condition"]))
    op = aircraft_point(model, sc["condition"])
    fixed = {n: float(v) for n, v in op.policy.get("trim_free", {}).items()}
    theta_cmd = model.input_with("attitude_command")
    sig[theta_cmd] = sig[theta_cmd] + constant(float(op.u[model.inputs.index(theta_cmd)]))
    return pv, op.x, {**fixed, **sig}


def _one(model, spec: FaultSpec, case, start):
    from ..simulation import RunFailed, simulate

    sc = spec.scenario
    pv, x0, signals = start
    try:
        res = simulate(model, sc["duration"], solver="rk4", dt=sc["dt"], dt_out=sc["dt_out"], zoh=True, p=pv, x0=x0,
                       **signals, **case.signals())
        return res, None
    except RunFailed as exc:
        return exc.result, exc.reason


def run_faults(params: Parameters | None = None, faults=None, *, variants: dict | None = None,
               healthy: int = 0, jobs: int | None = None, seed: int = 1, progress: bool = False) -> FaultResult:
    """Run every case of a fault file on one model and measure the ECU's detection.

    The model is built once with every fault kind and the monitors on
    (:func:`~ema_casadi.faults.fault_variants`); each case drives its fault's input from
    the onset, so no case rebuilds or recompiles it. Per case: the detection time of
    every monitor (the first sample with its latch at 1/2), the rod's peak deviation
    from the no-fault run after the onset (same noise sequence: the difference is the
    fault's), and the run's status (a case that leaves the physical envelope is a row
    with its reason; what happened before still counts).

    Parameters
    ----------
    params : Parameters, optional
        The parameter set (its [monitor] thresholds); not needed with a FaultSpec.
    faults : str, Path, dict or FaultSpec, optional
        The fault file, its dict, or a checked spec; default the packaged reference
        table (:data:`DEFAULT_FAULTS`).
    variants : dict, optional
        Variant choices on top of the parameter set's.
    healthy : int
        Healthy runs for the false-alarm count (:func:`healthy_runs`); 0: none.
    jobs : int, optional
        Local workers for the healthy runs (default: the cores); the fault cases run
        on two threads (the compiled rollout releases the interpreter).
    seed : int
        Seed of the healthy runs' tolerances and noise.
    progress : bool
        Progress on stderr (the healthy runs').
    """
    from ..model.assembly import build_model

    spec = _spec(params, faults, variants)
    healthy = integer(healthy, "healthy", FaultError, minimum=0)
    seed = integer(seed, "seed", FaultError, minimum=0)
    t0 = time.perf_counter()
    from ..simulation import sampling_split

    model = build_model(spec.params, spec.variants)
    sampling_split(model, spec.scenario["dt"], model.p(), FaultError, f"{spec.source} [scenario] dt")
    start = _start(model, spec)
    first = _one(model, spec, spec.cases[0], start)  # compiled once before the threads share the model
    with ThreadPoolExecutor(2, thread_name_prefix="ema-faults") as pool:
        runs = [first, *pool.map(lambda c: _one(model, spec, c, start), spec.cases[1:])]
    info = {"model_variants": spec.variants, "cases": len(spec.cases), "wall_time": time.perf_counter() - t0}
    result = FaultResult.from_runs(spec, model, runs, info)
    if healthy:
        result.healthy = healthy_runs(spec, healthy, jobs=jobs, seed=seed, progress=progress)
    return result


def healthy_runs(spec: FaultSpec, n: int, *, jobs: int | None = None, seed: int = 1,
                 tolerance: float | None = None, progress: bool = False, statistics: bool = True) -> dict:
    """False alarms over ``n`` healthy runs of the fault file's scenario (its
    ``[healthy]`` duration and step), through the sweep engine: sensor noise (a seed
    per run for every noise sequence) and the ``[healthy] vary`` parameters (the
    reference file: friction ``F_seal``, ``C_bear`` and stiffness ``C``) drawn uniformly
    within +-``tolerance``; no fault injection.

    Returns a dict: ``runs``, ``false_alarms`` (runs in which some monitor latched),
    ``by_monitor`` (latched runs per monitor), ``failed`` runs, ``wall_time``, ``jobs``,
    ``duration`` (s of one run) and with ``statistics`` the monitors' margins:
    ``maxima`` (statistic output -> its largest value in each completed run) and
    ``margins`` (latch -> ``statistic``, ``threshold`` (its parameter's value),
    ``healthy_max``, ``margin`` = 1 - healthy_max / threshold).

    Parameters
    ----------
    spec : FaultSpec
        The checked fault file (its scenario and thresholds).
    n : int
        Number of runs.
    jobs : int, optional
        Local workers (default: the cores).
    seed : int
        Seed of the draws.
    tolerance : float, optional
        Relative half-width of the uniform tolerances (-); default the file's
        ``[healthy] tolerance`` (HEALTHY_TOLERANCE).
    progress : bool
        Progress on stderr.
    statistics : bool
        Also keep the largest value of every monitor statistic per run (samples every
        ~0.1 ms instead of 1 ms).
    """
    from ..sweeps import make_sweep, sweep

    n = integer(n, "n", FaultError, minimum=1)
    seed = integer(seed, "seed", FaultError, minimum=0)  # numpy's generators take whole numbers >= 0
    h = spec.healthy or {"duration": spec.scenario["duration"], "dt": spec.scenario["dt"],
                         "dt_out": spec.scenario["dt_out"], "tolerance": HEALTHY_TOLERANCE, "vary": []}
    tolerance = h["tolerance"] if tolerance is None else tolerance
    if not (isinstance(tolerance, (int, float)) and 0 <= tolerance < 1):
        raise FaultError(f"tolerance: expected a fraction in [0, 1), got {tolerance!r}")
    if spec.scenario["condition"] is not None:
        raise FaultError("healthy runs: not in the aircraft loop (they run the actuator's scenario)")
    from ..model.assembly import build_model

    v = spec.healthy_variants or spec.variants
    model = build_model(spec.params, v)
    alarms = model.outputs_of("alarm")
    stats = model.outputs_of("statistic") if statistics else ()
    # a seed per run for every noise sequence (the parameters the noise inputs name)
    seeds = sorted({i.seed for i in model.input_info.values() if i.noise is not None and i.seed})
    tol = {"distribution": "uniform", "low": 1 - tolerance, "high": 1 + tolerance, "relative": True}
    parameters = {**{name: tol for name in h["vary"]},
                  **{name: {"distribution": "uniform", "low": 0.0, "high": 2.0**31} for name in seeds}}
    if not parameters:
        raise FaultError("healthy runs: nothing varies (no noise inputs, no [healthy] vary parameters)")
    # a sweep object from the scenario's signals as they were read (by role; one the model lacks
    # left out; a chirp keeps the scenario's duration), no file text written and parsed back
    signals = {role: s for role, s in spec.scenario["signals"].items() if model.inputs_with(role)}
    dt_out = min(h["dt_out"], h["dt"] * max(1, math.ceil(1e-4 / h["dt"] - 1e-9))) if stats else h["dt_out"]
    metrics = {"peak": {"signals": list(alarms)}, **({"maximum": {"signals": list(stats)}} if stats else {})}
    sw = make_sweep(spec.params, {"duration": h["duration"], "solver": "rk4", "dt": h["dt"], "dt_out": dt_out,
                                  "zoh": True, "signals": signals},
                    metrics, parameters=parameters, variants=v, seed=int(seed),
                    samples=n, name="healthy runs", source=f"{spec.source} (healthy runs)")
    res = sweep(sw, jobs=jobs, progress=progress)
    ok = [r for r in res.rows if r["status"] == "ok"]
    by = {a: sum(1 for r in ok if r[f"peak_{a}"] >= 0.5) for a in alarms}
    false = sum(1 for r in ok if any(r[f"peak_{a}"] >= 0.5 for a in alarms))
    out = {"runs": n, "false_alarms": false, "by_monitor": by, "failed": len(res.rows) - len(ok),
           "wall_time": res.info["wall_time"], "jobs": res.info["jobs"], "tolerance": tolerance,
           "duration": h["duration"],
           "worst_latch": {a: float(max((r[f"peak_{a}"] for r in ok), default=math.nan)) for a in alarms},
           "first_failure": next((r["reason"] for r in res.rows if r["status"] != "ok"), None)}
    if stats:
        out["maxima"] = {s: [float(r[f"max_{s}"]) for r in ok] for s in stats}
        P = model.pdict()
        out["margins"] = {}
        for s in stats:
            o = model.output_info[s]
            top = max(out["maxima"][s], default=math.nan)
            ref = float(getattr(P, o.threshold))
            out["margins"][o.alarm] = {"statistic": s, "unit": o.unit, "threshold": ref, "threshold_param": o.threshold,
                                       "healthy_max": top, "margin": 1 - top / ref if ref else math.nan}
    return out
