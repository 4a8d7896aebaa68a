"""Nichols chart of a describing function: one curve per amplitude, the critical point,
the predicted limit cycles."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ._base import plt, save, subplots

__all__ = ["plot_nichols", "plot_orbit", "plot_bifurcation"]


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
    fig, ax = subplots(figsize=(7.5, 6))
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


def plot_orbit(orbit, path: str | Path | None = None, *, signals=None):
    """A periodic orbit over one period (its summarised signals, or ``signals``) and its
    Floquet multipliers in the complex plane with the unit circle.

    Parameters
    ----------
    orbit : PeriodicOrbit
        The orbit (duck-typed: ``t``, ``signals``, ``multipliers``, ``[name]``).
    path : str or Path, optional
        PNG file; the Figure is returned when not given.
    signals : sequence of str, optional
        Signals drawn (default the orbit's summarised ones).
    """
    names = list(signals or orbit.signals)
    fig, axes = subplots(1, 2, figsize=(10, 4), gridspec_kw={"width_ratios": [2, 1]})
    ax = axes[0]
    for n in names:
        y = np.asarray(orbit[n])
        unit = orbit.units.get(n, "")
        scale, shown = (1e6, "um") if unit == "m" else (1.0, unit)
        ax.plot(orbit.t * 1e3, (y - y.mean()) * scale, label=f"{n} - mean ({shown})")
    ax.set_xlabel("time in the period (ms)")
    ax.set_title(f"periodic orbit: {orbit.freq_hz:.4g} Hz, {'stable' if orbit.stable else 'unstable'}")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    ax = axes[1]
    th = np.linspace(0, 2 * np.pi, 200)
    ax.plot(np.cos(th), np.sin(th), "k-", lw=0.8)
    mu = np.asarray(orbit.multipliers)
    ax.plot(mu[1:].real, mu[1:].imag, "o", ms=5, label="multipliers")
    ax.plot([mu[0].real], [mu[0].imag], "rx", ms=9, label="trivial (1)")
    ax.set_aspect("equal")
    ax.set_xlabel("Re")
    ax.set_ylabel("Im")
    ax.set_title("Floquet multipliers")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig if path is None else save(fig, path)


def plot_bifurcation(cont, path: str | Path | None = None):
    """Bifurcation diagram: the orbit's first-harmonic amplitude against the continued
    parameter, stable points solid, unstable dashed, the detected points marked.

    Parameters
    ----------
    cont : Continuation
        The branch (duck-typed: ``values``, ``amplitudes``, ``stable``, ``bifurcations``).
    path : str or Path, optional
        PNG file; the Figure is returned when not given.
    """
    xs, unit = (1e6, "um") if cont.unit == "m" else (1.0, cont.unit)
    v, a = np.asarray(cont.values) * xs, np.asarray(cont.amplitudes) * 1e6
    fig, ax = subplots(figsize=(7, 4.5))
    st = np.asarray(cont.stable)
    for i in range(len(v) - 1):
        good = st[i] and st[i + 1]
        ax.plot(v[i:i + 2], a[i:i + 2], "-" if good else "--", color="C0" if good else "C3", lw=1.8)
    ax.plot(v[st], a[st], "o", color="C0", ms=4, label="stable orbit")
    ax.plot(v[~st], a[~st], "o", color="C3", ms=4, mfc="none", label="unstable orbit")
    for b in cont.bifurcations:
        ax.plot([b["value"] * xs], [b["amplitude"] * 1e6], "k*", ms=11)
        ax.annotate(b["kind"], (b["value"] * xs, b["amplitude"] * 1e6), xytext=(6, 6), textcoords="offset points",
                    fontsize=8)
    ax.set_xlabel(f"{cont.name} ({unit})" if unit else cont.name)
    ax.set_ylabel(f"first-harmonic amplitude of {cont.signal} (um)")
    ax.set_title("periodic orbits by continuation")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig if path is None else save(fig, path)
