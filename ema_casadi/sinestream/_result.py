"""The sine-stream result: :class:`FreqResponse` on a grid with named axes, its table
and JSON writers, and the error type of the package."""

from __future__ import annotations

import csv
import itertools
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._util._files import write_with
from .._util._notebook import Summarised
from ..simulation import SimulationError

#: Result fields per point, with units. ``status`` is ``converged``, ``not_converged``
#: (not settled within max_periods: the last period's values) or ``failed`` (the run
#: left the physical envelope, went non-finite or its integrator gave up: no values,
#: NaN); ``reason`` says why a point is not converged, with the time of a failure.
FIELDS = {
    "gain_db": "dB", "phase_deg": "deg", "distortion": "1",
    "i_q_amp": "A", "i_q_phase_deg": "deg", "i_q_distortion": "1",
    "x_offset": "m", "periods": "1", "converged": "1", "status": "", "reason": "",
}
STATUSES = ("converged", "not_converged", "failed")


class FreqRespError(SimulationError):
    """Bad frequency-response request (one line, names the argument)."""


@dataclass(repr=False)
class FreqResponse(Summarised):
    """Sine-stream results on a grid with named axes.

    Attributes
    ----------
    axes : dict
        ``variant`` (labels), ``load`` (N), ``amplitude`` (m), ``frequency`` (Hz), in
        this order; every array in ``data`` has shape ``(n_variant, n_load,
        n_amplitude, n_frequency)``.
    data : dict of ndarray
        :data:`FIELDS`: ``gain_db`` (dB), ``phase_deg`` (deg, unwrapped along frequency,
        relative to x_cmd), ``distortion`` (-) of x_rod; ``i_q_amp`` (A), ``i_q_phase_deg``
        (deg, relative to x_cmd), ``i_q_distortion`` (-); ``x_offset`` (m, mean rod
        position over the last period); ``periods`` simulated; ``converged`` (bool);
        ``status`` and ``reason`` (str, see :data:`FIELDS`). A failed point is never
        converged and has no values (NaN).
    variants : dict
        Label -> complete variant dict.
    info : dict
        Options, wall time, counts, ``backend`` and ``timing`` (each point's CPU seconds
        and estimated cost, the tasks' CPU seconds, the workers' start-up).
    samples : dict, optional
        With ``keep=True``: (i_variant, i_load, i_amplitude, i_frequency) -> dict of
        ``t`` (s), ``x_cmd`` (m), ``x_rod`` (m), ``i_q`` (A) over all simulated periods.
    """

    axes: dict
    data: dict
    variants: dict
    info: dict = field(default_factory=dict)
    samples: dict | None = None

    @property
    def shape(self) -> tuple:
        """Grid shape ``(n_variant, n_load, n_amplitude, n_frequency)``."""
        return tuple(len(v) for v in self.axes.values())

    def rows(self) -> list[dict]:
        """One dict per point: variant, load_N, amplitude_m, freq_Hz, then the fields.

        Returns
        -------
        list of dict
            Load (N), amplitude (m), frequency (Hz) and the :data:`FIELDS` in their units.
        """
        out = []
        for idx in itertools.product(*[range(n) for n in self.shape]):
            iv, il, ia, jf = idx
            row = {
                "variant": self.axes["variant"][iv],
                "load_N": float(self.axes["load"][il]),
                "amplitude_m": float(self.axes["amplitude"][ia]),
                "freq_Hz": float(self.axes["frequency"][jf]),
            }
            for k in FIELDS:
                v = self.data[k][idx]
                if k in ("status", "reason"):
                    row[k] = str(v)
                else:
                    row[k] = bool(v) if k == "converged" else (int(v) if k == "periods" else float(v))
            out.append(row)
        return out

    def to_pandas(self):
        """:meth:`rows` as a :class:`pandas.DataFrame`, one row per point (SI). Needs pandas."""
        from .._util._notebook import data_frame

        rows = self.rows()
        return data_frame({k: [r[k] for r in rows] for k in rows[0]})

    def plot(self, path: str | Path | None = None, title: str = "", stroke: float | None = None):
        """Bode plot (gain dB, phase deg against Hz), one line per (variant, load,
        amplitude); points that did not settle marked ``x``.

        Parameters
        ----------
        path : str or Path, optional
            A PNG file to write; without it the figure is returned.
        title : str
            Figure title.
        stroke : float, optional
            Actuator stroke (m): amplitudes labelled in % of it too.

        Returns
        -------
        matplotlib.figure.Figure or Path
        """
        from ..plots._sinestream import plot_bode

        return plot_bode(self, path, title, stroke)

    def _facts(self) -> dict:
        converged = int(np.asarray(self.data["converged"]).sum())
        return {"shape": "x".join(map(str, self.shape)), "axes": ", ".join(self.axes),
                "converged": f"{converged} of {int(np.prod(self.shape))}"}

    def to_csv(self, path: str | Path) -> Path:
        """Write one row per point (columns as :meth:`rows`, SI units), atomically.

        Parameters
        ----------
        path : str or Path
            The CSV file.

        Returns
        -------
        Path
            ``path``.
        """
        rows = self.rows()
        cols = list(rows[0])

        def write(tmp):
            with Path(tmp).open("w", newline="") as fh:
                w = csv.writer(fh)
                w.writerow(cols)
                w.writerows([_fmt(r[c]) for c in cols] for r in rows)

        return write_with(path, write)

    def curve(self, variant=None, load=None, amplitude=None) -> dict:
        """Arrays along frequency for one (variant, load, amplitude).

        An axis of length one needs no value; otherwise the nearest value is taken
        (variant labels must match exactly).

        Parameters
        ----------
        variant : str, optional
            Variant label.
        load : float, optional
            External force F_ext (N).
        amplitude : float, optional
            Command amplitude A (m).

        Returns
        -------
        dict
            ``freq_Hz`` (Hz) and every field of :attr:`data` along frequency.
        """
        iv = _pick(self.axes["variant"], variant, "variant")
        il = _pick(self.axes["load"], load, "load")
        ia = _pick(self.axes["amplitude"], amplitude, "amplitude")
        out = {"freq_Hz": np.asarray(self.axes["frequency"])}
        out.update({k: v[iv, il, ia] for k, v in self.data.items()})
        return out

    def not_converged(self) -> list[dict]:
        """Rows (as :meth:`rows`) of the points that did not settle within ``max_periods``
        or failed."""
        return [r for r in self.rows() if not r["converged"]]

    def failed(self) -> list[dict]:
        """Rows (as :meth:`rows`) of the failed points (``status`` failed, with the reason)."""
        return [r for r in self.rows() if r["status"] == "failed"]

    def failure(self) -> str | None:
        """One line on the failed points (how many, the first one and why), or None."""
        bad = self.failed()
        if not bad:
            return None
        r = bad[0]
        where = f"load {r['load_N'] / 1e3:g} kN, amplitude {r['amplitude_m'] * 1e3:g} mm, {r['freq_Hz']:g} Hz"
        if len(self.axes["variant"]) > 1:
            where = f"{r['variant']}, {where}"
        return f"{len(bad)} of {self.data['status'].size} points failed; first ({where}): {r['reason']}"

    def to_dict(self) -> dict:
        """JSON-ready: axes (SI), variants, units, info and one entry per point."""
        return {
            "axes": {k: list(v) if k == "variant" else [float(a) for a in v] for k, v in self.axes.items()},
            "axis_units": {"variant": "", "load": "N", "amplitude": "m", "frequency": "Hz"},
            "units": dict(FIELDS),
            "variants": self.variants,
            "info": {k: _listed(v) if k == "timing" else v for k, v in self.info.items()},
            "points": self.rows(),
        }


def _listed(timing: dict) -> dict:
    """The timings with their arrays as (nested) lists."""
    return {k: v.tolist() if isinstance(v, np.ndarray) else v for k, v in timing.items()}


def _fmt(v) -> str:
    if isinstance(v, bool):
        return "1" if v else "0"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, float):
        return f"{v:.10g}"
    return str(v)


def _pick(values, want, name) -> int:
    if want is None:
        if len(values) != 1:
            raise FreqRespError(f"{name}: several values {list(values)}, say which one")
        return 0
    if name == "variant":
        if want not in list(values):
            raise FreqRespError(f"variant '{want}' not in {list(values)}")
        return list(values).index(want)
    return int(np.argmin(np.abs(np.asarray(values, float) - float(want))))
