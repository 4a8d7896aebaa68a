"""Benchmark: the reference scenario (1 s; 1 mm step at 0.01 s, 0.375 mm 1 Hz sine added
from 0.5 s; pmsm + elastic + smooth + ideal) with ema_casadi (compiled RODAS4, CVODES,
compiled RK4) against scipy solve_ivp
(LSODA, RK45) on a NumPy right-hand side of the same model and against python-control
nlsys + input_output_response. Every method is run at the loosest setting (from a
short ladder) that keeps its rod-position error <= 0.1 um against a tight-tolerance
reference (CVODES rtol 1e-10); wall times are medians of repeated runs (the
compiled rollout and the CVODES integrators are then reused, as in a sweep; the first
run is reported too), ratios measured in one run.

Usage: python benchmarks/bench_sim.py [--quick]   (--quick skips the slow peers)
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
import numpy_model  # noqa: E402
from _timing import timed  # noqa: E402

import ema_casadi as ema  # noqa: E402
from ema_casadi import Signal  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
T_END = 1.0
TOL = 0.1e-6
GRID = np.linspace(0, T_END, 1001)
X_CMD = Signal.step(1e-3, 0.01) + Signal.sine(0.375e-3, 1.0, 0.5)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="skip RK45 and python-control (minutes)")
    args = ap.parse_args()
    params = ema.load_parameters(ROOT / "models" / "cesa_ema.toml")
    model = ema.build_model(params)
    P = params.as_dict()
    ref = ema.simulate(model, T_END, X_CMD, solver="cvodes", dt_out=1e-3, rtol=1e-10, atol=1e-12)
    x_ref = ref["x_rod"]

    def err(x_rod):
        return float(np.abs(np.asarray(x_rod) - x_ref).max())

    rows, makers = [], {}

    def ladder(name, make, settings, repeat=3):
        for s in settings:
            t0 = time.perf_counter()
            x = make(s)
            cold = time.perf_counter() - t0
            if err(x) <= TOL:
                wall, x = timed(lambda s=s: make(s), repeat) if repeat > 1 else (cold, x)
                rows.append((name, s, wall, cold, err(x)))
                makers[name] = lambda s=s: make(s)
                print(f"{name:38s} {s!s:18s} {wall * 1e3:10.1f} ms (first run {cold * 1e3:.1f} ms)  "
                      f"err {err(x) * 1e6:.3f} um", flush=True)
                return
        print(f"{name}: no setting reached {TOL * 1e6} um", flush=True)

    # ema_casadi: compiled RODAS4, CVODES and compiled RK4 (compile time reported separately)
    t0 = time.perf_counter()
    ema.simulate(model, T_END, X_CMD, solver="rosenbrock", dt_out=1e-3)
    ros_build = time.perf_counter() - t0
    ladder("ema_casadi rosenbrock (compiled RODAS4)",
           lambda tol: ema.simulate(model, T_END, X_CMD, solver="rosenbrock", dt_out=1e-3, rtol=tol,
                                    atol=tol * 1e-3)["x_rod"],
           [1e-3, 3e-4, 1e-4, 3e-5, 1e-5, 1e-6, 1e-7, 1e-8], repeat=5)
    ladder("ema_casadi cvodes",
           lambda tol: ema.simulate(model, T_END, X_CMD, solver="cvodes", dt_out=1e-3, rtol=tol,
                                    atol=tol * 1e-3)["x_rod"],
           [1e-3, 3e-4, 1e-4, 3e-5, 1e-5, 1e-6, 1e-7, 1e-8], repeat=5)
    t0 = time.perf_counter()
    first = ema.simulate(model, T_END, X_CMD, dt=5e-6, dt_out=1e-3, solver="rk4")
    compile_time = time.perf_counter() - t0 - first.info["compute_time"]
    ladder("ema_casadi rk4 (compiled)", lambda dt: ema.simulate(model, T_END, X_CMD, dt=dt, dt_out=1e-3,
                                                                solver="rk4")["x_rod"],
           [1e-5, 5e-6, 2.5e-6])

    from scipy.integrate import solve_ivp

    def scipy_run(method, rtol):
        def f(t, x):
            return numpy_model.rhs(t, x, float(X_CMD(t)), 0.0, P["eta"], P)

        edges = [0.0, 0.01, 0.5, T_END]  # restart at the command's breakpoints, as ema_casadi does
        x0, xs = np.zeros(9), []
        for a, b in zip(edges[:-1], edges[1:], strict=True):
            sel = GRID[(GRID >= a) & (GRID < b)] if b < T_END else GRID[GRID >= a]
            sol = solve_ivp(f, (a, b), x0, method=method, t_eval=sel, rtol=rtol, atol=rtol * 1e-3)
            xs.append(sol.y[7])
            if sol.t[-1] == b:
                x0 = sol.y[:, -1]
            else:
                x0 = solve_ivp(f, (sol.t[-1], b), sol.y[:, -1], method=method, rtol=rtol, atol=rtol * 1e-3).y[:, -1]
        return np.concatenate(xs)

    ladder("scipy solve_ivp LSODA (NumPy RHS)", lambda tol: scipy_run("LSODA", tol),
           [1e-3, 3e-4, 1e-4, 3e-5, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9], repeat=5)
    if not args.quick:
        ladder("scipy solve_ivp RK45 (NumPy RHS)", lambda tol: scipy_run("RK45", tol), [1e-4, 1e-6, 1e-8], repeat=1)
        import control as ct

        def ct_run(method, rtol):
            sys_ = ct.nlsys(lambda t, x, u, params: numpy_model.rhs(t, x, float(X_CMD(t)), 0.0, P["eta"], P),
                            lambda t, x, u, params: x[7], states=9, inputs=0, outputs=1, name="ema")
            kw = {"solve_ivp_kwargs": {"rtol": rtol, "atol": rtol * 1e-3}}
            if method:
                kw["solve_ivp_method"] = method
            return ct.input_output_response(sys_, GRID, 0, np.zeros(9), **kw).outputs

        ladder("python-control nlsys (default RK45)", lambda tol: ct_run(None, tol), [1e-4, 1e-6, 1e-8], repeat=1)
        ladder("python-control nlsys (LSODA)", lambda tol: ct_run("LSODA", tol),
               [1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9], repeat=1)

    # headline ratio, robust to the machine's drift: the fastest ema_casadi method and
    # the fastest SciPy method timed alternately, 15 rounds, medians
    ours = min((r for r in rows if r[0].startswith("ema_casadi")), key=lambda r: r[2])[0]
    peer = min((r for r in rows if r[0].startswith("scipy")), key=lambda r: r[2])[0]
    t_ours, t_peer = [], []
    for _ in range(15):
        for name, acc in ((ours, t_ours), (peer, t_peer)):
            t0 = time.perf_counter()
            makers[name]()
            acc.append(time.perf_counter() - t0)
    m_ours, m_peer = statistics.median(t_ours), statistics.median(t_peer)
    ratios = sorted(b / a for a, b in zip(t_ours, t_peer, strict=True))
    print(f"\nalternating, 15 rounds: {ours} {m_ours * 1e3:.2f} ms, {peer} {m_peer * 1e3:.1f} ms: "
          f"ratio of medians {m_peer / m_ours:.1f}x (per-round ratios {ratios[0]:.1f}-{ratios[-1]:.1f}x, "
          f"median {statistics.median(ratios):.1f}x; every round >= 18x: {ratios[0] >= 18})")

    best = min(w for n, s, w, c, e in rows if n.startswith("ema_casadi"))
    print("\n| method | setting | wall time, median (ms) | first run (ms) | error (um) | ratio to fastest ema_casadi |")
    print("|---|---|---|---|---|---|")
    for n, s, w, c, e in rows:
        print(f"| {n} | {s} | {w * 1e3:.1f} | {c * 1e3:.1f} | {e * 1e6:.3f} | {w / best:.1f}x |")
    print(f"\nema_casadi rk4 one-time build + compile (disk-cached afterwards): {compile_time:.2f} s; "
          f"rosenbrock first run (build + compile, or loading the disk cache): {ros_build:.2f} s")


if __name__ == "__main__":
    main()
