"""Run a sweep on a SLURM cluster through dask-jobqueue (docs: sweeps).

Builds a ``dask_jobqueue.SLURMCluster`` (each SLURM job one Dask worker process with
``--cores`` threads), asks for ``--jobs`` jobs, runs the sweep on its scheduler and
writes the table: the rows are the same bit for bit as on a laptop. The scheduler runs
in this process (on the login node); the workers import ema_casadi from the same
environment, so install it on a shared file system (``pip install 'ema_casadi[slurm]'``
into a venv every node sees) and point ``EMA_CASADI_CACHE`` there too, so that the
compiled rollouts are built once.

Usage::

    python studies/sweep_slurm.py SPEC.toml --out results.csv [--model models/cesa_ema.toml]
        [--jobs 10] [--cores 4] [--memory 8GB] [--walltime 02:00:00] [--queue PARTITION]
        [--account ACCOUNT] [--print-script]

``--print-script`` prints the batch script SLURM would be given and submits nothing
(no SLURM needed). An interrupted sweep continues with the same command and --resume.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def build_cluster(cores: int = 4, memory: str = "8GB", walltime: str = "02:00:00", queue: str | None = None,
                  account: str | None = None, log_dir: str = "dask-logs"):
    """The SLURMCluster: one worker process per job with ``cores`` threads (a sweep's
    runs use one core each), no nanny restarts of a busy worker, logs in ``log_dir``.

    Parameters
    ----------
    cores : int
        Cores (worker threads) per job.
    memory : str
        Memory per job (SLURM ``--mem``).
    walltime : str
        Time limit per job (HH:MM:SS).
    queue : str, optional
        Partition.
    account : str, optional
        Account to charge.
    log_dir : str
        Folder of the jobs' output.
    """
    from dask_jobqueue import SLURMCluster

    return SLURMCluster(cores=cores, processes=1, memory=memory, walltime=walltime, queue=queue, account=account,
                        log_directory=log_dir, python=sys.executable,
                        job_script_prologue=["export OMP_NUM_THREADS=1"],
                        scheduler_options={"dashboard_address": None})


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("spec", nargs="?", default=str(ROOT / "models" / "sweep_hunting_backlash.toml"),
                    help="sweep description (default the hunting study's)")
    ap.add_argument("--model", default=str(ROOT / "models" / "cesa_ema.toml"), help="parameter file")
    ap.add_argument("--out", default="results.csv", help="the table (default results.csv)")
    ap.add_argument("--jobs", type=int, default=4, help="SLURM jobs (Dask workers); default 4")
    ap.add_argument("--cores", type=int, default=4, help="cores per job; default 4")
    ap.add_argument("--memory", default="8GB", help="memory per job; default 8GB")
    ap.add_argument("--walltime", default="02:00:00", help="time limit per job; default 02:00:00")
    ap.add_argument("--queue", default=None, help="partition")
    ap.add_argument("--account", default=None, help="account")
    ap.add_argument("--resume", action="store_true", help="continue an interrupted sweep")
    ap.add_argument("--print-script", action="store_true", help="print the job script, submit nothing")
    args = ap.parse_args(argv)
    cluster = build_cluster(args.cores, args.memory, args.walltime, args.queue, args.account)
    try:
        if args.print_script:
            print(cluster.job_script())
            return 0
        import ema_casadi as ema
        from ema_casadi.sweeps import load_sweep, sweep

        spec = load_sweep(args.spec, ema.load_parameters(args.model))
        cluster.scale(jobs=args.jobs)
        res = sweep(spec, args.out, scheduler=cluster.scheduler_address, resume=args.resume, progress=True)
        print(f"{len(res)} runs, {res.info['failed']} failed, {res.info['wall_time']:.1f} s; wrote {args.out}")
        return 0
    finally:
        cluster.close()


if __name__ == "__main__":
    sys.exit(main())
