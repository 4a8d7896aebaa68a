"""Plots (matplotlib, Agg backend, PNG written atomically). mm and mm/s on axes."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from .._util._files import write_with  # noqa: E402

__all__ = ["plot_simulation", "save"]


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


def plot_simulation(res, path: str | Path, title: str = "") -> Path:
    """Command and rod position, rod velocity, current, voltage against time.

    Parameters
    ----------
    res : SimResult
        The simulation.
    path : str or Path
        The image file written.
    title : str
        Figure title.
    """
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
    v = res.info.get("variants", {})
    ax[0].set_title(title or ", ".join(f"{k}={v[k]}" for k in ("motor", "screw", "friction") if k in v))
    fig.tight_layout()
    return save(fig, path)
