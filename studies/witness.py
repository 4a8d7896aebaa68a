"""Witness rigs with real friction, written independently of the model's friction code,
and the study of identify's estimates and robust 95 % intervals on them.

The rigs are the NumPy transcription of the reference actuator
(``benchmarks/numpy_model.py``: PMSM, elastic screw, P position loop, speed PI with
back-calculation, ideal inverter) with its friction replaced by one written here:

- ``hump``: a Stribeck hump of another shape than the model's (exponential, not
  Gaussian): F = F_r s(v) + (F_s - F_r) exp(-|v|/v_st) s(v) + c_v v with s(v) =
  tanh(v/v_s), F_r = F_seal + |f_ext| (2 pi/p) C_bear, F_s = r_start F_r;
- ``lugre``: LuGre (Canudas de Wit et al. 1995) with sign(v), no smoothing:
  dz/dt = v - sigma_0 |v| z/g(v), g(v) = F_r + (F_s - F_r) exp(-(v/v_st)^2),
  F = sigma_0 z + c_v v, sigma_0 = 1e10 N/m, no bristle damping;
- ``gauss`` (the control): the model's own law with ``stribeck = on`` (a Gaussian hump
  on tanh(v/v_s)), transcribed here: the records the matching structure can reproduce,
  which checks the rig's transcription, integration and inputs (:func:`check`).

The numpy model is run with its own friction set to zero (F_seal = C_bear = c_v = 0) and
the rig's friction subtracted from the rod's force balance, so the rest of the
actuator is the independently transcribed one. The true parameters (:data:`TRUTH`) are
10-30 % away from the reference set, the breakaway 1.4 x the sliding level and the
Stribeck velocity 1.5 mm/s. Four records at 2 kHz (:func:`commands`): ``steps`` and
``chirp`` as the benchmark's (``studies/ecu_records.py``, durations x 0.25), and
loaded ``push`` (+8 kN) and ``pull`` (-15 kN): a staircase of rod speeds 6, 8, 12, 16,
32, 64 mm/s (80 ms each: the steady segments a friction start reads), then a slew back
at the rate limit (slower stairs chatter: below ~4 mm/s under load the hump's slope is
steeper than the screw's contact damping, and the rod chatters on its spring). Five
channels with the benchmark's sensor noise (:data:`NOISE`). The
inputs are the sampled tables the fit is driven by (linear between samples). The
noise-free records are integrated once per rig by SciPy's LSODA (rtol 1e-11, absolute
tolerances a thousandth of each state's resolution, steps below a sample) and cached
under ``out/witness``. At rtol 1e-9 the rig's load cell differed from the toolkit's
converged solution by 0.15-0.25 of its noise (RMS): over the records' 33 100 residuals a
systematic error that size moves the best-determined estimates by several standard
deviations, so coverage measured against such records is the rig's integration error's.

The study fits ``n`` noise realisations per rig from the reference start with the
matching structure (:data:`STRUCTURE`; ``hump``: ``stribeck = on`` with the shape
exponent ``delta_st = 1``, the model's exponential hump, written apart from the rig's;
``lugre``: ``friction = lugre``, the
model's LuGre with sigma_0 = 1e10 N/m and sigma_1 = 0 as the rig's: stiff bristles
are not identifiable from 0.3 um position noise; ``lugre_smooth``: the LuGre rig's
records fitted with ``friction = lugre_smooth``, ``stribeck = on``, LuGre on the
smooth law's tanh curve), the nine parameters of :data:`TRUTH` free, and reports:
the share of realisations with every estimate within 2 % of its truth (c_v and v_st
within 10 %), the coverage of the robust 95 % intervals per
parameter, the verdicts, and the wall and CPU time per fit. ``--default`` fits the
default structure instead (the seven parameters without r_start, v_st) and reports
the exit status and whether the friction options are named.

Usage::

    python studies/witness.py [--rig hump|lugre|gauss] [--n 20] [--jobs 1] [--friction-start auto] [--from-truth]
        [--starts 6 --fit-jobs 2 --coarse-to-fine] [--unsettled leave-out] [--default] [--json]
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "benchmarks"))
sys.path.insert(0, str(ROOT / "studies"))
import coverage  # noqa: E402
import numpy_model  # noqa: E402

import ema_casadi as ema  # noqa: E402
from ema_casadi.identification import FitFailed, Record, identify  # noqa: E402
from ema_casadi.signals import parse_signal  # noqa: E402

#: The rigs' actuator: 10-30 % from the reference set; breakaway 1.4 F_r, v_st 1.5 mm/s.
TRUTH = {"F_seal": 180.0, "C_bear": 3.6e-5, "c_v": 260.0, "r_start": 1.4, "v_st": 1.5e-3, "B": 2.4e-5,
         "C": 2.0e8, "J_m": 1.38e-3, "psi": 0.27}
#: Acceptance tolerance per parameter (relative).
TOLERANCE = {**{k: 0.02 for k in TRUTH}, "c_v": 0.10, "v_st": 0.10}
#: The default structure's free set (no hump parameters).
DEFAULT_FREE = ("F_seal", "C_bear", "c_v", "B", "C", "J_m", "psi")
SIGMA_0 = 1e10
#: The rig's integration tolerances (LSODA; absolute per state of its ten).
RIG_RTOL = 1e-11
RIG_ATOL = [1e-9, 1e-9, 1e-9, 1e-10, 1e-10, 1e-11, 1e-9, 1e-14, 1e-12, 1e-17]
NOISE = {"x_rod": 0.3e-6, "phi": 2e-4, "omega": 0.2, "i_q": 0.05, "F_in": 10.0}
RATE = 2000.0
T_SCALE = 0.25
#: The loaded records' speed staircase (m/s) and dwell per speed (s).
SPEEDS = (6e-3, 8e-3, 12e-3, 16e-3, 32e-3, 64e-3)
DWELL = 0.08
#: The structure each rig is fitted with (matching), and its parameters beyond the file's.
STRUCTURE = {"hump": ({"stribeck": "on"}, {"delta_st": 1.0}), "gauss": ({"stribeck": "on"}, {}),
             "lugre": ({"friction": "lugre"}, {"sigma_0": SIGMA_0, "sigma_1": 0.0}),
             "lugre_smooth": ({"friction": "lugre_smooth", "stribeck": "on"}, {"sigma_0": SIGMA_0, "sigma_1": 0.0})}
#: The rig that makes the records of each structure's name.
RIG = {"lugre_smooth": "lugre"}


def commands(params) -> dict:
    """Record name -> (t, x_cmd, f_ext) sampled at :data:`RATE` (SI)."""
    out = {}
    for name, (dur, x_cmd, f_ext) in (("steps", (3.0, "step:2mm@0.1+step:-4mm@1.0+step:2mm@2.0", "0")),
                                       ("chirp", (4.0, "chirp:0.5mm@0.5-25", "0"))):
        t_end = dur * T_SCALE
        t = np.arange(int(round(t_end * RATE)) + 1) / RATE
        x = _scaled(x_cmd, T_SCALE)
        out[name] = (t, parse_signal(x, "length", stroke=params.actuator.stroke, duration=t_end)(t),
                     parse_signal(f_ext, "force", duration=t_end)(t))
    t0, t_back = 0.05, 0.05 + len(SPEEDS) * DWELL
    t = np.arange(int(round((t_back + 0.25) * RATE)) + 1) / RATE
    speed = np.zeros_like(t)
    for k, v in enumerate(SPEEDS):
        speed[(t >= t0 + k * DWELL) & (t < t0 + (k + 1) * DWELL)] = v
    ramp = np.concatenate([[0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) / RATE)])
    ramp[t >= t_back] = 0.0  # the slew back at the rate limit
    for name, sign, load in (("push", 1.0, 8e3), ("pull", -1.0, -15e3)):
        out[name] = (t, sign * ramp, np.where(t >= 0.02, load, 0.0))
    return out


def _scaled(text: str, factor: float) -> str:
    out = []
    for term in text.split("+"):
        head, *times = term.split("@")
        out.append("@".join([head, *[s if "-" in s else f"{float(s) * factor:g}" for s in times]]))
    return "+".join(out)


def friction(rig: str, v: float, z: float, f_ext: float, P: dict) -> tuple[float, float]:
    """The rig's friction force on the rod (N) and bristle rate dz/dt (m/s)."""
    F_r = P["F_seal"] + abs(f_ext) * 2 * math.pi / P["p"] * P["C_bear"]
    F_s = P["r_start"] * F_r
    if rig in ("hump", "gauss"):
        s = math.tanh(v / P["v_s"])
        hump = math.exp(-abs(v) / P["v_st"]) if rig == "hump" else math.exp(-((v / P["v_st"]) ** 2))
        return F_r * s + (F_s - F_r) * hump * s + P["c_v"] * v, 0.0
    g = F_r + (F_s - F_r) * math.exp(-((v / P["v_st"]) ** 2))
    dz = v - SIGMA_0 * abs(v) * z / g
    return SIGMA_0 * z + P["c_v"] * v, dz


def clean_records(rig: str, params=None) -> list[dict]:
    """The rig's noise-free records (cached in out/witness): per record ``name``, ``t``,
    ``inputs`` (x_cmd, f_ext) and ``channels`` (:data:`NOISE`'s)."""
    params = params or ema.load_parameters()
    cache = ROOT / "out" / "witness" / f"{rig}_{len(SPEEDS)}x{1e3 * SPEEDS[0]:g}mm_r{-math.log10(RIG_RTOL):g}.npz"
    cmds = commands(params)
    if cache.exists():
        data = np.load(cache)
        return [{"name": n, "t": c[0], "inputs": {"x_cmd": c[1], "f_ext": c[2]},
                 "channels": {ch: data[f"{n}.{ch}"] for ch in NOISE}} for n, c in cmds.items()]
    P = {**params.as_dict(), **TRUTH}
    P0 = {**P, "F_seal": 0.0, "C_bear": 0.0, "c_v": 0.0}
    out = []
    for name, (t, x_cmd, f_ext) in cmds.items():
        def rhs(tt, y, t=t, x_cmd=x_cmd, f_ext=f_ext):
            xc, fe = float(np.interp(tt, t, x_cmd)), float(np.interp(tt, t, f_ext))
            dy = np.empty(10)
            dy[:9] = numpy_model.rhs(tt, y[:9], xc, fe, P["eta"], P0)
            F, dy[9] = friction(rig, y[8], y[9], fe, P)
            dy[8] -= F / P["M"]
            return dy

        sol = solve_ivp(rhs, (0.0, t[-1]), np.zeros(10), method="LSODA", t_eval=t, rtol=RIG_RTOL,
                        max_step=0.5 / RATE, atol=RIG_ATOL)
        if not sol.success:
            raise RuntimeError(f"{rig} {name}: {sol.message}")
        y = sol.y
        r = P["p"] / (2 * math.pi)
        delta, half = y[5] * r - y[7], P["B"] / 2
        dz = np.maximum(delta - half, 0.0) + np.minimum(delta + half, 0.0)
        F_in = P["C"] * dz + np.where(np.abs(delta) >= half, P["c_c"] * (y[6] * r - y[8]), 0.0)
        out.append({"name": name, "t": t, "inputs": {"x_cmd": x_cmd, "f_ext": f_ext},
                    "channels": {"x_rod": y[7], "phi": y[5], "omega": y[6], "i_q": y[4], "F_in": F_in}})
    cache.parent.mkdir(parents=True, exist_ok=True)
    np.savez(cache, **{f"{c['name']}.{ch}": v for c in out for ch, v in c["channels"].items()})
    return out


def check(rig: str = "gauss") -> dict:
    """Channel -> RMS difference between the rig's noise-free records and the toolkit's
    simulation with the matching structure at the truth (compiled RODAS4, rtol 1e-10,
    driven by the same tables), in noise levels (:data:`NOISE`)."""
    from ema_casadi import Signal

    params = ema.load_parameters()
    variants, extra = STRUCTURE[rig]
    model = ema.build_model(params, variants or None)
    pv = params.vector(**TRUTH, **extra)
    diff = {c: [] for c in NOISE}
    for c in clean_records(RIG.get(rig, rig), params):
        res = ema.simulate(model, c["t"][-1], dt_out=1.0 / RATE, p=pv, solver="rosenbrock", rtol=1e-10, atol=1e-13,
                           **{k: Signal.table(c["t"], v) for k, v in c["inputs"].items()})
        for ch in NOISE:
            diff[ch].append(np.asarray(res[ch], float) - c["channels"][ch])
    return {ch: float(np.sqrt(np.mean(np.concatenate(d) ** 2)) / NOISE[ch]) for ch, d in diff.items()}


def realisation(clean: list[dict], seed: int) -> list[Record]:
    """The records with seeded noise (record k: seed * 100 + k), as the coverage study's."""
    return coverage.realisation(clean, seed, NOISE)


def write_records(rig: str, folder, seed: int = 0) -> list[Path]:
    """Realisation ``seed`` of the rig's records as CSV files in ``folder`` (the project's
    time-series layout: ``# sigma_<channel>`` fields, header, ``Unit:`` row)."""
    from ema_casadi._util._files import write_text

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    units = {"x_cmd": "m", "f_ext": "N", "x_rod": "m", "phi": "rad", "omega": "rad/s", "i_q": "A", "F_in": "N"}
    paths = []
    for rec in realisation(clean_records(RIG.get(rig, rig)), seed):
        cols = {**rec.inputs, **rec.channels}
        lines = [f"# sigma_{c}: {s}" for c, s in NOISE.items()] + [f"# witness: {rig}"]
        lines += ["time," + ",".join(cols), "Unit:," + ",".join(units[c] for c in cols)]
        lines += [",".join(f"{float(v):.17g}" for v in row) for row in np.column_stack([rec.t, *cols.values()])]
        paths.append(write_text(folder / rec.path, "\n".join(lines) + "\n"))
    return paths


def one_fit(rig: str, clean, seed: int, friction_start: str = "auto", default: bool = False,
            max_evaluations: int = 60, starts: int = 1, from_truth: bool = False, coarse: bool = False,
            jobs: int = 1, unsettled: str = "keep") -> dict:
    """One realisation's fit: verdict, estimates, robust intervals, wall and CPU time;
    ``from_truth``: started at :data:`TRUTH` (the statistics without the search)."""
    params = ema.load_parameters()
    variants, extra = ({}, {}) if default else STRUCTURE[rig]
    if extra:
        params = params.replace(**extra)
    free = list(DEFAULT_FREE if default else TRUTH)
    t0, c0 = time.perf_counter(), time.process_time()
    try:
        res = identify(params, realisation(clean, seed), free, sigma=NOISE, variants=variants or None,
                       friction_start=friction_start, max_evaluations=max_evaluations, starts=starts,
                       coarse_to_fine=coarse, jobs=jobs, unsettled=unsettled,
                       start={k: TRUTH[k] for k in free} if from_truth else None)
    except FitFailed as exc:
        return {"seed": seed, "status": exc.status, "reason": exc.reason, "hints": bool(getattr(exc, "hints", None)),
                "wall_s": time.perf_counter() - t0, "cpu_s": time.process_time() - c0}
    return {"seed": seed, "status": "converged", "verdict": res.adequacy["verdict"],
            "adequate": bool(res.adequacy["adequate"]), "estimate": dict(res.estimate),
            "interval": {k: list(v) for k, v in res.interval.items()},
            "hints": res.info.get("hints"), "evaluations": res.info.get("evaluations"),
            "coarse_to_fine": res.info.get("coarse_to_fine"), "unsettled": res.info.get("unsettled"),
            "prediction_accuracy": res.info.get("prediction_accuracy"),
            "friction_start": {k: v for k, v in res.info.get("friction_start", {}).items()
                               if k in ("used", "values", "fitted", "why", "start_costs")}, "cost": res.info["cost"],
            "wall_s": time.perf_counter() - t0, "cpu_s": time.process_time() - c0}


def _worker(item):
    return one_fit(*item)


def study(rig: str, n: int = 20, *, seed: int = 0, friction_start: str = "auto", default: bool = False,
          jobs: int = 1, max_evaluations: int = 60, progress: bool = True, log=None, starts: int = 1,
          from_truth: bool = False, coarse: bool = False, fit_jobs: int = 1, unsettled: str = "keep") -> dict:
    """The study of the module docstring for one rig; ``log``: a file each fit's
    document is appended to as one JSON line (a partial study survives)."""
    clean = clean_records(RIG.get(rig, rig))
    items = [(rig, clean, seed + i, friction_start, default, max_evaluations, starts, from_truth, coarse, fit_jobs,
              unsettled)
             for i in range(n)]
    if jobs > 1:
        from ema_casadi._util._parallel import process_map

        outs = process_map(_worker, items, jobs)
    else:
        outs = []
        for i, item in enumerate(items):
            outs.append(_worker(item))
            if log:
                with open(log, "a") as fh:
                    fh.write(json.dumps(outs[-1], default=float) + "\n")
            if progress:
                o = outs[-1]
                print(f"{rig} {i + 1}/{n}: {o.get('verdict', o['status'])} in {o['wall_s']:.0f} s", file=sys.stderr,
                      flush=True)
    return summary(rig, outs, default)


def summary(rig: str, outs: list[dict], default: bool = False) -> dict:
    """Shares and coverage over the fits ``outs``."""
    done = [o for o in outs if o["status"] == "converged"]
    doc = {"rig": rig, "structure": "default" if default else "matching", "n": len(outs), "converged": len(done),
           "verdicts": {}, "wall_s": [float(np.median([o["wall_s"] for o in outs]))] if outs else [],
           "cpu_s": float(np.median([o["cpu_s"] for o in outs])) if outs else float("nan"), "fits": outs}
    for o in outs:
        key = o.get("verdict", o["status"])
        doc["verdicts"][key] = doc["verdicts"].get(key, 0) + 1
    doc["wall_s"] = float(np.median([o["wall_s"] for o in outs])) if outs else float("nan")
    doc["wall_max_s"] = float(max(o["wall_s"] for o in outs)) if outs else float("nan")
    if default:
        doc["hints"] = sum(1 for o in outs if o.get("hints"))
        return doc
    names = list(TRUTH)
    within = [all(abs(o["estimate"][k] / TRUTH[k] - 1) <= TOLERANCE[k] for k in names) for o in done]
    doc["within_tolerance"] = sum(within)
    doc["error_median"] = {k: float(np.median([o["estimate"][k] / TRUTH[k] - 1 for o in done])) if done else None
                           for k in names}
    doc["coverage"] = {k: (sum(o["interval"][k][0] <= TRUTH[k] <= o["interval"][k][1] for o in done) / len(done)
                           if done else None) for k in names}
    return doc


def table(doc: dict) -> str:
    """The study as Markdown."""
    head = (f"{doc['rig']} ({doc['structure']} structure): {doc['n']} realisations, {doc['converged']} converged, "
            f"verdicts {doc['verdicts']}; wall per fit median {doc['wall_s']:.0f} s (max {doc['wall_max_s']:.0f} s), "
            f"CPU {doc['cpu_s']:.0f} s")
    if doc["structure"] == "default":
        return head + f"; friction options named in {doc['hints']} of {doc['n']}"
    lines = [head, f"every estimate within tolerance: {doc['within_tolerance']} of {doc['n']}", "",
             "| parameter | median error | robust 95 % covers |", "|---|---|---|"]
    for k in TRUTH:
        e, c = doc["error_median"][k], doc["coverage"][k]
        lines.append(f"| {k} | {'-' if e is None else f'{100 * e:+.2f} %'} | "
                     f"{'-' if c is None else f'{100 * c:.0f} %'} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rig", choices=tuple(STRUCTURE), default="hump")
    ap.add_argument("--n", type=int, default=20, help="noise realisations (default 20)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--jobs", type=int, default=1, help="fits at once (worker processes)")
    ap.add_argument("--friction-start", choices=("auto", "records", "off"), default="auto")
    ap.add_argument("--max-evaluations", type=int, default=60)
    ap.add_argument("--starts", type=int, default=1, help="identify's starts per fit (a Latin hypercube after a "
                    "friction start)")
    ap.add_argument("--unsettled", choices=("keep", "leave-out"), default="keep",
                    help="identify(unsettled=...): leave-out gives the chaotic bursts' samples weight zero")
    ap.add_argument("--coarse-to-fine", action="store_true", help="identify(coarse_to_fine=True): block means "
                    "of the residuals first (with --starts N: every start at the coarsest level, the best continued)")
    ap.add_argument("--fit-jobs", type=int, default=1, help="identify's worker processes for its starts")
    ap.add_argument("--from-truth", action="store_true", help="start every fit at the truth (the statistics "
                    "without the search)")
    ap.add_argument("--default", action="store_true", help="fit the default structure (no hump parameters)")
    ap.add_argument("--write", default=None, metavar="DIR", help="only write realisation --seed as CSV into DIR")
    ap.add_argument("--check", action="store_true", help="only the rig against the model at the truth (noise levels)")
    ap.add_argument("--json", default=None, metavar="FILE", help="also write the full document (every fit) here")
    ap.add_argument("--log", default=None, metavar="FILE", help="append each fit as a JSON line (partial studies)")
    ap.add_argument("--summarise", default=None, metavar="FILE", help="only the table of the fits in a --log FILE")
    args = ap.parse_args(argv)
    if args.n < 1:
        print("witness: --n must be >= 1", file=sys.stderr)
        return 2
    if args.summarise:
        outs = [json.loads(line) for line in Path(args.summarise).read_text().splitlines() if line.strip()]
        print(table(summary(args.rig, outs, args.default)))
        return 0
    if args.write:
        for p in write_records(args.rig, args.write, args.seed):
            print(p)
        return 0
    if args.check:
        print(json.dumps(check(args.rig)))
        return 0
    doc = study(args.rig, args.n, seed=args.seed, friction_start=args.friction_start, default=args.default,
                jobs=args.jobs, max_evaluations=args.max_evaluations, log=args.log, starts=args.starts,
                from_truth=args.from_truth, coarse=args.coarse_to_fine, fit_jobs=args.fit_jobs,
                unsettled=args.unsettled)
    if args.json:
        Path(args.json).write_text(json.dumps(doc, indent=1, default=float) + "\n")
    print(table(doc))
    return 0


if __name__ == "__main__":
    sys.exit(main())
