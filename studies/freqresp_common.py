"""Shared command line of the frequency-response studies (fig14a, fig14b,
freqresp_screw, freqresp_friction): model file, output folder, jobs, scheduler."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ema_casadi import load_parameters

ROOT = Path(__file__).resolve().parent.parent


def parse(doc: str, argv=None):
    """(Parameters, args) from the study's command line."""
    ap = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--model", default=str(ROOT / "models" / "cesa_ema.toml"), help="parameter file (TOML)")
    ap.add_argument("--out", default="out", help="output folder for the CSV and PNG (created); default out/")
    ap.add_argument("--jobs", type=int, default=None, help="worker threads; default all cores")
    ap.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT", help="Dask distributed scheduler")
    args = ap.parse_args(argv)
    args.progress = sys.stderr.isatty()
    return load_parameters(args.model), args


def summary(resp, png, stroke: float, bands=((1.0, "1 Hz"), (5.0, "5 Hz"))) -> None:
    """Print gain/phase at a few frequencies per curve and the files written."""
    f = resp.axes["frequency"]
    for iv, v in enumerate(resp.axes["variant"]):
        for il, load in enumerate(resp.axes["load"]):
            for ia, A in enumerate(resp.axes["amplitude"]):
                cells = []
                for f0, name in bands:
                    j = int(abs(f - f0).argmin())
                    cells.append(f"{name}: {resp.data['gain_db'][iv, il, ia, j]:6.2f} dB "
                                 f"{resp.data['phase_deg'][iv, il, ia, j]:7.1f} deg")
                print(f"{v:>10s}  {load / 1e3:4g} kN  {100 * A / stroke:5.2g} %  " + "  ".join(cells))
    info = resp.info
    print(f"{info['points']} points, {info['periods_total']} periods, {info['not_converged']} not settled, "
          f"{info['wall_time']:.1f} s")
    for w in info.get("written", [png]):
        print(f"wrote {w}")
