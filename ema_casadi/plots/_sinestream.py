"""Bode plot of a sine-stream result, drawn by :func:`ema_casadi.plots._frequency.plot_bode`."""

from __future__ import annotations

import itertools
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # annotations only: this layer imports no analysis
    from ..sinestream import FreqResponse


def plot_bode(resp: FreqResponse, path: str | Path | None = None, title: str = "", stroke: float | None = None):
    """Bode plot (gain dB, phase deg against Hz), one line per (variant, load, amplitude).

    Points that did not settle are marked with an ``x``. PNG, written atomically.

    Parameters
    ----------
    resp : FreqResponse
        Sine-stream result.
    path : str or Path, optional
        PNG file; without it the figure is returned.
    title : str
        Figure title.
    stroke : float, optional
        Actuator stroke (m); with it, amplitudes are labelled in % of the stroke too.

    Returns
    -------
    matplotlib.figure.Figure or Path
        The figure, or ``path`` when one was given.
    """
    from ._frequency import plot_bode as draw_bode  # matplotlib only when plotting

    axes = ("variant", "load", "amplitude")
    curves = []
    for iv, il, ia in itertools.product(*[range(len(resp.axes[k])) for k in axes]):
        curves.append({
            "freq_hz": resp.axes["frequency"],
            "mag_db": resp.data["gain_db"][iv, il, ia],
            "phase_deg": resp.data["phase_deg"][iv, il, ia],
            "marks": ~resp.data["converged"][iv, il, ia],
            "label": _label(resp, iv, il, ia, stroke),
        })
    return draw_bode(curves, path, title=title, mag_label="x_rod / x_cmd gain (dB)")


def _label(resp: FreqResponse, iv: int, il: int, ia: int, stroke: float | None) -> str:
    """Name a curve by the axes that have several values (the variant if none has)."""
    multi = {k: len(v) > 1 for k, v in resp.axes.items()}
    parts = []
    if multi["variant"] or not (multi["load"] or multi["amplitude"]):
        parts.append(str(resp.axes["variant"][iv]))
    if multi["load"]:
        parts.append(f"{resp.axes['load'][il] / 1e3:g} kN")
    if multi["amplitude"]:
        A = resp.axes["amplitude"][ia]
        parts.append(f"{100 * A / stroke:g} % ({A * 1e3:g} mm)" if stroke else f"{A * 1e3:g} mm")
    return ", ".join(parts)
