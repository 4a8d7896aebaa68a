"""Plots (matplotlib, PNG written atomically). mm and mm/s on axes.

Every plot function builds a :class:`matplotlib.figure.Figure`; given a path it writes
the PNG (and returns the path), without one it returns the figure (closed to pyplot,
so a notebook shows it once, as the cell's value). The Agg backend is selected unless
a backend was chosen (``MPLBACKEND``, a notebook's inline backend).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import matplotlib

if "MPLBACKEND" not in os.environ and "ipykernel" not in sys.modules:
    matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from .._util._files import write_with  # noqa: E402

__all__ = ["plot_simulation", "save", "finish"]


def finish(fig, path: str | Path | None):
    """The end of every plot function: write ``fig`` to ``path`` (PNG, atomically) and
    return the path, or without a path return the figure, closed to pyplot.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        The figure.
    path : str or Path or None
        The PNG file, or None.
    """
    if path is None:
        plt.close(fig)
        return fig
    return save(fig, path)


def save(fig, path: str | Path) -> Path:
    """Save a figure atomically (no half-written PNG) and close it.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        The figure (closed afterwards, also on failure).
    path : str or Path
        PNG file.

    Returns
    -------
    Path
        ``path``.
    """
    try:
        return write_with(path, lambda tmp: fig.savefig(tmp, dpi=110), suffix=".png")
    finally:
        plt.close(fig)


def plot_simulation(res, path: str | Path | None = None, title: str = "", signals=None):
    """Command and rod position, rod velocity, current, voltage against time; or, with
    ``signals``, those signals, one panel per unit (m shown in mm, m/s in mm/s).

    Parameters
    ----------
    res : SimResult
        The simulation.
    path : str or Path, optional
        The image file written; without it the figure is returned.
    title : str
        Figure title.
    signals : sequence of str, optional
        Names of the signals to draw.
    """
    if signals is not None:
        return finish(_signal_panels(res, signals, title), path)
    t = res.t
    fig, ax = plt.subplots(4, 1, figsize=(8, 9), sharex=True)
    ax[0].plot(t, res["x_cmd"] * 1e3, "k--", lw=1, label="x_cmd")
    ax[0].plot(t, res["x_rod"] * 1e3, lw=1.2, label="x_rod")
    ax[0].set_ylabel("position (mm)")
    ax[1].plot(t, res["v_rod"] * 1e3, lw=1.2, label="v_rod")
    ax[1].set_ylabel("rod velocity (mm/s)")
    ax[2].plot(t, res["i_q"], lw=1.2, label="i_q")
    ax[2].plot(t, res["i_cmd"], "k--", lw=0.8, label="i_cmd")
    ax[2].plot(t, res["i_d"], lw=0.8, label="i_d")
    ax[2].set_ylabel("current (A)")
    ax[3].plot(t, res["v_q"], lw=1.0, label="v_q")
    ax[3].plot(t, res["v_d"], lw=0.8, label="v_d")
    ax[3].set_ylabel("voltage (V)")
    ax[3].set_xlabel("time (s)")
    for a in ax:
        a.grid(True, alpha=0.3)
        a.legend(loc="best", fontsize=8)
    ax[0].set_title(title or _variants_title(res))
    fig.tight_layout()
    return finish(fig, path)


#: Units shown scaled: (label, factor).
_SHOWN = {"m": ("mm", 1e3), "m/s": ("mm/s", 1e3)}


def _variants_title(res) -> str:
    v = res.info.get("variants", {})
    return ", ".join(f"{k}={v[k]}" for k in ("motor", "screw", "friction") if k in v)


def _signal_panels(res, signals, title: str):
    """One panel per unit of the named signals."""
    if isinstance(signals, str):
        signals = [signals]
    units = res.units()
    groups: dict = {}
    for name in signals:
        res[name]  # a KeyError naming the signals there are
        groups.setdefault(units.get(name, ""), []).append(name)
    fig, axes = plt.subplots(len(groups), 1, figsize=(8, 2.4 + 2.0 * len(groups)), sharex=True, squeeze=False)
    for ax, (unit, names) in zip(axes[:, 0], groups.items(), strict=True):
        shown, factor = _SHOWN.get(unit, (unit, 1.0))
        for name in names:
            ax.plot(res.t, res[name] * factor, lw=1.1, label=name)
        ax.set_ylabel(f"{', '.join(names)} ({shown or '-'})" if len(names) < 3 else f"({shown or '-'})")
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best", fontsize=8)
    axes[-1, 0].set_xlabel("time (s)")
    axes[0, 0].set_title(title or _variants_title(res))
    fig.tight_layout()
    return fig
