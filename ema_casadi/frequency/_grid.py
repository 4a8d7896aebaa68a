"""Frequency grids for the linear analyses, and the refusal of grids the machine
cannot hold (the reliability contract, docs: reliability: work refused up front with the estimate)."""

from __future__ import annotations

import math

import numpy as np

from .._util._checks import describe, integer, number
from ..linearisation import LinearizationError

__all__ = ["frequency_grid", "check_points", "MAX_FREQ_POINTS", "SECONDS_PER_FREQ_POINT"]

#: Most frequencies one response may have (0.2 GB for the 9-state reference model; a
#: point costs about 4.3 us, measured on a 2-core x86-64 machine).
MAX_FREQ_POINTS = 100_000
#: Measured cost of one frequency of :func:`freqresp` on the reference model (s).
SECONDS_PER_FREQ_POINT = 4.3e-6


def frequency_grid(f_min: float = 1e-2, f_max: float = 1e5, per_decade: int = 200) -> np.ndarray:
    """Log-spaced frequencies (Hz).

    Parameters
    ----------
    f_min, f_max : float
        The ends (Hz), 0 < f_min < f_max.
    per_decade : int
        Points per decade.
    """
    f_min = number(f_min, "f_min", LinearizationError, unit="Hz", positive=True)
    f_max = number(f_max, "f_max", LinearizationError, unit="Hz", positive=True)
    per_decade = integer(per_decade, "per_decade", LinearizationError, minimum=1)
    if not (0 < f_min < f_max):
        raise LinearizationError(f"frequency range must satisfy 0 < f_min < f_max, got {f_min}, {f_max}")
    decades = math.log10(f_max) - math.log10(f_min)
    if per_decade * decades > MAX_FREQ_POINTS:
        check_points(per_decade * decades, "f_min/f_max/per_decade")
    n = max(2, int(math.ceil(per_decade * decades)) + 1)
    return np.logspace(math.log10(f_min), math.log10(f_max), n)


def check_points(n: int, label: str, nx: int = 9, error: type = LinearizationError) -> None:
    """Refuse a frequency grid above :data:`MAX_FREQ_POINTS` with its estimate.

    Parameters
    ----------
    n : int
        Number of frequencies.
    label : str
        The argument or flag named in the message.
    nx : int
        States of the system (sizes the estimate).
    error : type
        The exception raised.
    """
    if n > MAX_FREQ_POINTS:
        size = 16.0 * n * nx * (nx + 1)
        raise error(f"{label}: {n:.3g} frequencies, above the limit of {MAX_FREQ_POINTS} (MAX_FREQ_POINTS); "
                    f"the response of a {nx}-state model would hold {size / 1e9:.3g} GB and take about "
                    f"{n * SECONDS_PER_FREQ_POINT:.3g} s at {SECONDS_PER_FREQ_POINT * 1e6:g} us per frequency")


def _frequencies(f_hz, label: str, nx: int) -> np.ndarray:
    """``f_hz`` as a 1-D array of positive finite frequencies (Hz), at most
    :data:`MAX_FREQ_POINTS`."""
    try:
        f = np.atleast_1d(np.asarray(f_hz, float))
    except (TypeError, ValueError):
        raise LinearizationError(f"{label}: expected frequencies in Hz, got {describe(f_hz)}") from None
    if f.ndim != 1 or f.size == 0:
        raise LinearizationError(f"{label}: expected a 1-D sequence of frequencies in Hz, got shape {f.shape}")
    check_points(f.size, label, nx)
    if not (np.all(np.isfinite(f)) and np.all(f > 0)):
        bad = f[~(np.isfinite(f) & (f > 0))][0]
        raise LinearizationError(f"{label}: frequencies must be positive and finite (Hz), got {bad}")
    return f
