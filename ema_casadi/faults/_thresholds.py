"""The monitors' thresholds against their healthy margins: per monitor, over a range of
thresholds, the detection time of every fault case and the false-alarm rate per flight
hour (``ema faults --thresholds``).

Detection time at a threshold x: the model's own confirmation logic (module
``monitors``: a timer that counts while ``stat >= x`` and decays with ``TAU_RESET``
otherwise, tripping at the confirmation time, the latch ``TAU_LATCH ln 2`` later) run
on each case's sampled statistic. The monitors' reactions are off in the reference
set, so a threshold does not change the run, only when it is detected: one fault
table serves every threshold (a file that switches a reaction on is refused).

False-alarm rate at x: the healthy runs' largest statistic values ``M_i`` (one per run
of duration T) are fitted with the generalised extreme-value law (GEV, the limit law of
a maximum; maximum likelihood, shape free: a bounded statistic gets a bounded tail
where a Gumbel fit would overstate it - on the reference cross-check a Gumbel fit
expects 8.9 of 1000 runs above 30 um where none of the 1000 reached 25.8 um), whose
tail gives the probability ``q(x) = P(M > x)`` that a run's statistic ever reaches x;
runs are
independent stretches of the scenario's activity, so exceedances form a Poisson
process of rate ``-ln(1 - q) / T`` (per flight hour: x 3600). The confirmation time is
left out (a run whose statistic never reaches x cannot trip: an upper bound). The
count of healthy runs whose maximum reaches x is kept beside it (0 of N agrees with
any expected count below 3, the 95 % upper bound of a Poisson count observed 0), with
the rate the data alone bound: the 95 % upper bound of the observed count over N T
(``data_bound_per_hour``; 0 of 1000 runs of 0.3 s: 36 per flight hour). A fitted
bounded tail that ends below x says 0; that is the fit, and the data bound says how
far N runs back it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._util._checks import integer
from ._run import healthy_runs, run_faults
from ._spec import FaultError, FaultSpec

__all__ = ["ThresholdStudy", "threshold_study", "detection_time", "check_study_runs", "SCALES", "POISSON_ZERO_95",
           "MIN_STUDY_RUNS"]

#: Thresholds studied, as multiples of each monitor's reference threshold.
SCALES = (0.1, 0.15, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0, 1.25, 1.5, 2.0)
#: The 95 % upper bound of a Poisson mean whose count was observed 0 (-ln 0.05).
POISSON_ZERO_95 = -math.log(0.05)
#: Seconds per flight hour.
HOUR = 3600.0
#: The fewest healthy runs a study fits its extreme-value law to: three parameters by
#: maximum likelihood from a few maxima are noise (a reported study of 3 runs said
#: 8.72e3 false alarms per flight hour where 1000 runs observe none), and below 50 runs
#: the data alone bound the rate only above 720 per flight hour (runs of 0.3 s).
MIN_STUDY_RUNS = 50


def check_study_runs(healthy) -> int:
    """``healthy`` as the count of a threshold study's healthy runs: an integer of at
    least :data:`MIN_STUDY_RUNS` (:class:`FaultError` naming it otherwise).

    Parameters
    ----------
    healthy : int
        Healthy runs asked for (``--healthy-runs``).
    """
    n = integer(healthy, "healthy runs", FaultError)
    if n < MIN_STUDY_RUNS:
        raise FaultError(f"healthy runs {n}: a threshold study fits the law of the healthy runs' maxima, which "
                         f"{n} runs do not determine; give at least {MIN_STUDY_RUNS} (default 1000)")
    return n


def detection_time(t: np.ndarray, stat: np.ndarray, threshold: float, confirm: float, tau_reset: float,
                   tau_latch: float) -> float | None:
    """The first instant (s) a monitor latches on the sampled statistic ``stat`` at
    ``threshold``: the model's confirmation timer (counting while ``stat >= threshold``,
    decaying with ``tau_reset`` otherwise) reaches ``confirm``, plus the latch's
    ``tau_latch ln 2``; None if it never does.

    Parameters
    ----------
    t, stat : ndarray
        Sample instants (s) and the statistic there (the condition held over each
        sample interval as at its start).
    threshold, confirm, tau_reset, tau_latch : float
        The monitor's threshold (the statistic's unit), confirmation time, timer
        reset and latch time constants (s).
    """
    tc = 0.0
    on = stat >= threshold
    dts = np.diff(t)
    for n, dt in enumerate(dts):
        if on[n]:
            if tc + dt >= confirm:
                return float(t[n] + (confirm - tc) + tau_latch * math.log(2))
            tc += dt
        else:
            tc *= math.exp(-dt / tau_reset)
    return None


@dataclass
class ThresholdStudy:
    """Per monitor and threshold: the detection time of each fault case and the
    false-alarm rate per flight hour.

    Attributes
    ----------
    monitors : dict
        Latch output -> ``statistic``, ``threshold_param``, ``reference`` (its value),
        ``unit``, ``healthy_max`` (largest statistic over the healthy runs),
        ``margin`` (1 - healthy_max / reference), ``gev`` (``shape_c``, ``loc``,
        ``scale``; SciPy's ``genextreme``), and
        ``rows``: per threshold ``threshold``, ``scale``, ``false_alarms_per_hour``,
        ``data_bound_per_hour`` (95 % upper bound from the observed count alone),
        ``expected_in_runs`` (over the healthy runs), ``observed_in_runs``,
        ``detected_s`` (case -> delay after the onset or None) and
        ``alarm_without_fault`` (the cases it latches on before their onset, and the
        no-fault case: a false alarm at that threshold).
    runs : int
        Healthy runs.
    run_duration : float
        Duration of one healthy run (s).
    cases : list of str
        The fault cases.
    info : dict
        The healthy runs' wall time, failures and false alarms.
    healthy : dict
        The healthy runs' summary (:func:`~ema_casadi.faults.healthy_runs`, with the
        margins and the per-run maxima).
    """

    monitors: dict
    runs: int
    run_duration: float
    cases: list
    info: dict = field(default_factory=dict)
    healthy: dict = field(default_factory=dict, repr=False)

    def summary(self) -> dict:
        """The JSON form."""
        return {"runs": self.runs, "run_duration_s": self.run_duration, "cases": self.cases,
                "false_alarm_method": "generalised extreme-value fit of the healthy runs' largest statistic "
                                      "(maximum likelihood); rate = -ln(1 - P(M > x)) / T per run, x 3600 per "
                                      "flight hour; the confirmation time left out (an upper bound)",
                "monitors": self.monitors, **self.info}

    def table(self) -> list[dict]:
        """One row per monitor and threshold (the CSV)."""
        out = []
        for latch, m in self.monitors.items():
            for r in m["rows"]:
                out.append({"monitor": latch, "threshold": r["threshold"], "unit": m["unit"], "scale": r["scale"],
                            "false_alarms_per_hour": r["false_alarms_per_hour"],
                            "data_bound_per_hour": r["data_bound_per_hour"],
                            "expected_in_runs": r["expected_in_runs"], "observed_in_runs": r["observed_in_runs"],
                            "alarm_without_fault": " ".join(r["alarm_without_fault"]),
                            **{f"detected_{c}_s": r["detected_s"][c] for c in self.cases}})
        return out

    def to_csv(self, path: str | Path) -> Path:
        """Write :meth:`table`, atomically.

        Parameters
        ----------
        path : str or Path
            The CSV file.
        """
        from ..sweeps import write_table

        rows = self.table()
        return write_table(path, rows, list(rows[0]))

    def plot(self, path: str | Path | None = None):
        """Per monitor: detection time of each case and the false-alarm rate against
        the threshold; returns the Figure (written to ``path`` when given).

        Parameters
        ----------
        path : str or Path, optional
            A PNG file to write.
        """
        from ..plots._faults import plot_thresholds

        return plot_thresholds(self, path)


def _monitor_table(model, pv) -> dict:
    """Latch -> (statistic output, threshold parameter, its value, confirmation time, unit)."""
    out = {}
    for name in model.outputs_of("statistic"):
        o = model.output_info[name]
        P = model.pdict(pv)
        out[o.alarm] = (name, o.threshold, float(getattr(P, o.threshold)), float(getattr(P, o.confirm)), o.unit)
    return out


def _gev(maxima: np.ndarray):
    """(shape c, loc, scale) of the GEV fit of the maxima in SciPy's convention (c > 0:
    a bounded upper tail, c = 0 Gumbel), started from the Gumbel fit; None when they do
    not vary. The data are scaled to unit spread for the fit."""
    from scipy import stats

    m = maxima[np.isfinite(maxima)]
    if m.size < 3 or np.ptp(m) <= 1e-12 * max(1.0, abs(m).max()):
        return None
    mu, sd = float(np.mean(m)), float(np.std(m))
    z = (m - mu) / sd
    loc, scale = stats.gumbel_r.fit(z)
    c, loc, scale = stats.genextreme.fit(z, 0.0, loc=loc, scale=scale)
    return float(c), mu + sd * float(loc), sd * float(scale)


def _exceedance(fit, x: float, maxima: np.ndarray) -> float:
    """P(M > x) per run from the fit (the observed fraction without a fit)."""
    from scipy import stats

    if fit is None:
        return float(np.mean(maxima >= x)) if maxima.size else math.nan
    return float(stats.genextreme.sf(x, *fit))


def threshold_study(spec: FaultSpec, *, healthy: int = 1000, scales=SCALES, jobs: int | None = None, seed: int = 1,
                    progress: bool = False, table=None) -> ThresholdStudy:
    """The threshold study of a fault file (module docstring).

    Parameters
    ----------
    spec : FaultSpec
        The checked fault file (its scenario, cases and healthy runs).
    healthy : int
        Healthy runs for the false-alarm rates, at least :data:`MIN_STUDY_RUNS`.
    scales : sequence of float
        Thresholds as multiples of each monitor's reference threshold.
    jobs : int, optional
        Local workers of the healthy runs.
    seed : int
        Seed of the healthy runs.
    progress : bool
        Progress on stderr.
    table : FaultResult, optional
        The fault table already run on ``spec`` (else it is run).
    """
    from scipy import stats

    from ..model.assembly import build_model
    from ..model.components import TAU_LATCH, TAU_RESET

    healthy = check_study_runs(healthy)
    scales = sorted(float(s) for s in scales)
    if not scales or scales[0] <= 0:
        raise FaultError(f"scales: expected positive multiples of the reference thresholds, got {scales}")
    model = build_model(spec.params, spec.variants)
    pv = model.p()
    reacting = [n for n in model.param_names if n.startswith("react_") and pv[model.param_names.index(n)] != 0]
    if reacting:
        raise FaultError(f"threshold study: {reacting[0]} = 1 (a latched monitor changes the run, so one fault table "
                         "cannot serve every threshold); set the reactions to 0")
    mons = _monitor_table(model, pv)
    if not mons:
        raise FaultError("threshold study: the model has no monitor statistics (monitors = on)")
    res = table if table is not None else run_faults(faults=spec)
    h = healthy_runs(spec, healthy, jobs=jobs, seed=seed, progress=progress, statistics=True)
    cases = [res._label(r) for r in res.rows]
    out = {}
    for latch, (stat, param, ref, confirm, unit) in mons.items():
        maxima = np.asarray(h["maxima"][stat], float)
        fit = _gev(maxima)
        rows = []
        for s in scales:
            x = s * ref
            q = _exceedance(fit, x, maxima)
            rate = -math.log1p(-min(q, 1 - 1e-16)) / h["duration"] * HOUR
            det, early = {}, []
            for label, row, run in zip(cases, res.rows, res.runs, strict=True):
                if run is None or stat not in run.outputs:
                    det[label] = None
                    continue
                t0 = row["onset_s"] or 0.0
                td = detection_time(run.t, run[stat], x, confirm, TAU_RESET, TAU_LATCH)
                if td is not None and (row["onset_s"] is None or td < t0):  # latched with no fault present
                    early.append(label)
                    td = None
                det[label] = None if td is None else td - t0
            k = int(np.sum(maxima >= x))
            bound = stats.chi2.ppf(0.95, 2 * k + 2) / 2 / (len(maxima) * h["duration"]) * HOUR
            rows.append({"threshold": x, "scale": s, "false_alarms_per_hour": rate, "data_bound_per_hour": float(bound),
                         "expected_in_runs": q * len(maxima), "observed_in_runs": int(np.sum(maxima >= x)),
                         "detected_s": det, "alarm_without_fault": early})
        top = float(np.max(maxima)) if maxima.size else math.nan
        out[latch] = {"statistic": stat, "threshold_param": param, "reference": ref, "unit": unit,
                      "confirm_s": confirm, "healthy_max": top, "margin": 1 - top / ref if ref else math.nan,
                      "gev": None if fit is None else {"shape_c": fit[0], "loc": fit[1], "scale": fit[2]},
                      "rows": rows}
    return ThresholdStudy(monitors=out, runs=h["runs"] - h["failed"], run_duration=h["duration"], cases=cases,
                          info={"healthy_wall_time_s": h["wall_time"], "healthy_failed": h["failed"],
                                "healthy_false_alarms": h["false_alarms"]}, healthy=h)
