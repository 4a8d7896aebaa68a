"""Nichols chart of a describing function: one curve per amplitude, the critical point,
the predicted limit cycles."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ._base import plt, save

__all__ = ["plot_nichols"]


def plot_nichols(df, path: str | Path, *, unit_scale: float = 1e6, unit: str = "um", title: str = "") -> Path:
    """L_N(A, w) on a Nichols chart (phase of L_N in deg, gain in dB), amplitude contours.

    Parameters
    ----------
    df : DescribingFunction
        The grid and its predicted cycles.
    path : str or Path
        PNG file.
    unit_scale, unit : float, str
        Amplitude display scale and unit (default um).
    title : str
        Figure title.
    """
    fig, ax = plt.subplots(figsize=(7.5, 6))
    cmap = plt.get_cmap("viridis")
    for i, A in enumerate(df.amplitudes):
        L, ok = df.L[i], df.answered[i]
        ph = np.degrees(np.unwrap(np.angle(L[ok])))
        ph = ph - 360 * np.round((ph.mean() + 180) / 360) if ok.any() else ph
        ax.plot(ph, 20 * np.log10(np.abs(L[ok])), "-o", ms=3, color=cmap(i / max(1, len(df.amplitudes) - 1)),
                label=f"A = {A * unit_scale:.3g} {unit}")
    ax.plot([-180], [0], "r+", ms=16, mew=2, label="critical point -1")
    for c in df.cycles:
        ax.annotate(f"{'stable' if c['stable'] else 'unstable'} cycle\n{c['amplitude'] * unit_scale:.3g} {unit}, "
                    f"{c['freq_hz']:.3g} Hz", (-180, 0), xytext=(20, -30), textcoords="offset points", fontsize=8,
                    arrowprops={"arrowstyle": "->"})
    ax.axvline(-180, color="0.6", lw=0.8)
    ax.axhline(0, color="0.6", lw=0.8)
    ax.set_xlabel("phase of L_N (deg)")
    ax.set_ylabel("|L_N| (dB)")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, loc="best")
    ax.set_title(title or f"describing function at the {df.loop} loop break (frequency grows along each curve)",
                 fontsize=9)
    fig.tight_layout()
    return save(fig, path)
