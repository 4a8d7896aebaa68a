"""Bode plots, with stability margins marked (PNG, written atomically)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ._base import finish, save, subplots

__all__ = ["plot_bode", "plot_loop_margins"]


def _mark_margins(ax_m, ax_p, bode: dict, m) -> None:
    """Mark gain/phase crossovers and the reported GM and PM on a loop's Bode axes."""
    f, mag, ph = bode["freq_hz"], bode["mag_db"], bode["phase_deg"]

    def at(y, fx):
        return float(np.interp(np.log10(fx), np.log10(f), y))

    ax_m.axhline(0.0, color="k", lw=0.6)
    for c in m.gain_crossovers:
        ax_m.axvline(c["f_hz"], color="0.6", lw=0.6, ls=":")
        ax_p.axvline(c["f_hz"], color="0.6", lw=0.6, ls=":")
    if m.f_gc_hz is not None and f[0] <= m.f_gc_hz <= f[-1]:
        p_gc = at(ph, m.f_gc_hz)
        ref = -180.0 + 360.0 * np.round((p_gc + 180.0) / 360.0)
        ax_p.axhline(ref, color="k", lw=0.6)
        ax_p.annotate("", xy=(m.f_gc_hz, p_gc), xytext=(m.f_gc_hz, ref),
                      arrowprops={"arrowstyle": "<->", "color": "C3", "lw": 1.2})
        ax_p.text(m.f_gc_hz * 1.15, (p_gc + ref) / 2, f"PM {m.pm_deg:.1f}°\n@ {m.f_gc_hz:.3g} Hz",
                  color="C3", fontsize=8, va="center")
    for f_x, text, color in ((m.f_pc_hz, f"GM {m.gm_db:.1f} dB", "C2"),
                             (m.f_down_hz, f"gain-reduction margin {m.gm_down_db:.1f} dB", "C4")):
        if f_x is not None and f[0] <= f_x <= f[-1]:
            g_x = at(mag, f_x)
            ax_m.annotate("", xy=(f_x, g_x), xytext=(f_x, 0.0),
                          arrowprops={"arrowstyle": "<->", "color": color, "lw": 1.2})
            ax_m.text(f_x * 1.15, g_x / 2, f"{text}\n@ {f_x:.3g} Hz", color=color, fontsize=8, va="center")
    # a line each (loop, gain margins, phase and disk margins): side by side, one line runs into the next title
    ax_m.set_title(f"{m.loop} loop" + ("" if m.stable else " (closed loop UNSTABLE)") + f"\n{_gm_text(m)}\n"
                   f"PM {m.pm_deg:.1f}°, disk α {m.disk_margin:.2f}", fontsize=9)


def _gm_text(m) -> str:
    """The gain margins named for what they are, both >= 0: a rise (GM) and, for a
    conditionally stable loop, a fall (gain-reduction margin)."""
    text = f"GM {m.gm_db:.1f} dB"
    return text + (f", gain-reduction margin {m.gm_down_db:.1f} dB" if m.conditionally_stable else "")


def plot_bode(curves, path: str | Path | None = None, *, title: str = "", margins=None,
              mag_label: str = "magnitude (dB)", linear_magnitude: bool = False):
    """Bode plot of one or more curves.

    Parameters
    ----------
    curves : dict or list of dict
        Each with ``freq_hz`` (Hz), ``mag_db`` (dB), ``phase_deg`` (deg) and optionally
        ``label`` and ``marks`` (bool array along frequency: points drawn with an ``x``,
        e.g. not settled) (:func:`ema_casadi.frequency.bode`).
    path : str or Path
        PNG file.
    title : str
        Figure title.
    margins : LoopMargins, optional
        Marks the crossovers, GM and PM (the first curve is the loop transfer).
    mag_label : str
        Magnitude axis label.
    linear_magnitude : bool
        Plot each curve's ``magnitude`` (linear, e.g. N/m) on a log axis instead of dB.

    Returns
    -------
    Path
        ``path``.
    """
    if isinstance(curves, dict):
        curves = [curves]
    fig, (ax_m, ax_p) = subplots(2, 1, figsize=(8, 7), sharex=True)
    draw_m, key_m = (ax_m.loglog, "magnitude") if linear_magnitude else (ax_m.semilogx, "mag_db")
    for c in curves:
        f, mag, ph = np.asarray(c["freq_hz"]), np.asarray(c[key_m]), np.asarray(c["phase_deg"])
        line, = draw_m(f, mag, lw=1.3, label=c.get("label"))
        ax_p.semilogx(f, ph, lw=1.3, color=line.get_color(), label=c.get("label"))
        marks = np.asarray(c.get("marks", np.zeros(f.shape, bool)), bool)
        if marks.any():
            draw_m(f[marks], mag[marks], "x", color=line.get_color())
            ax_p.semilogx(f[marks], ph[marks], "x", color=line.get_color())
    if margins is not None:
        _mark_margins(ax_m, ax_p, curves[0], margins)
    ax_m.set_ylabel(mag_label)
    ax_p.set_ylabel("phase (deg)")
    ax_p.set_xlabel("frequency (Hz)")
    for a in (ax_m, ax_p):
        a.grid(True, which="both", alpha=0.3)
    if any(c.get("label") for c in curves):
        ax_m.legend(fontsize=8, loc="best")
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return finish(fig, path)


def plot_loop_margins(loops: dict, path: str | Path, *, title: str = "") -> Path:
    """Open-loop Bode of several loop breaks side by side, margins marked.

    Parameters
    ----------
    loops : dict
        Loop name -> (bode dict of L, LoopMargins).
    path : str or Path
        PNG file.
    title : str
        Figure title.

    Returns
    -------
    Path
        ``path``.
    """
    n = len(loops)
    fig, axes = subplots(2, n, figsize=(5.2 * n, 7), sharex="col", squeeze=False)
    for j, (bode, m) in enumerate(loops.values()):
        ax_m, ax_p = axes[0, j], axes[1, j]
        ax_m.semilogx(bode["freq_hz"], bode["mag_db"], lw=1.3)
        ax_p.semilogx(bode["freq_hz"], bode["phase_deg"], lw=1.3)
        _mark_margins(ax_m, ax_p, bode, m)
        ax_m.set_ylabel("|L| (dB)")
        ax_p.set_ylabel("phase L (deg)")
        ax_p.set_xlabel("frequency (Hz)")
        for a in (ax_m, ax_p):
            a.grid(True, which="both", alpha=0.3)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return save(fig, path)
