"""The figure of an optimal move: position, speed, current, voltage (and temperature)
against their limits; the optimum, its replay in the full model, the ECU's own step."""

from __future__ import annotations

import numpy as np

from ._base import finish, plt

__all__ = ["plot_optimal_move", "plot_envelope", "PANELS"]

#: Panels: rating name -> (axis label, display factor).
PANELS = {"stroke": ("rod position (mm)", 1e3), "rod_speed": ("rod speed (mm/s)", 1e3),
          "current": ("|i_dq| (A)", 1.0), "voltage": ("|v_dq| (V)", 1.0),
          "winding_temperature": ("winding (degC)", 1.0)}


def _magnitude(source, names):
    cols = [np.asarray(source[n], float) for n in names]
    return cols[0] if len(cols) == 1 else np.sqrt(sum(c**2 for c in cols))


def plot_optimal_move(res, path=None):
    """The figure of an :class:`~ema_casadi.optimal.OptimalMove`; a Figure, or the path
    of the PNG written.

    Parameters
    ----------
    res : OptimalMove
        The optimal move (its ``rating_signals``, ``limits``, ``replay``, ``ecu_step``).
    path : str or Path, optional
        PNG file.
    """
    panels = [k for k in PANELS if k in res.rating_signals]
    fig, axes = plt.subplots(len(panels), 1, figsize=(8, 1.9 * len(panels) + 0.8), sharex=True, squeeze=False)
    node = {**res.states, **res.outputs, **{k: np.append(v, v[-1]) for k, v in res.controls.items()}}
    for ax, key in zip(axes[:, 0], panels, strict=True):
        label, k = PANELS[key]
        names = res.rating_signals[key]
        ax.plot(res.t, k * _magnitude(node, names), "o-", ms=2.5, lw=1.2, label=f"optimum ({res.through})")
        if res.replay is not None and all(n in res.replay.columns() for n in names):
            ax.plot(res.replay.t, k * _magnitude(res.replay, names), lw=1.0, label="replay, full model")
        step = res.ecu_step.get("result")
        if step is not None and all(n in step.columns() for n in names):
            ax.plot(step.t, k * _magnitude(step, names), lw=1.0, ls="--", label="ECU step")
        if key == "stroke":
            target = res.start + res.move
            ax.axhspan(k * (target - 0.02 * abs(res.move)), k * (target + 0.02 * abs(res.move)), color="0.85",
                       label="2 % band")
        else:
            ax.axhline(k * res.limits[key], color="r", lw=0.8, ls=":", label="limit")
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.3)
    axes[0, 0].legend(fontsize=7, loc="best")
    axes[-1, 0].set_xlabel("time (s)")
    unit = "s" if res.objective == "time" else "J"
    fig.suptitle(f"optimal move ({res.objective}): {res.move * 1e3:g} mm under {res.load / 1e3:g} kN, "
                 f"{res.duration:.4g} s, cost {res.cost:.4g} {unit}", fontsize=10)
    fig.tight_layout()
    return finish(fig, path)


def plot_envelope(env, path=None):
    """The figure of a :class:`~ema_casadi.optimal.Envelope`: the top rod speed against
    the load opposing the move (the largest load held marked) and the minimum move time
    against the distance, one line per soak temperature; a Figure, or the path of the
    PNG written.

    Parameters
    ----------
    env : Envelope
        The envelope.
    path : str or Path, optional
        PNG file.
    """
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4))
    for T in env.temperatures:
        name = "parameter set" if T is None else f"{T:g} degC"
        line, = a.plot(np.asarray(env.loads) / 1e3, 1e3 * np.asarray(env.top_speed[T]), "o-", ms=3, label=name)
        a.axvline(env.largest_force[T] / 1e3, color=line.get_color(), lw=0.8, ls=":",
                  label=f"largest load held, {name}")
        b.plot(1e3 * np.asarray(env.distances), np.asarray(env.min_time[T]), "o-", ms=3, label=name)
    a.set_xlabel("load opposing the move (kN)")
    a.set_ylabel("top rod speed (mm/s)")
    b.set_xlabel("move distance (mm)")
    b.set_ylabel("minimum move time, no load (s)")
    for ax in (a, b):
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7, loc="best")
    fig.suptitle("performance envelope within the drive's operating limits", fontsize=10)
    fig.tight_layout()
    return finish(fig, path)
