"""Hunting and 1 mm step overshoot over backlash x seal friction x stiffness.

The sweep ``models/sweep_hunting_backlash.toml``: backlash B from 0.02 to 0.5 mm (10
log-spaced values) x 100 Monte Carlo draws of the seal friction F_seal (150 N +-50 %,
uniform) and the drive-train stiffness C (2.4e8 N/m +-30 %, uniform) = 1000 runs;
hybrid (Karnopp) friction, PI position loop at K_i_x = 3000 1/s^2, a 1 mm step at
0.01 s, 4 s at the RK4 step 1e-4 s. Hunting is measured as in ``studies/hunting.py``
(half the peak-to-peak of x_rod - x_cmd over 2-4 s, and its frequency), the overshoot
by the toolkit's step metric.

Usage::

    python studies/sweep_hunting_backlash.py [--out out] [--jobs 2] [--samples 100] [--resume]

Writes ``<out>/sweep_hunting_backlash.csv`` (one row per run), ``..._sweep.png`` (the
generic histograms and sensitivities), ``..._backlash.png`` (amplitude, frequency and
overshoot against backlash: median and 5-95 % band over the draws) and ``....json``
(summary, per-backlash table, wall time); prints a Markdown table. Interrupted, it is
continued with --resume (the rows done are kept in the table's journal).
"""

from __future__ import annotations

import argparse
import json
import sys
import tomllib
from pathlib import Path

import numpy as np

import ema_casadi as ema
from ema_casadi._util._files import write_text
from ema_casadi.plots._base import plt, save
from ema_casadi.sweeps import SweepError, parse_sweep, sweep

ROOT = Path(__file__).resolve().parent.parent
SPEC = ROOT / "models" / "sweep_hunting_backlash.toml"
STEM = "sweep_hunting_backlash"


def by_backlash(res) -> list[dict]:
    """Per backlash value: the draws' median and 5/95 % of each metric (ok runs)."""
    B = res.column("B")
    ok = res.column("status") == "ok"
    out = []
    for b in np.unique(B):
        sel = (B == b) & ok
        row = {"B_mm": b * 1e3, "runs": int((B == b).sum()), "failed": int(((B == b) & ~ok).sum())}
        for m, scale in (("hunting_amplitude_m", 1e6), ("hunting_frequency_hz", 1.0), ("step_overshoot", 100.0)):
            v = res.column(m)[sel]
            v = v[np.isfinite(v)]
            row[m] = [float(x) * scale for x in np.percentile(v, [5, 50, 95])] if len(v) else None
        amp = res.column("hunting_amplitude_m")[sel]
        row["hunting_share"] = float(np.mean(amp > 1e-7)) if len(amp) else None  # > 0.1 um: a limit cycle
        out.append(row)
    return out


def plot_backlash(table, path):
    fig, ax = plt.subplots(1, 3, figsize=(13, 3.8))
    B = [r["B_mm"] for r in table]
    for a, (m, label) in zip(ax, (("hunting_amplitude_m", "hunting amplitude (um, 1/2 p-p)"),
                                  ("hunting_frequency_hz", "hunting frequency (Hz)"),
                                  ("step_overshoot", "1 mm step overshoot (%)")), strict=True):
        q = np.array([r[m] if r[m] else [np.nan] * 3 for r in table])
        a.fill_between(B, q[:, 0], q[:, 2], alpha=0.3, label="5-95 % of the draws")
        a.plot(B, q[:, 1], "o-", label="median")
        a.set_xscale("log")
        a.set_xticks(B[::3], [f"{b:.3g}" for b in B[::3]])
        a.minorticks_off()
        a.set_xlabel("backlash B (mm)")
        a.set_ylabel(label)
        a.grid(True, alpha=0.3)
    ax[0].legend(fontsize=8)
    fig.suptitle("hybrid friction, PI position loop (K_i_x = 3000): F_seal +-50 %, C +-30 %", fontsize=10)
    fig.tight_layout()
    return save(fig, path)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model", default=str(ROOT / "models" / "cesa_ema.toml"), help="parameter file (TOML)")
    ap.add_argument("--spec", default=str(SPEC), help="the sweep description (default the study's)")
    ap.add_argument("--out", default="out", help="folder for the table, plots and summary (default out/)")
    ap.add_argument("--jobs", type=int, default=None, help="local worker processes (default: all cores)")
    ap.add_argument("--samples", type=int, default=None, help="draws per backlash value (default the file's, 100)")
    ap.add_argument("--resume", action="store_true", help="continue an interrupted run of the study")
    args = ap.parse_args(argv)
    out = Path(args.out)
    try:
        out.mkdir(parents=True, exist_ok=True)
        params = ema.load_parameters(args.model)
        data = tomllib.loads(Path(args.spec).read_text(encoding="utf-8"))
        if args.samples is not None:
            data["sweep"]["samples"] = args.samples
        spec = parse_sweep(data, params, args.spec, name=STEM)
        res = sweep(spec, out / f"{STEM}.csv", jobs=args.jobs, resume=args.resume, progress=True)
    except (OSError, tomllib.TOMLDecodeError, ema.ParameterError, SweepError) as exc:
        print(f"sweep_hunting_backlash.py: {exc}", file=sys.stderr)
        return 2
    table = by_backlash(res)
    summary = res.summary()
    print(f"\n{len(res)} runs ({res.info['resumed']} resumed, {res.info['failed']} failed) in "
          f"{res.info['wall_time']:.1f} s on {res.info['jobs']} {res.info['backend']}\n")
    print("| B (mm) | runs | failed | hunting share (> 0.1 um) | amplitude um, median [5-95 %] | "
          "frequency Hz, median [5-95 %] | overshoot %, median [5-95 %] |")
    print("|---|---|---|---|---|---|---|")

    def cell(q, f):
        return "-" if q is None else f"{q[1]:{f}} [{q[0]:{f}}-{q[2]:{f}}]"

    for r in table:
        print(f"| {r['B_mm']:.3g} | {r['runs']} | {r['failed']} | {r['hunting_share']:.2f} | "
              f"{cell(r['hunting_amplitude_m'], '.2f')} | {cell(r['hunting_frequency_hz'], '.2f')} | "
              f"{cell(r['step_overshoot'], '.1f')} |")
    print("\nSpearman rank correlation (ok runs):")
    for m, s in summary["sensitivity_spearman"].items():
        print(f"  {m:24s} " + "  ".join(f"{p} {v:+.2f}" for p, v in s.items() if p != "K_i_x"))
    png = res.plot(out / f"{STEM}_sweep.png")
    png2 = plot_backlash(table, out / f"{STEM}_backlash.png")
    js = write_text(out / f"{STEM}.json", json.dumps({"info": {k: v for k, v in res.info.items()},
                                                      "by_backlash": table, "summary": summary}, indent=1,
                                                     default=str))
    print(f"\nwrote {out / (STEM + '.csv')}, {png}, {png2} and {js}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
