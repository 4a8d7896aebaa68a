"""Sweeps and Monte Carlo (docs: sweeps): parameters on a grid or drawn from distributions,
metrics of the registry per run, one row per run.

SPEC.toml describes the sweep ([sweep] seed and samples, [variants], [parameters],
[scenario], [metrics]); the format is in the docs (sweeps) and in
models/sweep_hunting_backlash.toml. The runs go to --jobs local workers (processes, or
threads with --threads) or to a Dask scheduler (--scheduler); the rows are the same bit
for bit whichever runs them. --out writes the table (run, swept variants and
parameters, metrics, status, reason), atomically at the end; meanwhile every finished
row is kept in the journal .OUT.journal beside it, so that after Ctrl-C or a crash
--resume runs only what is missing. --plot draws histograms and each metric against
each parameter. Failed runs (left the physical envelope, integrator gave up, no
operating point) are rows with status failed and the reason; any makes the command
exit with status 3 after writing the whole table.
MODEL.toml comes first, SPEC.toml second (or by --spec); without them the packaged
reference set and sweep run. A single file that is a sweep is refused (name it with
--spec).
Example: ema sweep --spec models/sweep_hunting_backlash.toml --out results.csv --plot sweep.png --jobs 2
"""

from __future__ import annotations

from .._util._resources import REFERENCE_SWEEP
from . import UserError, add_progress, check_output_path, progress_of, second_file
from ._flags import NoEffect

COMMAND = "sweep"
#: The sweep run without a SPEC.toml (packaged).
DEFAULT_SPEC = REFERENCE_SWEEP
ORDER = 10
HELP = "sweep / Monte Carlo: parameters on a grid or from distributions, metrics per run"


_CLUSTER = NoEffect((), "with --scheduler (it runs on the cluster's workers)", lambda a: a.scheduler is not None)
#: Each flag -> the combinations where it has no effect (refused; docs: cli).
NO_EFFECT = {"--spec": (), "--out": (), "--plot": (), "--scheduler": (),
             "--jobs": (NoEffect(("--scheduler", "tcp://localhost:8786", "--jobs", "2"), _CLUSTER.why, _CLUSTER.when),),
             "--threads": (NoEffect(("--scheduler", "tcp://localhost:8786", "--threads"), _CLUSTER.why,
                                    _CLUSTER.when),),
             "--resume": (NoEffect(("--resume",), "without --out (the table whose journal holds the finished rows)",
                                   lambda a: a.out is None),)}

def add_arguments(p):
    p.add_argument("spec", metavar="SPEC.toml", nargs="?", default=None,
                   help="sweep description (parameters, scenario, metrics), after MODEL.toml; default: the packaged "
                        f"{DEFAULT_SPEC} (40 runs over tolerances)")
    p.add_argument("--spec", dest="spec_file", default=None, metavar="SPEC.toml",
                   help="the sweep description by name (with or without MODEL.toml)")
    p.add_argument("--out", default=None, metavar="FILE.csv", help="the table, one row per run (and its journal)")
    p.add_argument("--plot", default=None, metavar="FILE.png", help="histograms and sensitivities")
    p.add_argument("--jobs", type=int, default=None, metavar="N", help="local workers; default: all cores")
    p.add_argument("--threads", action="store_true", help="local workers are threads (default: processes)")
    p.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT",
                   help="run on a Dask distributed scheduler (needs ema_casadi[dask] here and on the workers)")
    p.add_argument("--resume", action="store_true",
                   help="take the rows already in --out's journal (or in a finished --out) instead of rerunning them")
    add_progress(p)


def interrupt_hint(args) -> str:
    """The interrupt message's tail: with --out the finished rows are in the table's
    journal, and the same command with --resume runs only the rest."""
    if args.out is None:
        return ""
    return " (the finished rows are kept: the same command with --resume runs only the rest)"


def run(args) -> dict:
    from ..model.params import load_parameters
    from ..sweeps import load_sweep, sweep

    args.spec = second_file(args, args.spec, args.spec_file, flag="--spec", what="sweep", key="sweep",
                            default=DEFAULT_SPEC)
    out = check_output_path(args.out, (".csv",), "--out")
    plot = check_output_path(args.plot, (".png",), "--plot")
    if args.jobs is not None and args.jobs < 1:
        raise UserError(f"--jobs must be a positive integer, got {args.jobs}")
    if args.scheduler is not None and "://" not in args.scheduler:
        raise UserError(f"--scheduler {args.scheduler}: expected an address like tcp://host:8786")
    if args.scheduler is not None and (args.jobs is not None or args.threads):
        raise UserError("--scheduler runs on the cluster's workers: give it or --jobs/--threads, not both")
    if args.resume and out is None:
        raise UserError("--resume needs --out (the table whose journal holds the finished rows)")
    from ..model.components import validate_variants

    given = dict(args.variant)
    validate_variants(given, "--variant")
    params = load_parameters(args.model, given)  # the sweep file's [variants] go on top
    validate_variants({k: v for k, v in params.variants.items() if k not in given}, str(args.model))
    validate_variants(params.variants, "--variant")
    progress = progress_of(args)
    spec = load_sweep(args.spec, params)
    res = sweep(spec, out, jobs=args.jobs, backend="threads" if args.threads else "processes",
                scheduler=args.scheduler, resume=args.resume, progress=progress)
    written = [str(out)] if out is not None else []
    if plot is not None:
        written.append(str(res.plot(plot)))
    failed = res.failed()
    return {
        "sweep": spec.name, "spec": args.spec, "model": args.model,
        "runs": res.info["runs"], "resumed": res.info["resumed"], "failed": res.info["failed"],
        "wall_time": res.info["wall_time"], "jobs": res.info["jobs"], "backend": res.info["backend"],
        "scheduler": res.info["scheduler"], "units": res.units(), "summary": res.summary(),
        "rows": None if out is not None else res.rows,
        "failure": (f"{len(failed)} of {len(res)} runs failed (first: run {failed[0]['run']}: {failed[0]['reason']})"
                    if failed else None),
        "written": written,
    }


def report(r: dict) -> None:
    print(f"sweep {r['sweep']}: {r['runs']} runs ({r['resumed']} resumed) in {r['wall_time']:.1f} s on "
          f"{r['backend'] if r['scheduler'] is None else r['scheduler']}"
          + (f" x {r['jobs']}" if r['jobs'] else "") + f"; {r['failed']} failed")
    stats = r["summary"]["statistics"]
    sens = r["summary"]["sensitivity_spearman"]
    params = list(next(iter(sens.values()), {}))
    from ..signals import column_unit, in_unit, unit_text

    units = r.get("units") or {}
    print(f"{'metric':34s} {'unit':>6s} {'n':>5s} {'mean':>11s} {'p05':>11s} {'median':>11s} {'p95':>11s} "
          + " ".join(f"{'rho ' + p:>10s}" for p in params))
    for m, s in stats.items():
        if s["n"]:
            si = units.get(m) or "1"
            keys = ("mean", "p05", "median", "p95")
            name, size = column_unit(si, [s[k] for k in keys])
            cells = " ".join(f"{in_unit(s[k], size, si_unit=si):>11s}" for k in keys)
            rho = " ".join(f"{sens[m][p]:10.2f}" for p in params)
            print(f"{m:34s} {unit_text(name):>6s} {s['n']:5d} {cells} {rho}")
        else:
            print(f"{m:34s} {'':>6s} {0:5d}")
    print("rho: Spearman's rank correlation of the metric with the swept parameter (-1..1)")
    for w in r["written"]:
        print(f"wrote {w}")
