"""Fit named parameters to test records (weighted least squares with exact sensitivities).

Records (CSV with a time column and a Unit: row or units in brackets, or .mat with
time and one field per signal): columns named after model inputs (x_cmd, f_ext, ...)
drive the model, columns named after model states or outputs (x_rod, phi, omega, i_q,
F_in, ...) are fitted. The fitted parameter file (--out) keeps the input file's
layout with the estimates in place; --report DIR writes measured vs fitted figures,
residuals, the correlation heat map, the intervals and summary.json/summary.md.
The headline 95 % intervals are robust (a Newey-West sandwich of the residuals'
autocorrelation per record, inflated by the records' disagreement), the textbook
ones beside them. A parameter whose robust interval is wider than +-50 % is poorly
determined: reported with its estimate and interval, held only on request (--hold
NAME[=VALUE], --hold-unidentifiable; its type-B effect on the others' intervals
shown); a strong correlation is a note with the combination that is determined.
A fit that does not converge ends with exit status 3 and writes nothing (with --json,
one document: status, reason, last iterate, cost history). The
verdict: adequate (the residuals are explained by the noise: chi-square, Ljung-Box
whiteness, records' consistency); adequate within model error (a test fails but
every channel's systematic misfit is at most --model-error noise levels and no
record's estimates move by more than 5x that in sandwich sd: status 0, the misfit
named); inadequate: exit status 3 with the fitted file written as
FILE.inadequate.toml, or status 0 and a warning with --allow-misfit.
--track fits each record alone in the order of its time stamp (--stamp: a file-level
field such as '# flight_hours: 1200' or a column) and extrapolates each parameter's
trend to --limit NAME=VALUE (remaining useful life).
Without records, the built-in example runs: records simulated from the reference set
with worn parameters, fitted from the reference values.
Example: ema identify step.csv chirp.csv --free F_seal,c_v,J_m,psi --sigma x_rod=0.3um --out fitted.toml
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

from .._util._parallel import cores
from . import UserError, add_progress, check_output_dir, check_output_path, load, progress_of
from ._flags import NoEffect, no_effect
from ._identify_parse import bounds, holds, quantities
from ._identify_text import text_report

COMMAND = "identify"
ORDER = 12
#: The records' time-stamp field of --track when --stamp is not given.
STAMP = "flight_hours"
HELP = "fit parameters to test records: estimates, 95 %% intervals, identifiability, health trend"


def add_arguments(p):
    p.add_argument("records", nargs="*", metavar="RECORD", help="test records (.csv or .mat); none: the example")
    p.add_argument("--free", default=None, metavar="NAME[,NAME...]", help="parameters to fit (flat names)")
    p.add_argument("--bounds", action="append", default=[], metavar="NAME=LO:HI",
                   help="bounds of a free parameter (SI), repeatable; LO > 0 for a positive (log-scaled) one")
    p.add_argument("--structural", action="append", default=[], metavar="NAME=LO:HI",
                   help="a constant held at its value whose plausible range (SI) widens the robust intervals by "
                        "the estimates' shift over it (type B), repeatable; e.g. P_blend=0.05:0.2")
    p.add_argument("--sigma", action="append", default=[], metavar="CHANNEL=VALUE",
                   help="noise standard deviation of a channel, repeatable (0.3um, 0.05A, 10N; bare: SI); "
                        "default: the record's field sigma_CHANNEL, else estimated from the residuals")
    p.add_argument("--starts", type=int, default=1, metavar="N", help="fits from N starts (best kept); default 1")
    p.add_argument("--seed", type=int, default=0, metavar="N",
                   help="--starts: the seed of the other starts (a second run with another seed tells whether the "
                        "search's outcome is the records' or the starts'); default 0")
    p.add_argument("--jobs", type=int, default=None, metavar="N",
                   help="--starts: worker processes (the result does not depend on it); default the cores")
    p.add_argument("--estimate-x0", nargs="?", const=True, default=False, metavar="STATE[,STATE...]",
                   help="estimate each record's initial state instead of starting at rest (a record cut from "
                        "a motion); bare: positions, speeds and the outer loops' integrals, or the states named")
    p.add_argument("--friction-start", choices=("off", "auto", "records"), default="off",
                   help="start the free friction parameters (F_seal, C_bear, c_v, r_start, v_st) at the steady-state "
                        "friction curve fitted to the records' steady-speed segments under a known load: auto where "
                        "they tell one, records requires that (exit 2 otherwise), off (default) the file's values; "
                        "with --starts N the other starts are a Latin hypercube over those parameters")
    p.add_argument("--coarse-to-fine", action="store_true",
                   help="fit the residuals' means over 200, 100, 50 and 25 ms blocks before every sample: records "
                        "with stick-slip make the cost over every sample rugged in the breakaway, the block means' "
                        "smooth; with --starts N every start is fitted at 200 ms and the lowest goes on; the fit "
                        "on every sample also runs from the first start and the lower cost is kept")
    p.add_argument("--unsettled", choices=("keep", "leave-out"), default="keep",
                   help="leave-out: give weight zero to the samples the model predicts differently at rtol 1e-8 and "
                        "1e-10 by more than a third of the noise level, +-20 ms (chaotic stick-slip bursts no "
                        "parameter value predicts), in the fit and its statistics; the windows are reported; "
                        "default keep")
    p.add_argument("--method", default="single", metavar="METHOD",
                   help="single (shooting from the start values), multiple (shooting) or collocation (node states and "
                        "parameters solved together, then finished by single shooting), or auto (single, then "
                        "collocation where it fails); the intervals and verdict are single shooting's; default single")
    p.add_argument("--nodes", type=int, default=None, metavar="N",
                   help="--method multiple/collocation: intervals per record (at least 1); default one per 0.5 ms")
    p.add_argument("--max-evaluations", type=int, default=60, metavar="N",
                   help="model evaluations per fit; more means not converged (exit 3); default 60")
    p.add_argument("--model-error", type=float, default=None, metavar="SIGMAS",
                   help="systematic misfit tolerated, in noise levels (default 1: a model error below the sensor "
                        "noise gives 'adequate within model error', exit 0); above 10 only with --allow-misfit")
    p.add_argument("--allow-misfit", action="store_true",
                   help="an inadequate fit (residuals not explained by the noise: chi-square or whiteness) "
                        "ends with status 0 and a warning instead of status 3 and FILE.inadequate.toml; confirms "
                        "a --model-error above 10")
    p.add_argument("--compare", action="append", default=[], metavar="KEY=V1,V2[,...]",
                   help="fit every combination of these variant/option values (repeatable: anti_windup=backcalc,"
                        "clamping) and rank them: adequate first, then by BIC; the best is written")
    p.add_argument("--max-fits", type=int, default=None, metavar="N",
                   help="--compare: most combinations (each a full fit); default 8")
    p.add_argument("--hold", action="append", default=[], metavar="NAME[=VALUE]",
                   help="hold a free parameter after the fit, at VALUE (SI or with a unit) or bare at its start "
                        "value, and fit the others again; its type-B effect on their intervals is shown (its range: "
                        "--structural NAME=LO:HI, else its interval while free), repeatable")
    p.add_argument("--hold-unidentifiable", action="store_true",
                   help="hold every poorly determined parameter (interval wider than +-50 %%) at its start value "
                        "(default: reported with its estimate and interval, marked poorly determined)")
    p.add_argument("--profile", action="append", default=[], metavar="NAME",
                   help="profile-likelihood interval of a free parameter, repeatable")
    p.add_argument("--validate", nargs="+", default=[], metavar="RECORD",
                   help="records not used in the fit, predicted with the estimates (NRMSE, residual whiteness)")
    p.add_argument("--track", action="store_true",
                   help="health trend: fit each record alone in the order of its time stamp")
    p.add_argument("--stamp", default=STAMP, metavar="FIELD",
                   help="--track: the records' time-stamp field or column; default flight_hours")
    p.add_argument("--limit", action="append", default=[], metavar="NAME=VALUE",
                   help="--track: a limit of a parameter (SI or with a unit: 0.1mm), repeatable")
    p.add_argument("--out", default=None, metavar="FILE.toml", help="the fitted parameter file")
    p.add_argument("--example-records", default=None, metavar="DIR",
                   help="write the records the guide fits into the new folder DIR and stop: steps, chirp, "
                        "slews_push, slews_pull (seven parameters away from the reference set) and rig_0000h .. "
                        "rig_1500h (seal friction growing with flight_hours)")
    p.add_argument("--report", default=None, metavar="DIR",
                   help="report folder (figures, summary.json, summary.md), assembled aside and moved in")
    add_progress(p)


def _split(args) -> list:
    """The records; a first positional that is not a .toml file is a record (then the
    model is the packaged reference, args.model set to None)."""
    records = list(args.records)
    if args.model is not None and Path(args.model).suffix.lower() != ".toml":
        records.insert(0, args.model)
        args.model = None
    return records


def _example_run(args) -> bool:
    """No records: the built-in example (one plain fit of its two records)."""
    return not args.records and (args.model is None or Path(args.model).suffix.lower() == ".toml")


_TRACK = NoEffect((), "with --track (each record is fitted alone, in order)", lambda a: a.track)
_COMPARE = NoEffect((), "with --compare (the combinations are ranked; profile or validate the best one's fit)",
                    lambda a: bool(a.compare))
_COMPARE_FIT = NoEffect((), "with --compare (each combination is one fit from the file's values with the defaults: "
                        "one start, no bounds, the unidentifiable held)", lambda a: bool(a.compare))
_EXAMPLE = NoEffect((), "without records (the built-in example is one plain fit; write its records with "
                    "--example-records DIR and fit those)", _example_run)
#: The command lines of the examples: a fit of one record, a trend, a comparison.
_FIT, _TRENDS = ("a.csv", "--free", "F_seal"), ("a.csv", "b.csv", "--free", "F_seal", "--track")
_CMP = (*_FIT, "--compare", "anti_windup=backcalc,clamping")


def _on(rule, *example, why=None) -> NoEffect:
    """``rule``'s condition (and reason, unless ``why``) with its example command line."""
    return NoEffect(example, why or rule.why, rule.when)


#: Each flag -> the combinations where it has no effect (refused; docs: cli).
NO_EFFECT = {
    "--free": (), "--sigma": (), "--max-evaluations": (), "--allow-misfit": (), "--report": (), "--example-records": (),
    "--friction-start": (_on(_TRACK, *_TRENDS, "--friction-start", "auto", why="with --track (each record is fitted "
                             "alone from the file's values)"), _on(_EXAMPLE, "--friction-start", "auto")),
    "--coarse-to-fine": (_on(_TRACK, *_TRENDS, "--coarse-to-fine", why="with --track (each record is fitted "
                             "alone from the file's values)"), _on(_EXAMPLE, "--coarse-to-fine")),
    "--unsettled": (_on(_TRACK, *_TRENDS, "--unsettled", "leave-out", why="with --track (each record is fitted alone "
                        "from the file's values)"), _on(_EXAMPLE, "--unsettled", "leave-out"),
                    _on(_COMPARE_FIT, *_CMP, "--unsettled", "leave-out", why="with --compare (each structure would "
                        "leave out its own samples, and their BICs would not compare)")),
    "--method": (_on(_TRACK, *_TRENDS, "--method", "auto"), _on(_COMPARE_FIT, *_CMP, "--method", "auto")),
    "--nodes": (_on(_TRACK, *_TRENDS, "--nodes", "50"), _on(_COMPARE_FIT, *_CMP, "--nodes", "50"),
                NoEffect((*_FIT, "--nodes", "50"), "with --method single (it sets the grid of multiple shooting and "
                         "collocation)", lambda a: a.method == "single")),
    "--track": (_on(_EXAMPLE, "--track"),),
    "--model-error": (_on(_TRACK, *_TRENDS, "--model-error", "2", why="with --track (a trend's fits are judged one "
                          "by one; give it without --track)"), _on(_EXAMPLE, "--model-error", "2")),
    "--compare": (_on(_TRACK, *_CMP, "--track"), _on(_EXAMPLE, "--compare", "anti_windup=backcalc,clamping")),
    "--estimate-x0": (_on(_TRACK, *_TRENDS, "--estimate-x0", why="with --track (a trend's records start at rest; "
                          "fit them one by one instead)"), _on(_EXAMPLE, "--estimate-x0")),
    "--max-fits": (_on(_TRACK, *_TRENDS, "--max-fits", "3"),
                   NoEffect((*_FIT, "--max-fits", "3"), "without --compare (it caps the combinations compared)",
                            lambda a: not a.compare)),
    **{flag: (_on(_TRACK, *_TRENDS, flag, "c.csv"), _on(_COMPARE, *_CMP, flag, "c.csv"))
       for flag in ("--profile", "--validate")},
    "--limit": (NoEffect((*_FIT, "--limit", "F_seal=300N"), "without --track (the limit is what a health trend runs "
                         "to)", lambda a: not a.track),),
    "--stamp": (NoEffect((*_FIT, "--stamp", "hours"), "without --track (it orders the records of a health trend)",
                         lambda a: not a.track),),
    "--out": (_on(_TRACK, *_TRENDS, "--out", "f.toml", why="with --track (a trend has one fit per record; use "
                  "--report DIR)"),),
    "--starts": (_on(_TRACK, *_TRENDS, "--starts", "3", why="with --track (each record is fitted once, from the "
                     "file's values)"), _on(_COMPARE_FIT, *_CMP, "--starts", "3")),
    "--seed": (_on(_TRACK, *_TRENDS, "--seed", "1", why="with --track (each record is fitted once, from the "
                   "file's values)"), _on(_COMPARE_FIT, *_CMP, "--seed", "1"),
               NoEffect((*_FIT, "--seed", "1"), "with one start (it draws the other starts)",
                        lambda a: a.starts == 1)),
    "--jobs": (_on(_TRACK, *_TRENDS, "--jobs", "2", why="with --track (each record is fitted once, in turn)"),
               _on(_COMPARE_FIT, *_CMP, "--jobs", "2"),
               NoEffect((*_FIT, "--jobs", "2"), "with one start (the workers run the --starts fits in parallel)",
                        lambda a: a.starts == 1)),
    "--bounds": (_on(_COMPARE_FIT, *_CMP, "--bounds", "F_seal=1:500"),),
    "--structural": tuple(_on(rule, *ex, "--structural", "P_blend=0.05:0.2") for rule, ex in
                          ((_TRACK, _TRENDS), (_EXAMPLE, ()), (_COMPARE_FIT, _CMP))),
    "--hold": (_on(_COMPARE_FIT, *_CMP, "--hold", "F_seal"),),
    "--hold-unidentifiable": (_on(_COMPARE_FIT, *_CMP, "--hold-unidentifiable"),),
}
#: A value of each flag for the examples of the --example-records rule (flags without one take none).
_SAMPLE = {"--free": "F_seal", "--sigma": "x_rod=0.3um", "--max-evaluations": "10", "--report": "rep",
           "--compare": "anti_windup=backcalc,clamping", "--max-fits": "2", "--profile": "F_seal",
           "--validate": "c.csv", "--limit": "F_seal=300N", "--stamp": "hours", "--out": "f.toml", "--starts": "2",
           "--seed": "1", "--jobs": "2", "--bounds": "F_seal=1:500", "--model-error": "2", "--hold": "F_seal",
           "--structural": "P_blend=0.05:0.2", "--friction-start": "auto",
           "--unsettled": "leave-out", "--method": "auto", "--nodes": "50"}
_WRITES = NoEffect((), "with --example-records (it writes the records and stops; fit them after)",
                   lambda a: a.example_records is not None)
for _flag in [f for f in NO_EFFECT if f != "--example-records"]:  # --example-records writes and stops: all idle
    NO_EFFECT[_flag] = (_on(_WRITES, "--example-records", "rec", _flag, *_SAMPLE.get(_flag, "").split()),
                        *NO_EFFECT[_flag])


def run(args) -> dict:
    from ..identification import FitFailed

    if args.example_records is not None:
        return _write_examples(args)
    out = check_output_path(args.out, (".toml",), "--out")
    records = _split(args)
    if args.starts < 1:
        raise UserError(f"--starts must be at least 1, got {args.starts}")
    if args.jobs is not None and args.jobs < 1:
        raise UserError(f"--jobs must be at least 1, got {args.jobs}")
    if args.max_evaluations < 2:
        raise UserError(f"--max-evaluations must be at least 2, got {args.max_evaluations}")
    if args.model_error is not None and not (math.isfinite(args.model_error) and args.model_error > 0):
        raise UserError(f"--model-error must be a positive number of noise levels, got {args.model_error}")
    if args.model_error is not None and args.track:
        raise UserError("--model-error with --track: a trend's fits are judged one by one (give it without --track)")
    if args.model_error is not None:  # the ceiling, before any work
        from ..identification import check_model_error

        check_model_error(args.model_error, args.allow_misfit)
    params, model = load(args)  # built once here, passed down
    progress = progress_of(args)
    try:
        if not records:
            return _example(args, params, model, out, progress)
        if args.free is None:
            raise UserError("--free: name the parameters to fit, e.g. --free F_seal,c_v,J_m")
        free = [s.strip() for s in args.free.split(",") if s.strip()]
        kw = {"bounds": bounds(args.bounds), "sigma": quantities(args.sigma, "--sigma", model),
              "starts": args.starts, "seed": args.seed, "max_evaluations": args.max_evaluations,
              "hold": holds(args.hold, model), "hold_unidentifiable": args.hold_unidentifiable,
              "estimate_x0": args.estimate_x0, "friction_start": args.friction_start,
              "coarse_to_fine": args.coarse_to_fine, "unsettled": args.unsettled,
              "method": args.method, "nodes": args.nodes,
              "jobs": min(args.starts, args.jobs or cores()), "progress": progress,
              **({} if args.model_error is None else {"model_error": args.model_error,
                                                      "allow_misfit": args.allow_misfit}),
              **({"structural": bounds(args.structural, "--structural")} if args.structural else {})}
        if args.track:
            return _track(args, params, model, records, free, kw)
        if args.compare:
            return _compare(args, params, model, records, free, kw, out)
        return _fit(args, params, model, records, free, kw, out)
    except FitFailed as exc:  # not converged, or the model fails at the start: the document still
        return {**exc.to_dict(), "failure": exc.reason, "written": []}


def _write_examples(args) -> dict:
    """--example-records DIR: the guide's records (identification.guide_records) from the
    packaged set or MODEL.toml, into a new folder written whole or not at all."""
    from ..identification import GUIDE_FILES, TREND_TRUTH, guide_records
    from ..simulation import SimulationError
    from ._flags import new_output_folder, output_folder

    records, out = _split(args), Path(args.example_records)
    if records:
        raise UserError(f"--example-records writes records; {records[0]} given too (fit the records after)")
    if out.exists():
        raise UserError(f"--example-records {out}: exists; name a new folder")
    top = new_output_folder(out, GUIDE_FILES, "--example-records")
    params = load(args)[0]
    with output_folder(out, top) as folder:
        try:
            paths, truth = guide_records(params, folder)
        except SimulationError as exc:  # a variant the variable-step RODAS4 cannot run
            raise UserError(f"--example-records with --variant {', '.join('='.join(v) for v in args.variant)}: "
                            f"{exc}") from None
    return {"model": args.model, "truth": truth, "trend_truth": {"F_seal": TREND_TRUTH},
            "written": [str(out / p.name) for p in paths]}


def _fit(args, params, model, records, free, kw, out) -> dict:
    from ..identification import is_frequency_record, profile, read_record, report_names, validate

    kinds = {is_frequency_record(r) for r in records}
    if len(kinds) > 1:
        raise UserError("records: time series and frequency responses (freq_hz, gain_db, phase_deg) cannot be "
                        "fitted together; give one kind")
    if kinds == {True}:
        return _fit_frequency(args, params, records, free, kw, out)
    recs = [read_record(r, model) for r in records]  # every record checked before any work
    checks = [read_record(r, model) for r in args.validate]
    for name in args.profile:
        if name not in free:
            from .._util._checks import nearest

            raise UserError(f"--profile {name}: not a free parameter{nearest(name, free)}")
    if args.profile and kw.get("estimate_x0") is not False:
        raise UserError("--profile with --estimate-x0: the profile re-fits start at rest; use the Wald intervals")
    report = check_output_dir(args.report, report_names(len(recs), len(free)), "--report")
    res = identify_api(params, recs, free, **kw, model=model)
    doc = res.to_dict()
    _channel_units(doc, model)
    if args.profile:
        doc["profiles"] = {n: profile(res, n) for n in args.profile}
    if checks:
        doc["validation"] = validate(res, checks)
    written = []
    bad = not res.adequacy["adequate"]
    if out is not None:
        written.append(str(res.write(_target(out, bad and not args.allow_misfit),
                                     note=f"command: ema {' '.join(sys.argv[1:])}"[:300])))
    if report is not None:
        written.append(str(res.write_report(report)))
    doc["written"] = written
    doc["reason"] = res.info["optimizer_message"]
    doc["last_iterate"] = {**res.estimate, **{n: h["held_at"] for n, h in res.held.items()}}
    if bad:
        reasons = res.adequacy["reasons"]
        line = f"inadequate fit: {reasons[0]}" + (f" (and {len(reasons) - 1} more)" if len(reasons) > 1 else "")
        if args.allow_misfit:
            sys.stderr.write(f"ema identify: warning: {line}\n")
        else:
            doc["failure"] = doc["reason"] = line + "; the intervals are not trustworthy (--allow-misfit to accept)"
    return doc


def _target(out: Path, inadequate: bool) -> Path:
    """The fitted file's name: FILE.inadequate.toml for an inadequate fit."""
    return out.with_name(out.name[: -len(out.suffix)] + ".inadequate.toml") if inadequate else out


def _fit_frequency(args, params, records, free, kw, out) -> dict:
    """Frequency-response records: fitted through the linear model."""
    from ..identification import identify_frequency

    for flag in ("track", "profile", "validate", "estimate_x0"):
        if getattr(args, flag):
            raise UserError(f"--{flag.replace('_', '-')} is for time-series records, not frequency responses")
    for flag in ("--starts", "--seed", "--jobs", "--bounds", "--hold", "--hold-unidentifiable", "--model-error",
                 "--structural", "--friction-start", "--coarse-to-fine", "--unsettled", "--method",
                 "--nodes"):  # none
        no_effect(args, flag, "with frequency-response records (one fit through the linear model from the file's "
                  "values, none held)")
    from ..identification import report_names

    report = check_output_dir(args.report, report_names(len(records), len(free)), "--report")
    res = identify_frequency(params, records, free, sigma={k: v for k, v in kw["sigma"].items()},
                             max_evaluations=kw["max_evaluations"])
    doc = res.to_dict()
    doc["written"] = []
    if out is not None:
        doc["written"].append(str(res.write(out, note="frequency-response fit through the linear model")))
    if report is not None:
        doc["written"].append(str(res.write_report(report)))
    return doc


def _channel_units(doc: dict, model) -> None:
    """The SI unit of each fitted channel, for the text report's residuals."""
    doc["channel_units"] = {c["channel"]: model.units.get(c["channel"], "") for c in doc.get("channels", [])}


def _compare(args, params, model, records, free, kw, out) -> dict:
    """--compare: every combination fitted, ranked; the best written (as inadequate when
    no combination is adequate)."""
    from ..identification import MAX_FITS, combinations, compare, read_record

    options = {}
    for item in args.compare:
        key, sep, values = item.partition("=")
        vals = [v.strip() for v in values.split(",") if v.strip()]
        if not sep or not key.strip() or not vals:
            raise UserError(f"--compare expects KEY=V1,V2[,...], got '{item}'")
        options[key.strip()] = vals
    max_fits = MAX_FITS if args.max_fits is None else args.max_fits
    if max_fits < 1:
        raise UserError(f"--max-fits must be at least 1, got {max_fits}")
    combinations(options, dict(args.variant), max_fits)  # checked before any work
    for r in records:
        read_record(r, model)
    from ..identification import report_names

    report = check_output_dir(args.report, [*report_names(len(records), len(free)), "comparison.png"], "--report")
    cmp = compare(params, records, free, options, sigma=kw["sigma"], variants=dict(args.variant) or None,
                  max_fits=max_fits, max_evaluations=kw["max_evaluations"], progress=kw["progress"],
                  estimate_x0=kw["estimate_x0"], model_error=kw.get("model_error"),
                  friction_start=kw["friction_start"], coarse_to_fine=kw["coarse_to_fine"],
                  allow_misfit=kw.get("allow_misfit", False))
    best = cmp.best
    if best is None:  # every combination failed: their reasons, one document
        why = "no combination converged: " + "; ".join(f"{r['variants']}: {r['failed']}" for r in cmp.rows)
        return {"status": "failed", "converged": False, "reason": why, **cmp.to_dict(), "failure": why,
                "written": []}
    doc = {**best.to_dict(), **cmp.to_dict()}
    _channel_units(doc, model)
    bad = not best.adequacy["adequate"]
    doc["written"] = []
    if out is not None:
        note = f"structure chosen by comparison: {cmp.rows[0]['variants']}"
        doc["written"].append(str(best.write(_target(out, bad and not args.allow_misfit), note=note)))
    if report is not None:
        doc["written"].append(str(cmp.write_report(report)))
    if bad and not args.allow_misfit:
        doc["failure"] = f"no compared structure is adequate; the best: {best.adequacy['reasons'][0]}"
    return doc


def identify_api(params, recs, free, **kw):
    """The API call the command makes (one place to see it)."""
    from ..identification import identify

    return identify(params, recs, free, **kw)  # the command's model: built once, passed down


def _track(args, params, model, records, free, kw) -> dict:
    from ..identification import track

    limits = quantities(args.limit, "--limit", model)
    report = check_output_dir(args.report, ("trend.png", "trend.json"), "--report")
    if args.out is not None:
        raise UserError("--out with --track: a trend has one fit per record; use --report DIR")
    if kw["estimate_x0"] is not False:
        raise UserError("--estimate-x0 with --track: a trend's records start at rest (fit them one by one instead)")
    kw = {k: v for k, v in kw.items() if k not in ("starts", "seed", "estimate_x0", "jobs", "friction_start",
                                                 "coarse_to_fine", "unsettled", "method", "nodes")}
    tr = track(params, records, free, stamp=args.stamp, limits=limits, **kw, model=model)
    doc = tr.to_dict()
    if report is not None:
        doc["written"] = [str(tr.write_report(report))]
    return doc


def _example(args, params, model, out, progress) -> dict:
    """The built-in example: records simulated with worn parameters, fitted."""
    from .._util._files import scratch_dir
    from ..identification import example_records

    with scratch_dir() as tmp:
        paths, truth = example_records(params, tmp)
        free = list(truth) if args.free is None else [s.strip() for s in args.free.split(",") if s.strip()]
        doc = _fit(args, params, model, paths, free, {"progress": progress, "starts": args.starts, "seed": args.seed,
                                                      "max_evaluations": args.max_evaluations,
                                                      "hold": holds(args.hold, model),
                                                      "hold_unidentifiable": args.hold_unidentifiable,
                                                      "sigma": quantities(args.sigma, "--sigma", model),
                                                      "bounds": bounds(args.bounds), "method": args.method,
                                                      "nodes": args.nodes,
                                                      "jobs": min(args.starts, args.jobs or cores())}, out)
    doc["example"] = {"truth": truth, "note": "records simulated by the toolkit from the reference set with "
                                              "these values, sensor noise added; fitted from the reference values"}
    return doc


report = text_report  # the command's text report (without --json)
