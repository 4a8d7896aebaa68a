"""Simulation results: named time series, step metrics, progress (docs: simulate)."""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._util._errors import InputError
from .._util._files import write_with

__all__ = ["SimulationError", "SimResult", "step_response_metrics", "hunting_metrics", "progress_bar"]


class SimulationError(InputError, ValueError):
    """Bad simulation request (one line, names the argument)."""


@dataclass
class SimResult:
    """Named time series of a simulation (SI units).

    ``res["x_rod"]`` looks a name up among outputs, then inputs, then states.

    Attributes
    ----------
    t : ndarray
        Sample times (s).
    inputs, outputs, states : dict
        Name -> samples (SI, the unit in :meth:`units`).
    info : dict
        Run facts: solver, variants, ``t_end`` (s), ``wall_time`` (s), solver statistics.
    unit_table : dict
        Signal name -> SI unit (the model's :attr:`~ema_casadi.model.assembly.Model.units`).
    kinds : dict
        Output name -> its kind (``loss``, ``power``, ...), for :meth:`energies`.
    roles : dict
        Output name -> the roles it declares (``x_rod`` -> ``("rod_position",)``).
    """

    t: np.ndarray
    inputs: dict
    outputs: dict
    states: dict
    info: dict = field(default_factory=dict)
    unit_table: dict = field(default_factory=dict)
    kinds: dict = field(default_factory=dict)
    roles: dict = field(default_factory=dict)

    def __getitem__(self, name: str) -> np.ndarray:
        if name in ("t", "time"):
            return self.t
        for d in (self.outputs, self.inputs, self.states):
            if name in d:
                return d[name]
        raise KeyError(f"no signal '{name}'; have {', '.join(self.columns()[1:])}")

    def columns(self) -> list[str]:
        """The signals in table order: ``t`` (the time; :meth:`to_csv` names it ``time``),
        inputs, outputs, states not already outputs."""
        extra = [n for n in self.states if n not in self.outputs]
        return ["t", *self.inputs, *self.outputs, *extra]

    def energies(self) -> dict:
        """Energy (J) of every power and loss output over the run: ``{name: integral}``.

        A switched (PWM) run integrates them as quadratures in its own steps, exact at
        every switching instant (``info["energies"]``); other runs by the trapezoid rule
        over the kept samples (keep them dense enough: ``dt_out``), each sample interval
        holding an input's step integrated on both sides of it
        (``info["step_corrections"]``, :func:`step_corrections`).
        """
        if "energies" in self.info:
            return dict(self.info["energies"])
        names = [n for n, k in self.kinds.items() if k in ("loss", "power")]
        at_steps = self.info.get("step_corrections", {})  # the trapezoid across an input's step
        return {n: float(np.trapezoid(self.outputs[n], self.t)) + at_steps.get(n, 0.0) for n in names}

    def with_instantaneous(self) -> SimResult:
        """This result with the instantaneous samples of a switched run's power and loss
        outputs added as columns ``<name>_inst`` (its ``<name>`` columns hold the
        carrier-period averages); the result itself when it has none."""
        inst = self.info.get("instantaneous") or {}
        if not inst:
            return self
        outputs = dict(self.outputs) | {f"{k}_inst": v for k, v in inst.items()}
        units = dict(self.unit_table) | {f"{k}_inst": self.unit_table.get(k, "") for k in inst}
        kinds = dict(self.kinds) | {f"{k}_inst": "aux" for k in inst}
        return SimResult(t=self.t, inputs=self.inputs, outputs=outputs, states=self.states, info=self.info,
                         unit_table=units, kinds=kinds, roles=self.roles)

    def final(self) -> dict:
        """Last value of every output."""
        return {k: float(v[-1]) for k, v in self.outputs.items()}

    def table(self) -> np.ndarray:
        """Samples x (time, then every signal of :meth:`columns`), SI."""
        cols = self.columns()[1:]
        return np.column_stack([self.t] + [self[c] for c in cols])

    def to_pandas(self):
        """The time series as a :class:`pandas.DataFrame` indexed by ``time`` (s), one
        column per signal (SI; units in ``frame.attrs["units"]``). Needs pandas."""
        from .._util._notebook import data_frame

        cols = self.columns()[1:]
        return data_frame({"time": self.t, **{c: self[c] for c in cols}}, index="time", units=self.units())

    def plot(self, signals=None, path: str | Path | None = None, title: str = ""):
        """Plot against time: by default command and rod position, rod velocity, current,
        voltage; with ``signals`` (names) one panel per unit, lengths in mm.

        Parameters
        ----------
        signals : sequence of str, optional
            The signals to draw (``["x_rod", "F_in"]``).
        path : str or Path, optional
            A PNG file to write; without it the figure is returned.
        title : str
            Figure title (default the variants).

        Returns
        -------
        matplotlib.figure.Figure or Path
        """
        from ..plots._base import plot_simulation

        return plot_simulation(self, path, title, signals=signals)

    def _facts(self) -> dict:
        t_end = f"{self.t[-1]:g} s" if len(self.t) else None
        return {"t_end": t_end, "samples": len(self.t), "signals": len(self.columns()) - 1,
                "solver": self.info.get("solver"), "status": self.info.get("status"),
                "wall_time": f"{self.info['wall_time']:.3g} s" if "wall_time" in self.info else None}

    def __repr__(self) -> str:
        from .._util._notebook import short_repr

        return short_repr("SimResult", self._facts())

    def _repr_html_(self) -> str:
        from .._util._notebook import html_summary

        shown = {"rod_position", "rod_velocity", "motor_current", "screw_force"}
        final = {k: f"{v:.6g} {self.unit_table.get(k, '')}" for k, v in self.final().items()
                 if shown & set(self.roles.get(k, ()))}
        return html_summary("SimResult", {**self._facts(), **{f"final {k}": v for k, v in final.items()}})

    def to_csv(self, path: str | Path) -> Path:
        """Write the time series as CSV (the file layout, docs: simulate); atomic.

        The layout of MATLAB's Simulation Data Inspector: a header row ``time`` then one
        column per signal (:meth:`columns`), a second row ``Unit:`` followed by each
        signal's SI unit (:meth:`units`), then one row per sample, every number with 17
        significant digits (a float written and read back is the same float).
        :func:`~ema_casadi.signals.parse_signal` reads it back (``run.csv:x_rod``).

        Parameters
        ----------
        path : str or Path
            The CSV file.
        """
        from ..signals import write_series

        cols = self.columns()[1:]
        units = self.units()
        return write_series(path, ["time", *cols], ["s", *(units[c] for c in cols)], self.table())

    def to_mat(self, path: str | Path, name: str = "ema_sim") -> Path:
        """Write the time series as a MATLAB struct (the file layout, docs: simulate); atomic.

        One struct variable ``name`` with the field ``time`` (s), one field per signal
        (:meth:`columns`, SI, column vectors) and ``units`` (a struct: signal name ->
        unit text, ``time`` included); ``load('run.mat'); ema_sim.x_rod``.

        Parameters
        ----------
        path : str or Path
            The ``.mat`` file.
        name : str
            Name of the struct variable in the file.
        """
        from scipy.io import savemat

        cols = self.columns()[1:]
        units = self.units()
        run = {"time": np.asarray(self.t, float), **{c: np.asarray(self[c], float) for c in cols},
               "units": {"time": "s", **{c: units[c] for c in cols}}}

        def write(tmp):
            with open(tmp, "wb") as fh:
                savemat(fh, {name: run}, oned_as="column")

        return write_with(path, write, suffix=".mat")

    def to_npz(self, path: str | Path) -> Path:
        """Write all signals as named arrays (plus ``t``); atomic.

        Parameters
        ----------
        path : str or Path
            The ``.npz`` file.
        """
        return write_with(path, lambda tmp: np.savez(tmp, t=self.t, **{c: self[c] for c in self.columns()[1:]}),
                          suffix=".npz")

    def units(self) -> dict:
        """SI unit of every column, from the model's one unit table."""
        return {c: self.unit_table.get(c, "") for c in self.columns()}


def step_response_metrics(t: np.ndarray, y: np.ndarray, band: float = 0.02) -> dict:
    """Metrics of a normalised step response y(t) (final value 1, step at t = 0).

    Parameters
    ----------
    t : ndarray
        Times (s) from the step.
    y : ndarray
        The response divided by its final value (-).
    band : float
        Settling band as a fraction of the final value (-).

    Returns
    -------
    dict
        ``rise_time_s`` (10-90 %, inf if 90 % is never reached), ``overshoot``
        (fraction) and ``settling_time_s`` (last entry into 1 +- band; 0 if never
        outside, inf if still outside at the end).
    """
    i10, i90 = np.argmax(y >= 0.1), np.argmax(y >= 0.9)
    outside = np.nonzero(np.abs(y - 1) > band)[0]
    if not len(outside):
        settle = 0.0
    elif outside[-1] == len(y) - 1:
        settle = math.inf
    else:
        settle = float(t[outside[-1] + 1])
    return {
        "rise_time_s": float(t[i90] - t[i10]) if y.max() >= 0.9 else math.inf,
        "overshoot": float(max(0.0, y.max() - 1)),
        "settling_time_s": settle,
    }


def hunting_metrics(t: np.ndarray, e: np.ndarray, t_from: float = 0.0) -> dict:
    """Limit cycle ("hunting") of an error signal e(t) over t >= t_from.

    Parameters
    ----------
    t : ndarray
        Times (s).
    e : ndarray
        The error, e.g. x_rod - x_cmd (m).
    t_from : float
        Start of the window (s): the cycle should be established by then.

    Returns
    -------
    dict
        ``amplitude`` (half the peak-to-peak of e, in e's unit), ``frequency`` (Hz:
        upward passes through the middle counted with a hysteresis of half the
        amplitude; None with fewer than two full cycles) and ``mean_error``.
    """
    sel = t >= t_from
    t, e = t[sel], e[sel]
    amp = 0.5 * float(np.ptp(e))
    mid, band = 0.5 * (e.max() + e.min()), 0.5 * amp
    ups, low = [], False  # upward passes through mid + band/2 after being below mid - band/2
    for ti, ei in zip(t, e, strict=True):
        if ei < mid - 0.5 * band:
            low = True
        elif low and ei > mid + 0.5 * band:
            ups.append(ti)
            low = False
    freq = (len(ups) - 1) / (ups[-1] - ups[0]) if len(ups) >= 3 and amp > 0 else None
    return {"amplitude": amp, "frequency": freq, "mean_error": float(e.mean())}


# ---------------------------------------------------------------------------------


#: The last tenth each label reported, when stderr is not a terminal (a log).
_logged: dict = {}


def progress_bar(frac: float, enabled: bool, label: str = "simulate", note: str = ""):
    """Show progress on stderr: on a terminal a one-line bar redrawn in place (a newline
    at 1); into a file or a pipe (a log) whole lines only, one per tenth done, never a
    carriage return.

    Parameters
    ----------
    frac : float
        Fraction done, 0..1.
    enabled : bool
        Draw at all (callers pass their ``progress`` flag).
    label : str
        Text before the bar.
    note : str
        Text after the percentage (counts, an ETA).
    """
    if not enabled:
        return
    n = int(30 * frac)
    text = f"{label} [{'#' * n}{'.' * (30 - n)}] {100 * frac:5.1f}%{' ' + note if note else ''}"
    if _is_terminal(sys.stderr):
        sys.stderr.write(f"\r{text.ljust(len(label) + 88)}" + ("\n" if frac >= 1 else ""))
    else:
        tenth = int(10 * frac + 1e-9)
        if frac > 0 and tenth == _logged.get(label):
            return
        _logged[label] = None if frac >= 1 else tenth
        sys.stderr.write(text.rstrip() + "\n")
    sys.stderr.flush()


def _is_terminal(stream) -> bool:
    try:
        return stream.isatty()
    except (AttributeError, ValueError):
        return False


def _result(model, sig, t, X, Y, info):
    inputs = {n: s(t) for n, s in sig.items()}
    outputs = {n: Y[i] for i, n in enumerate(model.outputs)}
    states = {n: X[i] for i, n in enumerate(model.states)}
    kinds = {n: o.kind for n, o in model.output_info.items()}
    roles = {n: o.roles for n, o in model.output_info.items() if o.roles}
    return SimResult(t=t, inputs=inputs, outputs=outputs, states=states, info=info, unit_table=model.units, kinds=kinds,
                     roles=roles)


def step_corrections(model, sig: dict, pv, res: SimResult, zoh: bool = False) -> SimResult:
    """``res`` with ``info["step_corrections"]``: per power and loss output, what the
    trapezoid rule misses (J) in the sample intervals that hold a step of an input.

    An output jumps where an input steps (a fault switched on: the bridge off, the DC
    link lost), and its samples show the value after the step: the trapezoid over the
    interval before it ran to the wrong side (0.18 J of 8 J at a free-run's step, 1e-4 s
    samples). Here each such interval is integrated as two trapezoids, to the output's
    left limit at the step and from its right limit (the states interpolated there, the
    inputs just before and at the step). Continuous-ECU runs (with ``zoh`` the held
    values are not kept: none); a table's rows (noise sequences) are left as they are.

    Parameters
    ----------
    model : Model
        The model run.
    sig : dict
        Input name -> Signal of the run.
    pv : array
        The run's parameter vector.
    res : SimResult
        The run.
    zoh : bool
        The sampled ECU ran.
    """
    names = [n for n, k in res.kinds.items() if k in ("loss", "power")]
    t = res.t
    # steps, ramps, starts; not a table's rows (noise sequences: many, and small)
    steps = sorted({b for s in sig.values() for term in s.terms if term.kind != "table" for b in term.breakpoints()
                    if t[0] < b <= t[-1]})
    if zoh or not names or not steps or model.switched:
        return res
    X = np.array([res.states[n] for n in model.states])
    rows = [model.yindex(n) for n in names]
    out = dict.fromkeys(names, 0.0)
    for tb in steps:
        k = int(np.searchsorted(t, tb))  # t[k-1] < tb <= t[k]
        x = np.array([np.interp(tb, t, xi) for xi in X])
        before = 1e-9 * max(abs(tb), 1.0)
        left, right = ([float(sig[n](np.array([tb + d]))[0]) if n in sig else 0.0 for n in model.inputs]
                       for d in (-before, 0.0))
        y_l, y_r = (np.asarray(model.f(x, u, pv)[1]).ravel()[rows] for u in (left, right))
        if np.allclose(y_l, y_r, rtol=0, atol=0):
            continue
        h1, h2 = tb - t[k - 1], t[k] - tb
        for j, n in enumerate(names):
            y0, y1 = res.outputs[n][k - 1], res.outputs[n][k]
            out[n] += (y0 + y_l[j]) / 2 * h1 + (y_r[j] + y1) / 2 * h2 - (y0 + y1) / 2 * (h1 + h2)
    res.info["step_corrections"] = {n: v for n, v in out.items() if v}
    return res
