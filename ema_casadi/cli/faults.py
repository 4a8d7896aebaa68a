"""Fault studies (docs: faults): every case of a fault file on one model, the ECU's
detection per monitor, the rod's transient, the coverage matrix.

MODEL.toml comes first, FAULTS.toml second (or by --faults); without them the packaged
reference set and fault table run. FAULTS.toml holds the [scenario] (command, load,
duration, sensors) and [[fault]] tables
(kind, target, onset, severity, ramp; onsets and severities may be lists); its format is
in the guide ("Faults, sensors and monitors") and in models/faults_reference.toml. The
model carries every fault kind and the monitors (faults = on, monitors = on, and the
PMSM's winding_short = on), so no case rebuilds it. Writes OUT/<file>.csv (one row per
case), OUT/<file>.json and OUT/<file>.png (coverage matrix and transients).
--healthy-runs N adds the false-alarm count over N healthy runs with sensor noise and
+-5 % friction and stiffness tolerances (the sweep engine, --jobs local workers).
--thresholds runs the threshold study instead: per monitor, over thresholds from 0.1 to
2 x its reference, the detection delay of every case (the model's confirmation logic
on the case's statistic) and the false-alarm rate per flight hour (an extreme-value fit of the
largest statistic of each of --healthy-runs N healthy runs, default 1000); writes
OUT/<file>_thresholds.csv and .png, and the margins (largest healthy statistic against
each threshold) in the JSON.
--list prints the fault kinds the model injects and the monitors.
Exit status: 2 for a mistake in a file or flag (unknown kind or target, onset outside
the run, severity out of range, a threshold in the wrong unit), before any run.
Example: ema faults models/cesa_ema.toml models/faults_reference.toml --healthy-runs 100
"""

from __future__ import annotations

import math
from pathlib import Path

from .._util._resources import REFERENCE_FAULTS
from . import UserError, add_progress, jsonable, progress_of, second_file
from ._flags import NoEffect, new_output_folder, output_folder

COMMAND = "faults"
DEFAULT_FAULTS = REFERENCE_FAULTS
DEFAULT_OUT = "out/faults"
#: Healthy runs of --thresholds without --healthy-runs.
STUDY_RUNS = 1000
ORDER = 13
HELP = "fault study: jam, free-run, shorts, supply, sensor faults, wear; detection per monitor, coverage"


_LIST = NoEffect((), "with --list (it prints the fault kinds and monitors and stops)", lambda a: a.list)
_HEALTHY = NoEffect((), "without --healthy-runs N or --thresholds (they run the healthy runs)",
                    lambda a: not a.healthy_runs and not a.thresholds)
#: Each flag -> the combinations where it has no effect (refused; docs: cli).
NO_EFFECT = {"--faults": (), "--list": (),
             "--thresholds": (NoEffect(("--list", "--thresholds"), _LIST.why, _LIST.when),),
             "--out": (NoEffect(("--list", "--out", "o"), _LIST.why, _LIST.when),),
             "--healthy-runs": (NoEffect(("--list", "--healthy-runs", "3"), _LIST.why, _LIST.when),),
             **{flag: (NoEffect(("--list", flag, "2"), _LIST.why, _LIST.when),
                       NoEffect((flag, "2"), _HEALTHY.why, _HEALTHY.when)) for flag in ("--jobs", "--seed")}}

def add_arguments(p):
    p.add_argument("faults", metavar="FAULTS.toml", nargs="?", default=None,
                   help=f"fault file (scenario, fault cases), after MODEL.toml; default: the packaged {DEFAULT_FAULTS}")
    p.add_argument("--faults", dest="faults_file", default=None, metavar="FAULTS.toml",
                   help="the fault file by name (with or without MODEL.toml)")
    p.add_argument("--out", default=DEFAULT_OUT, metavar="DIR",
                   help=f"folder for <file>.csv, <file>.json and <file>.png (created); default {DEFAULT_OUT}")
    p.add_argument("--healthy-runs", type=int, default=None, metavar="N",
                   help="false alarms over N healthy runs (noise, +-5 %% friction and stiffness); default 0 "
                        f"(with --thresholds {STUDY_RUNS}, at least 50: the study's minimum)")
    p.add_argument("--jobs", type=int, default=None, metavar="N", help="local workers of the healthy runs")
    p.add_argument("--seed", type=int, default=1, help="seed of the healthy runs' draws; default 1")
    p.add_argument("--thresholds", action="store_true",
                   help="threshold study: per monitor, detection delay per case and false alarms per flight hour "
                        "over 0.1-2 x the reference thresholds (with --healthy-runs, default 1000)")
    p.add_argument("--list", action="store_true", help="print the fault kinds and monitors of the model and exit")
    add_progress(p)


def _check(args) -> Path:
    from ..model.components import validate_variants
    from ..sweeps import MAX_RUNS

    if args.healthy_runs is None:  # not given: none, or the threshold study's default
        args.healthy_runs = STUDY_RUNS if args.thresholds else 0
    elif args.thresholds:
        from ..faults import check_study_runs
  # given: 0 is no healthy run, which a study cannot fit (not the default)
        check_study_runs(args.healthy_runs)
    if args.healthy_runs < 0:
        raise UserError(f"--healthy-runs must be a non-negative integer, got {args.healthy_runs}")
    if args.healthy_runs > MAX_RUNS:
        raise UserError(f"--healthy-runs {args.healthy_runs}: above the limit of {MAX_RUNS} runs (MAX_RUNS)")
    validate_variants(dict(args.variant), "--variant")  # before the fault file's choices join them
    if args.jobs is not None and args.jobs < 1:
        raise UserError(f"--jobs must be a positive integer, got {args.jobs}")
    if args.seed < 0:
        raise UserError(f"--seed must be a non-negative integer, got {args.seed}")
    return Path(args.out)


def _listing(params, variants) -> dict:
    from ..faults import fault_kinds, fault_variants
    from ..model.assembly import build_model

    v = fault_variants(params, variants)
    kinds = {k: {str(t): {"input": f.input, "unit": f.unit, "range": [f.lo, f.hi], "ramp": f.rate, "doc": f.doc}
                 for t, f in targets.items()} for k, targets in fault_kinds(v).items()}
    return {"kinds": kinds, "monitors": list(build_model(params, v).outputs_of("alarm")), "written": []}


def run(args) -> dict:
    from ..faults import load_faults, run_faults
    from ..model.params import load_parameters

    out = _check(args)
    args.faults = second_file(args, args.faults, args.faults_file, flag="--faults", what="fault", key="fault",
                              default=DEFAULT_FAULTS)
    stem = Path(args.faults).stem
    names = [f"{stem}.csv", f"{stem}.json", f"{stem}.png"]
    if args.thresholds:
        names += [f"{stem}_thresholds.csv", f"{stem}_thresholds.png"]
    top = None if args.list else new_output_folder(out, names)  # the outputs checked before any work
    params = load_parameters(args.model)
    if args.list:
        return _listing(params, dict(args.variant))
    spec = load_faults(args.faults, params, dict(args.variant))
    res = run_faults(faults=spec, healthy=0 if args.thresholds else args.healthy_runs, jobs=args.jobs,
                     seed=args.seed, progress=progress_of(args))
    study = None
    if args.thresholds:
        from ..faults import threshold_study

        study = threshold_study(spec, healthy=args.healthy_runs, jobs=args.jobs, seed=args.seed,
                                progress=progress_of(args), table=res)
        res.healthy = study.healthy
    with output_folder(out, top) as folder:  # whole, or not at all
        res.to_csv(folder / names[0])
        if study is not None:
            study.to_csv(folder / names[3])
            study.plot(folder / names[4])
        res.to_json(folder / names[1], extra=None if study is None else {"thresholds": study.summary()})
        res.plot(folder / names[2])
    summary = res.summary()
    if study is not None:
        summary["thresholds"] = study.summary()
    summary["written"] = [str(out / n) for n in names]
    return jsonable(summary)


def _report_cases(r: dict) -> None:
    """The cases' table: each case's run, the rod's deviation and each monitor's delay,
    with the words defined under it."""
    from ..signals import format_quantity as q

    mons = r["monitors"]
    print(f"{r['cases']} cases in {r['wall_time']:.1f} s")
    head = " ".join(f"{m.removeprefix('latch_'):>7s}" for m in mons)
    print(f"{'case':20s} {'run':6s} {'peak dev':>9s} {head}")
    print(f"{'':20s} {'':6s} {'(mm)':>9s} " + " ".join(f"{'(ms)':>7s}" for _ in mons))
    for row in r["rows"]:
        cells = [row[f"detected_{m}_s"] for m in mons]
        dev = row["peak_deviation_m"]
        dev = q(dev, "m", unit="mm") if dev is not None and math.isfinite(dev) else "-"
        print(f"{row['case']:20s} {'done' if row['status'] == 'ok' else 'FAILED':6s} {dev.removesuffix(' mm'):>9s} "
              + " ".join(f"{q(c, 's', unit='ms').removesuffix(' ms'):>7s}" if c is not None else f"{'-':>7s}"
                         for c in cells))
    print("run: done = the case ran to its end (FAILED: the run stopped; --json has the reason); peak dev: the "
          "largest |x_rod| difference from the no-fault run after the onset")
    print("monitor columns: the delay from the fault's onset to the monitor's latch (- : not latched; in the row "
          "none, a false alarm's time)")
    for m, doc in r.get("monitor_doc", {}).items():
        print(f"  {m.removeprefix('latch_')}: {doc}")


def report(r: dict) -> None:
    if "kinds" in r:
        for kind, targets in r["kinds"].items():
            for target, f in targets.items():
                what = kind if target == "None" else f"{kind} target={target}"
                lo, hi = f["range"]
                print(f"{what:28s} severity {lo:g}..{hi:g} {f['unit']:6s} ({f['input']}): {f['doc']}")
        print("monitors: " + ", ".join(r["monitors"]))
        return
    _report_cases(r)
    if r["false_alarms_no_fault"]:
        print("false alarms without a fault: " + ", ".join(r["false_alarms_no_fault"]))
    h = r.get("healthy_runs")
    if h:
        print(f"healthy runs: {h['false_alarms']} of {h['runs']} with a false alarm ({h['failed']} failed) in "
              f"{h['wall_time']:.1f} s on {h['jobs']} workers")
    for latch, m in (h or {}).get("margins", {}).items():
        print(f"margin {latch.removeprefix('latch_'):6s}: healthy max {m['healthy_max']:.4g} {m['unit']} against "
              f"{m['threshold_param']} = {m['threshold']:.4g} ({m['margin']:.0%} below it)")
    th = r.get("thresholds")
    if th:
        print(f"threshold study ({th['runs']} healthy runs of {th['run_duration_s']:g} s; {th['false_alarm_method']}):")
        for latch, m in th["monitors"].items():
            ref = next(x for x in m["rows"] if x["scale"] == 1.0) if any(x["scale"] == 1.0 for x in m["rows"]) \
                else None
            if ref is not None:
                print(f"  {latch.removeprefix('latch_'):6s} at {m['threshold_param']} = {m['reference']:.4g}: "
                      f"{ref['false_alarms_per_hour']:.3g} false alarms per flight hour (the data alone: at most "
                      f"{ref['data_bound_per_hour']:.3g}), expected "
                      f"{ref['expected_in_runs']:.3g} in the runs, observed {ref['observed_in_runs']}")
    for w in r.get("written", []):
        print(f"wrote {w}")
