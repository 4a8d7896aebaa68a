"""Hunting (limit cycling) under integral position control: smooth against hybrid friction.

The paper (Bilyaletdinova & Steblinkin 2017, "Enhanced friction model") claims that the
hybrid (Karnopp stick-slip) friction model run at a 1e-4 s step shows no more
"hunting" than the smooth (tanh) model at 1e-5 s. This study measures it on the
reference actuator (pmsm + elastic screw + ideal inverter) with the PI position loop
(controller = "PI"): a 1 mm step at 0.01 s, then the command is held. "smooth" is the
reference set's smooth variant (tanh, v_s = 1e-4 m/s, no Stribeck hump); "hybrid" has
F_start = 1.3 F_r and the dead band eps = 1e-4 m/s.

K_i_x: without friction the PI loop is well damped for every K_i_x tried here (the
slowest poles of the linearised loop are -41 +- 31j 1/s at K_i_x = 3000 1/s^2), so any
sustained oscillation is friction-induced. Stiction (F_start = 1.3 F_r) with the
integral action makes the classic stick-slip cycle: the integrator winds up while the
rod is stuck, the rod breaks away, overshoots and sticks on the other side. The default
K_i_x = 3000 1/s^2 is the one at which every case below hunts; at 2000 the smooth model
at 1e-5 s does not hunt at all while its converged solution does (see --k-i-x).

Measured over the second half of the run (the cycle is established by then):
- amplitude: half the peak-to-peak of the position error x_rod - x_cmd (um);
- frequency: cycles of the error about its mean, counted with a hysteresis of half the
  amplitude (Hz);
- wall time: median of --repeats runs after a warm-up run (compilation excluded), the
  time simulate() reports, with samples kept every --dt-out (default 1 ms, 200 per
  hunting cycle; a kept sample costs about half an RK4 step, so keeping every 1e-4 s
  step of the hybrid run nearly doubles its time). Run the study alone on the machine
  for meaningful times.

Cases: smooth at 1e-5 and 1e-6 s, hybrid at 1e-4 and 1e-5 s (compiled RK4); hybrid with
CVODES and located switching instants (variable-step check); with --reference also
smooth at 2e-7 s (converged; ~1 min).

Usage::

    python studies/hunting.py [--out out] [--k-i-x 3000] [--t-end 4] [--repeats 3] [--dt-out 1e-3] [--reference]

Writes ``<out>/hunting.png`` and ``<out>/hunting.json``; prints a Markdown table.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
from pathlib import Path

import ema_casadi as ema
from ema_casadi import Signal
from ema_casadi._util._files import write_text
from ema_casadi.plots._base import plt, save
from ema_casadi.simulation import hunting_metrics

ROOT = Path(__file__).resolve().parent.parent
STEP = Signal.step(1e-3, 0.01)


def hunting(res, t_from: float) -> dict:
    """Limit-cycle amplitude (m, half peak-to-peak of x_rod - x_cmd) and frequency (Hz)
    over t >= t_from (:func:`ema_casadi.simulation.hunting_metrics`)."""
    return hunting_metrics(res.t, res["x_rod"] - res["x_cmd"], t_from)


def run_case(model, p, t_end, dt, solver, repeats, dt_out):
    if solver == "rk4":
        kw = dict(dt=dt, dt_out=dt_out, p=p)
    else:
        kw = dict(dt=dt_out, p=p, solver="cvodes", rtol=1e-8, atol=1e-11)
    res = ema.simulate(model, t_end, STEP, **kw)  # warm-up: compiles (or loads) the rollout
    walls = []
    for _ in range(repeats):
        res = ema.simulate(model, t_end, STEP, **kw)
        walls.append(res.info["wall_time"])
    return res, statistics.median(walls)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model", default=str(ROOT / "models" / "cesa_ema.toml"), help="parameter file (TOML)")
    ap.add_argument("--out", default="out", help="folder for hunting.png and hunting.json (default out/)")
    ap.add_argument("--k-i-x", type=float, default=3000.0,
                    help="position-loop integral gain K_i_x (1/s^2); default 3000")
    ap.add_argument("--t-end", type=float, default=4.0,
                    help="simulated time (s); hunting is measured over its second half")
    ap.add_argument("--repeats", type=int, default=3, help="timed runs per case (median); default 3")
    ap.add_argument("--dt-out", type=float, default=1e-3,
                    help="spacing of the kept samples (s), the same for every case; default 1e-3 (200 per cycle)")
    ap.add_argument("--reference", action="store_true", help="also smooth at 2e-7 s (converged reference, ~1 min)")
    args = ap.parse_args(argv)
    if not (args.t_end > 0.5 and math.isfinite(args.t_end)):
        ap.error(f"--t-end must be a number of seconds above 0.5, got {args.t_end}")
    if not (args.k_i_x >= 0 and math.isfinite(args.k_i_x)):
        ap.error(f"--k-i-x must be a non-negative number, got {args.k_i_x}")
    if args.repeats < 1:
        ap.error(f"--repeats must be at least 1, got {args.repeats}")
    if not (1e-4 <= args.dt_out <= 1e-2):
        ap.error(f"--dt-out must be between 1e-4 and 1e-2 s (a multiple of every step), got {args.dt_out}")
    out = Path(args.out)
    try:
        out.mkdir(parents=True, exist_ok=True)
        params = ema.load_parameters(args.model)
    except (OSError, ema.ParameterError) as exc:
        print(f"hunting.py: {exc}", file=sys.stderr)
        return 2

    cases = [("smooth", 1e-5, "rk4"), ("smooth", 1e-6, "rk4"), ("hybrid", 1e-4, "rk4"), ("hybrid", 1e-5, "rk4"),
             ("hybrid", None, "cvodes")]
    if args.reference:
        cases.append(("smooth", 2e-7, "rk4"))
    models = {fr: ema.build_model(params, {"friction": fr, "controller": "PI"}) for fr in ("smooth", "hybrid")}
    t_from = args.t_end / 2
    rows, traces = [], []
    for fr, dt, solver in cases:
        model = models[fr]
        repeats = 1 if (dt is not None and dt < 1e-6) else args.repeats
        res, wall = run_case(model, model.p(K_i_x=args.k_i_x), args.t_end, dt, solver, repeats, args.dt_out)
        h = hunting(res, t_from)
        label = f"{fr}, {f'RK4 dt={dt:g} s' if solver == 'rk4' else 'CVODES, located switches'}"
        row = {"friction": fr, "solver": solver, "dt": dt, "amplitude_um": h["amplitude"] * 1e6,
               "frequency_hz": h["frequency"], "mean_error_um": h["mean_error"] * 1e6, "wall_time_s": wall,
               "mode_switches": res.info.get("mode_switches"), "label": label}
        rows.append(row)
        traces.append((label, res))
        f_txt = f"{h['frequency']:.2f}" if h["frequency"] else "-"
        print(f"{label:34s} amplitude {row['amplitude_um']:8.4f} um  frequency {f_txt:>6s} Hz  "
              f"wall {wall * 1e3:8.1f} ms", flush=True)

    by = {(r["friction"], r["dt"]): r for r in rows}
    h4, s5 = by[("hybrid", 1e-4)], by[("smooth", 1e-5)]
    claim = {
        "hybrid_1e-4_amplitude_um": h4["amplitude_um"],
        "smooth_1e-5_amplitude_um": s5["amplitude_um"],
        "amplitude_not_larger": h4["amplitude_um"] <= s5["amplitude_um"],
        "wall_time_ratio_smooth_1e-5_over_hybrid_1e-4": s5["wall_time_s"] / h4["wall_time_s"],
    }
    claim["holds"] = bool(claim["amplitude_not_larger"] and claim["wall_time_ratio_smooth_1e-5_over_hybrid_1e-4"] >= 5)

    print(f"\nK_i_x = {args.k_i_x:g} 1/s^2, {args.t_end:g} s, hunting measured over t >= {t_from:g} s, "
          f"samples every {args.dt_out:g} s\n")
    print("| friction | integrator | amplitude (um) | frequency (Hz) | wall time (ms) | mode switches |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        integ = f"RK4 {r['dt']:g} s" if r["solver"] == "rk4" else "CVODES + located switches"
        f_txt = f"{r['frequency_hz']:.2f}" if r["frequency_hz"] else "-"
        print(f"| {r['friction']} | {integ} | {r['amplitude_um']:.3f} | {f_txt} | {r['wall_time_s'] * 1e3:.1f} | "
              f"{r['mode_switches'] if r['mode_switches'] is not None else '-'} |")
    print(f"\npaper's claim (hybrid 1e-4 s amplitude <= smooth 1e-5 s, >= 5x less wall time): "
          f"{'holds' if claim['holds'] else 'does not hold'} "
          f"({h4['amplitude_um']:.3f} vs {s5['amplitude_um']:.3f} um, "
          f"wall-time ratio {claim['wall_time_ratio_smooth_1e-5_over_hybrid_1e-4']:.1f}x)")

    fig, ax = plt.subplots(2, 1, figsize=(9, 7))
    for label, res in traces:
        e = (res["x_rod"] - res["x_cmd"]) * 1e6
        ax[0].plot(res.t, e, lw=0.9, label=label)
        z = res.t >= args.t_end - 0.6
        ax[1].plot(res.t[z], e[z], lw=1.1, label=label)
    ax[0].set_ylim(-4 * max(r["amplitude_um"] for r in rows) - 1, 4 * max(r["amplitude_um"] for r in rows) + 1)
    ax[0].set_title(f"hunting under PI position control (K_i_x = {args.k_i_x:g} 1/s^2), 1 mm step at 0.01 s")
    ax[1].set_title("last 0.6 s")
    for a in ax:
        a.set_xlabel("time (s)")
        a.set_ylabel("x_rod - x_cmd (um)")
        a.grid(True, alpha=0.3)
    ax[1].legend(fontsize=8, loc="upper right")
    fig.tight_layout()
    png = save(fig, out / "hunting.png")

    result = {"k_i_x": args.k_i_x, "t_end": args.t_end, "dt_out": args.dt_out, "measured_from": t_from,
              "cases": rows, "claim": claim,
              "model": str(args.model), "variants": {"motor": "pmsm", "screw": "elastic", "inverter": "ideal",
                                                      "controller": "PI"}}
    js = out / "hunting.json"
    write_text(js, json.dumps(result, indent=2))
    print(f"\nwrote {png} and {js}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
