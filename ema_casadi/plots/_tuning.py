"""Before/after figures of a tuning: Bode plots of the closed loop and the loop
transfers, and the nonlinear step (the curves come from :mod:`ema_casadi.tuning`)."""

from __future__ import annotations

from pathlib import Path

__all__ = ["draw_bode", "draw_step", "cascade_figure"]


def draw_bode(f, curves: dict, titles: list, suptitle: str, path: str | Path | None = None):
    """One column per system (closed loop, then each loop transfer), gain over phase.

    Parameters
    ----------
    f : ndarray
        Frequencies (Hz).
    curves : dict
        ``{label: (line style, [bode dict per system])}``; a bode dict holds ``mag_db``
        and ``phase_deg`` on ``f``.
    titles : list of str
        One title per system (the first is the closed loop, its -3 dB line drawn).
    suptitle : str
        Figure title.
    path : str or Path
        PNG file, written atomically.
    """

    from ._base import finish, subplots

    fig, ax = subplots(2, len(titles), figsize=(17, 7), sharex=True, squeeze=False)
    for lbl, (ls, bodes) in curves.items():
        for j, b in enumerate(bodes):
            ax[0, j].semilogx(f, b["mag_db"], ls, label=lbl)
            ax[1, j].semilogx(f, b["phase_deg"], ls, label=lbl)
    for j, ttl in enumerate(titles):
        ax[0, j].set_title(ttl, fontsize=9)
        ax[0, j].axhline(-3 if j == 0 else 0, color="k", lw=0.6)
        ax[1, j].set_xlabel("frequency (Hz)")
        for a in ax[:, j]:
            a.grid(True, which="both", alpha=0.3)
    ax[0, 0].set_ylabel("magnitude (dB)")
    ax[1, 0].set_ylabel("phase (deg)")
    ax[0, 0].legend(fontsize=8)
    fig.suptitle(suptitle, fontsize=10)
    fig.tight_layout()
    return finish(fig, path)


def draw_step(steps: dict, path: str | Path | None = None):
    """Rod position and q-axis current of nonlinear steps, one line per gain set.

    Parameters
    ----------
    steps : dict
        ``{label: (line style, step)}``; a step holds ``t``, ``x_rod``, ``i_q``,
        ``amp_m``, ``overshoot`` and ``settling_time_s`` (SI).
    path : str or Path
        PNG file, written atomically.
    """

    from ._base import finish, subplots

    fig, ax = subplots(2, 1, figsize=(8, 7), sharex=True)
    amp = None
    for lbl, (ls, nl) in steps.items():
        amp = nl["amp_m"]
        ax[0].plot(nl["t"], nl["x_rod"] * 1e3, ls,
                   label=f"{lbl}: overshoot {100 * nl['overshoot']:.1f} %, "
                         f"settles {1e3 * nl['settling_time_s']:.1f} ms")
        ax[1].plot(nl["t"], nl["i_q"], ls, label=lbl)
    ax[0].set_ylabel("x_rod (mm)")
    ax[1].set_ylabel("i_q (A)")
    ax[1].set_xlabel("time (s)")
    for a in ax:
        a.grid(True, alpha=0.3)
        a.legend(fontsize=8)
    ax[0].set_title(f"nonlinear {amp * 1e3:g} mm step (full model, no load)", fontsize=10)
    fig.tight_layout()
    return finish(fig, path)


def cascade_figure(f, curves: dict, loops: list, suptitle: str, path: str | Path | None = None):
    """One column per loop (with its outer loops open), gain over phase, one colour per
    gain set, each gain crossover marked.

    Parameters
    ----------
    f : ndarray
        Frequencies (Hz).
    curves : dict
        ``{label: [(bode dict, gain crossovers in Hz, PM in deg) per loop]}``.
    loops : list of str
        The loop names, in the order of the curves.
    suptitle : str
        Figure title.
    path : str or Path, optional
        PNG file, written atomically; without it the Figure is returned.
    """

    from ._base import finish, subplots


    fig, ax = subplots(2, len(loops), figsize=(5 * len(loops), 6.5), sharex=True, squeeze=False)
    for k, (lbl, per_loop) in enumerate(curves.items()):
        for j, (b, fcs, pm) in enumerate(per_loop):
            fc = ", ".join(f"{x:.3g}" for x in fcs)
            ax[0, j].semilogx(f, b["mag_db"], color=f"C{k}", label=f"{lbl}: crossover {fc} Hz, PM {pm:.0f} deg")
            ax[1, j].semilogx(f, b["phase_deg"], color=f"C{k}")
            for x in fcs:
                ax[0, j].plot(x, 0.0, "o", color=f"C{k}")
    for j, n in enumerate(loops):
        ax[0, j].set_title(f"L, {n} loop (outer loops open)", fontsize=9)
        ax[0, j].axhline(0, color="k", lw=0.6)
        ax[1, j].axhline(-180, color="k", lw=0.6)
        ax[1, j].set_xlabel("frequency (Hz)")
        ax[0, j].legend(fontsize=7)
        for a in ax[:, j]:
            a.grid(True, which="both", alpha=0.3)
    ax[0, 0].set_ylabel("magnitude (dB)")
    ax[1, 0].set_ylabel("phase (deg)")
    fig.suptitle(suptitle, fontsize=10)
    fig.tight_layout()
    return finish(fig, path)
