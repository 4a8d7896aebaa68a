"""Test records from an actuator whose ECU is not built like the toolkit's default: the
clamping anti-windup (``anti_windup = "clamping"``) with its band faded over the 2 %
*below* the limit (``w_aw = -0.02``; the toolkit's default clamping band sits 1 % above
it) and a sharper screw-efficiency switch (``P_blend = 0.02`` W instead of 0.1 W), for
the identification's misfit detection and model selection (records that the default
structure cannot explain).

Four records at 2 kHz, as a rig logs them: the rod command ``x_cmd`` and the external
load ``f_ext`` sampled at the record rate (the model is driven by that very table, so
a fit that interpolates the logged command sees the input that made the record), and
five measured channels with seeded Gaussian noise, 1 sigma: rod position ``x_rod``
0.3 um, shaft angle ``phi`` 2e-4 rad, motor speed ``omega`` 0.2 rad/s, q-current
``i_q`` 0.05 A, screw force ``F_in`` (the load cell) 10 N.

- ``steps``: 3 s, +2 mm at 0.1 s, -4 mm at 1 s, +2 mm at 2 s, unloaded;
- ``chirp``: 4 s, 0.5 mm 0.5-25 Hz, unloaded;
- ``slews_push``: 3 s, +-5 mm slews (at the 80 mm/s rate limit) under +8 kN from 0.1 s;
- ``slews_pull``: 2.5 s, the same under -15 kN.

The slews saturate the rate limit and, at each start and stop, the current limit:
that is where clamping and back-calculation differ. The true parameters are the
reference set with the seven offsets of :data:`TRUTH` (20-100 %), so that a fit has
something to find. The simulation is the compiled RODAS4 at rtol 1e-10, atol 1e-13
(continuous ECU).

CSV layout (the project's time-series layout): ``# NAME: VALUE`` lines (the ECU
structure, the truth and each channel's noise as ``sigma_<channel>``), the header
``time,x_cmd,f_ext,x_rod,...``, a ``Unit:`` row, one row per sample (17 significant
digits). ``records.json`` beside them lists the files, the structure and the truth.

Usage::

    python studies/ecu_records.py [--out out/ecu_records] [--seed 0] [--anti-windup clamping]
        [--blend 0.02] [--t-scale 1]

Python: ``ecu_records(folder, params=None, seed=0, ...)`` returns the paths and the truth.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

import ema_casadi as ema
from ema_casadi import Signal
from ema_casadi._util._files import write_text
from ema_casadi.signals import parse_signal

ROOT = Path(__file__).resolve().parent.parent

#: The actuator "as built": seal friction +50 %, bearing friction +40 %, viscous friction
#: +100 %, backlash +30 %, stiffness -20 %, rotor inertia +20 %, flux linkage -20 %.
TRUTH = {"F_seal": 225.0, "C_bear": 4.2e-5, "c_v": 400.0, "B": 2.6e-5, "C": 1.92e8, "J_m": 1.44e-3, "psi": 0.24}

#: Sensor noise, 1 sigma (SI).
NOISE = {"x_rod": 0.3e-6, "phi": 2e-4, "omega": 0.2, "i_q": 0.05, "F_in": 10.0}

#: name -> (duration s, rod command, load).
RECORDS = {
    "steps": (3.0, "step:2mm@0.1+step:-4mm@1.0+step:2mm@2.0", "0"),
    "chirp": (4.0, "chirp:0.5mm@0.5-25", "0"),
    "slews_push": (3.0, "step:5mm@0.3+step:-10mm@1.3+step:5mm@2.3", "step:8kN@0.1"),
    "slews_pull": (2.5, "step:-5mm@0.3+step:10mm@1.2+step:-5mm@2.0", "step:-15kN@0.1"),
}

RATE = 2000.0  # Hz


def record(model, params, path, t_end, x_cmd, f_ext, pv, seed, rate=RATE, fields=None) -> Path:
    """Simulate one record and write it (atomically) as CSV.

    Parameters
    ----------
    model : Model
        The actuator with the ECU structure of the record.
    params : Parameters
        The parameter set (its stroke reads percentages in the signals).
    path : str or Path
        The CSV file.
    t_end : float
        Duration (s).
    x_cmd, f_ext : str
        Rod command and load in the signal syntax of ``ema simulate``.
    pv : ndarray
        The true parameter vector.
    seed : int
        Seed of the noise.
    rate : float
        Sample rate (Hz).
    fields : dict, optional
        File-level fields written as ``# NAME: VALUE`` lines.
    """
    t = np.arange(int(round(t_end * rate)) + 1) / rate
    sampled = {name: parse_signal(text, model.input_info[name].kind, stroke=params.actuator.stroke, duration=t_end)(t)
               for name, text in (("x_cmd", x_cmd), ("f_ext", f_ext))}
    tables = {k: Signal.table(t, v) for k, v in sampled.items()}
    res = ema.simulate(model, t[-1], solver="rosenbrock", dt_out=1.0 / rate, p=pv, rtol=1e-10, atol=1e-13, **tables)
    rng = np.random.default_rng(seed)
    cols = {**sampled, **{c: np.asarray(res[c], float) + rng.normal(0.0, s, len(res.t)) for c, s in NOISE.items()}}
    meta = {**(fields or {}), **{f"sigma_{c}": s for c, s in NOISE.items()}, "seed": seed}
    lines = [f"# {k}: {v}" for k, v in meta.items()]
    lines += ["time," + ",".join(cols), "Unit:," + ",".join(model.units[c] for c in cols)]
    lines += [",".join(f"{float(v):.17g}" for v in row) for row in np.column_stack([res.t, *cols.values()])]
    return write_text(path, "\n".join(lines) + "\n")


#: The rig's clamping band: faded over the 2 % below the limit.
W_AW = -0.02


def ecu_records(folder, params=None, *, seed: int = 0, anti_windup: str = "clamping", P_blend: float = 0.02,
                w_aw: float = W_AW, truth: dict | None = None, t_scale: float = 1.0) -> tuple[list[Path], dict]:
    """The four records of the module docstring, written into ``folder``.

    Parameters
    ----------
    folder : str or Path
        Where the CSV files (and ``records.json``) go; created if missing.
    params : Parameters, optional
        The parameter set (default the reference set ``models/cesa_ema.toml``).
    seed : int
        Seed of the noise (record k uses seed + k).
    anti_windup : {"clamping", "backcalc"}
        The ECU's anti-windup law.
    P_blend : float
        The screw-efficiency switch width (W) of the actuator.
    w_aw : float
        The clamping band (-, signed fraction of the limit; used with ``clamping``).
    truth : dict, optional
        True flat parameter values (default :data:`TRUTH`).
    t_scale : float
        Factor on every duration and event time (shorter records for tests), in (0, 1].

    Returns
    -------
    paths, truth : list of Path, dict
        The files and the true values (``P_blend`` and, with clamping, ``w_aw`` included).
    """
    if not 0 < t_scale <= 1:
        raise ValueError(f"t_scale: expected a factor in (0, 1], got {t_scale!r}")
    params = params or ema.load_parameters(ROOT / "models" / "cesa_ema.toml")
    truth = {**(TRUTH if truth is None else truth), "P_blend": float(P_blend),
             **({"w_aw": float(w_aw)} if anti_windup == "clamping" else {})}
    model = ema.build_model(params, {"anti_windup": anti_windup})
    pv = params.vector(**truth)
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    fields = {"anti_windup": anti_windup, **{f"true_{k}": v for k, v in truth.items()}}
    paths = []
    for k, (name, (t_end, x_cmd, f_ext)) in enumerate(RECORDS.items()):
        paths.append(record(model, params, folder / f"{name}.csv", t_end * t_scale, _scaled(x_cmd, t_scale),
                            _scaled(f_ext, t_scale), pv, seed + k, fields=fields))
    summary = {"records": [p.name for p in paths], "anti_windup": anti_windup, "truth": truth, "noise": NOISE,
               "rate_hz": RATE, "seed": seed, "t_scale": t_scale}
    write_text(folder / "records.json", json.dumps(summary, indent=2) + "\n")
    return paths, truth


def _scaled(text: str, factor: float) -> str:
    """A signal text with every event time (after '@') scaled by ``factor`` (chirp
    frequency ranges are left alone: they follow an '@' but hold a '-')."""
    if factor == 1.0:
        return text
    out = []
    for term in text.split("+"):
        head, *times = term.split("@")
        times = [t if "-" in t else f"{float(t) * factor:g}" for t in times]
        out.append("@".join([head, *times]))
    return "+".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default="out/ecu_records", help="output folder (default out/ecu_records)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the noise (default 0)")
    ap.add_argument("--anti-windup", default="clamping", choices=("clamping", "backcalc"),
                    help="the ECU's anti-windup law (default clamping)")
    ap.add_argument("--blend", type=float, default=0.02, help="efficiency switch width P_blend in W (default 0.02)")
    ap.add_argument("--w-aw", type=float, default=W_AW,
                    help=f"clamping band, signed fraction of the limit (default {W_AW}: below the limit)")
    ap.add_argument("--t-scale", type=float, default=1.0, help="factor on the durations, in (0, 1] (default 1)")
    args = ap.parse_args(argv)
    if args.blend < 0 or not 0 < args.t_scale <= 1:
        print("ecu_records: --blend must be >= 0 and --t-scale in (0, 1]", file=sys.stderr)
        return 2
    if not (-1 <= args.w_aw <= 1 and args.w_aw != 0):
        print("ecu_records: --w-aw must be in [-1, 1] and not 0", file=sys.stderr)
        return 2
    paths, _ = ecu_records(args.out, seed=args.seed, anti_windup=args.anti_windup, P_blend=args.blend,
                           w_aw=args.w_aw, t_scale=args.t_scale)
    for p in paths:
        print(p)
    return 0


if __name__ == "__main__":
    sys.exit(main())
