"""Benchmark: the aircraft loop against its targets.

Targets: margins of the whole aircraft loop (trim at the flight condition, the loop
transfer at the actuator-command break with the linearised EMA, frequency.margins) in
under 0.2 s after import (model build and first Jacobian included, measured from a fresh
process state: the first call); a 300 s nonlinear aircraft simulation with hybrid
friction at 1e-4 s (RK4, compiled rollout, loaded from the cache when present) in under
10 s. Also the repeated margins (model built) and the wall time per RK4 step.

Usage::

    .venv/bin/python benchmarks/bench_aircraft.py [--repeat 5] [--json]

The machine's load average is printed: figures taken while other jobs run are upper bounds.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _timing import timed  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
MODEL = ROOT / "models" / "cesa_ema.toml"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--t-end", type=float, default=300.0)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    load0 = os.getloadavg()[0]
    t0 = time.perf_counter()
    import ema_casadi as ema
    from ema_casadi.aircraft import aircraft_margins, aircraft_point

    t_import = time.perf_counter() - t0
    params = ema.load_parameters(MODEL)
    t0 = time.perf_counter()
    model = ema.build_model(params, {"airframe": "transport"})
    first = aircraft_margins(model, "cruise_sl")
    t_first = time.perf_counter() - t0
    t_again, _ = timed(lambda: aircraft_margins(model, "cruise_sl"), args.repeat)

    hyb = ema.build_model(params, {"airframe": "transport", "friction": "hybrid"})
    op = aircraft_point(hyb, "cruise_sl")
    kw = dict(dt=1e-4, dt_out=0.1, x0=op.x, **op.policy["trim_free"])
    ema.simulate(hyb, 0.1, **kw)  # compiles or loads the rollout
    t_sim, res = timed(lambda: ema.simulate(hyb, args.t_end, **kw), 1)
    out = {
        "import_s": t_import,
        "margins_first_call_s (build + trim + linearise + margins)": t_first,
        "margins_repeated_s": t_again,
        "pm_ema_deg": first.ema.pm_deg, "gm_ema_db": first.ema.gm_db,
        f"sim_{args.t_end:g}s_hybrid_1e-4_s": t_sim,
        "us_per_step": t_sim / (args.t_end / 1e-4) * 1e6,
        "mode_switches": res.info.get("mode_switches"),
        "targets": {"margins_s": 0.2, "sim_300s_s": 10.0},
        "load_average": [load0, os.getloadavg()[0]],
    }
    if args.json:
        print(json.dumps(out, indent=1))
    else:
        print("| aircraft loop | s |\n|---|---|")
        for k, v in out.items():
            if isinstance(v, float):
                print(f"| {k} | {v:.4g} |")
        print(f"load average {out['load_average']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
