"""Benchmark: a periodic orbit found by shooting against the simulation that shows it.

"The simulation that shows it" is defined here as the run a user would make to see the
same orbit to the same accuracy: the loop's own scenario (the 1 mm command step held)
with the same variable-step RODAS4 (rtol 1e-8: its settled period is within 5e-9 of the
orbit's), run just until every period after it agrees with the shooting's period within
``--eps`` (relative, default 1e-6) and its last period's first harmonic of x_rod with the
orbit's within ``10 * eps``. How long that is depends on how strongly the orbit attracts:
the transient shrinks by the largest nontrivial Floquet multiplier |mu| per period. The
settling time is read off an untimed long run, then a run of exactly that length is timed.

Cases (PI position loop, K_i_x = 3000 1/s^2, smooth friction, the reference set):
``B = 20 um`` (the reference play: |mu| = 0.055, a disturbed run is back in two periods)
and ``B = 0.5 um`` (near the orbit's birth at B = 0: |mu| = 0.61). Each: the shooting
from its 2 s start run (included) to the converged orbit with its multipliers, and the
simulation that shows it; both timed in this process, after a warm-up that builds or
loads every compiled library.

With ``--aircraft`` also the 747 loop with backlash (hybrid friction: the
finite-difference fallback) against its 300 s RK4 run at 1e-4 s (the study's run).

Usage::

    .venv/bin/python benchmarks/bench_orbits.py [--eps 1e-6] [--aircraft] [--json]

The machine's load average is printed: figures taken while other jobs run are upper bounds.
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
MODEL = ROOT / "models" / "cesa_ema.toml"
#: Tolerance and sample spacing of the simulation that shows the orbit.
SIM_RTOL, SIM_DT_OUT = 1e-8, 2e-5


def _timed(fn):
    t0 = time.perf_counter()
    out = fn()
    return time.perf_counter() - t0, out


def _crossings(t, y):
    """Upward crossings of y's level 0 (linear interpolation)."""
    i = np.nonzero((y[:-1] < 0) & (y[1:] >= 0))[0]
    return t[i] - y[i] * (t[i + 1] - t[i]) / (y[i + 1] - y[i])


def shows_after(res, orb, signal, eps):
    """The first time after which every period of the run is within eps of the orbit's
    and the first harmonic over each within 10 eps (s; None when the run never does)."""
    t = np.asarray(res.t)
    y = np.asarray(res[signal])
    tc = _crossings(t, y - orb.signals[signal]["mean"])
    a_orb = orb.signals[signal]["amplitude"]
    ok = []
    for t0, t1 in zip(tc[:-1], tc[1:], strict=True):  # the first harmonic by the trapezoid rule, ends interpolated
        sel = (t > t0) & (t < t1)
        tt = np.concatenate([[t0], t[sel], [t1]])
        yy = np.interp(tt, t, y)
        c = 2 * np.trapezoid(yy * np.exp(-2j * np.pi * (tt - t0) / (t1 - t0)), tt) / (t1 - t0)
        ok.append(abs((t1 - t0) / orb.T - 1) < eps and abs(abs(c) / a_orb - 1) < 10 * eps)
    if os.environ.get("BENCH_DEBUG"):
        print([f"{(t1 - t0) / orb.T - 1:+.1e}" for t0, t1 in zip(tc[:-1], tc[1:], strict=True)])
    bad = [k for k, good in enumerate(ok) if not good]
    if not ok or (bad and bad[-1] >= len(ok) - 2):
        return None
    return float(tc[bad[-1] + 2]) if bad else float(tc[1])


def hunting_case(ema, model, p, eps, t_long):
    from ema_casadi import Signal

    step = Signal.step(1e-3, 0.01)
    cmd = model.input_with("command")
    signal = model.output_with("rod_position")

    def sim(t_end):
        return ema.simulate(model, t_end, p=p, dt_out=SIM_DT_OUT, rtol=SIM_RTOL, atol=SIM_RTOL * 1e-3, **{cmd: step})

    t_orb, orb = _timed(lambda: ema.periodic_orbit(model, "position", p=p))
    t_show = shows_after(sim(t_long), orb, signal, eps)
    if t_show is None:
        return {"shooting s": t_orb, "simulation that shows it": f"not within {t_long:g} s"}
    t_sim, _ = _timed(lambda: sim(t_show))
    return {"shooting s (start run included)": t_orb, "Newton runs": orb.info["runs"],
            "largest nontrivial |mu|": float(np.max(np.abs(orb.multipliers[1:]))),
            "simulated time that shows it s": t_show, "simulation that shows it s": t_sim,
            "shooting / simulation": t_orb / t_sim, "orbit freq Hz": orb.freq_hz}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--eps", type=float, default=1e-6, help="relative accuracy the simulation must show; default 1e-6")
    ap.add_argument("--aircraft", action="store_true", help="also the aircraft loop with backlash (slow)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    load0 = os.getloadavg()[0]
    import ema_casadi as ema
    from ema_casadi.limitcycle import setup

    params = ema.load_parameters(MODEL)
    model = ema.build_model(params, {"controller": "PI", "friction": "smooth", "screw_lock": "blend"})
    ema.periodic_orbit(model, "position", p=model.p(K_i_x=3000.0))  # warm-up: builds or loads the drivers
    ema.simulate(model, 0.1, x_cmd=1e-3, p=model.p(K_i_x=3000.0), dt_out=SIM_DT_OUT, rtol=SIM_RTOL)
    out = {}
    for label, B, t_long in (("B = 20 um", 20e-6, 4.0), ("B = 0.5 um", 0.5e-6, 16.0)):
        for k, v in hunting_case(ema, model, model.p(K_i_x=3000.0, B=B), args.eps, t_long).items():
            out[f"{label}: {k}"] = v
    if args.aircraft:
        ac = ema.build_model(params, {"airframe": "b747", "friction": "hybrid", "screw": "rigid"})
        pa = ac.p(B=3e-4)
        s = setup(ac, "aircraft", pa)
        s["confirm"](1.0, 1e-4)  # warm-up
        t_aorb, aorb = _timed(lambda: ema.periodic_orbit(ac, "aircraft", p=pa, t_warm=100.0))
        t_asim, _ = _timed(lambda: s["confirm"](300.0, 1e-4))
        out.update({"aircraft orbit (100 s start run, FD fallback) s": t_aorb,
                    "aircraft 300 s RK4 run at 1e-4 s s": t_asim, "aircraft orbit freq Hz": aorb.freq_hz})
    out["eps"] = args.eps
    out["load_average"] = (load0, os.getloadavg()[0])
    if args.json:
        json.dump(out, sys.stdout, indent=1)
        print()
        return 0
    print("| periodic orbits | value |\n|---|---|")
    for k, v in out.items():
        print(f"| {k} | {v if isinstance(v, tuple | str | int) else f'{v:.4g}'} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
