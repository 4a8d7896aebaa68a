"""The result of a sweep: one row per run, summary statistics, sensitivities, a plot."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ._journal import write_table
from ._metrics import metric_columns

__all__ = ["SweepResult", "spearman"]


def spearman(x: np.ndarray, y: np.ndarray) -> float:
    """Spearman's rank correlation of x and y (ties at their mean rank); NaN when one
    of them is constant or fewer than three pairs are given.

    Parameters
    ----------
    x, y : ndarray
        Paired samples.
    """
    from scipy.stats import rankdata

    if len(x) < 3 or np.ptp(x) == 0 or np.ptp(y) == 0:
        return float("nan")
    rx, ry = rankdata(x), rankdata(y)
    return float(np.corrcoef(rx, ry)[0, 1])


@dataclass
class SweepResult:
    """One row per run: the run's number, swept variants and parameters (SI), the
    metrics (SI, unit in the column name or :meth:`units`), ``status`` (``ok`` or
    ``failed``) and ``reason``.

    Attributes
    ----------
    spec : SweepSpec
        The description that was run.
    rows : list of dict
        The rows, in run order.
    columns : list of str
        The table's columns.
    info : dict
        ``runs``, ``resumed`` (taken from an earlier, interrupted run), ``computed``,
        ``failed``, ``wall_time`` (s), ``jobs``, ``backend``, ``scheduler``.
    """

    spec: object
    rows: list
    columns: list
    info: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.rows)

    def column(self, name: str) -> np.ndarray:
        """One column over every run (numbers as floats, NaN where empty).

        Parameters
        ----------
        name : str
            The column.
        """
        if name not in self.columns:
            raise KeyError(f"no column '{name}'; have {', '.join(self.columns)}")
        vals = [r[name] for r in self.rows]
        return np.array(vals, dtype=object if isinstance(vals[0], str) else float)

    @property
    def metrics(self) -> list[str]:
        """The metric columns."""
        return [c for c, _ in metric_columns(self.spec.metrics)]

    @property
    def parameters(self) -> list[str]:
        """The swept parameters."""
        return list(self.spec.parameters)

    def units(self) -> dict:
        """SI unit of every numeric column."""
        u = {"run": "1", **{k: self.spec.params.units()[k] for k in self.parameters}}
        u.update(dict(metric_columns(self.spec.metrics)))
        return u

    def failed(self) -> list[dict]:
        """The failed rows."""
        return [r for r in self.rows if r["status"] != "ok"]

    def to_csv(self, path: str | Path) -> Path:
        """Write the table (one header row, one row per run, 17 significant digits,
        empty cells for values that do not exist), atomically.

        Parameters
        ----------
        path : str or Path
            The CSV file.
        """
        return write_table(path, self.rows, self.columns)

    def summary(self) -> dict:
        """Statistics of every metric over the runs that succeeded (``n``, ``mean``,
        ``std``, ``min``, ``p05``, ``median``, ``p95``, ``max``; values that do not exist,
        such as the frequency of no hunting, left out) and the sensitivity of each metric
        to each swept parameter: Spearman's rank correlation over those runs."""
        ok = np.array([r["status"] == "ok" for r in self.rows])
        stats, sens = {}, {}
        for m in self.metrics:
            y = self.column(m)
            good = ok & np.isfinite(y)
            v = y[good]
            stats[m] = {"n": int(good.sum())}
            if len(v):
                q = np.percentile(v, [5, 50, 95])
                stats[m].update(mean=float(v.mean()), std=float(v.std(ddof=1)) if len(v) > 1 else 0.0,
                                min=float(v.min()), p05=float(q[0]), median=float(q[1]), p95=float(q[2]),
                                max=float(v.max()))
            sens[m] = {p: spearman(self.column(p)[good], v) for p in self.parameters}
        return {"runs": len(self.rows), "ok": int(ok.sum()), "failed": int((~ok).sum()),
                "statistics": stats, "sensitivity_spearman": sens}

    def plot(self, path: str | Path, max_panels: int = 6) -> Path:
        """Histograms of the metrics (top row) and each metric against each swept
        parameter that varies, with the rank correlation (below); failed runs and
        values that do not exist (inf, NaN) left out.

        Parameters
        ----------
        path : str or Path
            The PNG file (written atomically).
        max_panels : int
            At most this many metrics and parameters are drawn.
        """
        from ..plots._base import plt, save

        ok = np.array([r["status"] == "ok" for r in self.rows])
        varied = [p for p in self.parameters if np.ptp(self.column(p)) > 0]  # not the one-value grids
        metrics, params = self.metrics[:max_panels], varied[:max_panels]
        ncol = max(len(metrics), len(params), 1)
        nrow = 1 + (len(metrics) if params else 0)
        fig, axes = plt.subplots(nrow, ncol, figsize=(3.0 * ncol, 2.4 * nrow), squeeze=False)
        for ax in axes.ravel():
            ax.set_visible(False)
        units = self.units()
        sens = self.summary()["sensitivity_spearman"]
        for j, m in enumerate(metrics):
            y = self.column(m)
            good = ok & np.isfinite(y)
            ax = axes[0, j]
            ax.set_visible(True)
            ax.hist(y[good], bins=min(30, max(5, int(np.sqrt(good.sum())))), color="C0")
            ax.set_xlabel(f"{m} ({units.get(m, '')})", fontsize=8)
            ax.set_title(f"{good.sum()} of {len(y)} runs", fontsize=8)
            for i, p in enumerate(params):
                ax = axes[1 + j, i]
                ax.set_visible(True)
                ax.plot(self.column(p)[good], y[good], ".", ms=2, color="C1")
                ax.set_title(f"rho = {sens[m][p]:.2f}", fontsize=8)
                ax.set_xlabel(f"{p} ({units.get(p, '')})", fontsize=8)
                ax.set_ylabel(m, fontsize=7)
        fig.suptitle(f"sweep {self.spec.name}: {len(self.rows)} runs, {int((~ok).sum())} failed", fontsize=10)
        fig.tight_layout()
        return save(fig, path)
