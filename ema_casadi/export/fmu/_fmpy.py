"""Running a model-exchange FMU in FMPy with a time-varying input.

A model-exchange FMU computes its derivatives from the inputs it was given last:
following a time-varying input is the importer's job, and Simulink's FMU block, Dymola
and OpenModelica set the inputs at every right-hand-side evaluation. FMPy's
``simulate_fmu`` sets continuous inputs only at its output points and inside CVode's
root function, so between them CVode integrates a staircase whose steps are its own
(docs: exports: on the reference scenario 0.15-21 um off at rtol 1e-6 depending on the
input table's spacing, and at rtol 1e-8 the jumps at every step stop CVode). :func:`inputs_at_every_call` makes FMPy's
CVode set them at every right-hand-side call as well.
"""

from __future__ import annotations

import contextlib
import threading

from .._errors import ExportError

__all__ = ["inputs_at_every_call"]

_LOCK = threading.Lock()  # the patch replaces a module attribute of FMPy


@contextlib.contextmanager
def inputs_at_every_call():
    """Within the ``with`` block, FMPy's CVode sets the inputs at every right-hand-side call.

    ``fmpy.simulate_fmu(..., input=table)`` called inside the block then integrates the
    input table's linear interpolation itself, not a staircase of it. FMPy's CVode
    solver class is replaced for the duration of the block (one block at a time per
    process).

    Yields
    ------
    list
        The CVode solvers made inside the block (one per ``simulate_fmu`` call): a
        check that the patch took effect.

    Examples
    --------
    >>> with inputs_at_every_call():                                    # doctest: +SKIP
    ...     res = fmpy.simulate_fmu("ema_me.fmu", stop_time=1.0, input=table,
    ...                             relative_tolerance=1e-8, output_interval=1e-3)
    """
    try:
        import fmpy.sundials
    except ImportError as exc:  # an optional dependency
        raise ExportError("FMPy is not installed (pip install fmpy)") from exc
    made = []
    base = fmpy.sundials.CVodeSolver

    class EveryCall(base):
        def __init__(self, *args, **kw):
            super().__init__(*args, **kw)
            made.append(self)

        def f(self, t, y, ydot, user_data):
            self.input.apply(t)
            return super().f(t, y, ydot, user_data)

    with _LOCK:
        fmpy.sundials.CVodeSolver = EveryCall
        try:
            yield made
        finally:
            fmpy.sundials.CVodeSolver = base
