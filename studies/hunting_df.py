"""The hunting case (docs: aircraft) by describing function: the PI position loop (K_i_x = 3000
1/s^2) with hybrid (Karnopp) friction, predicted from the nonlinear open loop at a
break and checked against the long simulation of studies/hunting.py's scenario (1 mm
step, held; the cycle measured over the second half of the run).

Cases: the reference actuator (elastic screw: backlash between nut and rod, friction on
the rod) and the rigid screw (backlash as a play on the fed-back position, friction on
the shaft), both broken at the position loop. (A break at the velocity loop was tried:
with the speed loop open the stick-slip open loop answers with no usable first harmonic,
gain rising with frequency; not kept.)

For each: L_N(A, f) on a grid (``--amplitudes``/``--freqs`` per break below), the roots
of L_N = -1 with their stability, Newton refinement, the harmonic balance with the 3rd,
5th and 7th harmonics from that root (``--harmonics``), the simulation (RK4 at 1e-4 s, the
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
from ema_casadi._util._files import write_text
from ema_casadi.limitcycle import cycle_of, describing_function, harmonic_balance, harmonic_orders, plot_nichols, refine
from ema_casadi.signals import parse_list

ROOT = Path(__file__).resolve().parent.parent
#: case -> (variants, loop, break signal, amplitudes, freqs (Hz), display scale, unit)
CASES = {
    "elastic_position": ({"screw": "elastic"}, "position", "x_rod", np.geomspace(1e-6, 3e-5, 7),
                         np.geomspace(1.5, 15, 10), 1e6, "um"),
    "rigid_position": ({"screw": "rigid"}, "position", "x_rod", np.geomspace(1e-6, 3e-5, 7),
                       np.geomspace(1.5, 15, 10), 1e6, "um"),
}


def run_case(params, name, k_i_x, t_end, dt, out, orders=(3, 5, 7)):
    variants, loop, signal, amps, freqs, scale, unit = CASES[name]
    model = ema.build_model(params, {"controller": "PI", "friction": "hybrid", **variants})
    p = model.p(K_i_x=k_i_x)
    t0 = time.perf_counter()
    kw = dict(p=p, x0=model.x0(), dt=dt)
    df = describing_function(model, loop, amps, freqs, **kw)
    cycles = [harmonic_balance(model, loop, refine(model, loop, c, **kw), harmonics=orders, **kw)
              for c in df.cycles]
    df.cycles = cycles
    t_df = time.perf_counter() - t0
    res = ema.simulate(model, t_end, x_cmd=Signal.step(1e-3, 0.01), dt=dt, dt_out=dt, p=p, solver="rk4")
    sim = cycle_of(res.t, res[signal], t_end / 2)
    plot_nichols(df, out / f"hunting_df_{name}.png", unit_scale=scale, unit=unit,
                 title=f"hunting by describing function: {name} (PI, K_i_x = {k_i_x:g}, hybrid friction)")
    row = {"case": name, "loop": loop, "signal": signal, "unit": unit, "predicted": cycles, "simulation": sim,
           "df_wall_time_s": t_df, "grid": df.as_dict()}
    stable = [c for c in cycles if c["stable"]]
    if stable and sim["freq_hz"]:
        c = stable[0]
        row["df_amplitude_error"] = c["df_amplitude"] / sim["amplitude"] - 1
        row["df_frequency_error"] = c["df_freq_hz"] / sim["freq_hz"] - 1
        if c["harmonic_balance"]["converged"]:
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
    ap.add_argument("--harmonics", default="3,5,7", help="higher harmonics balanced (comma-separated); default 3,5,7")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    params = ema.load_parameters(args.model)
    orders = harmonic_orders(parse_list(args.harmonics, "dimensionless", "1"))
    rows = [run_case(params, c, args.k_i_x, args.t_end, 1e-4, out, orders) for c in args.cases.split(",")]
    write_text(out / "hunting_df.json", json.dumps(rows, indent=1, default=float))
    print("| case | describing function | harmonic balance (1, " + args.harmonics + ") | simulated (1st harmonic) "
          "| DF error: amplitude, frequency | HB error: amplitude, frequency |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        sc, u, s = CASES[r["case"]][5], r["unit"], r["simulation"]
        sim = f"{s['amplitude'] * sc:.3g} {u}, {s['freq_hz'] or float('nan'):.3g} Hz"
        if not r["predicted"]:
            print(f"| {r['case']} | none | none | {sim} | | |")
        for c in r["predicted"]:
            hb = f"{c['amplitude'] * sc:.3g} {u}, {c['freq_hz']:.3g} Hz"
            hb += "" if c["harmonic_balance"]["converged"] else " (not converged)"
            err = [r.get(k, float("nan")) for k in ("df_amplitude_error", "df_frequency_error", "amplitude_error",
                                                     "frequency_error")]
            print(f"| {r['case']} | {c['df_amplitude'] * sc:.3g} {u}, {c['df_freq_hz']:.3g} Hz "
                  f"({'stable' if c['stable'] else 'unstable'}) | {hb} | {sim} "
                  f"| {err[0]:+.1%}, {err[1]:+.1%} | {err[2]:+.1%}, {err[3]:+.1%} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
