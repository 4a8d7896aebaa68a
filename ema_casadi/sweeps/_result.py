"""The result of a sweep: one row per run, summary statistics, sensitivities, a plot."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._util._notebook import Summarised
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


@dataclass(repr=False)
class SweepResult(Summarised):
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
        units = {k: v[1] for k, v in self.spec.params.scalars().items()}
        u = {"run": "1", **{k: units[k] for k in self.parameters}}
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

    def to_pandas(self):
        """The table (one row per run, the columns of :meth:`to_csv`) as a
        :class:`pandas.DataFrame` indexed by ``run``; units in ``frame.attrs["units"]``.
        Needs pandas."""
        from .._util._notebook import data_frame

        return data_frame({c: [r.get(c) for r in self.rows] for c in self.columns}, index="run", units=self.units())

    def _facts(self) -> dict:
        return {"sweep": self.spec.name, "runs": len(self.rows), "failed": self.info.get("failed"),
                "metrics": len(self.metrics)}

    def plot(self, path: str | Path | None = None, max_panels: int = 6):
        """One row per metric: its histogram, then the metric against each swept
        parameter that varies, with the rank correlation; failed runs and values that do
        not exist (inf, NaN) left out, and a metric without any finite value not drawn
        (named in the title instead).

        Parameters
        ----------
        path : str or Path, optional
            A PNG file to write (atomically); without it the figure is returned (a
            notebook shows it).
        max_panels : int
            At most this many metrics (rows) and parameters are drawn.

        Returns
        -------
        matplotlib.figure.Figure or Path
            The figure, or ``path`` when one was given.
        """
        from ..plots._base import finish, subplots

        ok = np.array([r["status"] == "ok" for r in self.rows])
        varied = [p for p in self.parameters if np.ptp(self.column(p)) > 0]  # not the one-value grids
        drawable = [m for m in self.metrics if (ok & np.isfinite(self.column(m))).any()]
        empty = [m for m in self.metrics if m not in drawable]
        metrics, params = drawable[:max_panels], varied[:max_panels]
        nrow, ncol = max(len(metrics), 1), 1 + len(params)
        fig, axes = subplots(nrow, ncol, figsize=(3.2 * ncol, 2.3 * nrow + 0.6), squeeze=False,
                                 layout="constrained")
        units = self.units()
        sens = self.summary()["sensitivity_spearman"]
        for j, m in enumerate(metrics):
            y = self.column(m)
            good = ok & np.isfinite(y)
            ax = _panel(axes[j, 0])
            ax.hist(y[good], bins=min(30, max(5, int(np.sqrt(good.sum())))), color="C0")
            ax.set_ylabel("runs", fontsize=7)
            ax.set_xlabel(f"{_wrap(m)} ({units.get(m, '') or '-'}), {good.sum()} of {len(y)} runs", fontsize=7)
            for i, p in enumerate(params):
                ax = _panel(axes[j, 1 + i])
                ax.plot(self.column(p)[good], y[good], ".", ms=3, color="C1")
                ax.text(0.03, 0.95, f"rho = {sens[m][p]:.2f}", transform=ax.transAxes, fontsize=7, va="top")
                ax.set_xlabel(f"{p} ({units.get(p, '')})", fontsize=7)
        for ax in axes.ravel():
            if not ax.has_data():
                ax.set_visible(False)
        title = f"sweep {self.spec.name}: {len(self.rows)} runs, {int((~ok).sum())} failed"
        if len(drawable) > len(metrics):
            title += f"; first {len(metrics)} of {len(drawable)} metrics"
        if empty:
            title += f"\nno finite value: {', '.join(empty[:4])}{', ...' if len(empty) > 4 else ''}"
        fig.suptitle(title, fontsize=9)
        return finish(fig, path)


def _panel(ax):
    """An axes with few, small ticks labelled with just the digits that tell them apart
    (no offset text such as '1e8' or '+7.6e1' to run into the panel below)."""
    from matplotlib.ticker import FuncFormatter, MaxNLocator

    ax.tick_params(labelsize=7)
    for axis in (ax.xaxis, ax.yaxis):
        axis.set_major_locator(MaxNLocator(4))
        axis.set_major_formatter(FuncFormatter(lambda x, pos, axis=axis: _tick_label(x, axis.get_majorticklocs())))
    return ax


def _tick_label(x: float, locs) -> str:
    """``x`` with the fewest significant digits (2 or more, and the whole digits of
    numbers below a million) that keep the ticks distinct."""
    locs = list(locs) or [x]
    top = max(abs(v) for v in locs)
    whole = int(math.floor(math.log10(top))) + 1 if 1 <= top < 1e6 else 0  # 150, not 1.5e+02
    digits = next((d for d in range(max(2, whole), 13) if len({f"{v:.{d}g}" for v in locs}) == len(locs)), 13)
    return f"{x:.{digits}g}"


def _wrap(name: str, width: int = 26) -> str:
    """A long column name broken at its underscores onto lines of about ``width``."""
    lines, line = [], ""
    for part in name.split("_"):
        piece = part if not line else f"{line}_{part}"
        if len(piece) > width and line:
            lines.append(line + "_")
            line = part
        else:
            line = piece
    return "\n".join([*lines, line])
