"""Plots (matplotlib, PNG written atomically). mm and mm/s on axes.

Every plot function builds a :class:`matplotlib.figure.Figure`; given a path it writes
the PNG (closes the figure and returns the path), without one it returns the figure,
managed by pyplot like any figure of ``plt.subplots``: ``fig = res.plot(); plt.show()``
shows it, and in a notebook an assigned figure displays at the end of the cell (the
inline backend shows pyplot's figures); a bare ``res.plot()`` as the cell's last line
displays once (:class:`Figure` leaves it to the backend). The backend is matplotlib's
own choice (``MPLBACKEND``, a notebook's inline backend, a display's GUI, else Agg);
the ``ema`` command line draws off screen (Agg).
"""

from __future__ import annotations

from pathlib import Path

import matplotlib.figure
import matplotlib.pyplot as plt

from .._util._files import write_with

__all__ = ["plot_simulation", "save", "finish", "Figure", "subplots", "write_figures"]


class Figure(matplotlib.figure.Figure):
    """The package's figures: a matplotlib Figure that a notebook displays once. While
    pyplot manages it in interactive mode (a notebook's inline backend, ``plt.ion()``),
    the backend shows it, so the notebook's display hook adds nothing (the plain
    Figure would be drawn twice: by the backend and as the cell's value); a figure
    closed to pyplot displays as its PNG."""

    def _ipython_display_(self):
        from matplotlib._pylab_helpers import Gcf

        managed = any(m.canvas.figure is self for m in Gcf.get_all_fig_managers())
        if managed and matplotlib.is_interactive():
            return  # the backend draws it at the end of the cell
        import io

        from IPython.display import display

        buf = io.BytesIO()
        self.savefig(buf, format="png", dpi=self.dpi, bbox_inches="tight")
        display({"image/png": buf.getvalue(), "text/plain": repr(self)}, raw=True)


def subplots(*args, **kwargs):
    """``plt.subplots`` making a :class:`Figure` (managed by pyplot)."""
    return plt.subplots(*args, FigureClass=Figure, **kwargs)


def finish(fig, path: str | Path | None):
    """The end of every plot function: write ``fig`` to ``path`` (PNG, atomically),
    close it and return the path, or without a path return the figure (managed by
    pyplot: ``plt.show()`` shows it, ``plt.close(fig)`` releases it).

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        The figure.
    path : str or Path or None
        The PNG file, or None.
    """
    if path is None:
        return fig
    return save(fig, path)


def write_figures(name: str | None = None) -> list[Path]:
    """The end of an example script run as a script (``cd examples; python plot_fig14.py``,
    from any folder): each figure pyplot holds written as ``<name>.png`` (a second one
    ``<name>_2.png``, ...) into the working folder, a line each on stdout, and closed.
    Under sphinx-gallery (which collects the figures itself) nothing is written.

    Parameters
    ----------
    name : str, optional
        The files' stem; default the script's name (``sys.argv[0]``).

    Returns
    -------
    list of Path
        The files written.
    """
    import sys

    if "sphinx_gallery" in sys.modules:
        return []
    stem = name or Path(sys.argv[0]).stem or "figure"
    if stem.startswith("-"):  # python -c / -m
        stem = "figure"
    written = []
    for k, num in enumerate(plt.get_fignums()):
        path = save(plt.figure(num), Path.cwd() / (f"{stem}.png" if k == 0 else f"{stem}_{k + 1}.png"))
        print(f"wrote {path}")
        written.append(path)
    return written


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
    fig, ax = subplots(4, 1, figsize=(8, 9), sharex=True)
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
    fig, axes = subplots(len(groups), 1, figsize=(8, 2.4 + 2.0 * len(groups)), sharex=True, squeeze=False)
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
