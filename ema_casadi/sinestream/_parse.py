"""The grid axes: command-line lists (amplitudes, loads, frequencies) read through
:mod:`ema_casadi.signals`, and the checks every axis passes."""

from __future__ import annotations

import numpy as np

from .._util._checks import describe
from ..signals import SignalError, log_grid, parse_list, parse_range
from ._result import FreqRespError

#: Most points (variants x loads x amplitudes x frequencies) one sine stream may have.
MAX_SINE_STREAM_POINTS = 100_000
#: Most periods one sine stream may simulate in the worst case (points x max_periods).
MAX_SINE_STREAM_PERIODS = 10_000_000
#: Measured wall time of one simulated period of one point on one core (s): CVODES, 64
#: samples per period, reference model, 2-core x86-64 machine (hybrid-friction points
#: through RK4 cost about the same).
SECONDS_PER_PERIOD = 0.01
#: Periods a point typically needs to settle (measured over the Fig. 14 grid: 3-6).
TYPICAL_PERIODS = 4


def parse_amplitudes(text: str, stroke: float) -> np.ndarray:
    """Read command amplitudes such as ``"0.5%,1%,2mm"``.

    Parameters
    ----------
    text : str
        Comma-separated amplitudes; a bare number is mm, ``%`` is of the stroke.
    stroke : float
        Actuator stroke (m).

    Returns
    -------
    ndarray
        Amplitudes (m).
    """
    try:
        vals = parse_list(text, "length", "mm", stroke)
    except SignalError as exc:
        raise FreqRespError(f"--amplitudes {exc}") from None
    return _as_axis(vals, "--amplitudes", "m")


def parse_loads(text: str) -> np.ndarray:
    """Read constant external forces such as ``"0,10kN,30kN"``.

    Parameters
    ----------
    text : str
        Comma-separated forces; a bare number is N (positive pushes the rod in).

    Returns
    -------
    ndarray
        Loads (N).
    """
    try:
        vals = parse_list(text, "force", "N")
    except SignalError as exc:
        raise FreqRespError(f"--loads {exc}") from None
    return _as_axis(vals, "--loads", "N", positive=False)


def parse_freqs(text: str) -> np.ndarray:
    """Read frequencies: a list ``"0.1,1,5"`` or a log-spaced range ``"0.1-30:40"``.

    Parameters
    ----------
    text : str
        Comma-separated frequencies (Hz, optional ``Hz`` suffix), or ``F0-F1:N`` for N
        log-spaced points from F0 to F1 (Hz).

    Returns
    -------
    ndarray
        Frequencies (Hz).
    """
    try:
        rng = parse_range(text, "frequency", "Hz")
        if rng is not None:
            f0, f1, n = rng
            if not (0 < f0 < f1) or n < 2:
                raise FreqRespError(f"--freqs {text}: expected F0-F1:N with 0 < F0 < F1 and N >= 2")
            if n > MAX_SINE_STREAM_POINTS:
                raise FreqRespError(f"--freqs {text}: {n:.3g} frequencies, above the limit of "
                                    f"{MAX_SINE_STREAM_POINTS} points (MAX_SINE_STREAM_POINTS); about "
                                    f"{_hours(n * TYPICAL_PERIODS * SECONDS_PER_PERIOD)} on one core at "
                                    f"{SECONDS_PER_PERIOD * 1e3:g} ms per period")
            return log_grid(text, "frequency", "Hz", "--freqs", FreqRespError, MAX_SINE_STREAM_POINTS)
        vals = parse_list(text, "frequency", "Hz")
    except SignalError as exc:
        raise FreqRespError(f"--freqs {exc}; expected a list '0.1,1,5' or a range '0.1-30:40'") from None
    return _as_axis(vals, "--freqs", "Hz")


def _as_axis(values, name, unit, positive=True) -> np.ndarray:
    """``values`` as a 1-D float axis, finite and (unless ``positive`` is False) > 0."""
    if isinstance(values, (str, bytes)):
        raise FreqRespError(f"{name}: expected numbers ({unit}), got {describe(values)}; "
                            "parse_amplitudes/parse_freqs/parse_loads read text")
    try:
        a = np.atleast_1d(np.asarray(values, dtype=float))
    except (TypeError, ValueError):
        raise FreqRespError(f"{name}: expected one or more numbers ({unit}), got {describe(values)}") from None
    if a.ndim != 1 or a.size == 0:
        raise FreqRespError(f"{name}: expected one or more numbers ({unit})")
    if not np.all(np.isfinite(a)):
        raise FreqRespError(f"{name}: non-finite value")
    if positive and np.any(a <= 0):
        raise FreqRespError(f"{name}: values must be positive ({unit}), got {a[a <= 0][0]:g}")
    return a


def check_grid(counts: dict, max_periods: int, jobs: int = 1, periods_label: str = "max_periods") -> None:
    """Refuse a sine-stream grid above :data:`MAX_SINE_STREAM_POINTS` points or
    :data:`MAX_SINE_STREAM_PERIODS` worst-case periods, with the estimate.

    Parameters
    ----------
    counts : dict
        Axis label (the argument or flag to name) -> number of values.
    max_periods : int
        Periods after which a point stops (the worst case per point).
    jobs : int
        Worker threads (divides the time estimate).
    periods_label : str
        The name of ``max_periods`` in the message (the argument or flag).
    """
    points = int(np.prod([max(1, int(n)) for n in counts.values()], dtype=float))
    axes = " x ".join(f"{label} {n}" for label, n in counts.items())
    names = "/".join(counts)
    if points > MAX_SINE_STREAM_POINTS:
        raise FreqRespError(f"{names}: {axes} = {points:.3g} points, above the limit of {MAX_SINE_STREAM_POINTS} "
                            f"(MAX_SINE_STREAM_POINTS); about {_hours(points * TYPICAL_PERIODS * SECONDS_PER_PERIOD)}"
                            f" on one core at {SECONDS_PER_PERIOD * 1e3:g} ms per period")
    worst = points * max_periods
    if worst > MAX_SINE_STREAM_PERIODS:
        raise FreqRespError(f"{names} with {periods_label} {max_periods}: up to {worst:.3g} periods, above the "
                            f"limit of {MAX_SINE_STREAM_PERIODS:.0e} (MAX_SINE_STREAM_PERIODS); up to "
                            f"{_hours(worst * SECONDS_PER_PERIOD / max(1, jobs))} on {max(1, jobs)} core(s) at "
                            f"{SECONDS_PER_PERIOD * 1e3:g} ms per period")


def _hours(s: float) -> str:
    for unit, size in (("days", 86400), ("h", 3600), ("min", 60)):
        if s >= size:
            return f"{s / size:.3g} {unit}"
    return f"{s:.3g} s"
