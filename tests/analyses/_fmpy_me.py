"""FMPy's CVode on a model-exchange FMU as a time-varying-input importer runs it.

``fmpy.simulate_fmu`` sets continuous inputs of a model-exchange FMU only at its
communication points and inside the root function: between them CVode integrates with
the inputs held from wherever they were last set (a staircase that depends on CVode's
own steps). An importer that integrates a model with a time-varying input (Simulink's
FMU block, Dymola, OpenModelica) evaluates the input at every right-hand-side call;
:func:`inputs_at_every_rhs` makes FMPy's CVode do the same and counts what it did.
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass, field

import numpy as np


@dataclass
class Counts:
    """What the patched solvers did: the solver objects made, and per solver the state
    events (CVode's root returns) and the right-hand-side evaluations."""

    solvers: list = field(default_factory=list)
    events: list = field(default_factory=list)
    rhs: list = field(default_factory=list)


@contextlib.contextmanager
def inputs_at_every_rhs():
    """FMPy's CVode with the continuous inputs set at every right-hand-side evaluation.

    Yields a :class:`Counts` (to check that the patch took effect and to count the
    events located).
    """
    import fmpy.sundials

    base, counts = fmpy.sundials.CVodeSolver, Counts()

    class EveryRhs(base):
        def __init__(self, *args, **kw):
            super().__init__(*args, **kw)
            self.k = len(counts.solvers)
            counts.solvers.append(self)
            counts.events.append(0)
            counts.rhs.append(0)

        def f(self, t, y, ydot, user_data):
            counts.rhs[self.k] += 1
            self.input.apply(t)
            return super().f(t, y, ydot, user_data)

        def step(self, t, t_next):
            state_event, roots, t_ret = super().step(t, t_next)
            counts.events[self.k] += bool(state_event)
            return state_event, roots, t_ret

    fmpy.sundials.CVodeSolver = EveryRhs
    try:
        yield counts
    finally:
        fmpy.sundials.CVodeSolver = base


def on_grid(res, dt=1e-3):
    """The rows of an FMPy result at the multiples of dt (the last row where an event
    recorded a time twice)."""
    k = np.abs(res["time"] / dt - np.round(res["time"] / dt)) < 1e-6
    res = res[k]
    i = np.round(res["time"] / dt).astype(int)
    return res[np.r_[i[1:] != i[:-1], True]]


def step_input(t_end, t_step=0.01, height=1e-3):
    """FMPy's input table of a step of x_cmd (two points at the step time)."""
    return np.array([(0.0, 0.0), (t_step, 0.0), (t_step, height), (t_end, height)],
                    dtype=[("time", float), ("x_cmd", float)])
