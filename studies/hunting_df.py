"""The README's hunting case by describing function: the PI position loop (K_i_x = 3000
1/s^2) with hybrid (Karnopp) friction, predicted from the nonlinear open loop at a
break and checked against the long simulation of studies/hunting.py's scenario (1 mm
step, held; the cycle measured over the second half of the run).

Cases: the reference actuator (elastic screw: backlash between nut and rod, friction on
the rod) and the rigid screw (backlash as a play on the fed-back position, friction on
the shaft), both broken at the position loop. (A break at the velocity loop was tried:
with the speed loop open the stick-slip open loop answers with no usable first harmonic,
gain rising with frequency; not kept.)

For each: L_N(A, f) on a grid (``--amplitudes``/``--freqs`` per break below), the roots
of L_N = -1 with their stability, Newton refinement, the simulation (RK4 at 1e-4 s, the
hybrid model's converged step), and the relative errors of amplitude (first harmonic of
the break signal) and frequency.

Usage::

    python studies/hunting_df.py [--out out] [--k-i-x 3000] [--t-end 6]

Writes ``<out>/hunting_df.json``, ``<out>/hunting_df_<case>.png`` (Nichols charts); prints
a Markdown table.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

import ema_casadi as ema
from ema_casadi import Signal
from ema_casadi._files import write_text
from ema_casadi.limitcycle import cycle_of, describing_function, plot_nichols, refine

ROOT = Path(__file__).resolve().parent.parent
#: case -> (variants, loop, break signal, amplitudes, freqs (Hz), display scale, unit)
CASES = {
    "elastic_position": ({"screw": "elastic"}, "position", "x_rod", np.geomspace(1e-6, 3e-5, 7),
                         np.geomspace(1.5, 15, 10), 1e6, "um"),
    "rigid_position": ({"screw": "rigid"}, "position", "x_rod", np.geomspace(1e-6, 3e-5, 7),
                       np.geomspace(1.5, 15, 10), 1e6, "um"),
}


def run_case(params, name, k_i_x, t_end, dt, out):
    variants, loop, signal, amps, freqs, scale, unit = CASES[name]
    model = ema.build_model(params, {"controller": "PI", "friction": "hybrid", **variants})
    p = model.p(K_i_x=k_i_x)
    t0 = time.perf_counter()
    kw = dict(p=p, x0=model.x0(), dt=dt)
    df = describing_function(model, loop, amps, freqs, **kw)
    cycles = [refine(model, loop, c, **kw) for c in df.cycles]
    df.cycles = cycles
    t_df = time.perf_counter() - t0
    res = ema.simulate(model, t_end, x_cmd=Signal.step(1e-3, 0.01), dt=dt, dt_out=dt, p=p)
    sim = cycle_of(res.t, res[signal], t_end / 2)
    plot_nichols(df, out / f"hunting_df_{name}.png", unit_scale=scale, unit=unit,
                 title=f"hunting by describing function: {name} (PI, K_i_x = {k_i_x:g}, hybrid friction)")
    row = {"case": name, "loop": loop, "signal": signal, "unit": unit, "predicted": cycles, "simulation": sim,
           "df_wall_time_s": t_df, "grid": df.as_dict()}
    stable = [c for c in cycles if c["stable"]]
    if stable and sim["freq_hz"]:
        c = stable[0]
        row["amplitude_error"] = c["amplitude"] / sim["amplitude"] - 1
        row["frequency_error"] = c["freq_hz"] / sim["freq_hz"] - 1
    return row


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model", default=str(ROOT / "models" / "cesa_ema.toml"), help="parameter file (TOML)")
    ap.add_argument("--out", default="out", help="output folder (default out/)")
    ap.add_argument("--k-i-x", type=float, default=3000.0, help="position-loop integral gain (1/s^2)")
    ap.add_argument("--t-end", type=float, default=6.0, help="confirming run (s); default 6")
    ap.add_argument("--cases", default=",".join(CASES), help=f"comma-separated, of {', '.join(CASES)}")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    params = ema.load_parameters(args.model)
    rows = [run_case(params, c, args.k_i_x, args.t_end, 1e-4, out) for c in args.cases.split(",")]
    write_text(out / "hunting_df.json", json.dumps(rows, indent=1, default=float))
    print("| case | predicted amplitude | predicted f (Hz) | simulated amplitude (1st harm.) | simulated f (Hz) "
          "| amplitude error | frequency error |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        sc = CASES[r["case"]][5]
        for c in r["predicted"] or [{"amplitude": float("nan"), "freq_hz": float("nan"), "stable": False}]:
            s = r["simulation"]
            print(f"| {r['case']} | {c['amplitude'] * sc:.3g} {r['unit']} ({'stable' if c['stable'] else 'unstable'})"
                  f" | {c['freq_hz']:.3g} | {s['amplitude'] * sc:.3g} {r['unit']} | {s['freq_hz'] or float('nan'):.3g}"
                  f" | {r.get('amplitude_error', float('nan')):+.0%} | {r.get('frequency_error', float('nan')):+.0%} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
