"""The result of a fault study: one row per case, the coverage matrix, the figures."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._util._notebook import Summarised

__all__ = ["FaultResult"]


def _first(t, flag):
    return float(t[int(np.argmax(flag))]) if np.any(flag) else None


@dataclass(repr=False)
class FaultResult(Summarised):
    """Per case: detection time of every monitor, peak deviation, status.

    Attributes
    ----------
    spec : FaultSpec
        The checked fault file.
    monitors : tuple of str
        The model's alarm outputs (``latch_<monitor>``), in order.
    rows : list of dict
        One per case: ``case``, ``kind``, ``target``, ``onset_s``, ``severity``,
        ``unit``, ``status``, ``reason``, ``peak_deviation_m`` (the largest absolute
        difference of x_rod from the no-fault run's, from the onset; in the aircraft loop also ``peak_theta_dev``,
        rad, and ``peak_n_z_dev``, -), ``detected_<monitor>_s`` (delay from the
        onset to the latch, None if not detected; for the no-fault case the time of a
        false alarm), ``first_monitor``.
    runs : list
        The simulation results (``SimResult``) of the cases, in order.
    info : dict
        Wall time, variants, case count.
    healthy : dict or None
        The false-alarm count of the healthy runs (:func:`~ema_casadi.faults.healthy_runs`).
    """

    spec: object
    monitors: tuple
    rows: list
    runs: list = field(repr=False, default_factory=list)
    info: dict = field(default_factory=dict)
    healthy: dict | None = None

    def _facts(self) -> dict:
        return {"cases": len(self.rows), "monitors": len(self.monitors),
                "failed": sum(r["status"] != "ok" for r in self.rows),
                "false_alarms_no_fault": ", ".join(self.false_alarms()) or "none",
                "healthy_runs": None if not self.healthy else self.healthy.get("runs")}

    @classmethod
    def from_runs(cls, spec, model, runs, info) -> FaultResult:
        """Rows from the cases' runs (the first is the no-fault case).

        Parameters
        ----------
        spec : FaultSpec
            The checked fault file.
        model : Model
            The model the cases ran on (its ``alarm`` outputs are the monitors).
        runs : list of (SimResult or None, str or None)
            Per case: the run (up to a failure) and the failure's reason.
        info : dict
            Wall time and the like, kept in :attr:`info`.
        """
        monitors = model.outputs_of("alarm")
        rod = model.output_with("rod_position")
        flight = [n for r in ("pitch_attitude", "load_factor") for n in model.signals_with(r)]
        ref = runs[0][0]
        rows = []
        for case, (res, reason) in zip(spec.cases, runs, strict=True):
            f = case.fault
            row = {"case": case.label, "kind": f.kind if f else "none", "target": f.target if f else None,
                   "onset_s": None if f is None else case.onset, "severity": case.severity if f else None,
                   "unit": f.unit if f else None, "status": "failed" if reason else "ok", "reason": reason}
            t0 = 0.0 if f is None else case.onset
            if res is None:
                row.update({f"detected_{m}_s": None for m in monitors}, peak_deviation_m=math.nan, first_monitor=None)
                rows.append(row)
                continue
            n = min(len(res.t), len(ref.t))
            after = res.t[:n] >= t0
            dev = np.abs(res[rod][:n] - ref[rod][:n])[after]
            row["peak_deviation_m"] = float(dev.max()) if dev.size else math.nan
            for name in flight:  # the aircraft loop's pitch and load-factor excursions
                d = np.abs(res[name][:n] - ref[name][:n])[after]
                row[f"peak_{name}_dev"] = float(d.max()) if d.size else math.nan
            det = {}
            for m in monitors:
                t = _first(res.t, res[m] >= 0.5)
                det[m] = None if t is None else t - t0
                row[f"detected_{m}_s"] = det[m]
            hits = {m: d for m, d in det.items() if d is not None}
            row["first_monitor"] = min(hits, key=hits.get) if hits else None
            rows.append(row)
        docs = {m: model.output_info[m].doc.removeprefix("latched monitor: ") for m in monitors}
        return cls(spec=spec, monitors=monitors, rows=rows, runs=[r for r, _ in runs],
                   info={**info, "monitor_doc": docs})

    @property
    def columns(self) -> list[str]:
        """The table's columns, in order."""
        extra = [c for c in (self.rows[0] if self.rows else ()) if c.startswith("peak_") and c.endswith("_dev")]
        return ["case", "kind", "target", "onset_s", "severity", "unit", "status", "peak_deviation_m", *extra,
                *(f"detected_{m}_s" for m in self.monitors), "first_monitor", "reason"]

    def coverage(self) -> dict:
        """Case label (with onset and severity when the file has several) -> monitor ->
        detection delay (s) or None."""
        out = {}
        for row in self.rows:
            out[self._label(row)] = {m: row[f"detected_{m}_s"] for m in self.monitors}
        return out

    def _label(self, row) -> str:
        many = len({(r["kind"], r["target"]) for r in self.rows}) < len(self.rows)
        if row["onset_s"] is None or not many:
            return row["case"]
        return f"{row['case']} @{row['onset_s']:g} s x{row['severity']:g}"

    def false_alarms(self) -> list[str]:
        """Monitors latched in the no-fault case (should be none)."""
        return [m for m in self.monitors if self.rows[0][f"detected_{m}_s"] is not None]

    def summary(self) -> dict:
        """The JSON result: rows, coverage, false alarms, healthy runs (their margins,
        without the per-run maxima), info."""
        healthy = None if self.healthy is None else {k: v for k, v in self.healthy.items() if k != "maxima"}
        return {"cases": len(self.rows), "monitors": list(self.monitors), "rows": self.rows,
                "coverage_s": self.coverage(), "false_alarms_no_fault": self.false_alarms(),
                "healthy_runs": healthy, "failed": [r["case"] for r in self.rows if r["status"] != "ok"],
                "wall_time": self.info.get("wall_time"), "variants": self.info.get("model_variants"),
                "monitor_doc": self.info.get("monitor_doc", {})}

    def to_csv(self, path: str | Path) -> Path:
        """Write the table (one row per case, SI units in the header), atomically.

        Parameters
        ----------
        path : str or Path
            The CSV file.
        """
        from ..sweeps import write_table

        return write_table(path, self.rows, self.columns)

    def to_json(self, path: str | Path, extra: dict | None = None) -> Path:
        """Write :meth:`summary` as JSON, atomically.

        Parameters
        ----------
        path : str or Path
            The JSON file.
        extra : dict, optional
            More entries (the threshold study's).
        """
        from .._util._files import write_text

        return write_text(path, json.dumps({**self.summary(), **(extra or {})}, indent=1, default=_plain) + "\n")

    def plot(self, path: str | Path | None = None):
        """The coverage matrix (cases x monitors, detection delay in ms) beside the
        rod's deviation after the onset of each case; returns the Figure (and writes
        it to ``path``, atomically, when given).

        Parameters
        ----------
        path : str or Path, optional
            A PNG file to write.
        """
        from ..plots._faults import plot_coverage

        return plot_coverage(self, path)


def _plain(v):
    if isinstance(v, (np.floating, np.integer)):
        return v.item()
    return str(v)
