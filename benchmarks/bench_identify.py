"""Benchmark: parameter identification, seven free parameters from four records (target:
under 10 s, and at least 10x faster to the same cost than a finite-difference fit).

The problem: the seven-parameter recovery case of
:func:`ema_casadi.identification.recovery_records` (F_seal, C_bear, c_v, B, C, J_m, psi,
20-100 % from the reference set; records of 2.5-4 s at 2 kHz: steps, a 0.5 mm chirp
0.5-25 Hz, slews under +8 kN and -15 kN; rod position and q-current with 0.3 um /
0.05 A noise), fitted from the reference values with the noise levels given.

- ``ema.identify``: trust-region least squares with the exact Jacobian from the
  compiled RODAS4 with forward sensitivities.
- The peer, what a user would write today: ``scipy.optimize.least_squares`` (trf,
  finite-difference Jacobian, ``diff_step`` 1e-4 on log-parameters, the same bounds
  and scaling) around ``ema.simulate(..., solver="rosenbrock", p=params.vector(**theta))``
  at its default tolerances, the records' inputs fed as the same tables.

Both run in one process, one after the other, from the same start. Each residual
evaluation logs (time, cost); "time to the same cost" is when a method's best cost
first falls to the worse of the two final costs (x (1 + 1e-6)), in wall time and in
the process's CPU time (all threads). The machine's load average is printed: on a
shared machine the load changes between the two phases, which moves the wall-time
ratio; the CPU-time ratio is the steadier comparison.

Usage::

    .venv/bin/python benchmarks/bench_identify.py [--json] [--quick]

``--quick`` skips the peer (the identify time only). The robust intervals' own time
(the Newey-West sandwich and the records' scale factor from the optimum's Jacobian
and residuals, no model run) is printed as a fraction of the rest of the fit
(target: under 20 %).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
TARGET_S = 10.0
SIGMA = {"x_rod": 0.3e-6, "i_q": 0.05}


def _peer(params, paths, free, log):
    """scipy least_squares with a finite-difference Jacobian around ema.simulate."""
    from scipy.optimize import least_squares

    import ema_casadi as ema
    from ema_casadi.identification import read_record

    model = ema.build_model(params)
    recs = [read_record(p, model) for p in paths]
    theta0 = np.array([params.as_dict()[n] for n in free])
    t0, c0 = time.perf_counter(), time.process_time()

    def fun(z):
        theta = theta0 * np.exp(z)
        pv = params.vector(**dict(zip(free, theta, strict=True)))
        r = []
        for rec in recs:
            sig = {k: ema.Signal.table(rec.t, v) for k, v in rec.inputs.items()}
            try:
                res = ema.simulate(model, rec.t[-1], solver="rosenbrock", dt_out=rec.t[1] - rec.t[0], p=pv, **sig)
            except ema.RunFailed:
                return np.full(sum(len(x.t) - 1 for x in recs) * 2, 1e6)
            for c, meas in rec.channels.items():
                r.append((meas[1:] - res[c][1:]) / SIGMA[c])
        r = np.concatenate(r)
        log.append((time.perf_counter() - t0, 0.5 * float(r @ r), time.process_time() - c0))
        return r

    sol = least_squares(fun, np.zeros(len(free)), diff_step=1e-4, method="trf", x_scale=1.0)
    return {"wall": time.perf_counter() - t0, "cpu": time.process_time() - c0, "cost": float(sol.cost),
            "evaluations": int(sol.nfev + sol.njev * len(free)),
            "estimate": dict(zip(free, (theta0 * np.exp(sol.x)).tolist(), strict=True))}


def _ours(params, paths, free, log):
    from ema_casadi.identification import _fit, identify

    orig = _fit._Fit._raw
    orig_robust = _fit.robust_of
    robust_s, robust_cpu = [], []

    def robust(fit, out, structural=None):  # the robust covariance's own time (no model run: J and r of the optimum)
        t, c = time.perf_counter(), time.process_time()
        got = orig_robust(fit, out, structural)
        robust_s.append(time.perf_counter() - t)
        robust_cpu.append(time.process_time() - c)
        return got

    t0, c0 = time.perf_counter(), time.process_time()

    def raw(self, z):  # log (time, cost) at each model evaluation, with the fit's weights
        out = orig(self, z)
        if out is not None:
            cost = 0.5 * sum(float(np.sum((e / SIGMA[k[1]]) ** 2)) for k, e in out[1].items())
            log.append((time.perf_counter() - t0, cost, time.process_time() - c0))
        return out

    _fit._Fit._raw = raw
    _fit.robust_of = robust
    try:
        # the fit itself (the peer does no more); the records-consistency test adds about half the CPU time
        res = identify(params, paths, free, sigma=SIGMA, consistency=False)
    finally:
        _fit._Fit._raw = orig
        _fit.robust_of = orig_robust
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    return {"wall": wall, "cpu": cpu, "cost": res.info["cost"],
            "robust_s": sum(robust_s), "robust_fraction": sum(robust_s) / (wall - sum(robust_s)),
            "robust_cpu_s": sum(robust_cpu), "robust_cpu_fraction": sum(robust_cpu) / (cpu - sum(robust_cpu)),
            "std_textbook": res.std_textbook,
            "evaluations": res.info["evaluations"],
            "estimate": res.estimate, "std": res.std, "identifiable": res.identifiable}


def _time_to(log, cost, cpu=False):
    """Wall (or CPU) time when the best cost first reaches ``cost``."""
    best = np.inf
    for t, c, tc in log:
        best = min(best, c)
        if best <= cost:
            return tc if cpu else t
    return float("nan")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--quick", action="store_true", help="identify only, no peer")
    args = ap.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    import ema_casadi as ema
    from ema_casadi.identification import recovery_records

    params = ema.load_parameters(ROOT / "models" / "cesa_ema.toml")
    with tempfile.TemporaryDirectory() as tmp:
        paths, truth = recovery_records(params, tmp, seed=100)
        free = list(truth)
        from ema_casadi.simulation import sensitivity_library

        model = ema.build_model(params)  # the compiled libraries built or loaded from the disk cache (not timed)
        sensitivity_library(model, len(free))
        ema.simulate(model, 1e-3, solver="rosenbrock")
        ours_log, peer_log = [], []
        ours = _ours(params, paths, free, ours_log)
        peer = None if args.quick else _peer(params, paths, free, peer_log)
    load = os.getloadavg()[0]
    out = {"load_average": load, "ours": ours, "truth": truth, "target_s": TARGET_S}
    if peer is not None:
        target = max(ours["cost"], peer["cost"]) * (1 + 1e-6)
        t_ours, t_peer = _time_to(ours_log, target), _time_to(peer_log, target)
        c_ours, c_peer = _time_to(ours_log, target, True), _time_to(peer_log, target, True)
        out.update(peer=peer, target_cost=target, time_to_cost={"ours": t_ours, "peer": t_peer},
                   cpu_to_cost={"ours": c_ours, "peer": c_peer}, ratio=t_peer / t_ours, cpu_ratio=c_peer / c_ours)
    if args.json:
        print(json.dumps(out, indent=1, default=float))
        return
    print(f"load average {load:.2f}")
    print(f"ema.identify: {ours['wall']:.2f} s wall ({ours['cpu']:.2f} s CPU), {ours['evaluations']} evaluations, "
          f"cost {ours['cost']:.6g} "
          f"(target < {TARGET_S:g} s: {'met' if ours['wall'] < TARGET_S else 'NOT met'})")
    print(f"robust intervals: {ours['robust_s']:.3f} s wall ({ours['robust_cpu_s']:.3f} s CPU), "
          f"{100 * ours['robust_fraction']:.2f} % of the fit's wall time without them "
          f"({100 * ours['robust_cpu_fraction']:.2f} % of its CPU time; target < 20 %)")
    for n in free:
        z = (ours["estimate"][n] - truth[n]) / ours["std"][n]
        ratio = ours["std"][n] / ours["std_textbook"][n]
        print(f"  {n:7s} truth {truth[n]:.6g}  estimate {ours['estimate'][n]:.6g}  ({z:+.2f} robust sigma; "
              f"robust / textbook sd {ratio:.3f})")
    if peer is not None:
        print(f"peer (least_squares, finite differences, ema.simulate rosenbrock): {peer['wall']:.2f} s wall "
              f"({peer['cpu']:.2f} s CPU), "
              f"{peer['evaluations']} evaluations, cost {peer['cost']:.6g}")
        print(f"time to cost {out['target_cost']:.6g}: ema.identify {out['time_to_cost']['ours']:.2f} s, peer "
              f"{out['time_to_cost']['peer']:.2f} s: ratio {out['ratio']:.1f}x (target >= 10x); CPU time "
              f"{out['cpu_to_cost']['ours']:.2f} s vs {out['cpu_to_cost']['peer']:.2f} s: {out['cpu_ratio']:.1f}x")


if __name__ == "__main__":
    main()
