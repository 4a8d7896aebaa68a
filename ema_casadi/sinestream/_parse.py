"""The grid axes: command-line lists (amplitudes, loads, frequencies) read through
:mod:`ema_casadi.signals`, and the checks every axis passes."""

from __future__ import annotations

import numpy as np

from ..signals import SignalError, parse_list, parse_range
from ._result import FreqRespError


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
            return np.geomspace(f0, f1, n)
        vals = parse_list(text, "frequency", "Hz")
    except SignalError as exc:
        raise FreqRespError(f"--freqs {exc}; expected a list '0.1,1,5' or a range '0.1-30:40'") from None
    return _as_axis(vals, "--freqs", "Hz")


def _as_axis(values, name, unit, positive=True) -> np.ndarray:
    """``values`` as a 1-D float axis, finite and (unless ``positive`` is False) > 0."""
    a = np.atleast_1d(np.asarray(values, dtype=float))
    if a.ndim != 1 or a.size == 0:
        raise FreqRespError(f"{name}: expected one or more numbers ({unit})")
    if not np.all(np.isfinite(a)):
        raise FreqRespError(f"{name}: non-finite value")
    if positive and np.any(a <= 0):
        raise FreqRespError(f"{name}: values must be positive ({unit}), got {a[a <= 0][0]:g}")
    return a
