"""Plots of ``ema aircraft``: loop Bode (ideal and EMA, margins marked) and responses."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ._base import save, subplots

__all__ = ["plot_condition"]


def plot_condition(curves: dict, condition: str, delay_s: float, step, gust, friction: str,
                   folder: Path) -> list[Path]:
    """The loop Bode of one flight condition (ideal actuator and EMA, margins marked) and
    its nonlinear responses; two PNGs in ``folder``.

    Parameters
    ----------
    curves : dict
        ``{"ideal": (bode dict, margins), "EMA": (bode dict, margins)}`` of the aircraft loop.
    condition : str
        Flight condition name (file names and titles).
    delay_s : float
        The EMA's equivalent delay (s), for the title.
    step, gust : SimResult or None
        The theta_cmd step and the 1-cosine gust responses.
    friction : str
        The friction variant, for the title.
    folder : Path
        Existing folder.
    """
    from ._frequency import plot_loop_margins

    out = [plot_loop_margins(curves, folder / f"aircraft_{condition}_margins.png",
                             title=f"aircraft loop at the actuator command, {condition}: ideal actuator | EMA "
                                   f"(equivalent delay {delay_s * 1e3:.1f} ms)")]
    path = folder / f"aircraft_{condition}_responses.png"
    fig, axes = subplots(3, 2, figsize=(11, 8), sharex="col")
    for j, (r, what) in enumerate(((step, "theta_cmd step"), (gust, "1-cosine gust"))):
        if r is None:
            continue
        t = r["t"]
        axes[0, j].plot(t, np.degrees(r["theta"]))
        axes[0, j].set_ylabel("theta (deg)")
        axes[0, j].set_title(what)
        axes[1, j].plot(t, r["n_z"])
        axes[1, j].set_ylabel("n_z (-)")
        axes[2, j].plot(t, np.degrees(r["delta_e"]), label="delta_e")
        axes[2, j].plot(t, np.degrees(r["delta_cmd"]), "--", label="delta_cmd")
        axes[2, j].set_ylabel("elevator (deg)")
        axes[2, j].set_xlabel("time (s)")
        axes[2, j].legend(fontsize=8)
        for a in axes[:, j]:
            a.grid(True, alpha=0.3)
    fig.suptitle(f"{condition}: nonlinear EMA ({friction} friction)", fontsize=10)
    fig.tight_layout()
    out.append(save(fig, path))
    return out

