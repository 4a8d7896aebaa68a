"""Jam during cruise activity in the aircraft loop (``models/faults_aircraft.toml``).

The medium transport at sea-level cruise flies a +1 deg attitude step and back; the
elevator actuator jams, or loses its drive, at instants of the manoeuvre. For each case:
which monitor of the ECU detects it and how fast, the rod's deviation from the no-fault
flight, and the pitch-attitude and load-factor excursions the airframe sees (a jam
freezes the surface at its onset position: the excursion depends on where in the
manoeuvre it strikes).

Usage::

    python studies/faults_aircraft_jam.py [--out out]

Writes ``<out>/faults_aircraft.json``, ``.csv`` and ``.png``; prints a Markdown table.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import ema_casadi as ema

ROOT = Path(__file__).resolve().parent.parent


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="out", help="output folder (created)")
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    params = ema.load_parameters(ROOT / "models" / "cesa_ema.toml")
    res = ema.run_faults(params, ROOT / "models" / "faults_aircraft.toml")
    res.to_json(out / "faults_aircraft.json")
    res.to_csv(out / "faults_aircraft.csv")
    res.plot(out / "faults_aircraft.png")
    mons = [m.removeprefix("latch_") for m in res.monitors]
    print("| case | onset (s) | rod dev (mm) | theta dev (deg) | n_z dev (g) | " + " | ".join(mons) + " |")
    print("|---|---|---|---|---|" + "---|" * len(mons))
    for r in res.rows:
        det = [r[f"detected_latch_{m}_s"] for m in mons]
        onset = "-" if r["onset_s"] is None else f"{r['onset_s']:g}"
        print(f"| {r['case']} | {onset} | {1e3 * r['peak_deviation_m']:.2f} | "
              f"{math.degrees(r['peak_theta_dev']):.2f} | {r['peak_n_z_dev']:.3f} | "
              + " | ".join("-" if d is None else f"{1e3 * d:.0f} ms" for d in det) + " |")
    print(f"({res.info['wall_time']:.0f} s)")


if __name__ == "__main__":
    main()
