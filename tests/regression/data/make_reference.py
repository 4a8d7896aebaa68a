"""Write the pre-refactor reference data that tests/regression/test_pre_refactor.py checks against.

Kept as the record of how the data were made: it ran on commit c009899, whose API
differs (``ema.tune`` was the tuning module, ``ema.VARIANTS`` had no ``endstop`` key);
it is not meant to run on later code.

Captures the behaviour of the code as it is (commit c009899) through the public API only:

a. the reference scenario (benchmarks/bench_sim.py, tests/test_foundation.py: 1 mm step
   at 0.01 s plus a 0.375 mm 1 Hz sine from 0.5 s), shortened to T_END = 0.2 s (the
   sine term is part of the command but does not start within the horizon), simulated
   for every variant combination the model accepts (friction_shape and stribeck only
   for smooth friction; hybrid friction with their defaults) with both solvers,
   x_rod kept every 0.5 ms;
b. ``ema.loop_margins`` of the default model (all loops);
c. ``ema.sine_stream`` of the default model at 0.5 % and 10 % of the stroke, 1 and 5 Hz,
   0 and 30 kN;
d. the gain tuning of studies/tune_from_poor_start.py (every gain x 0.2, loads 0, 15,
   30 kN, bandwidth objective).

Every call is described in the JSON side file (variants, the exact ``simulate()``
keyword arguments, the sine-stream and tuning arguments), so the test repeats it
exactly; the rod trajectories go to a compressed npz.

Usage (from the repository root)::

    EMA_CASADI_CACHE=.cache python tests/data/make_reference.py [--out tests/data] [--skip-tune]
"""

from __future__ import annotations

import argparse
import itertools
import json
import platform
import subprocess
import sys
import time
from pathlib import Path

import casadi
import numpy as np

import ema_casadi as ema

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
PARAMETER_FILE = "models/cesa_ema.toml"  # relative to the repository root
NPZ_NAME = "reference_pre_refactor.npz"
JSON_NAME = "reference_pre_refactor.json"

# (a) the reference scenario ----------------------------------------------------------
X_CMD = ema.Signal.step(1e-3, 0.01) + ema.Signal.sine(0.375e-3, 1.0, 0.5)
X_CMD_TEXT = X_CMD.text  # SI numbers, parses back to the same floats (checked below)
T_END = 0.2              # s
DT_OUT = 5e-4            # s, x_rod kept every 0.5 ms
RK4_DT = {"smooth": 5e-6, "hybrid": 1e-4}  # the steps the tests and benchmarks use
CVODES_TOL = {"rtol": 1e-8, "atol": 1e-11}  # simulate()'s defaults, passed explicitly
EVENT_TOL = 1e-7          # simulate()'s default, passed explicitly (hybrid + cvodes)
# rk4 runs in CasADi's VM: no C compiler and no on-disk cache of compiled rollouts in
# the comparison (a stale cached library could otherwise hide a change), and building
# the rollout in the VM costs about as much as compiling it.
RK4_JIT = False
SOLVERS = ("cvodes", "rk4")

# (c) sine stream -----------------------------------------------------------------------
SINE_AMPLITUDES_PCT = (0.5, 10.0)  # % of the 75 mm stroke
SINE_FREQS = (1.0, 5.0)            # Hz
SINE_LOADS = (0.0, 30e3)           # N

# (d) tuning (studies/tune_from_poor_start.py defaults) ------------------------------------
TUNE_FACTOR = 0.2
TUNE_LOADS = (0.0, 15e3, 30e3)
TUNE_OBJECTIVE = "bandwidth"


def combinations() -> list[dict]:
    """Every variant combination the model accepts; friction_shape and stribeck only
    vary with smooth friction (hybrid friction keeps their defaults)."""
    keys = list(ema.VARIANTS)
    out = []
    for values in itertools.product(*(ema.VARIANTS[k] for k in keys)):
        v = dict(zip(keys, values))
        if v["friction"] == "hybrid" and any(v[k] != ema.DEFAULT_VARIANTS[k] for k in ("friction_shape", "stribeck")):
            continue
        out.append(v)
    return out


def case_key(variants: dict, solver: str) -> str:
    return ",".join(f"{k}={v}" for k, v in variants.items()) + "|" + solver


def simulate_kwargs(variants: dict, solver: str) -> dict:
    """The exact keyword arguments of ``ema.simulate(model, **kwargs)``."""
    kw = {"t_end": T_END, "x_cmd": X_CMD_TEXT, "solver": solver}
    if solver == "cvodes":
        kw.update(dt=DT_OUT, dt_out=DT_OUT, **CVODES_TOL)
        if variants["friction"] == "hybrid":
            kw["event_tol"] = EVENT_TOL
    else:
        kw.update(dt=RK4_DT[variants["friction"]], dt_out=DT_OUT, jit=RK4_JIT)
    return kw


def git_commit() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(HERE), help="output folder (default: tests/data)")
    ap.add_argument("--skip-tune", action="store_true", help="leave the tuning out (for quick trials)")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    # the text form of the command must give exactly the benchmark's signal
    parsed = ema.parse_signal(X_CMD_TEXT, "length")
    assert parsed.terms == X_CMD.terms, (parsed.terms, X_CMD.terms)

    params = ema.load_parameters(ROOT / PARAMETER_FILE)
    arrays: dict[str, np.ndarray] = {}
    ref: dict = {
        "meta": {
            "what": "pre-refactor reference behaviour of ema_casadi (tests/test_regression.py)",
            "generator": "tests/data/make_reference.py",
            "git_commit": git_commit(),
            "parameter_file": PARAMETER_FILE,
            "python": platform.python_version(),
            "casadi": casadi.__version__,
            "numpy": np.__version__,
            "platform": platform.platform(),
            "generated": time.strftime("%Y-%m-%d %H:%M:%S %z"),
            "npz": NPZ_NAME,
            "npz_layout": "x_rod (m) under the case key; its time grid (s) under the case's t_key",
        },
    }

    # (a) trajectories ------------------------------------------------------------------
    cases, timing, checks = {}, {}, {}
    # Every model stays referenced until the end: simulate() caches its integrators,
    # rollouts and output maps under id(model.f), so a model freed and a new one
    # allocated at the same address would silently get the old model's functions
    # (seen here as a CVODES input-shape error when an elastic model's integrator was
    # handed to a rigid one).
    models = []
    t_sims = time.perf_counter()
    for variants in combinations():
        model = ema.build_model(params, variants)
        models.append(model)
        runs = {}
        for solver in SOLVERS:
            key = case_key(variants, solver)
            kw = simulate_kwargs(variants, solver)
            t0 = time.perf_counter()
            res = ema.simulate(model, **kw)
            timing[key] = time.perf_counter() - t0
            x = np.asarray(res["x_rod"], float)
            if not np.all(np.isfinite(x)):
                raise SystemExit(f"{key}: non-finite x_rod")
            arrays[key] = x
            # one time grid per solver and step, shared by the cases (they are identical)
            t_key = f"t|{solver}" + (f"|dt={kw['dt']!r}" if solver == "rk4" else "")
            t = np.asarray(res.t, float)
            if t_key in arrays and not np.array_equal(arrays[t_key], t):
                raise SystemExit(f"{key}: its time grid differs from {t_key}'s")
            arrays[t_key] = t
            cases[key] = {"variants": dict(variants), "solver": solver, "kwargs": kw, "t_key": t_key,
                          "n_samples": len(x), "x_rod_final": float(x[-1])}
            if "mode_switches" in res.info:
                cases[key]["mode_switches"] = int(res.info["mode_switches"])
            runs[solver] = res
            print(f"{key:100s} {timing[key]:6.2f} s  x_rod(end) {1e3 * x[-1]:.6f} mm", flush=True)
        a, b = runs["cvodes"], runs["rk4"]
        same_grid = a.t.shape == b.t.shape and np.allclose(a.t, b.t, rtol=0, atol=1e-12)
        checks[case_key(variants, "")[:-1]] = float(np.abs(a["x_rod"] - b["x_rod"]).max()) if same_grid else None
    t_sims = time.perf_counter() - t_sims
    ref["simulate"] = {
        "scenario": ("reference scenario of benchmarks/bench_sim.py and tests/test_foundation.py: x_cmd = "
                     "1 mm step at 0.01 s + 0.375 mm 1 Hz sine from 0.5 s, f_ext = 0, eta = the set's; "
                     f"shortened to t_end = {T_END} s (the sine does not start), x_rod every {DT_OUT * 1e3:g} ms"),
        "call": "ema.simulate(ema.build_model(ema.load_parameters(parameter_file), variants), **kwargs)",
        "cases": cases,
        "cvodes_vs_rk4_max_abs_diff_m": checks,
        "wall_time_s": t_sims,
    }
    worst = max(checks.items(), key=lambda kv: kv[1])
    print(f"simulations: {len(cases)} runs in {t_sims:.1f} s; largest cvodes-rk4 difference "
          f"{worst[1] * 1e6:.3f} um ({worst[0]})", flush=True)

    # (b) loop margins of the default model -------------------------------------------------
    model = ema.build_model(params)
    lm = ema.loop_margins(model)
    fields = ("gm_db", "pm_deg", "f_gc_hz", "f_pc_hz", "disk_margin")
    ref["loop_margins"] = {
        "call": "ema.loop_margins(ema.build_model(ema.load_parameters(parameter_file)))",
        "variants": dict(model.variants),
        "values": {loop: {f: (None if getattr(m, f) is None else float(getattr(m, f))) for f in fields}
                   for loop, m in lm.items()},
    }
    print("loop margins:", json.dumps(ref["loop_margins"]["values"]), flush=True)

    # (c) sine stream -------------------------------------------------------------------------
    stroke = params.actuator.stroke
    ss_kwargs = {"amplitudes": [pct / 100 * stroke for pct in SINE_AMPLITUDES_PCT],
                 "freqs": list(SINE_FREQS), "loads": list(SINE_LOADS)}
    t0 = time.perf_counter()
    fr = ema.sine_stream(params, **ss_kwargs)
    t_ss = time.perf_counter() - t0
    ax = fr.axes
    points = []
    for il, ia, jf in itertools.product(range(len(ax["load"])), range(len(ax["amplitude"])), range(len(ax["frequency"]))):
        idx = (0, il, ia, jf)
        points.append({
            "load_N": float(ax["load"][il]), "amplitude_m": float(ax["amplitude"][ia]),
            "amplitude_pct": float(100 * ax["amplitude"][ia] / stroke), "freq_hz": float(ax["frequency"][jf]),
            "index": list(idx),
            "gain_db": float(fr.data["gain_db"][idx]), "phase_deg": float(fr.data["phase_deg"][idx]),
            "converged": bool(fr.data["converged"][idx]), "periods": int(fr.data["periods"][idx]),
        })
    ref["sine_stream"] = {
        "call": "ema.sine_stream(ema.load_parameters(parameter_file), **kwargs)",
        "kwargs": ss_kwargs,
        "variant_label": ax["variant"][0],
        "points": points,
        "wall_time_s": t_ss,
    }
    print(f"sine stream: {len(points)} points in {t_ss:.2f} s", flush=True)
    for pt in points:
        print(f"  {pt['load_N'] / 1e3:4g} kN {pt['amplitude_pct']:4g} % {pt['freq_hz']:3g} Hz: "
              f"{pt['gain_db']:+.5f} dB {pt['phase_deg']:+.4f} deg ({pt['periods']} periods)", flush=True)

    # (d) tuning from the poor start of studies/tune_from_poor_start.py -------------------------
    if not args.skip_tune:
        model = ema.build_model(params)
        free = ema.tune.default_free(model)
        start = ema.tune.scaled_gains(params, TUNE_FACTOR, free)
        t0 = time.perf_counter()
        res = ema.tune.tune(params, model=model, loads=TUNE_LOADS, start=start, objective=TUNE_OBJECTIVE)
        t_tune = time.perf_counter() - t0
        ref["tune"] = {
            "call": ("model = ema.build_model(params); free = ema.tune.default_free(model); "
                     "start = ema.tune.scaled_gains(params, factor, free); "
                     "ema.tune.tune(params, model=model, loads=loads, start=start, objective=objective)"),
            "factor": TUNE_FACTOR, "loads": list(TUNE_LOADS), "objective": TUNE_OBJECTIVE,
            "free": list(free), "start": start,
            "gains_before": dict(res.gains_before), "gains_after": dict(res.gains_after),
            "status": res.status, "success": bool(res.success), "iterations": int(res.iterations),
            "rounds": int(res.rounds), "objective_value": float(res.objective_value),
            "wall_time_s": t_tune,
        }
        print(f"tune: {res.status}, {res.iterations} iterations, {t_tune:.1f} s; after {res.gains_after}", flush=True)

    npz_path, json_path = out / NPZ_NAME, out / JSON_NAME
    tmp = out / (NPZ_NAME + ".tmp.npz")
    np.savez_compressed(tmp, **arrays)
    tmp.replace(npz_path)
    tmp = out / (JSON_NAME + ".tmp")
    tmp.write_text(json.dumps(ref, indent=1) + "\n")
    tmp.replace(json_path)
    for p in (npz_path, json_path):
        print(f"wrote {p} ({p.stat().st_size / 1024:.1f} kB)")


if __name__ == "__main__":
    sys.exit(main())
