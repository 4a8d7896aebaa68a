"""Health trend: each record fitted alone, in the order of its time stamp; a trend per
parameter, its uncertainty, and the predicted crossing of a limit (remaining useful
life)."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._util._files import atomic_dir
from .._util._notebook import Summarised
from ._data import plain
from ._fit import given_model, identify
from ._records import IdentificationError, read_record
from ._result import Z95


@dataclass(repr=False)
class TrackResult(Summarised):
    """Estimates of successive records against their time stamp, and the trends.

    Attributes
    ----------
    stamp : str
        The time-stamp field (``flight_hours``).
    rows : list of dict
        Per record in stamp order: ``record``, ``stamp``, and per parameter its
        ``estimate``, ``std``, ``interval``, ``identifiable``.
    trends : dict
        Parameter -> ``slope`` and ``intercept`` (SI per stamp unit) with their
        covariance, the scatter factor, and with a limit: ``limit``, ``crossing``
        (the stamp where the trend reaches it), ``crossing_std``, ``crossing_interval``
        (95 %), ``remaining`` (crossing minus the last stamp), or ``note`` when the
        trend does not approach the limit.
    """

    stamp: str
    rows: list
    trends: dict = field(default_factory=dict)

    def _facts(self) -> dict:
        return {"stamp": self.stamp, "records": len(self.rows), "trends": ", ".join(self.trends) or None}

    def to_dict(self) -> dict:
        """Plain data (``--json``)."""
        return {"stamp": self.stamp, "records": self.rows, "trend": self.trends}

    def plot(self):
        """The health-trend figure: per parameter the estimates with their 95 %
        intervals against the stamp, the fitted trend with its 95 % band, the limit and
        the predicted crossing."""
        import matplotlib.pyplot as plt

        names = list(self.trends)
        fig, axes = plt.subplots(len(names), 1, figsize=(7.5, 2.8 * len(names) + 0.4), squeeze=False)
        t = np.array([r["stamp"] for r in self.rows])
        for ax, n in zip(axes[:, 0], names, strict=True):
            tr = self.trends[n]
            est = np.array([r["parameters"][n]["estimate"] for r in self.rows])
            lo = np.array([r["parameters"][n]["interval"][0] for r in self.rows])
            hi = np.array([r["parameters"][n]["interval"][1] for r in self.rows])
            ax.errorbar(t, est, yerr=[est - lo, hi - est], fmt="o", color="C0", capsize=3, label="estimate, 95 %")
            t_end = max(t.max(), tr.get("crossing_interval", [0, 0])[1] if "crossing" in tr else 0)
            tt = np.linspace(t.min(), t_end if np.isfinite(t_end) else t.max(), 200)
            mean, band = _line(tr, tt)
            ax.plot(tt, mean, "-", color="C1", label="trend")
            ax.fill_between(tt, mean - Z95 * band, mean + Z95 * band, color="C1", alpha=0.2)
            if "limit" in tr:
                ax.axhline(tr["limit"], color="C3", ls="--", label=f"limit {tr['limit']:.4g}")
                if "crossing" in tr:
                    a, b = tr["crossing_interval"]
                    ax.errorbar([tr["crossing"]], [tr["limit"]], xerr=[[tr["crossing"] - a], [b - tr["crossing"]]],
                                fmt="s", color="C3", capsize=4, label=f"crossing {tr['crossing']:.4g}")
            ax.set_ylabel(n)
            ax.legend(fontsize=7, loc="best")
        axes[-1, 0].set_xlabel(self.stamp)
        fig.suptitle("health trend", fontsize=10)
        fig.tight_layout()
        return fig

    def write_report(self, folder) -> Path:
        """``trend.png`` and ``trend.json`` in ``folder`` (assembled aside, moved in).

        Parameters
        ----------
        folder : str or Path
            The folder.
        """
        import matplotlib.pyplot as plt

        with atomic_dir(folder) as tmp:
            fig = self.plot()
            fig.savefig(Path(tmp) / "trend.png", dpi=110)
            plt.close(fig)
            (Path(tmp) / "trend.json").write_text(json.dumps(plain(self.to_dict()), indent=1) + "\n")
        return Path(folder)


def _line(tr, t):
    """The trend's mean and standard deviation at ``t``."""
    C = np.asarray(tr["covariance"])
    mean = tr["intercept"] + tr["slope"] * t
    var = C[0, 0] + 2 * t * C[0, 1] + t * t * C[1, 1]
    return mean, np.sqrt(np.maximum(var, 0))


def trend(t, est, std, limit: float | None = None) -> dict:
    """Weighted straight line through the estimates (weights 1/std^2; the covariance
    scaled by the reduced chi-square when the scatter exceeds the intervals), and the
    crossing of ``limit`` with its uncertainty (first order in the line's parameters).

    Parameters
    ----------
    t : array_like
        Time stamps.
    est, std : array_like
        Estimates and their standard deviations.
    limit : float, optional
        The limit of the parameter.
    """
    t, est, std = (np.asarray(v, float) for v in (t, est, std))
    A = np.column_stack([np.ones_like(t), t])
    w = 1 / np.maximum(std, 1e-300) ** 2
    cov = np.linalg.inv(A.T @ (A * w[:, None]))
    a, b = cov @ (A.T @ (w * est))
    chi2 = float(np.sum(w * (est - a - b * t) ** 2))
    dof = len(t) - 2
    scatter = max(1.0, chi2 / dof) if dof > 0 else 1.0
    cov = cov * scatter
    out = {"intercept": float(a), "slope": float(b), "covariance": cov.tolist(), "scatter": scatter}
    if limit is None:
        return out
    out["limit"] = float(limit)
    if b == 0 or (limit - (a + b * t[-1])) / b < 0:
        out["note"] = "the trend does not approach the limit"
        return out
    tc = (limit - a) / b
    g = np.array([-1 / b, -(limit - a) / b**2])
    s = float(np.sqrt(g @ cov @ g))
    out.update(crossing=float(tc), crossing_std=s, crossing_interval=[float(tc - Z95 * s), float(tc + Z95 * s)],
               remaining=float(tc - t[-1]))
    return out


def track(params, records, free, *, stamp: str = "flight_hours", limits: dict | None = None,
          sigma: dict | None = None, bounds: dict | None = None, variants: dict | None = None,
          max_evaluations: int = 60, hold=None, hold_unidentifiable: bool = False, progress: bool = False,
          model=None) -> TrackResult:
    """Fit each record alone and trend the estimates against the records' time stamp.

    Parameters
    ----------
    params : Parameters
        The parameter set (the start of every fit).
    records : sequence of str or Path
        Record files, each with the time stamp (a field ``# flight_hours: 1200`` or a
        column of that name).
    free : sequence of str
        Parameters fitted.
    stamp : str
        The time-stamp field or column.
    limits : dict, optional
        Parameter -> limit (SI): the crossing is predicted.
    sigma, bounds, variants, max_evaluations, hold, hold_unidentifiable, progress, model
        As for :func:`~ema_casadi.identification.identify`, for every fit (the model
        built once, by the caller or here, and passed to each).
    """
    fit = {"sigma": sigma, "bounds": bounds, "variants": variants, "max_evaluations": max_evaluations,
           "hold": hold, "hold_unidentifiable": hold_unidentifiable, "progress": progress}
    limits = dict(limits or {})
    for n in limits:
        if n not in free:
            from .._util._checks import nearest

            raise IdentificationError(f"--limit {n}: not a free parameter{nearest(n, free)}")
    model = given_model(model, params, variants)
    recs = [read_record(r, model, extra=(stamp,)) for r in records]
    if len(recs) < 2:
        raise IdentificationError("--track needs at least two records (one per time stamp)")
    order = sorted(range(len(recs)), key=lambda k: recs[k].stamp(stamp))
    rows = []
    for k in order:
        res = identify(params, [recs[k]], free, **fit, model=model)
        doc = res.to_dict()
        rows.append({"record": recs[k].path, "stamp": recs[k].stamp(stamp), "parameters": {
            n: {"estimate": res.estimate[n], "std": res.std[n], "interval": list(res.interval[n]),
                "identifiable": res.identifiable[n] is True} for n in res.names},
            "held": list(doc["parameters"][n] for n in res.held)})
    trends = {}
    t = [r["stamp"] for r in rows]
    for n in free:
        if not all(n in r["parameters"] for r in rows):
            continue  # held on request in some record
        est = [r["parameters"][n]["estimate"] for r in rows]
        std = [r["parameters"][n]["std"] for r in rows]
        trends[n] = trend(t, est, std, limits.get(n))
    return TrackResult(stamp, rows, trends)


def report_text(doc: dict) -> str:
    """The trend as text (the command line's report).

    Parameters
    ----------
    doc : dict
        :meth:`TrackResult.to_dict`.
    """
    lines = []
    for r in doc["records"]:
        vals = ", ".join(f"{n} {d['estimate']:.5g} +-{Z95 * d['std']:.2g}" for n, d in r["parameters"].items())
        lines.append(f"{doc['stamp']} {r['stamp']:g}: {vals}")
    for n, tr in doc["trend"].items():
        s = f"trend {n}: {tr['slope']:+.4g} per {doc['stamp']}"
        if "crossing" in tr:
            a, b = tr["crossing_interval"]
            s += (f"; reaches {tr['limit']:.4g} at {tr['crossing']:.5g} (95 %: {a:.5g} .. {b:.5g}), "
                  f"remaining {tr['remaining']:.4g}")
        elif "note" in tr:
            s += f"; {tr['note']}"
        lines.append(s)
    return "\n".join(lines) + "\n"
