"""Benchmark: experiment design, the acceptance case (target: the design under 60 s on
2 cores), and the Fisher information from exact sensitivities against the
finite-difference one pyomo.DoE computes by default.

The problem: the reference set, the seven parameters F_seal, C_bear, c_v, B, C, J_m,
psi, a 10 s test within +-10 mm and a 15 kN load capability, rod position and motor
current with 0.3 um / 0.05 A noise, the default DC criterion (``ema.design_experiment`` with its
defaults). Reported: the wall and CPU time of the design, its parts (the candidates'
sensitivity runs, IPOPT), the geometric-mean ratio of the predicted 95 % interval widths
against chirp + steps + loaded slews of the same length, and |corr(J_m, psi)|.

The Fisher-information comparison, on the designed test: ``information()`` (one run of
the compiled RODAS4 with 7 forward-sensitivity directions, identify's tolerances)
against central finite differences of the predicted outputs (pyomo.DoE's default
scheme: ``formula="central"``, relative step 1e-3, here on each parameter, 14 runs of
the same compiled RODAS4 at the same tolerances, and again at rtol 1e-8), each FIM
compared with a reference of exact sensitivities at rtol 1e-8: the relative error of
the predicted interval widths, and the time.

Usage::

    .venv/bin/python benchmarks/bench_design.py [--json] [--quick]

``--quick`` skips the finite-difference comparison.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
TARGET_S = 60.0


def _runner(model, test, sigma):
    """(outputs(pv, W, rtol, atol) -> (weighted outputs, weighted sensitivities)) on the
    test's one record: the compiled RODAS4 with forward sensitivities, started at rest."""
    from ema_casadi.signals import Signal
    from ema_casadi.simulation import forward_sensitivities, input_signals

    rec = test.records[0]
    t = np.asarray(rec["t"], float)
    tables = {k: Signal.table(t, v) for k, v in rec["inputs"].items()}
    rows = [model.index(c) for c in sigma]
    scale = np.array(list(sigma.values()))

    def run(pv, W, rtol, atol):
        sig = input_signals(model, tables, pv)
        X, SX, _ = forward_sensitivities(model, sig, t, pv, model.x0(), W, np.zeros((model.nx, W.shape[1])), rtol,
                                         atol)
        y = (X[rows][:, 1:] / scale[:, None]).ravel()
        dy = np.concatenate([SX[1:, :, r] / s for r, s in zip(rows, scale, strict=True)])
        return y, dy
    return run


def _exact_information(model, test, fr, sigma, rtol, atol):
    """J^T J from one run with the free parameters' directions (optimiser coordinates)."""
    run = _runner(model, test, sigma)
    pv = model.p()
    W = np.zeros((len(pv), len(fr.names)))
    W[fr.index, np.arange(len(fr.names))] = fr.dtheta_dz(fr.theta0)
    _, J = run(pv, W, rtol, atol)
    return J.T @ J


def _fd_information(model, test, fr, sigma, rtol, atol, step=1e-3):
    """J^T J with J by central finite differences of the outputs in the optimiser
    coordinates (relative step ``step``: pyomo.DoE's default scheme), two runs per
    parameter, each with its own error-controlled steps (one zero direction: the
    driver's cost is then a plain run's)."""
    run = _runner(model, test, sigma)
    W = np.zeros((len(model.param_names), 1))
    n = len(fr.names)
    cols = []
    for k in range(n):
        e = np.zeros(n)
        e[k] = step
        ys = []
        for z in (e, -e):
            pv = model.p()
            pv[fr.index] = fr.theta(z)
            ys.append(run(pv, W, rtol, atol)[0])
        cols.append((ys[0] - ys[1]) / (2 * step))
    J = np.column_stack(cols)
    return J.T @ J


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--save-candidates", default=None, metavar="FILE.npz",
                    help="the admissible candidates' information, for the optimiser alone on other BLAS kernels")
    a = ap.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    import ema_casadi as ema
    from ema_casadi.design import information, intervals
    from ema_casadi.simulation import sensitivity_library

    params = ema.load_parameters()
    model = ema.build_model(params)
    sensitivity_library(model, 7)  # compiled (or loaded from the cache) outside the timing
    load = os.getloadavg()[0]
    t0, c0 = time.perf_counter(), time.process_time()
    res = ema.design_experiment(params)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    comp = res.comparison()
    if a.save_candidates:
        np.savez(a.save_candidates, M=np.array([m for _, m in res.candidates]), slots=int(res.test.duration))
    out = {"load_average": load, "design_wall_s": wall, "design_cpu_s": cpu, "target_s": TARGET_S,
           "candidates_s": res.info["time_candidates"], "ipopt_s": res.info["time_optimiser"],
           "ipopt": res.info["ipopt"], "candidates": res.info["candidates"], "admissible": res.info["admissible"],
           "geometric_mean_ratio": comp["geometric_mean_ratio"], "corr_J_m_psi": res.correlation("J_m", "psi"),
           "corr_J_m_psi_standard": res.correlation("J_m", "psi", standard=True), "limits_used": res.usage,
           "standard_limits_used": res.info["standard_usage"], "cpu_count": os.cpu_count(),
           "widths": comp["parameters"]}
    if not a.quick:
        fr, sig = res.free, res.info["sigma"]
        rtol, atol = 1e-4, 1e-7  # identify's prediction tolerances
        M_ref = _exact_information(model, res.test, fr, sig, 1e-8, 1e-11)
        w_ref = intervals(M_ref, fr, fr.theta0)["width"]

        def err(M):
            w = intervals(M, fr, fr.theta0)["width"]
            return {n: float(w[k] / w_ref[k] - 1) for k, n in enumerate(fr.names)}

        fisher = {}
        for name, fn, tol in (("exact sensitivities", _exact_information, (rtol, atol)),
                              ("central FD, step 1e-3", _fd_information, (rtol, atol)),
                              ("central FD, step 1e-3, rtol 1e-8", _fd_information, (1e-8, 1e-11))):
            t = time.perf_counter()
            M = fn(model, res.test, fr, sig, *tol)
            fisher[name] = {"time_s": time.perf_counter() - t, "width_error": err(M)}
        t = time.perf_counter()
        information(model, res.test, fr, sig, threads=1)
        fisher["exact sensitivities"]["information_s"] = time.perf_counter() - t
        out["fisher"] = fisher
    if a.json:
        print(json.dumps(out, indent=1, default=float))
    else:
        print(f"load average {load:.1f}")
        print(f"design: {wall:.1f} s wall, {cpu:.1f} s CPU (target {TARGET_S:g} s); candidates "
              f"{out['candidates_s']:.1f} s, IPOPT {out['ipopt_s']:.2f} s ({out['ipopt']['status']}, "
              f"{out['ipopt']['iterations']} iterations)")
        print(f"widths {comp['geometric_mean_ratio']:.3g}x narrower (geometric mean) than chirp+steps+slews; "
              f"corr(J_m, psi) {out['corr_J_m_psi']:+.3f} (standard {out['corr_J_m_psi_standard']:+.3f})")
        print("limits used (fraction): designed " + ", ".join(f"{k} {v:.3g}" for k, v in res.usage.items())
              + "; standard " + ", ".join(f"{k} {v:.3g}" for k, v in res.info["standard_usage"].items()))
        for name, d in out.get("fisher", {}).items():
            e = max(abs(v) for v in d["width_error"].values())
            print(f"  FIM {name}: {d['time_s']:.2f} s, largest width error {100 * e:.3g} %")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
