"""Benchmark: a periodic orbit found by shooting against the simulation that shows it.

"The simulation that shows it" is the run a user makes to see the same orbit: the loop's
own scenario from the same start (the actuator at rest, the 1 mm command step at 10 ms),
by the toolkit's default solver (variable-step RODAS4 at its default rtol 1e-5), run just
long enough that its periods give the orbit to a stated accuracy, every period after
that point too (read off an untimed long run; then a run of that length is timed and its
own last period checked; the long run sampled as the timed one). Two accuracies:

- ``acceptance``: the accuracy the acceptance asks of the orbit, frequency within 0.5 %
  and first harmonic of x_rod within 1 % (output every 1 ms: 170 samples a period, the
  trapezoid rule's error far below 1 %); ``acceptance, seen settled``: besides, each
  period within that of the one before (what a user without the orbit can check);
- ``eps``: frequency within ``--eps`` (default 1e-6) and amplitude within 10 eps, a
  tighter accuracy towards what the shooting delivers (its period agrees with a
  rtol-1e-10 reference to 5e-10); output every 0.1 ms.

The shooting is ``ema.periodic_orbit(model, "position", p=p)`` with its defaults: its
start run (the same scenario), Newton with the monodromy matrix from forward
sensitivities at rtol 1e-10, events located with saltation matrices, the multipliers and
the orbit's time series. Every timing is the median of ``--repeats`` runs in this process
after a warm-up that builds or loads every compiled library; wall and CPU time
(``time.process_time``: on a shared machine the CPU time is the fairer figure).

Cases (PI position loop, K_i_x = 3000 1/s^2, smooth friction, the reference set):
``B = 20 um`` (the reference play: |mu| = 0.055, a disturbed run is back in two periods)
and ``B = 0.5 um`` (near the orbit's birth at B = 0: |mu| = 0.61).

With ``--aircraft`` also the 747 loop with backlash (hybrid friction: the
finite-difference fallback) against its 300 s RK4 run at 1e-4 s (the study's run), once.

Usage::

    .venv/bin/python benchmarks/bench_orbits.py [--eps 1e-6] [--repeats 5] [--aircraft] [--json]

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
def _timed(fn, repeats=1):
    """Median wall and CPU time of ``repeats`` calls, and the last result."""
    walls, cpus = [], []
    for _ in range(repeats):
        w0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        walls.append(time.perf_counter() - w0)
        cpus.append(time.process_time() - c0)
    return float(np.median(walls)), float(np.median(cpus)), out


def _crossings(t, y):
    """Upward crossings of y's level 0 (linear interpolation)."""
    i = np.nonzero((y[:-1] < 0) & (y[1:] >= 0))[0]
    return t[i] - y[i] * (t[i + 1] - t[i]) / (y[i + 1] - y[i])


def periods(res, orb, signal):
    """(end time, period error, first-harmonic error) of each whole period of the run,
    between upward crossings of the orbit's mean (interpolated; the first harmonic by the
    trapezoid rule), relative to the orbit."""
    t = np.asarray(res.t)
    y = np.asarray(res[signal])
    tc = _crossings(t, y - orb.signals[signal]["mean"])
    a_orb = orb.signals[signal]["amplitude"]
    out = []
    for t0, t1 in zip(tc[:-1], tc[1:], strict=True):
        sel = (t > t0) & (t < t1)
        tt = np.concatenate([[t0], t[sel], [t1]])
        yy = np.interp(tt, t, y)
        c = 2 * np.trapezoid(yy * np.exp(-2j * np.pi * (tt - t0) / (t1 - t0)), tt) / (t1 - t0)
        out.append((float(t1), (t1 - t0) / orb.T - 1, abs(c) / a_orb - 1))
    if os.environ.get("BENCH_DEBUG"):
        print([f"{e:.3f} {dT:+.1e} {dA:+.1e}" for e, dT, dA in out])
    return out


def shows_after(res, orb, signal, f_tol, a_tol, seen=False):
    """The end of the first period from which on every period of the run is within f_tol
    of the orbit's and its first harmonic within a_tol (s; None when the run never does).
    With ``seen``, also within f_tol and a_tol of the period before it (the run itself
    shows that it has settled, without the orbit to compare with)."""
    per = periods(res, orb, signal)
    ok = [abs(dT) < f_tol and abs(dA) < a_tol for _, dT, dA in per]
    if seen:
        ok = [good and k > 0 and abs((1 + per[k][1]) / (1 + per[k - 1][1]) - 1) < f_tol
              and abs((1 + per[k][2]) / (1 + per[k - 1][2]) - 1) < a_tol for k, good in enumerate(ok)]
    bad = [k for k, good in enumerate(ok) if not good]
    if not ok or (bad and bad[-1] >= len(ok) - 2):
        return None
    return per[bad[-1] + 1][0] if bad else per[0][0]


def hunting_case(ema, model, p, eps, t_long, repeats):
    from ema_casadi import Signal

    step = Signal.step(1e-3, 0.01)
    cmd = model.input_with("command")
    signal = model.output_with("rod_position")

    def sim(t_end, dt_out):
        return ema.simulate(model, t_end, p=p, dt_out=dt_out, **{cmd: step})

    w_orb, c_orb, orb = _timed(lambda: ema.periodic_orbit(model, "position", p=p), repeats)
    out = {"shooting wall s": w_orb, "shooting CPU s": c_orb, "Newton runs": orb.info["runs"],
           "residual": orb.residual, "|trivial - 1|": abs(orb.trivial_multiplier - 1),
           "largest nontrivial |mu|": float(np.max(np.abs(orb.multipliers[1:]))), "orbit freq Hz": orb.freq_hz}
    longs = {}
    for label, f_tol, a_tol, dt_out, seen in (("acceptance", 5e-3, 1e-2, 1e-3, False),
                                              ("acceptance, seen settled", 5e-3, 1e-2, 1e-3, True),
                                              ("eps", eps, 10 * eps, 1e-4, False)):
        if dt_out not in longs:  # read off a long run sampled as the timed one
            longs[dt_out] = sim(t_long, dt_out)
        t_show = shows_after(longs[dt_out], orb, signal, f_tol, a_tol, seen)
        if t_show is None:
            out[f"{label}: simulation that shows it"] = f"not within {t_long:g} s"
            continue
        t_run = t_show + 2 * dt_out  # the period's closing crossing inside the run
        w_sim, c_sim, res = _timed(lambda t_run=t_run, dt_out=dt_out: sim(t_run, dt_out), repeats)
        _, dT, dA = periods(res, orb, signal)[-1]
        out.update({f"{label}: simulated time s": t_run, f"{label}: its last period, freq error": dT,
                    f"{label}: its last period, amplitude error": dA, f"{label}: simulation wall s": w_sim,
                    f"{label}: simulation CPU s": c_sim, f"{label}: shooting / simulation (CPU)": c_orb / c_sim})
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--eps", type=float, default=1e-6, help="relative accuracy the simulation must show; default 1e-6")
    ap.add_argument("--repeats", type=int, default=5, help="timed repeats (median); default 5")
    ap.add_argument("--aircraft", action="store_true", help="also the aircraft loop with backlash (slow)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    load0 = os.getloadavg()[0]
    import ema_casadi as ema
    from ema_casadi.limitcycle import setup

    params = ema.load_parameters(MODEL)
    model = ema.build_model(params, {"controller": "PI", "friction": "smooth", "screw_lock": "blend"})
    ema.periodic_orbit(model, "position", p=model.p(K_i_x=3000.0))  # warm-up: builds or loads the drivers
    ema.simulate(model, 0.1, x_cmd=1e-3, p=model.p(K_i_x=3000.0), dt_out=1e-3)
    out = {}
    for label, B, t_long in (("B = 20 um", 20e-6, 4.0), ("B = 0.5 um", 0.5e-6, 16.0)):
        for k, v in hunting_case(ema, model, model.p(K_i_x=3000.0, B=B), args.eps, t_long, args.repeats).items():
            out[f"{label}: {k}"] = v
    if args.aircraft:
        ac = ema.build_model(params, {"airframe": "b747", "friction": "hybrid", "screw": "rigid"})
        pa = ac.p(B=3e-4)
        s = setup(ac, "aircraft", pa)
        s["confirm"](1.0, 1e-4)  # warm-up
        w_aorb, c_aorb, aorb = _timed(lambda: ema.periodic_orbit(ac, "aircraft", p=pa, t_warm=100.0))
        w_asim, c_asim, _ = _timed(lambda: s["confirm"](300.0, 1e-4))
        out.update({"aircraft orbit (100 s start run, FD fallback) wall s": w_aorb,
                    "aircraft orbit CPU s": c_aorb, "aircraft 300 s RK4 run at 1e-4 s wall s": w_asim,
                    "aircraft 300 s run CPU s": c_asim, "aircraft orbit freq Hz": aorb.freq_hz})
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
