"""Benchmark: the optimisation layer's three transcriptions, the measurements behind its
choice rule (``ema_casadi.optimisation``, docs: architecture).

Two parts:

- ``estimate``: parameters of a lightly damped oscillator with smooth Coulomb friction
  (a stand-in for a position loop at small commands: x'' + c x' + k x + F tanh(x'/v_s)
  = u, k = (2 pi 2 Hz)^2, c = 0.5 1/s, F = 2 m/s^2, v_s = 5 mm/s) from a 10 s record of
  x (steps and a slow sine, 400 intervals of 25 ms, RK4 with 8 substeps, noise 1e-4),
  fitted by IPOPT (the layer's wrapper) from starts with k, c and F all off by a factor
  (x0.25, x0.4, x2.5, x4):
  single shooting (one rollout from the start), multiple shooting and Radau collocation
  (the node states started from the record: x measured, x' by differences). Reported
  per start and transcription: whether it reached the truth (every estimate within 1 %),
  IPOPT's iterations, wall time.
- ``move``: the reference 10 mm minimum-time move, unloaded and against 15 kN, by
  multiple shooting and by collocation (``ema.optimal``'s ``method``): time to solution,
  iterations, optimum (the stiff case's RK4 substeps make the shooting NLP large).

Usage::

    .venv/bin/python benchmarks/bench_transcriptions.py [--part estimate|move|all] [--json]

The machine's load average is printed: figures taken while other jobs run are upper bounds.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import casadi as ca
import numpy as np

from ema_casadi.optimisation import METHODS, decision_parameters, solve_ipopt, transcribe

ROOT = Path(__file__).resolve().parent.parent
TRUTH = np.array([(2 * np.pi * 2.0) ** 2, 0.5, 2.0])  # k (1/s^2), c (1/s), F (m/s^2)
V_S = 5e-3
N, T_END, SUBSTEPS, SIGMA = 400, 10.0, 8, 1e-4
FACTORS = (0.25, 0.4, 2.5, 4.0)


def _rate(x, u, p):
    return ca.vertcat(x[1], u - p[1] * x[1] - p[0] * x[0] - p[2] * ca.tanh(x[1] / V_S))


def _interval():
    x, u, p, dt = ca.SX.sym("x", 2), ca.SX.sym("u"), ca.SX.sym("p", 3), ca.SX.sym("dt")
    h, xk = dt / SUBSTEPS, x
    for _ in range(SUBSTEPS):
        k1 = _rate(xk, u, p)
        k2 = _rate(xk + h / 2 * k1, u, p)
        k3 = _rate(xk + h / 2 * k2, u, p)
        k4 = _rate(xk + h * k3, u, p)
        xk = xk + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return ca.Function("F", [x, u, p, dt], [xk])


def _record(F):
    t = np.linspace(0, T_END, N + 1)
    u = 40.0 * ((t[:-1] % 4.0) < 2.0) - 20.0 + 10.0 * np.sin(2 * np.pi * 0.3 * t[:-1])
    x, X = np.zeros(2), [np.zeros(2)]
    for k in range(N):
        x = np.array(F(x, u[k], TRUTH, t[1] - t[0])).ravel()
        X.append(x)
    X = np.array(X).T
    return t, u, X[0] + np.random.default_rng(7).normal(0, SIGMA, N + 1), X


def fit(method, factor, F, t, u, y):
    opti = ca.Opti()
    p, z = decision_parameters(opti, TRUTH * factor, [0, 1, 2])
    U, dts = ca.DM(u).T, ca.DM(np.diff(t)).T
    guess = np.vstack([y, np.gradient(y, t)])

    sx = [ca.SX.sym("x", 2), ca.SX.sym("u"), ca.SX.sym("p", 3)]
    f = ca.Function("f", sx, [_rate(*sx)])

    def rates(X, Uc):  # (xdot, y) at the columns of X: the output is the state
        n = X.shape[1]
        return f.map(n)(X, Uc, ca.repmat(p, 1, n)), X

    tr = transcribe(opti, method, x0=np.zeros(2), guess=guess, scale=np.array([0.1, 1.0]), U=U, dts=dts,
                    rates=rates, interval=F, interval_args=(U, ca.repmat(p, 1, N), dts))
    opti.minimize(0.5 * ca.sumsqr((tr.X[0, :] - ca.DM(y).T) / SIGMA) / N)
    res = solve_ipopt(opti, {"max_iter": 300, "tol": 1e-8}, expand=True)
    est = np.array(res.value(p), float).ravel()
    err = np.abs(est / TRUTH - 1)
    return {"method": method, "factor": factor, "status": res.status, "iterations": res.iterations,
            "wall_s": res.wall_s, "max_rel_error": float(err.max()), "truth_reached": bool(err.max() < 0.01)}


def estimate() -> list:
    F = _interval()
    t, u, y, _ = _record(F)
    return [fit(m, f, F, t, u, y) for f in FACTORS for m in METHODS]


def move() -> list:
    import ema_casadi as ema
    from ema_casadi.optimal import Problem, solve

    model = ema.build_model(ema.load_parameters(ROOT / "models" / "cesa_ema.toml"))
    rows = []
    for load in (0.0, 15e3):
        for method in ("shooting", "collocation"):
            prob = Problem(model, 0.01, load, "time", None, 0.0, "drive", 40, False, method=method)
            t0 = time.perf_counter()
            try:
                sol = solve(prob)
                row = {"T_s": sol["T"], "status": sol["status"], "iterations": sol["iterations"]}
            except ema.optimal.Infeasible as exc:
                row = {"T_s": None, "status": str(exc)[:80], "iterations": None}
            rows.append({"load_N": load, "method": method, "substeps": prob.substeps,
                         "time_to_solution_s": time.perf_counter() - t0, **row})
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--part", choices=("estimate", "move", "all"), default="all")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    out = {"load_average": os.getloadavg()}
    if a.part in ("estimate", "all"):
        out["estimate"] = estimate()
    if a.part in ("move", "all"):
        out["move"] = move()
    if a.json:
        print(json.dumps(out, indent=1))
        return
    print(f"load average {out['load_average'][0]:.2f}")
    for r in out.get("estimate", []):
        print(f"start x{r['factor']:<4} {r['method']:<12} {r['status']:<28} {r['iterations']:>4} it "
              f"{r['wall_s']:7.2f} s  max error {r['max_rel_error']:.2e}  {'truth' if r['truth_reached'] else '-'}")
    for r in out.get("move", []):
        print(f"10 mm against {r['load_N'] / 1e3:g} kN {r['method']:<12} substeps {r['substeps']:>4}  "
              f"{r['status']:<18} {r['iterations']} it  {r['time_to_solution_s']:.2f} s  T {r['T_s']}")


if __name__ == "__main__":
    main()
