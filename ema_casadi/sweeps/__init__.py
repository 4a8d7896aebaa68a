"""Sweeps and Monte Carlo (docs: sweeps): any parameters on a grid or drawn from
distributions, any metric of the registry per run, on local cores or a Dask cluster,
one row per run, resumable after an interruption or a crash.

Usage (worker processes import the main script again: in a script, call ``sweep`` under
``if __name__ == "__main__":``; an unguarded call is refused)::

    import ema_casadi as ema
    from ema_casadi.sweeps import load_sweep, sweep

    if __name__ == "__main__":
        spec = load_sweep(ema.packaged_file("sweep_hunting_backlash.toml"), ema.load_parameters())
        result = sweep(spec, "results.csv", jobs=2)     # or scheduler="tcp://host:8786"
        result.summary(); result.plot("sweep.png")      # result.plot(): the Figure

Layout: ``_spec`` reads and checks the description and expands it into runs (grid x
draws, per-sample seeds); ``_metrics`` is the metric registry (each metric is the
toolkit's own analysis); ``_run`` runs the runs (this thread, a local pool of
processes or threads, or Dask through :mod:`ema_casadi._util._parallel`, shared with the
sine stream), with progress and the ETA; ``_journal`` keeps finished rows on disk
while the sweep runs and writes the table; ``_result`` holds the table, the summary
statistics, the sensitivities and the plot.
"""

from ._journal import journal_path, write_table
from ._metrics import METRICS
from ._result import SweepResult, spearman
from ._run import BACKENDS, sweep
from ._spec import DISTRIBUTIONS, MAX_RUNS, Run, SweepError, SweepSpec, load_sweep, make_sweep, parse_sweep

__all__ = [
    "sweep", "load_sweep", "parse_sweep", "make_sweep", "SweepSpec", "SweepResult", "SweepError", "Run", "METRICS",
    "DISTRIBUTIONS", "BACKENDS", "MAX_RUNS", "journal_path", "spearman", "write_table",
]
