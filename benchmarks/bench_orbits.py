"""Benchmark: a periodic orbit found by shooting against the simulation that shows it.

Hunting case (PI position loop, K_i_x = 3000 1/s^2, smooth friction, reference set):
``ema.periodic_orbit`` from its 2 s start run to the converged orbit with multipliers,
against a 4 s variable-step RODAS4 run (the long simulation the tests measure the orbit
against) and the hunting study's 6 s RK4 run at 1e-5 s. With ``--aircraft`` also the
747 loop with backlash (hybrid friction: the finite-difference fallback) against its
300 s RK4 run at 1e-4 s. Compiled libraries are built (or loaded) by a warm-up first.

Usage::

    .venv/bin/python benchmarks/bench_orbits.py [--aircraft] [--json]

The machine's load average is printed: figures taken while other jobs run are upper bounds.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
MODEL = ROOT / "models" / "cesa_ema.toml"


def _timed(fn):
    t0 = time.perf_counter()
    out = fn()
    return time.perf_counter() - t0, out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--aircraft", action="store_true", help="also the aircraft loop with backlash (slow)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    load0 = os.getloadavg()[0]
    import ema_casadi as ema
    from ema_casadi import Signal
    from ema_casadi.limitcycle import setup

    params = ema.load_parameters(MODEL)
    model = ema.build_model(params, {"controller": "PI", "friction": "smooth"})
    p = model.p(K_i_x=3000.0)
    step = Signal.step(1e-3, 0.01)
    ema.periodic_orbit(model, "position", p=p)  # warm-up: builds or loads the compiled drivers
    ema.simulate(model, 0.1, x_cmd=step, p=p, dt=1e-5, dt_out=1e-3, solver="rk4")
    t_orb, orb = _timed(lambda: ema.periodic_orbit(model, "position", p=p))
    t_ros, _ = _timed(lambda: ema.simulate(model, 4.0, x_cmd=step, p=p, dt_out=1e-5, rtol=1e-9, atol=1e-12))
    t_rk4, _ = _timed(lambda: ema.simulate(model, 6.0, x_cmd=step, p=p, dt=1e-5, dt_out=1e-3, solver="rk4"))
    out = {"hunting orbit by shooting (2 s start run included) s": t_orb,
           "hunting 4 s RODAS4 run (rtol 1e-9) s": t_ros, "hunting 6 s RK4 run at 1e-5 s s": t_rk4,
           "orbit freq Hz": orb.freq_hz, "orbit Newton steps": orb.info["iterations"]}
    if args.aircraft:
        ac = ema.build_model(params, {"airframe": "b747", "friction": "hybrid", "screw": "rigid"})
        pa = ac.p(B=3e-4)
        s = setup(ac, "aircraft", pa)
        s["confirm"](1.0, 1e-4)  # warm-up
        t_aorb, aorb = _timed(lambda: ema.periodic_orbit(ac, "aircraft", p=pa, t_warm=100.0))
        t_asim, _ = _timed(lambda: s["confirm"](300.0, 1e-4))
        out.update({"aircraft orbit (100 s start run, FD fallback) s": t_aorb,
                    "aircraft 300 s RK4 run at 1e-4 s s": t_asim, "aircraft orbit freq Hz": aorb.freq_hz})
    out["load_average"] = (load0, os.getloadavg()[0])
    if args.json:
        json.dump(out, sys.stdout, indent=1)
        print()
        return 0
    print("| periodic orbits | value |\n|---|---|")
    for k, v in out.items():
        print(f"| {k} | {v if isinstance(v, tuple) else f'{v:.4g}'} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
