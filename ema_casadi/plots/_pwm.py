"""Plots of a switched (PWM) run: phase currents, leg states, phase and line voltages
over a few carrier periods, the DC-link voltage over the run; and the PWM-against-
averaged figure of the demo. Matplotlib, PNG written atomically."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ._base import save, subplots

__all__ = ["plot_switched", "plot_pwm_vs_averaged"]


def plot_switched(res, path: str | Path, periods: int = 4, f_sw: float | None = None) -> Path:
    """The last ``periods`` carrier periods of a run that kept every sub-interval
    (``dt_out=None``): phase currents, leg states, phase voltage a and line voltage a-b
    (step plots: each sample's value holds until the next), and v_dc over the whole run.

    Parameters
    ----------
    res : SimResult
        A switched run with every sub-interval kept.
    path : str or Path
        The PNG written.
    periods : int
        Carrier periods shown.
    f_sw : float, optional
        Carrier frequency (Hz); default from the sample times (8 per period).
    """
    t = res.t
    if f_sw is None:
        f_sw = res.info["carrier_periods"] / res.info["t_end"]
    win = t >= t[-1] - periods / f_sw - 1e-12
    tw = (t[win] - t[win][0]) * 1e6
    fig, ax = subplots(5, 1, figsize=(8, 11))
    for k in "abc":
        ax[0].plot(tw, res[f"i_{k}"][win], lw=1.0, label=f"i_{k}")
    ax[0].set_ylabel("phase current (A)")
    for j, k in enumerate("abc"):
        ax[1].step(tw, res[f"s_{k}"][win] + 1.5 * j, where="post", lw=1.0, label=f"s_{k} (+{1.5 * j:g})")
    ax[1].set_ylabel("leg state (-)")
    ax[2].step(tw, res["v_an"][win], where="post", lw=1.0, label="v_an")
    ax[2].plot(tw, res["v_dc"][win] * (res["d_a"][win] - (res["d_a"] + res["d_b"] + res["d_c"])[win] / 3), "k--",
               lw=0.8, label="averaged v_an")
    ax[2].set_ylabel("phase voltage (V)")
    ax[3].step(tw, res["v_ab"][win], where="post", lw=1.0, label="v_ab")
    ax[3].set_ylabel("line voltage (V)")
    ax[3].set_xlabel(f"time from {t[win][0] * 1e3:.3f} ms (us)")
    ax[4].plot(t, res["v_dc"], lw=0.8, label="v_dc")
    ax[4].set_ylabel("DC link (V)")
    ax[4].set_xlabel("time (s)")
    for a in ax:
        a.grid(True, alpha=0.3)
        a.legend(loc="best", fontsize=7)
    v = res.info.get("variants", {})
    ax[0].set_title(f"switched bridge, f_sw = {f_sw / 1e3:g} kHz, supply = {v.get('supply', 'ideal')}")
    fig.tight_layout()
    return save(fig, path)


def plot_pwm_vs_averaged(sw, av, path: str | Path, pp: int, periods: int = 6, f_sw: float = 16e3) -> Path:
    """Rod position of a switched and an averaged run of one scenario, and the phase-a
    current of both over the last carrier periods (the switched run kept every
    sub-interval).

    Parameters
    ----------
    sw, av : SimResult
        The switched run (every sub-interval kept) and the averaged run.
    path : str or Path
        The PNG written.
    pp : int
        Pole pairs (the averaged run's phase current from its dq currents and shaft angle).
    periods : int
        Carrier periods in the zoom.
    f_sw : float
        Carrier frequency (Hz).
    """
    fig, ax = subplots(3, 1, figsize=(8, 8))
    ax[0].plot(av.t, av["x_rod"] * 1e3, lw=1.5, label="averaged")
    ax[0].plot(sw.t, sw["x_rod"] * 1e3, "--", lw=1.0, label="switched PWM")
    ax[0].plot(av.t, av["x_cmd"] * 1e3, "k:", lw=0.8, label="x_cmd")
    ax[0].set_ylabel("rod position (mm)")
    ax[0].set_xlabel("time (s)")
    t1 = sw.t[-1]
    win_s = sw.t >= t1 - periods / f_sw - 1e-12
    win_a = av.t >= t1 - periods / f_sw - 1e-12
    t0 = sw.t[win_s][0]
    ax[1].plot((sw.t[win_s] - t0) * 1e6, sw["i_a"][win_s], lw=1.0, label="i_a switched")
    theta = pp * av["phi"]
    i_a_av = av["i_d"] * np.cos(theta) - av["i_q"] * np.sin(theta)
    ax[1].plot((av.t[win_a] - t0) * 1e6, i_a_av[win_a], "k--", lw=0.8, label="i_a averaged")
    ax[1].set_ylabel("current (A)")
    ax[2].step((sw.t[win_s] - t0) * 1e6, sw["v_an"][win_s], where="post", lw=1.0, label="v_an switched")
    ax[2].set_ylabel("phase voltage (V)")
    ax[2].set_xlabel(f"time from {t0 * 1e3:.3f} ms (us)")
    for a in ax:
        a.grid(True, alpha=0.3)
        a.legend(loc="best", fontsize=8)
    ax[0].set_title("switched PWM bridge against the averaged bridge")
    fig.tight_layout()
    return save(fig, path)
