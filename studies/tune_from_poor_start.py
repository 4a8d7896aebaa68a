"""Gain tuning from a deliberately poor start (docs: tune).

Every gain of the reference set (models/cesa_ema.toml) is multiplied by 0.2 (K_x,
K_p_w, K_p_i, K_i_i; the speed loop's integral time T_i_w is kept, so its integral
gain K_p_w/T_i_w scales by 0.2 too). From there ``ema_casadi.tuning.tune`` maximises the
worst-case closed-loop bandwidth over the load cases 0, 15 and 30 kN subject to
GM >= 6 dB and PM >= 45 deg on the position, velocity and current loops (each broken
with the others closed), overshoot <= 5 %, and current and voltage within their
limits on a 0.1 mm step (at 30 kN the holding current is 13.2 A of the 24 A limit).

Then, independently of the optimiser: python-control margins of loop transfers freshly
linearised with the tuned gains in every load case, and nonlinear step simulations
(full model: smooth friction, backlash, rate/current/voltage limits) of the start, the
reference and the tuned gains, 1 mm at 0 and 30 kN.

Usage::

    python studies/tune_from_poor_start.py [--out out/tune_poor_start] [--factor 0.2]
        [--objective bandwidth|tracking]

Writes ``tuned.toml``, ``tune_bode.png``, ``tune_step.png`` and ``summary.json`` into
the output folder and prints Markdown tables.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import control as ct
import numpy as np

import ema_casadi as ema
from ema_casadi import linearisation as lz
from ema_casadi import tuning as T
from ema_casadi._util._files import write_text

ROOT = Path(__file__).resolve().parent.parent
LOADS = (0.0, 15e3, 30e3)


def independent_margins(model, params, loads):
    """Per load and loop: python-control on a fresh linearisation (GM: the smallest gain
    rise that destabilises, gain-reduction margin: the smallest fall, both dB >= 0,
    inf if none; PM deg), crossovers outside 0.01 Hz - 100 kHz dropped."""
    out = {}
    for F in loads:
        op = lz.operating_point(model, f_ext=F, p=params.vector())
        row = {}
        for loop in lz.LOOPS:
            gm, pm, _, wpc, wgc, _ = ct.stability_margins(lz.loop_transfer(model, loop, op), returnall=True)
            gm, pm, wpc, wgc = (np.atleast_1d(np.asarray(v, float)) for v in (gm, pm, wpc, wgc))
            kp = (wpc > 2 * np.pi * 1e-2) & (wpc < 2 * np.pi * 1e5) & np.isfinite(gm)
            kg = (wgc > 2 * np.pi * 1e-2) & (wgc < 2 * np.pi * 1e5)
            gm_db = 20 * np.log10(gm[kp])
            pms = np.abs((pm[kg] + 180) % 360 - 180)
            row[loop] = {"gm_db": float(min(gm_db[gm_db > 0], default=np.inf)),
                         "gm_down_db": float(min(-gm_db[gm_db <= 0], default=np.inf)),
                         "pm_deg": float(pms.min()) if pms.size else float("inf")}
        out[F] = row
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="out/tune_poor_start", help="output folder")
    ap.add_argument("--factor", type=float, default=0.2, help="start = factor x reference gains")
    ap.add_argument("--objective", choices=T.OBJECTIVES, default="bandwidth")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    params = ema.load_parameters(ROOT / "models" / "cesa_ema.toml")
    model = ema.build_model(params)
    free = T.default_free(model)
    start = T.scaled_gains(params, args.factor, free)
    t0 = time.perf_counter()
    res = T.tune(params, model=model, loads=LOADS, start=start, objective=args.objective)
    wall = time.perf_counter() - t0
    print(f"{res.message}\nIPOPT {res.status}: {res.iterations} iterations in {res.rounds} solve(s), "
          f"solve {res.solve_time:.2f} s, build {res.build_time:.2f} s, tune() total {wall:.2f} s "
          f"(incl. verification and nonlinear steps)")
    if res.active:
        print("limited by: " + "; ".join(T.describe_constraint(a, res.requirements) for a in res.active))

    sets = {"start": params.replace(**start), "reference": params, "tuned": res.params}
    print("\n| gain | start | reference | tuned |\n|---|---|---|---|")
    for g in free:
        print(f"| {g} | {start[g]:.5g} | {params.as_dict()[g]:.5g} | {res.gains_after[g]:.5g} |")

    summary = {"tune": {k: v for k, v in res.to_dict().items() if k not in ("before", "after")},
               "tune_wall_s": wall, "sets": {}}
    print("\n| gains | load | position GM/PM | velocity GM/PM | current GM/PM | bandwidth (Hz) |"
          "\n|---|---|---|---|---|---|")
    for name, ps in sets.items():
        m = independent_margins(model, ps, LOADS)
        ver = T.verify(model, ps, LOADS, res.requirements)
        steps = {F: T.step_metrics(model, ps, 1e-3, f_ext=F) for F in (0.0, 30e3)}
        for F in LOADS:
            cells = " | ".join((f"{m[F][k]['gm_db']:.1f} dB" + (f" (GRM {m[F][k]['gm_down_db']:.1f} dB)"
                                                     if np.isfinite(m[F][k]["gm_down_db"]) else "")
                              + f" / {m[F][k]['pm_deg']:.1f} deg") for k in lz.LOOPS)
            bw = ver["loads"][f"{F / 1e3:g} kN"]["bandwidth_hz"]
            print(f"| {name} | {F / 1e3:g} kN | {cells} | {bw:.3g} |")
        summary["sets"][name] = {
            "gains": {g: ps.as_dict()[g] for g in free},
            "margins_python_control": {f"{F / 1e3:g} kN": v for F, v in m.items()},
            "meets_requirements": ver["meets"], "failures": ver["failures"],
            "nonlinear_step_1mm": {f"{F / 1e3:g} kN": {k: v for k, v in s.items() if k not in ("t", "x_rod", "i_q")}
                                   for F, s in steps.items()},
        }
    print("\n| gains | load | overshoot (%) | 2 % settling (ms) | peak i_q (A) | peak abs(v_dq) (V) |\n"
          "|---|---|---|---|---|---|")
    for name, d in summary["sets"].items():
        for lbl, s in d["nonlinear_step_1mm"].items():
            print(f"| {name} | {lbl} | {100 * s['overshoot']:.2f} | {1e3 * s['settling_time_s']:.1f} | "
                  f"{s['i_q_peak_A']:.3g} | {s['v_dq_peak_V']:.4g} |")

    written = [res.write(out / "tuned.toml")]
    written += T.plot_tuning(res, model, sets["start"], out, reference=params)
    written.append(write_text(out / "summary.json", json.dumps(summary, indent=1, default=float)))
    for w in written:
        print(f"wrote {w}")


if __name__ == "__main__":
    main()
