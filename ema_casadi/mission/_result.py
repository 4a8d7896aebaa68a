"""What a mission run returns: temperatures, losses and energies per part and segment,
peaks against the limits, the heat balance; CSV, JSON-ready summary, figure."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from ..model.components import node_outflow
from ._profile import Mission

__all__ = ["MissionResult"]


def _cumtrapz(t: np.ndarray, y: np.ndarray) -> np.ndarray:
    out = np.zeros_like(y, dtype=float)
    out[1:] = np.cumsum(0.5 * (y[1:] + y[:-1]) * np.diff(t))
    return out


@dataclass
class MissionResult:
    """A mission run: the kept samples and what a mission reports.

    Attributes
    ----------
    mission : Mission
        The mission run.
    t : ndarray
        Sample times (s), every ``info["dt_out"]``.
    series : dict
        Signal name -> samples: the temperature states and ``T_amb`` (degC), every loss
        and the heat flows (W), ``E_th`` (J), ``x_cmd``, ``x_rod`` (m), ``f_ext`` (N), ...
    units : dict
        Signal name -> unit.
    losses : tuple of str
        The model's loss outputs.
    owners : dict
        Loss -> the part family that causes it (``motor``, ``inverter``, ``screw``, ...).
    nodes : dict
        Temperature state -> thermal node (``T_w`` -> ``winding``).
    heat_of : dict
        Loss -> the thermal node it heats.
    P : SimpleNamespace
        The parameter values of the run (SI, by flat name).
    capacity : dict
        Temperature state -> the heat capacity of its node (J/K), as the thermal part
        declares it.
    info : dict
        ``dt``, ``dt_out`` (s), ``steps``, ``wall_time``, ``compile_time`` (s),
        ``mode_switches``, ``blocks``, ``variants``, ``model``.
    names : dict
        Role -> the signal of the model that plays it (``load`` -> ``f_ext``): the kept
        signals the report reads by role (:data:`~ema_casadi.mission.KEPT`).
    """

    mission: Mission
    t: np.ndarray
    series: dict
    units: dict
    losses: tuple
    owners: dict
    nodes: dict
    heat_of: dict
    P: SimpleNamespace
    capacity: dict = field(default_factory=dict)
    info: dict = field(default_factory=dict)
    names: dict = field(default_factory=dict)
    _cum: dict = field(default_factory=dict, repr=False)

    def __getitem__(self, name: str) -> np.ndarray:
        if name in ("t", "time"):
            return self.t
        return self.series[name]

    # -- integrals ---------------------------------------------------------------
    def energy(self, name: str, t0: float | None = None, t1: float | None = None) -> float:
        """Integral of a sampled power signal over [t0, t1] (J), trapezoidal on the kept
        samples (every ``dt_out``). Smooth signals (heat flows, P_amb) integrate to
        ~1e-6; losses that chatter with the stick-slip or spike in a full-stroke move do
        not (see :meth:`energies`).

        Parameters
        ----------
        name : str
            A power signal (W): a loss, ``P_dc``, ``P_load``, ``P_amb``, ``P_heat_*``.
        t0, t1 : float, optional
            Interval (s); default the whole mission.
        """
        if name not in self._cum:
            self._cum[name] = _cumtrapz(self.t, self.series[name])
        c = self._cum[name]
        a = self.t[0] if t0 is None else t0
        b = self.t[-1] if t1 is None else t1
        return float(np.interp(b, self.t, c) - np.interp(a, self.t, c))

    def node_heat(self, state: str, t0: float | None = None, t1: float | None = None) -> float:
        """Heat that entered a thermal node over [t0, t1] (J), from its temperature:
        C_th (T(t1) - T(t0)) + the integral of what it passed on to its neighbours and
        the ambient. The temperature integrates every loss at every RK4 stage, and the
        flows are smooth, so this is exact to the integration (unlike a sampled loss).

        Parameters
        ----------
        state : str
            The node's temperature state (``T_w``, ``T_h``, ``T_s``, ``T_inv``).
        t0, t1 : float, optional
            Interval (s); default the whole mission.
        """
        key = node_outflow(self.nodes[state])  # kept by the run, as the thermal part provides it
        a = self.t[0] if t0 is None else t0
        b = self.t[-1] if t1 is None else t1
        T = self.series[state]
        C = self.capacity[state]
        return float(C * (np.interp(b, self.t, T) - np.interp(a, self.t, T)) + self.energy(key, a, b))

    def load_work(self, t0: float | None = None, t1: float | None = None) -> float:
        """Work done on the load over [t0, t1] (J): the integral of f_ext dx_rod on the
        kept samples (the load and the rod position are smooth where the rod velocity,
        and so a sampled f_ext v_rod, chatters with the stick-slip).

        Parameters
        ----------
        t0, t1 : float, optional
            Interval (s); default the whole mission.
        """
        if "W_load" not in self._cum:
            f, x = self.series[self.names["load"]], self.series["x_mech"]
            self._cum["W_load"] = np.concatenate([[0.0], np.cumsum(0.5 * (f[1:] + f[:-1]) * np.diff(x))])
        c = self._cum["W_load"]
        a = self.t[0] if t0 is None else t0
        b = self.t[-1] if t1 is None else t1
        return float(np.interp(b, self.t, c) - np.interp(a, self.t, c))

    def _bounds(self):
        starts = self.mission.starts
        ends = starts + np.array([s.duration for s in self.mission.segments])
        return list(zip(starts, ends, strict=True))

    def _energies(self, a: float, b: float) -> dict:
        raw = {n: self.energy(n, a, b) for n in self.losses}
        state_of = {node: n for n, node in self.nodes.items()}
        heat = {node: self.node_heat(n, a, b) for n, node in self.nodes.items()}
        out = {}
        for n in self.losses:
            group = [m for m in self.losses if self.heat_of.get(m) == self.heat_of.get(n)]
            total = sum(raw[m] for m in group)
            node_heat = heat[self.heat_of[n]] if self.heat_of.get(n) in state_of else raw[n]
            out[n] = node_heat * raw[n] / total if total > 0 else node_heat / len(group)
        out.update({f"Q_{node}": q for node, q in heat.items()})
        name = self.names
        out[name["load_power"]] = work = self.load_work(a, b)
        E = self.series[name["stored_energy"]]
        out[name["electrical_power"]] = (float(np.interp(b, self.t, E) - np.interp(a, self.t, E)) + sum(heat.values())
                                         + work)
        out[name["ambient_heat"]] = self.energy(name["ambient_heat"], a, b)
        return out

    def energies(self) -> dict:
        """Energy per segment and in total (J). Keys ``"1. <name>"``, ... and ``"total"``;
        in each: every loss; ``Q_<node>``, the heat into each thermal node (exact, from
        its temperature: :meth:`node_heat`); ``P_load``, the work on the load;
        ``P_dc``, the electrical input = change of the stored energy + the heat of all
        nodes + the work on the load (the model's energy balance); ``P_amb``, the heat
        to the ambient.

        A node's heat is split among the losses that feed it (the screw node's screw-nut,
        contact, friction and viscous losses; the inverter's conduction and switching)
        in proportion to their sampled integrals; a node fed by one loss (copper ->
        winding, iron -> housing) gives that loss exactly."""
        out = {f"{k}. {seg.name}": self._energies(a, b)
               for k, ((a, b), seg) in enumerate(zip(self._bounds(), self.mission.segments, strict=True), 1)}
        rows = list(out.values())
        out["total"] = {n: sum(r[n] for r in rows) for n in rows[0]}  # the split adds up over segments
        return out

    def by_part(self, energies: dict) -> dict:
        """Losses of one :meth:`energies` row summed per part family (J).

        Parameters
        ----------
        energies : dict
            Signal -> energy (J), a row of :meth:`energies`.
        """
        out: dict = {}
        for n in self.losses:
            out[self.owners.get(n, n)] = out.get(self.owners.get(n, n), 0.0) + energies[n]
        return out

    def heat_balance(self) -> dict:
        """Heat conservation over the mission, each side measured on its own: the
        losses integrated from their samples = heat stored (sum of C_th dT, from the
        temperatures) + heat to the ambient. Returns the three (J) and the relative
        residual (the sampling error of the losses, and anything the network loses)."""
        lost = sum(self.energy(n) for n in self.losses)
        E_th = self.series[self.names["thermal_energy"]]
        stored = float(E_th[-1] - E_th[0])
        ambient = self.energy(self.names["ambient_heat"])
        return {"losses_J": lost, "stored_heat_J": stored, "heat_to_ambient_J": ambient,
                "relative_residual": (lost - stored - ambient) / lost if lost else 0.0}

    # -- temperatures --------------------------------------------------------------
    def peaks(self) -> dict:
        """Per temperature state: the peak (degC), when and in which segment, the limit
        of the mission (degC), the margin (K) and whether it holds."""
        out = {}
        labels = [s.name for s in self.mission.segments]
        for n in self.nodes:
            y = self.series[n]
            k = int(np.argmax(y))
            seg = labels[min(int(np.searchsorted(self.mission.starts, self.t[k], side="right")) - 1,
                             len(labels) - 1)]
            limit = self.mission.limits.get(n)
            out[n] = {"node": self.nodes[n], "peak_degC": float(y[k]), "t_peak_s": float(self.t[k]), "segment": seg,
                      "limit_degC": limit, "margin_K": None if limit is None else float(limit - y[k]),
                      "ok": True if limit is None else bool(y[k] <= limit)}
        return out

    def segments(self) -> list[dict]:
        """Per segment: times, cavity temperature, each node's temperature at the end and
        its peak (degC), energies per loss and per part (J), mean losses (W)."""
        rows = []
        for ((a, b), seg), (_label, e) in zip(zip(self._bounds(), self.mission.segments, strict=True),
                                              self.energies().items(), strict=False):
            sel = (self.t >= a - 1e-9) & (self.t <= b + 1e-9)
            T_amb = self.series[self.names["ambient_temperature"]][sel]
            rows.append({
                "name": seg.name, "t_start_s": float(a), "duration_s": float(b - a),
                "T_amb_degC": {"min": float(T_amb.min()), "max": float(T_amb.max())},
                "temperature_end_degC": {n: float(np.interp(b, self.t, self.series[n])) for n in self.nodes},
                "temperature_peak_degC": {n: float(self.series[n][sel].max()) for n in self.nodes},
                "energy_J": e, "energy_by_part_J": self.by_part(e),
                "mean_loss_W": {n: e[n] / (b - a) for n in self.losses},
                "signals": dict(seg.text),
            })
        return rows

    def summary(self) -> dict:
        """Everything a mission reports, JSON-ready (the ``ema mission --json`` result)."""
        totals = self.energies()["total"]
        peaks = self.peaks()
        return {
            "mission": self.mission.name, "source": self.mission.source, "duration_s": self.mission.duration,
            "T_start_degC": self.mission.T_start, "variants": self.info.get("variants"),
            "limits_ok": all(p["ok"] for p in peaks.values()), "peaks": peaks,
            "segments": self.segments(),
            "energy_J": totals, "energy_by_part_J": self.by_part(totals),
            "heat_balance": self.heat_balance(),
            "run": {k: self.info.get(k) for k in ("dt", "dt_out", "steps", "blocks", "mode_switches", "wall_time",
                                                  "compile_time", "model")},
        }

    # -- files ---------------------------------------------------------------------
    def table(self, dt: float = 1.0) -> tuple[list[str], list[str], np.ndarray]:
        """Rows every ``dt`` seconds: names, units and values. Temperatures, positions
        and the load are the values at the row's time; powers are the means over the
        interval up to it (so sum(P dt) is the energy; the first row holds the
        instantaneous values at t = 0).

        Parameters
        ----------
        dt : float
            Row spacing (s), a multiple of the kept samples' spacing.
        """
        t_rows = np.arange(0.0, self.t[-1] + 1e-9, dt)
        if t_rows[-1] < self.t[-1] - 1e-9:
            t_rows = np.append(t_rows, self.t[-1])
        seg = np.clip(np.searchsorted(self.mission.starts, t_rows, side="right"), 1, len(self.mission.segments))
        n = self.names
        names = ["time", "segment", n["ambient_temperature"], *self.nodes, n["command"], n["rod_position"], n["load"],
                 *self.losses, n["electrical_power"], n["ambient_heat"]]
        cols = [t_rows, seg.astype(float)]
        for n in names[2:]:
            y = self.series[n]
            if self.units.get(n) == "W":
                c = _cumtrapz(self.t, y)
                ci = np.interp(t_rows, self.t, c)
                mean = np.empty_like(t_rows)
                mean[0] = y[0]
                mean[1:] = np.diff(ci) / np.diff(t_rows)
                cols.append(mean)
            else:
                cols.append(np.interp(t_rows, self.t, y))
        units = ["s", "", *(self.units.get(n, "") for n in names[2:])]
        return names, units, np.column_stack(cols)

    def to_csv(self, path: str | Path, dt: float = 1.0) -> Path:
        """Write :meth:`table` as CSV (atomically) in the layout of every time series the
        toolkit writes (:func:`~ema_casadi.signals._tables.write_series`): ``time``, one column
        per signal, a ``Unit:`` row (temperatures in degC, SI otherwise), 10 significant
        digits; readable back as a signal (``mission.csv:x_cmd``).

        Parameters
        ----------
        path : str or Path
            The CSV file.
        dt : float
            Row spacing (s).
        """
        from ..signals import write_series

        names, units, data = self.table(dt)
        return write_series(path, names, units, data, fmt="%.10g")

    def plot(self, path: str | Path | None = None, title: str = ""):
        """Temperatures and losses over the mission, segments shaded.

        Parameters
        ----------
        path : str or Path, optional
            A PNG file to write (atomically); without it the figure is returned.
        title : str
            Figure title (default the mission's name).

        Returns
        -------
        matplotlib.figure.Figure or Path
        """
        from ..plots._mission import plot_mission

        return plot_mission(self, path, title)

    def to_pandas(self, dt: float = 1.0):
        """:meth:`table` as a :class:`pandas.DataFrame` indexed by ``time`` (s), units in
        ``frame.attrs["units"]``. Needs pandas.

        Parameters
        ----------
        dt : float
            Row spacing (s).
        """
        from .._util._notebook import data_frame

        names, units, data = self.table(dt)
        return data_frame({n: data[:, i] for i, n in enumerate(names)}, index="time", units=dict(zip(names, units,
                                                                                                   strict=True)))

    def _facts(self) -> dict:
        return {"mission": self.mission.name, "duration": f"{self.t[-1]:g} s", "samples": len(self.t),
                "solver": self.info.get("solver"),
                "wall_time": f"{self.info['wall_time']:.3g} s" if "wall_time" in self.info else None}

    def __repr__(self) -> str:
        from .._util._notebook import short_repr

        return short_repr("MissionResult", self._facts())

    def _repr_html_(self) -> str:
        from .._util._notebook import html_summary

        peaks = {f"peak {n}": f"{float(np.max(self.series[n])):.1f} degC" for n in self.nodes}
        return html_summary("MissionResult", {**self._facts(), **peaks})
