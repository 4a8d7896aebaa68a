"""The fault study's figure (:meth:`ema_casadi.faults.FaultResult.plot`): the coverage
matrix and the rod's transients, drawn from the result (duck-typed)."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["plot_coverage", "plot_thresholds"]


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
    margins = (result.healthy or {}).get("margins")
    if margins:  # the healthy margins under each monitor's column
        labels = []
        for m in result.monitors:
            g = margins.get(m, {})
            top, thr = g.get("healthy_max", math.nan), g.get("threshold", math.nan)
            labels.append(f"{m.removeprefix('latch_')}\nhealthy max {top / thr:.0%}" if thr else m)
        ax.set_xticks(range(len(mons)), labels, fontsize=8)
        ax.set_xlabel(f"largest healthy statistic / threshold over {result.healthy['runs']} healthy runs")
    ref = result.runs[0]
    # the output that plays the rod position (x_rod; a surface's x_surf with several actuators)
    rod = next((k for k, r in getattr(ref, "roles", {}).items() if "rod_position" in r), "x_rod")
    for label, res in zip(cases[1:], result.runs[1:], strict=True):
        if res is None:
            continue
        n = min(len(res.t), len(ref.t))
        bx.plot(res.t[:n], 1e3 * (res[rod][:n] - ref[rod][:n]), lw=1, label=label)
    bx.set_xlabel("time (s)")
    bx.set_ylabel(f"{rod} - {rod} without fault (mm)")
    bx.set_title("rod transient")
    bx.grid(True, alpha=0.3)
    bx.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    if path is not None:
        from ._base import save

        save(fig, path)
    return fig


def plot_thresholds(study, path=None):
    """Per monitor (one column each): the detection delay of every fault case it
    catches and the false-alarm rate per flight hour against its threshold, the
    reference threshold and the largest healthy statistic marked.

    Parameters
    ----------
    study : ThresholdStudy
        The threshold study.
    path : str or Path, optional
        A PNG to write (atomically).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    def shown(d):  # a monitor that detects some case or whose statistic moves
        hits = any(v is not None for r in d["rows"] for v in r["detected_s"].values())
        return hits or (np.isfinite(d["healthy_max"]) and d["healthy_max"] > 0)

    mons = [m for m, d in study.monitors.items() if shown(d)]
    fig, axes = plt.subplots(2, max(1, len(mons)), figsize=(3.6 * max(1, len(mons)), 6.5), squeeze=False)
    for j, m in enumerate(mons):
        d = study.monitors[m]
        x = np.array([r["threshold"] for r in d["rows"]])
        ax, bx = axes[0, j], axes[1, j]
        for case in study.cases:
            t = np.array([np.nan if r["detected_s"][case] is None else 1e3 * r["detected_s"][case] for r in d["rows"]])
            if np.any(np.isfinite(t)) and case != "none":
                ax.plot(x, t, "o-", ms=3, lw=1, label=case)
        rate = np.array([r["false_alarms_per_hour"] for r in d["rows"]])
        bx.semilogy(x, np.maximum(rate, 1e-12), "k.-")
        for a in (ax, bx):
            a.axvline(d["reference"], color="C3", lw=1, ls="--")
            if np.isfinite(d["healthy_max"]):
                a.axvline(d["healthy_max"], color="0.5", lw=1, ls=":")
            a.grid(True, alpha=0.3)
        ax.set_title(f"{m.removeprefix('latch_')} ({d['threshold_param']})", fontsize=9)
        ax.set_ylabel("detection delay (ms)")
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=6)
        bx.set_xlabel(f"threshold ({d['unit']}); -- reference, : healthy max")
        bx.set_ylabel("false alarms per flight hour")
        bx.set_ylim(1e-12, None)
    fig.suptitle(f"thresholds: detection vs false alarms (GEV fit of {study.runs} healthy runs' maxima)",
                 fontsize=10)
    fig.tight_layout()
    if path is not None:
        from ._base import save

        save(fig, path)
    return fig
