"""The result of a design: the test as the rig plays it, its predicted intervals and
correlation, the comparison with the standard test, the figure, the files."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .._util._files import write_text
from ..signals import write_series

__all__ = ["DesignResult"]


class DesignResult:
    """A designed rig test and what it is predicted to deliver.

    Parameters
    ----------
    params : Parameters
        The parameter set it was designed at.
    model : Model
        The model.
    free : Free
        The free parameters.
    test, standard : Test
        The designed test and the standard test of the same length.
    M, M_standard : ndarray
        Their Fisher information (optimiser coordinates, averaged over the draws).
    predicted, standard_predicted : dict
        Their predicted intervals (:func:`~ema_casadi.design.intervals`).
    usage : dict
        Limit -> the designed test's largest use of it (fraction), worst draw.
    segments : list of dict
        The segments chosen: label, load, amplitude, share, count.
    thetas : list of ndarray
        The prior's draws (SI).
    info : dict
        Criterion, weights, IPOPT's status, timings, limits.
    runs : list of dict
        The designed test's predicted trajectory (``t``, ``y``) at the centre.
    """

    def __init__(self, *, params, model, free, test, standard, M, M_standard, predicted, standard_predicted, usage,
                 segments, thetas, info, runs):
        self.params, self.model, self.free = params, model, free
        self.test, self.standard = test, standard
        self.M, self.M_standard = M, M_standard
        self.predicted, self.standard_predicted = predicted, standard_predicted
        self.usage, self.segments, self.thetas, self.info, self.runs = usage, segments, thetas, info, runs
        #: The verification (:meth:`verify`), once run.
        self.verification = None
        #: The admissible candidates the optimiser chose from: (Segment, information per
        #: segment averaged over the draws) pairs.
        self.candidates = []

    def __repr__(self) -> str:
        c = self.comparison()
        return (f"DesignResult({self.info['criterion']}-optimal {self.test.duration:g} s test of "
                f"{', '.join(self.free.names)}: interval widths {c['geometric_mean_ratio']:.3g}x narrower "
                f"(geometric mean) than {self.standard.name})")

    def _repr_html_(self) -> str:
        from .._util._notebook import html_summary

        c = self.comparison()
        return html_summary("DesignResult", {"criterion": self.info["criterion"],
                                             "duration": f"{self.test.duration:g} s",
                                             "free": ", ".join(self.free.names),
                                             "narrower": f"{c['geometric_mean_ratio']:.3g}x than {self.standard.name}"})

    def comparison(self) -> dict:
        """The designed against the standard test: per parameter the predicted relative
        95 % interval widths and their ratio, the geometric mean of the ratios, the
        largest correlation of each."""
        names = self.free.names
        wd = np.asarray(self.predicted["width"], float)
        ws = np.asarray(self.standard_predicted["width"], float)
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = ws / wd
        fin = np.isfinite(ratio) & (ratio > 0)
        gm = float(np.exp(np.mean(np.log(ratio[fin])))) if fin.all() else float("inf") if np.isinf(ws).any() \
            else float("nan")

        def worst(corr):
            c = np.abs(np.asarray(corr) - np.eye(len(names)))
            i, j = np.unravel_index(np.argmax(c), c.shape)
            return {"pair": [names[i], names[j]], "corr": float(np.asarray(corr)[i, j])}

        return {"parameters": {n: {"designed": float(wd[k]), "standard": float(ws[k]), "ratio": float(ratio[k])}
                               for k, n in enumerate(names)},
                "geometric_mean_ratio": gm,
                "geometric_mean_width": {"designed": float(np.exp(np.mean(np.log(wd)))),
                                         "standard": float(np.exp(np.mean(np.log(ws))))},
                "largest_correlation": {"designed": worst(self.predicted["corr"]),
                                        "standard": worst(self.standard_predicted["corr"])}}

    def correlation(self, a: str, b: str, standard: bool = False) -> float:
        """The predicted correlation of two free parameters.

        Parameters
        ----------
        a, b : str
            Parameter names.
        standard : bool
            Of the standard test instead.
        """
        k, j = self.free.names.index(a), self.free.names.index(b)
        return float((self.standard_predicted if standard else self.predicted)["corr"][k, j])

    def table(self) -> str:
        """The comparison as a Markdown table: each parameter's value in its unit, the
        95 % interval widths in % of the value the designed and the standard test
        predict, and their ratio standard / designed (above 1: the design pins the
        parameter down that many times more narrowly)."""
        from ..model.params import Parameters
        from ..signals import format_quantity

        c, units = self.comparison(), Parameters.units()
        lines = [f"| parameter | value | designed test: 95 % width | standard test ({self.standard.name}): "
                 "95 % width | ratio standard / designed (> 1: the design is narrower) |", "|---|---|---|---|---|"]
        for k, n in enumerate(self.free.names):
            p = c["parameters"][n]
            lines.append(f"| {n} | {format_quantity(self.thetas[0][k], units.get(n, '1'))} | "
                         f"{100 * p['designed']:.3g} % | {100 * p['standard']:.3g} % | {p['ratio']:.3g} |")
        g = c["geometric_mean_width"]
        lines.append(f"| geometric mean | | {100 * g['designed']:.3g} % | {100 * g['standard']:.3g} % | "
                     f"{c['geometric_mean_ratio']:.3g} |")
        return "\n".join(lines)

    def to_json(self) -> dict:
        """Everything as plain JSON types."""
        c = self.comparison()
        names = self.free.names
        out = {"free": list(names), "duration": self.test.duration, "criterion": self.info["criterion"],
               "segments": self.segments, "comparison": c,
               "predicted": {n: {"value": float(self.thetas[0][k]),
                                 "interval": [float(v) for v in self.predicted["interval"][k]],
                                 "width": float(self.predicted["width"][k])} for k, n in enumerate(names)},
               "correlation": np.asarray(self.predicted["corr"]).round(6).tolist(),
               "standard_correlation": np.asarray(self.standard_predicted["corr"]).round(6).tolist(),
               "limits_used": self.usage, "standard_limits_used": self.info["standard_usage"],
               "info": {k: v for k, v in self.info.items() if k != "standard_usage"}}
        if self.verification is not None:
            out["verification"] = self.verification
        return json.loads(json.dumps(out, default=float))

    def plot(self, path=None):
        """The figure: designed and standard command and load, predicted interval widths.

        Parameters
        ----------
        path : str or Path, optional
            PNG file; without it the Figure is returned.
        """
        from ..plots._design import design_figure

        return design_figure(self, path)

    def write(self, folder) -> Path:
        """Write the test into ``folder`` (assembled aside and moved in whole):
        ``design.csv`` (time, command, load: the table the rig controller plays, the
        layout ``ema simulate`` plays back as ``design.csv:x_cmd`` and ``ema identify``
        reads with the measured columns added), the standard test's records
        ``standard_<name>.csv``, ``summary.json``, ``comparison.md`` and ``design.png``.

        Parameters
        ----------
        folder : str or Path
            The folder (replaced whole).
        """
        from .._util._files import atomic_dir

        units = self.model.units
        with atomic_dir(folder) as tmp:
            tmp = Path(tmp)
            for prefix, test in (("design", self.test), ("standard_", self.standard)):
                for rec in test.records:
                    cols = list(rec["inputs"])
                    name = f"{prefix}.csv" if prefix == "design" else f"{prefix}{rec['name']}.csv"
                    data = np.column_stack([rec["t"], *(rec["inputs"][c] for c in cols)])
                    write_series(tmp / name, ["time", *cols], ["s", *(units[c] for c in cols)], data)
            write_text(tmp / "summary.json", json.dumps(self.to_json(), indent=1) + "\n")
            write_text(tmp / "comparison.md", self.table() + "\n")
            self.plot(tmp / "design.png")
        return Path(folder)

    def verify(self, n: int = 20, *, seed: int = 0, jobs: int | None = None, progress: bool = False) -> dict:
        """Simulate the designed test ``n`` times with the sensor noise, fit each with
        ``identify`` and compare the realised intervals with the predicted ones (kept in
        :attr:`verification`).

        Parameters
        ----------
        n : int
            Simulated tests.
        seed : int
            Seed of the noise and the fits' starts.
        jobs : int, optional
            Fits at once (threads; default the cores).
        progress : bool
            One line of progress on stderr.
        """
        from ._verify import verify

        self.verification = verify(self, n, seed=seed, jobs=jobs, progress=progress)
        return self.verification
