"""Benchmark: the minimum-time move against rockit on the same problem.

Two problems, the motor voltages as the control (``ema.optimal_move(..., through="drive")``),
40 intervals on the cosine-clustered grid, the same operating limits at every node
(current, voltage circle, i_d >= 0, stroke, rated rod speed), the same end (at the
target, at rest) and the same initial guess:

- ``noload``: 10 mm at no load on the rigid, frictionless reference actuator, by multiple
  shooting with the same RK4 substeps (rockit's ``MultipleShooting``);
- ``loaded``: 10 mm against 15 kN on the reference actuator (smooth friction, the screw's
  efficiency switch), the stiff case ``ema`` collocates (Radau IIA of degree 3, rockit's
  ``DirectCollocation`` with the same points). ``ema`` starts from the switch widened
  (its continuation); rockit is given the problem as it is, from the same guess.

rockit (``pip install rockit-meco``, a benchmark peer only; without it the rockit
column is skipped with a message) is given the model's own ``f_held`` as its
right-hand side. Reported: both optima (the same within 1e-4 relative), IPOPT's status
and iterations, and the time to solution of each, side by side (one run each, the same
process: a ratio, not an absolute figure).

Usage::

    .venv/bin/python benchmarks/bench_optimal.py [--case noload|loaded|all] [--json]

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

import ema_casadi as ema
from ema_casadi.optimal import Problem, initial_guess, solve

ROOT = Path(__file__).resolve().parent.parent
MODEL = ROOT / "models" / "cesa_ema.toml"
FRICTIONLESS = {"F_seal": 0.0, "C_bear": 0.0, "c_v": 0.0, "b_m": 0.0}
IPOPT = {"print_level": 0, "max_iter": 500, "tol": 1e-8, "mu_strategy": "monotone", "mu_init": 1e-2}


def problem(case):
    params = ema.load_parameters(MODEL)
    if case == "noload":
        model = ema.build_model(params.replace(**FRICTIONLESS), {"screw": "rigid"})
        return Problem(model, 0.01, 0.0, "time", None, 0.0, "drive", 40, False)
    return Problem(ema.build_model(params), 0.01, 15e3, "time", None, 0.0, "drive", 40, False)


def ours(prob):
    t0 = time.perf_counter()
    sol = solve(prob)
    return {"T_s": sol["T"], "status": sol["status"], "iterations": sol["iterations"], "method": sol["method"],
            "time_to_solution_s": time.perf_counter() - t0}


def rockit_solve(prob, x0, guess, substeps):
    from rockit import DirectCollocation, FreeTime, MultipleShooting, Ocp
    from rockit.sampling_method import FunctionGrid

    m, N = prob.model, prob.N
    t0 = time.perf_counter()
    scale = np.maximum(m.full_scale(prob.p), 1e-6)
    ocp = Ocp(T=FreeTime(guess["T"]))
    xs = ocp.state(m.nx)
    cs = ocp.control(len(prob.controls))
    c_scale = prob._control_scale()
    x, c = ca.diag(scale) @ xs, ca.diag(c_scale) @ cs
    u0 = m.u(prob.p, **{prob.load_input: prob.load, prob.cmd: prob.target})
    h = ca.MX.zeros(len(m.holds))
    for j, i in enumerate(prob.controls):
        h[i] = c[j]
    xdot, y = m.f_held(x, u0, prob.p, h)
    rest = m.rest_states(prob.p)
    # a memory state at rest on its signal: its rate that of the signal (it is read by nothing here)
    for n, sig in rest.items():
        xdot[m.index(n)] = ca.jacobian(prob._signal(sig, x, y), xs) @ (xdot / scale)
    ocp.set_der(xs, xdot / scale)
    lim = prob.limits
    for r in prob.ratings:
        s = [prob._signal(n, x, y) for n in r.signals]
        if r.sense == "norm":
            ocp.subject_to(sum(v**2 for v in s) / lim[r.name] ** 2 <= 1, include_last=True)
        elif r.sense == "max":
            ocp.subject_to(s[0] <= lim[r.name], include_last=True)
        else:
            ocp.subject_to(s[0] >= lim[r.name], include_last=True)
    ocp.subject_to(ocp.at_t0(xs) == x0 / scale)
    ocp.subject_to(ocp.at_tf(prob._signal(prob.rod, x, y)) == prob.target)
    implied = prob._kinematic()  # a rate zero where the speeds are (the shaft angle's): not again
    for i, n in enumerate(m.states):
        roles = m.state_info[n].roles
        if "temperature" in roles or "controller_integral" in roles or n in rest or i in implied:
            continue
        ocp.subject_to(ocp.at_tf(xdot[i] / (scale[i] / guess["T"])) == 0)
        if {"shaft_speed", "rod_velocity", "contact_velocity"} & set(roles):
            ocp.subject_to(ocp.at_tf(xs[i]) == 0)
    ocp.subject_to(ocp.T >= 0.05 * guess["T"])
    ocp.add_objective(ocp.T / guess["T"])
    frac = prob.fractions()
    grid = FunctionGrid(lambda n: list(frac))
    if prob.method == "collocation":
        ocp.method(DirectCollocation(N=N, M=1, degree=3, scheme="radau", grid=grid, expand=True))
    else:
        ocp.method(MultipleShooting(N=N, M=substeps, intg="rk", grid=grid, expand=True))
    ocp.solver("ipopt", {"print_time": False, "ipopt.sb": "yes", "ipopt": IPOPT})
    ocp.set_initial(xs, guess["X"][:, 0] / scale)
    ocp.set_initial(cs, guess["C"][:, 0] / c_scale)
    setup = time.perf_counter() - t0
    try:
        sol = ocp.solve()
    except RuntimeError:  # IPOPT stopped short: its last iterate
        sol = ocp.non_converged_solution
    stats = sol.stats
    return {"T_s": float(sol.value(ocp.T)), "status": stats["return_status"], "iterations": stats["iter_count"],
            "time_to_solution_s": time.perf_counter() - t0, "setup_s": setup}


def compare(case):
    prob = problem(case)
    a = ours(prob)
    out = {"case": case, "ema": a}
    try:
        import rockit  # noqa: F401
    except ImportError:
        out["rockit"] = None
        out["skipped"] = "rockit not installed (pip install rockit-meco): the ema column alone"
        return out
    x0 = prob.start_state()
    guess = initial_guess(prob, x0)
    b = rockit_solve(prob, x0, guess, prob.substeps)
    rel = abs(a["T_s"] - b["T_s"]) / a["T_s"]
    out.update({"rockit": b, "relative_difference": rel, "same_optimum_1e-4": rel < 1e-4,
                "speed_ratio_rockit_over_ema": b["time_to_solution_s"] / a["time_to_solution_s"]})
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", choices=("noload", "loaded", "all"), default="all")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    cases = ("noload", "loaded") if args.case == "all" else (args.case,)
    out = {"load_average": os.getloadavg(), "cases": [compare(c) for c in cases]}
    if args.json:
        print(json.dumps(out, indent=1))
        return
    print(f"load average {out['load_average']}")
    for c in out["cases"]:
        print(f"{c['case']} ({c['ema']['method']})")
        if c.get("skipped"):
            print(f"  {c['skipped']}")
        print(f"  {'':8s} {'T (s)':>12s} {'status':>28s} {'iter':>5s} {'time (s)':>9s}")
        for k in ("ema", "rockit"):
            r = c[k]
            if r is not None:
                print(f"  {k:8s} {r['T_s']:12.8f} {r['status']:>28s} {r['iterations']:5d} "
                      f"{r['time_to_solution_s']:9.2f}")
        if c.get("rockit"):
            print(f"  relative difference {c['relative_difference']:.2e} "
                  f"(same optimum within 1e-4: {c['same_optimum_1e-4']})")


if __name__ == "__main__":
    main()
