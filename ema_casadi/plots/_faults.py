"""The fault study's figure (:meth:`ema_casadi.faults.FaultResult.plot`): the coverage
matrix and the rod's transients, drawn from the result (duck-typed)."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["plot_coverage"]


def plot_coverage(result, path=None):
    """Coverage matrix (cases x monitors: detection delay in ms, blank when not
    detected) and the rod's deviation from the no-fault run of every case.

    Parameters
    ----------
    result : FaultResult
        The fault study.
    path : str or Path, optional
        A PNG to write (atomically); the Figure is returned either way (and closed
        once written).
    """
    from ._base import subplots

    cov = result.coverage()
    cases, mons = list(cov), [m.removeprefix("latch_") for m in result.monitors]
    D = np.array([[math.nan if cov[c][m] is None else 1e3 * cov[c][m] for m in result.monitors] for c in cases])
    fig, (ax, bx) = subplots(1, 2, figsize=(12, 0.45 * len(cases) + 2.0), width_ratios=(1.1, 1))
    shown = np.where(np.isfinite(D), np.log10(np.maximum(D, 1e-3) + 1), np.nan)
    ax.imshow(np.ma.masked_invalid(shown), cmap="viridis_r", aspect="auto", vmin=0, vmax=4)
    for i in range(len(cases)):
        for j in range(len(mons)):
            text = "-" if not np.isfinite(D[i, j]) else f"{D[i, j]:.1f}"
            ax.text(j, i, text, ha="center", va="center", fontsize=8, color="k" if np.isfinite(D[i, j]) else "0.5")
    ax.set_xticks(range(len(mons)), mons)
    ax.set_yticks(range(len(cases)), [c + (" (failed)" if r["status"] != "ok" else "")
                                      for c, r in zip(cases, result.rows, strict=True)])
    ax.set_title("detection delay after the onset (ms); - not detected")
    ref = result.runs[0]
    for label, res in zip(cases[1:], result.runs[1:], strict=True):
        if res is None:
            continue
        n = min(len(res.t), len(ref.t))
        bx.plot(res.t[:n], 1e3 * (res["x_rod"][:n] - ref["x_rod"][:n]), lw=1, label=label)
    bx.set_xlabel("time (s)")
    bx.set_ylabel("x_rod - x_rod without fault (mm)")
    bx.set_title("rod transient")
    bx.grid(True, alpha=0.3)
    bx.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    if path is not None:
        from ._base import save

        save(fig, path)
    return fig
