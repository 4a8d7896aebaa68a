"""The result of an optimal move: the optimum on the shooting grid, the command profile,
its replay in the full model, the CSV files and the figure."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..signals import Signal

__all__ = ["OptimalMove", "STAIR"]

#: Width (s) of the step between two intervals of a piecewise-constant command in its CSV
#: table (linear interpolation between the two rows): far below the ECU's sample periods.
STAIR = 1e-7


@dataclass
class OptimalMove:
    """An optimal move (:func:`~ema_casadi.optimal.optimal_move`).

    Attributes
    ----------
    objective, through : str
        What was minimised (``time``, ``energy``, ``heat``) and the control (``drive``:
        the motor voltages; ``ecu``: the rod command through the cascade).
    move, load, start : float
        The move (m), the constant load (N, + pushes the rod in), the start position (m).
    duration : float
        The move's duration (s): the minimum time, or the one given.
    cost : float
        The objective's value: s, or J (energy from the DC link, heat in the winding).
    t : ndarray
        The shooting nodes (s).
    states, outputs : dict
        Name -> values at the nodes (SI) on the smooth variant.
    controls : dict
        Control name -> its value on each interval (SI).
    limits : dict
        Rating name -> its limit (SI).
    margins : dict
        Rating name -> 1 - peak/limit at the nodes (0 on the limit; for a lower limit, the
        smallest value less the limit).
    binding : list of str
        The ratings the optimum sits on (margin below 1e-3).
    ipopt : dict
        ``solver``, ``status``, ``iterations``, ``solve_time_s``, ``setup_time_s``, ``intervals``, ``substeps``
        (RK4 substeps per interval: the shooting's, or what it would take where it collocates), ``method``
        (the transcription: ``shooting``, ``collocation``; ``shaping`` through the ECU), ``solver_warnings``
        (CasADi's warnings during the solve, kept off stderr: NaN trial points).
    variants : dict
        The smooth variants the problem was solved on.
    rod, command : str
        The rod's mechanical position (the signal the stroke limits) and the command input.
    rating_signals : dict
        Rating name -> the signals it limits.
    ecu_step : dict
        The ECU's own step of the same size on the same model: ``settling_time_s`` (2 %
        band), ``t``, rod position.
    replay : SimResult or None
        The command profile replayed in the full model (:meth:`replayed`).
    replay_check : dict
        Per rating, its peak in the replay, whether it held (``within``) and the ECU step's
        peak beside it (``ecu_step_peak``).
    profile : tuple or None
        A shaped command's own table rows (t, x_cmd) (``through = "ecu"``), else None.
    """

    objective: str
    through: str
    move: float
    load: float
    start: float
    duration: float
    cost: float
    t: np.ndarray
    states: dict
    outputs: dict
    controls: dict
    limits: dict
    margins: dict
    binding: list
    ipopt: dict
    variants: dict
    rod: str
    command: str
    rating_signals: dict = field(default_factory=dict)
    profile: tuple | None = None
    ecu_step: dict = field(default_factory=dict)
    replay: object = None
    replay_check: dict = field(default_factory=dict)

    def __repr__(self):
        return (f"OptimalMove({self.objective}, through {self.through}: {self.move * 1e3:g} mm under "
                f"{self.load / 1e3:g} kN in {self.duration:.5g} s, cost {self.cost:.5g}, "
                f"binding {', '.join(self.binding) or 'none'}, {self.ipopt.get('solver', 'IPOPT')} "
                f"{self.ipopt['status']})")

    @property
    def command_profile(self) -> tuple[np.ndarray, np.ndarray]:
        """(t, x_cmd): the rod command to send to the ECU (s, m) as table rows: the
        optimal command's steps (``through = "ecu"``: the start at t = 0, each
        interval's value from ``STAIR`` after its start to its end) or the optimal rod
        trajectory (``through = "drive"``)."""
        if self.profile is not None:  # a shaped command's own table rows
            return tuple(np.asarray(v, float).copy() for v in self.profile)
        if self.through == "ecu":
            # at the start at t = 0 (where a replay trims), then each interval's value from STAIR after its start
            v = next(iter(self.controls.values()))
            t = np.column_stack([self.t[:-1] + STAIR, self.t[1:]]).ravel()
            return np.append(0.0, t), np.append(self.start, np.repeat(v, 2))
        return self.t.copy(), np.asarray(self.states.get(self.rod, self.outputs.get(self.rod)), float).copy()

    def command_signal(self) -> Signal:
        """The command profile as a :class:`~ema_casadi.signals.Signal` (held after the move)."""
        return Signal.table(*self.command_profile)

    def as_dict(self) -> dict:
        """The result as JSON can hold it (the CLI's ``--json``)."""
        out = {k: getattr(self, k) for k in ("objective", "through", "move", "load", "start", "duration", "cost",
                                              "limits", "margins", "binding", "ipopt", "variants")}
        out["ecu_step_settling_time_s"] = self.ecu_step.get("settling_time_s")
        out["replay"] = self.replay_check or None
        return out

    def series(self) -> tuple[list, list, np.ndarray]:
        """(names, units, data) of the shooting nodes: time, states, outputs, controls (the last node holds
        the last interval's control)."""
        names = ["time", *self.states, *self.outputs, *self.controls]
        data = [self.t, *self.states.values(), *self.outputs.values(),
                *(np.append(v, v[-1]) for v in self.controls.values())]
        return names, self.units(names), np.column_stack(data)

    def units(self, names) -> list:
        """SI units of the named columns (``time``: s).

        Parameters
        ----------
        names : list of str
            Column names: ``time``, states, outputs, controls.
        """
        table = self._units
        return ["s" if n == "time" else table.get(n, "") for n in names]

    _units: dict = field(default_factory=dict, repr=False)

    def plot(self, path=None):
        """The figure: position, speed, current, voltage (and temperature) against their
        limits, the optimum, its replay and the ECU's own step; a matplotlib Figure
        (written to ``path`` if given).

        Parameters
        ----------
        path : str or Path, optional
            A .png file to write.
        """
        from ..plots._optimal import plot_optimal_move

        return plot_optimal_move(self, path)
