"""Running a sweep: the runs of one worker, the local pools and Dask, progress, resume.

Every run is computed by :func:`_run_one` from its :class:`Run` alone, whoever runs it
(this thread, a thread or process of the local pool, a Dask worker): the rows do not
depend on the number of workers or the order. A worker builds each model once
(:class:`_Worker`, cached per sweep and process or thread) and reuses its compiled
rollouts and integrators across runs (the parameters are an input).
"""

from __future__ import annotations

import math
import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .._util import _interrupts
from .._util._files import after_commit, on_error
from .._util._parallel import check_main_guard, cores
from .._util._tasks import quiet_resource_tracker, run_tasks
from ..simulation import progress_bar
from ._journal import Journal, journal_path, read_table, write_table
from ._metrics import PointFailed, compute_metrics, metric_columns, needs_simulation, simulate_scenario
from ._spec import SweepError, SweepSpec

if TYPE_CHECKING:
    from ._result import SweepResult

__all__ = ["sweep", "BACKENDS", "PointFailed"]

BACKENDS = ("processes", "threads")


# -- one run ---------------------------------------------------------------------
class _Worker:
    """What one worker keeps between runs of a sweep: a model per variant choice."""

    def __init__(self, spec: SweepSpec):
        self.spec = spec
        self.models = {}
        self.names = None

    def model(self, variant: tuple):
        from ..model.assembly import build_model

        if variant not in self.models:
            self.models[variant] = build_model(self.spec.params, dict(variant))
        return self.models[variant]


def _run_one(worker: _Worker, run) -> dict:
    """The row of one run: its values, its metrics, ``status`` and ``reason``."""
    from ..linearisation import LinearizationError
    from ..simulation import RunFailed
    from ..sinestream import FreqRespError

    spec = worker.spec
    model = worker.model(run.variant)
    pv = model.p()
    for k, v in run.values.items():
        pv[model.param_names.index(k)] = v
    swept = spec.swept_variants
    row = {"run": run.index, **{k: v for k, v in run.variant if k in swept}, **run.values}
    row.update({c: None for c, _ in metric_columns(spec.metrics)})
    status, reason = "ok", ""
    try:
        res = simulate_scenario(model, pv, spec.scenario) if needs_simulation(spec.metrics) else None
        for name, opts in spec.metrics.items():
            row.update(compute_metrics(name, opts, model, spec.params, pv, res))
    except RunFailed as exc:
        status, reason = "failed", exc.reason
    except (LinearizationError, FreqRespError, PointFailed) as exc:
        status, reason = "failed", str(exc).splitlines()[0] if str(exc) else type(exc).__name__
    except Exception as exc:  # noqa: BLE001 - a run that breaks an analysis is a failed row, not a lost sweep
        _interrupts.check()  # CasADi turns an interrupt into a RuntimeError
        status, reason = "failed", f"{type(exc).__name__}: {(str(exc).splitlines() or [''])[0][:300]}"
    row.update(status=status, reason=reason)
    return {k: (float(v) if isinstance(v, (float, np.floating)) else (math.nan if v is None else v))
            for k, v in row.items()}


_STATE = threading.local()
#: Set when a sweep on the thread pool is abandoned (an interrupt, an error): its
#: threads stop at their next run (in the API a KeyboardInterrupt sets no signal flag).
_STOP = threading.Event()


def _worker_for(spec: SweepSpec) -> _Worker:
    """This thread's worker for ``spec`` (one per sweep and thread; processes and Dask
    workers run one thread per task)."""
    key = spec.fingerprint()
    cache = getattr(_STATE, "workers", None)
    if cache is None:
        cache = _STATE.workers = {}
    if key not in cache:
        cache.clear()
        cache[key] = _Worker(spec)
    return cache[key]


def _run_indices(spec: SweepSpec, indices: list) -> list:
    """Rows of the runs ``indices`` (the task of a pool worker or a Dask worker: the spec
    reached the worker once, the task carries only the run indices)."""
    worker = _worker_for(spec)
    out = []
    for i in indices:
        _interrupts.check()
        if _STOP.is_set():
            raise RuntimeError("sweep abandoned")
        out.append(_run_one(worker, spec.runs[i]))
    return out


# -- the driver ------------------------------------------------------------------
def sweep(spec: SweepSpec, out: str | Path | None = None, *, jobs: int | None = None, backend: str = "processes",
          scheduler: str | None = None, resume: bool = False, progress: bool = False) -> SweepResult:
    """Run every run of a sweep and return its table.

    Parameters
    ----------
    spec : SweepSpec
        From :func:`~ema_casadi.sweeps.load_sweep` (or ``parse_sweep``).
    out : str or Path, optional
        The CSV table (written atomically at the end); while the sweep runs, finished
        rows go to its journal beside it (:mod:`~ema_casadi.sweeps._journal`).
    jobs : int, optional
        Local workers (default: the cores); 1 runs in this thread.
    backend : {"processes", "threads"}
        The local pool. Processes are started by spawn and import the main script
        again: a script must call ``sweep`` under ``if __name__ == "__main__":``
        (refused with :class:`SweepError` otherwise, before any work).
    scheduler : str, optional
        Address of a Dask distributed scheduler (``tcp://host:8786``) instead.
    resume : bool
        Take the rows already in the journal (or in a finished ``out``) instead of
        running them again; without it an existing journal is refused.
    progress : bool
        Progress, failures and the ETA on stderr.

    Returns
    -------
    SweepResult
    """
    from ._result import SweepResult

    t0 = time.perf_counter()
    _check_request(spec, out, jobs, backend, scheduler, resume)
    if backend == "processes" and not scheduler and (jobs or cores()) > 1:
        check_main_guard(SweepError, f"sweep(jobs={jobs or cores()})")
    columns, text = _columns(spec)
    done, journal = _previous(spec, out, columns, text, resume)
    todo = [r for r in spec.runs if r.index not in done]
    # a journal this sweep starts goes with a failure (a scheduler out of reach, a full
    # disk: the next run must not be refused for it); an interrupt keeps it for --resume
    new_journal = journal is not None and not journal.path.exists()
    fresh = {}
    n_jobs = 1 if scheduler else (jobs or cores())
    try:
        if todo and journal is not None:
            journal.open()
        _execute(spec, todo, n_jobs, backend, scheduler, fresh, journal, progress, len(spec.runs) - len(todo))
    except Exception:
        if new_journal:
            journal.remove()
        raise
    finally:
        if journal is not None:
            journal.close()
    if new_journal:
        on_error(journal.remove)
    rows = [done.get(r.index) or fresh[r.index] for r in spec.runs]
    info = {"runs": len(rows), "resumed": len(spec.runs) - len(todo), "computed": len(todo),
            "failed": sum(r["status"] != "ok" for r in rows), "wall_time": time.perf_counter() - t0,
            "jobs": None if scheduler else n_jobs,
            "backend": "dask" if scheduler else (backend if n_jobs > 1 else "serial"),
            "scheduler": scheduler, "fingerprint": spec.fingerprint()}
    result = SweepResult(spec=spec, rows=rows, columns=columns, info=info)
    if out is not None:
        try:
            write_table(out, rows, columns)
        except Exception:
            if new_journal:
                journal.remove()
            raise
        if journal is not None:
            after_commit(journal.remove)
    return result


def _check_request(spec, out, jobs, backend, scheduler, resume) -> None:
    if not isinstance(spec, SweepSpec):
        raise SweepError("spec: expected a SweepSpec (from load_sweep)")
    if jobs is not None and (isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1):
        raise SweepError(f"jobs: expected a positive integer, got {jobs!r}")
    if backend not in BACKENDS:
        raise SweepError(f"backend: expected one of {', '.join(BACKENDS)}, got {backend!r}")
    if scheduler is not None and not (isinstance(scheduler, str) and "://" in scheduler):
        raise SweepError(f"scheduler: expected an address like tcp://host:8786, got {scheduler!r}")
    if resume and out is None:
        raise SweepError("resume: needs the output table (out) whose journal holds the finished rows")


def _columns(spec: SweepSpec) -> tuple[list, set]:
    text = {*spec.swept_variants, "status", "reason"}
    cols = ["run", *spec.swept_variants, *spec.parameters, *(c for c, _ in metric_columns(spec.metrics)),
            "status", "reason"]
    return cols, text


def _previous(spec, out, columns, text, resume) -> tuple[dict, Journal | None]:
    """The rows finished before (``resume``) and the journal of this sweep."""
    if out is None:
        return {}, None
    journal = Journal(journal_path(out), spec.fingerprint())
    if not resume:
        if journal.path.exists():
            raise SweepError(f"{journal.path}: the journal of an interrupted sweep exists: continue it with "
                             "--resume (resume=True) or remove it")
        return {}, journal
    done = {}
    if Path(out).is_file() and not journal.path.exists():
        done = read_table(Path(out), columns, text, SweepError)
    done.update(journal.read(SweepError))
    by_index = {r.index: r for r in spec.runs}
    for i, row in done.items():
        r = by_index.get(i)
        if r is None or any(row.get(k) != v for k, v in r.values.items()):
            raise SweepError(f"{journal.path if journal.path.exists() else out}: row {i} is not this sweep's run "
                             "(other parameter values); remove it to start afresh")
    return done, journal


def _execute(spec, todo, jobs, backend, scheduler, fresh, journal, progress, before) -> None:
    """Run ``todo`` into ``fresh`` (index -> row), journaling each finished batch."""
    total = len(spec.runs)
    clock = {"t0": time.perf_counter(), "failed": 0}

    def finished(rows):
        if journal is not None:
            journal.append(rows)
        for row in rows:
            fresh[row["run"]] = row
            clock["failed"] += row["status"] != "ok"
        _progress(progress, before, len(fresh), total, clock)

    _progress(progress, before, 0, total, clock)
    if not todo:
        return
    spec.fingerprint()  # computed once here: the workers' caches key on it
    if not scheduler and jobs > 1 and backend == "processes":
        quiet_resource_tracker()
    _STOP.clear()
    run_tasks(_run_indices, spec, [r.index for r in todo], finished, jobs=jobs, backend=backend,
              scheduler=scheduler, error=SweepError, on_abort=_STOP.set)


def _progress(enabled, before, fresh, total, clock) -> None:
    if not enabled:
        return
    done = before + fresh
    elapsed = time.perf_counter() - clock["t0"]
    left = total - done
    eta = "ETA " + _clock(elapsed / fresh * left) if fresh and left else ("done" if not left else "ETA ...")
    note = f"{done}/{total} runs" + (f", {clock['failed']} failed" if clock["failed"] else "") + f", {eta}"
    progress_bar(done / total if total else 1.0, True, "sweep", note)


def _clock(s: float) -> str:
    s = int(round(s))
    return f"{s // 3600}h{s % 3600 // 60:02d}m" if s >= 3600 else (f"{s // 60}m{s % 60:02d}s" if s >= 60 else f"{s}s")
