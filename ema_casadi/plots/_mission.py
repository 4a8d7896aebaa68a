"""The mission figure: temperatures against their limits, losses per part, the rod
command and load; segments shaded and named."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ._base import finish, subplots

__all__ = ["plot_mission"]

_COLOURS = {"T_w": "tab:red", "T_h": "tab:blue", "T_s": "tab:green", "T_inv": "tab:purple"}


def _means(t: np.ndarray, y: np.ndarray, width: float):
    """Mean of y over windows of ``width`` seconds (losses chatter at the ECU rates)."""
    edges = np.arange(t[0], t[-1] + width, width)
    c = np.concatenate([[0.0], np.cumsum(0.5 * (y[1:] + y[:-1]) * np.diff(t))])
    ci = np.interp(edges, t, c)
    return 0.5 * (edges[1:] + edges[:-1]), np.diff(ci) / np.diff(edges)


def plot_mission(res, path: str | Path | None = None, title: str = ""):
    """Temperatures (degC) with the limits, losses per part (W, 5 s means) and the rod
    command and load over the mission; segments shaded and labelled.

    Parameters
    ----------
    res : MissionResult
        The run.
    path : str or Path
        The PNG file (written atomically).
    title : str
        Figure title (default the mission's name).
    """
    t = res.t / 60.0
    fig, ax = subplots(3, 1, figsize=(11, 10), sharex=True, gridspec_kw={"height_ratios": [3, 2, 1.4]})
    starts = res.mission.starts / 60.0
    ends = starts + np.array([s.duration for s in res.mission.segments]) / 60.0
    for k, (a, b, seg) in enumerate(zip(starts, ends, res.mission.segments, strict=True)):
        for axis in ax:
            axis.axvspan(a, b, color="0.92" if k % 2 == 0 else "0.98", zorder=0)
        ax[0].text(0.5 * (a + b), 1.01, seg.name, rotation=30, ha="left", va="bottom", fontsize=7,
                   transform=ax[0].get_xaxis_transform())
    limits: dict = {}
    for n, node in res.nodes.items():
        c = _COLOURS.get(n)
        ax[0].plot(t, res[n], color=c, lw=1.4, label=f"{n} ({node})")
        limit = res.mission.limits.get(n)
        if limit is not None:
            ax[0].axhline(limit, color=c, lw=0.8, ls=":")
            limits.setdefault(limit, []).append(n)
    for limit, names in limits.items():
        ax[0].text(t[-1], limit, f" {', '.join(names)} limit {limit:g}", fontsize=7, va="center")
    ax[0].plot(t, res["T_amb"], "k--", lw=1.0, label="T_amb (cavity)")
    ax[0].set_ylabel("temperature (degC)")
    width = 5.0 if res.t[-1] > 300 else 1.0
    parts: dict = {}
    for n in res.losses:
        parts.setdefault(res.owners.get(n, n), []).append(n)
    for part, names in parts.items():
        y = sum(res[n] for n in names)
        if np.max(np.abs(y)) == 0:
            continue
        tm, ym = _means(res.t, y, width)
        ax[1].plot(tm / 60.0, ym, lw=1.1, label=f"{part} ({'+'.join(names)})")
    ax[1].set_ylabel(f"loss, {width:g} s mean (W)")
    ax[1].set_yscale("symlog", linthresh=1.0)
    ax[2].plot(t, res["x_cmd"] * 1e3, lw=0.8, label="x_cmd (mm)")
    ax2 = ax[2].twinx()
    ax2.plot(t, res["f_ext"] / 1e3, color="tab:orange", lw=0.8, label="f_ext (kN)")
    ax[2].set_ylabel("x_cmd (mm)")
    ax2.set_ylabel("f_ext (kN)", color="tab:orange")
    ax[2].set_xlabel("mission time (min)")
    for axis in ax:
        axis.grid(True, alpha=0.3)
        if axis.get_legend_handles_labels()[0]:
            axis.legend(loc="upper left", fontsize=7)
    fig.suptitle(title or res.mission.name)
    fig.tight_layout()
    return finish(fig, path)
