"""Plots of ``ema aircraft``: loop Bode (ideal and EMA, margins marked) and responses."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..plotting import plt, save


def plot_condition(model, condition, am, step, gust, folder: Path) -> list[Path]:
    from ..aircraft import ema_loop, ideal_loop
    from ..frequency import bode, frequency_grid
    from ..plot_frequency import plot_loop_margins

    f = frequency_grid(1e-3, 100.0, 100)
    op = _op(model, condition)
    curves = {"ideal": (bode(ideal_loop(model, op), f), am.ideal), "EMA": (bode(ema_loop(model, op), f), am.ema)}
    out = [plot_loop_margins(curves, folder / f"aircraft_{condition}_margins.png",
                             title=f"aircraft loop at the actuator command, {condition}: ideal actuator | EMA "
                                   f"(equivalent delay {am.delay['tau_s'] * 1e3:.1f} ms)")]
    path = folder / f"aircraft_{condition}_responses.png"
    fig, axes = plt.subplots(3, 2, figsize=(11, 8), sharex="col")
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
    fig.suptitle(f"{condition}: nonlinear EMA ({model.variants['friction']} friction)", fontsize=10)
    fig.tight_layout()
    out.append(save(fig, path))
    return out


def _op(model, condition):
    from ..aircraft import aircraft_point

    return aircraft_point(model, condition)

