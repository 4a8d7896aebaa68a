"""Benchmark: what the ECU structure options cost the variable-step solvers.

Step counts (and wall times, medians after a warm-up run) of CVODES and the compiled
RODAS4 (rtol 1e-8, atol 1e-11, output every 1 ms) on the reference set (pmsm + elastic
screw + smooth friction, P position loop), continuous ECU:

- ``hold``: a 15 kN load step at 0.05 s held at standstill for 1 s (x_cmd = 0): the
  screw-efficiency switch sits on the transmitted power q = F omega p/2pi = 0, the case
  an exact switch turns into a sliding mode; P_blend = 0.1 W (the default), 0.02 W, 0;
- ``slews``: +-5 mm slews at the rate limit under 8 kN (the loaded-slew record of
  studies/ecu_records.py, 3 s): the efficiency switch crosses at every reversal and the
  PIs saturate at each start and stop; P_blend 0.1 / 0.02 / 0 W, and anti_windup =
  clamping and limit_shape = smooth at the default width.

Step counts are the solvers' accepted steps (``SimResult.info["steps"]``); they do not
depend on the machine load, wall times do (run alone for meaningful times).

The exact switch (P_blend = 0) makes a sliding mode while the load is held: RODAS4
gives up within a second, CVODES runs into its 10^7-step cap after minutes; those runs
are made only with ``--exact`` and reported as failed at the time they stopped.

Usage: python benchmarks/bench_ecu_structure.py [--quick] [--exact]   (--quick: one repeat)
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import ema_casadi as ema
from ema_casadi.simulation import RunFailed

ROOT = Path(__file__).resolve().parent.parent

SCENARIOS = {
    "hold": (1.05, {"x_cmd": 0.0, "f_ext": "step:15kN@0.05"}),
    "slews": (3.0, {"x_cmd": "step:5mm@0.3+step:-10mm@1.3+step:5mm@2.3", "f_ext": "step:8kN@0.1"}),
}
CASES = [  # label, variants, P_blend (W)
    ("default (backcalc, clip, 0.1 W)", {}, 0.1),
    ("P_blend = 0.02 W", {}, 0.02),
    ("anti_windup = clamping", {"anti_windup": "clamping"}, 0.1),
    ("limit_shape = smooth", {"limit_shape": "smooth"}, 0.1),
]


def _signals(params, spec, t_end):
    out = {}
    for name, value in spec.items():
        kind = "length" if name == "x_cmd" else "force"
        out[name] = ema.parse_signal(value, kind, stroke=params.actuator.stroke, duration=t_end) \
            if isinstance(value, str) else value
    return out


def _one(model, t_end, solver, p, sig, repeats):
    walls, res = [], None
    for _ in range(repeats + 1):
        t0 = time.perf_counter()
        try:
            res = ema.simulate(model, t_end, solver=solver, dt=1e-3, p=p, **sig)
        except RunFailed as exc:
            return f"fails at t = {exc.time:.4g} s", time.perf_counter() - t0
        walls.append(time.perf_counter() - t0)
    return res.info.get("steps"), statistics.median(walls[1:])


def run(repeats: int, exact: bool = False) -> list[dict]:
    params = ema.load_parameters(ROOT / "models" / "cesa_ema.toml")
    rows = []
    for scen, (t_end, spec) in SCENARIOS.items():
        sig = _signals(params, spec, t_end)
        cases = CASES + ([("P_blend = 0 (exact switch)", {}, 0.0)] if exact else [])
        for label, variants, blend in cases:
            if scen == "hold" and variants:
                continue
            model = ema.build_model(params, variants)
            p = params.vector(P_blend=blend)
            for solver in ("cvodes", "rosenbrock"):
                steps, wall = _one(model, t_end, solver, p, sig, 0 if blend == 0 else repeats)
                rows.append({"scenario": scen, "case": label, "solver": solver, "steps": steps, "wall_s": wall})
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="one repeat instead of three")
    ap.add_argument("--exact", action="store_true", help="also the exact switch (CVODES: minutes until it fails)")
    args = ap.parse_args(argv)
    rows = run(1 if args.quick else 3, args.exact)
    print("| scenario | case | solver | steps | wall (s) |\n|---|---|---|---:|---:|")
    for r in rows:
        print(f"| {r['scenario']} | {r['case']} | {r['solver']} | {r['steps']} | {r['wall_s']:.3f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
