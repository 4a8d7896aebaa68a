"""Before/after plots of a tuning: Bode plots of the closed loop and the loop transfers,
and the nonlinear step."""

from __future__ import annotations

from pathlib import Path

from ..assembly import Model
from ..frequency import bode, closed_loop, frequency_grid
from ..linearisation import loop_model, operating_point
from ..params import Parameters
from ._requirements import _load_label
from ._solve import TuneResult
from ._verify import step_metrics


def plot_tuning(result: TuneResult, model: Model, params_before: Parameters, folder,
                reference: Parameters | None = None) -> list:
    """Bode plots (closed loop x_rod/x_cmd and the three loop transfers, first load case)
    and the nonlinear step (no load) before and after, optionally with a reference gain
    set, and the cascade view (:func:`cascade_bode_figure`); PNGs ``tune_bode.png``,
    ``tune_step.png`` and ``tune_cascade.png`` written atomically.

    Parameters
    ----------
    result : TuneResult
        The tuning; its nonlinear steps are reused where it has them.
    model : Model
        The assembled model.
    params_before : Parameters
        The parameter set with the start gains.
    folder : str or Path
        Existing folder the PNGs are written into.
    reference : Parameters, optional
        A further gain set drawn dotted.

    Returns
    -------
    list of Path
        The two PNG files.
    """
    folder = Path(folder)
    sets = {"before": (params_before, "--"), "after": (result.params, "-")}
    if reference is not None:
        sets["reference"] = (reference, ":")
    from ..plotting import save

    cascade = cascade_bode_figure(model, {k: v[0] for k, v in sets.items()}, result.loads[0])
    return [_plot_bode(result, model, sets, folder / "tune_bode.png"),
            _plot_step(result, model, sets, folder / "tune_step.png"),
            save(cascade, folder / "tune_cascade.png")]


def cascade_bode_figure(model: Model, sets: dict, f_ext: float = 0.0, f=None):
    """Bode plots of every loop with its outer loops open (the cascade view), one
    column per loop, for each gain set; the gain crossovers marked and the 0 dB and
    -180 deg lines drawn.

    Parameters
    ----------
    model : Model
        The assembled model.
    sets : dict
        Label -> Parameters (the gain sets to compare).
    f_ext : float
        Load (N) of the operating point.
    f : array_like, optional
        Frequencies (Hz; default 0.1 Hz - 10 kHz).

    Returns
    -------
    matplotlib.figure.Figure
    """
    import matplotlib.pyplot as plt

    from ..frequency import margins

    f = frequency_grid(0.1, 1e4, 60) if f is None else f
    loops = list(model.loops)
    fig, ax = plt.subplots(2, len(loops), figsize=(5 * len(loops), 6.5), sharex=True, squeeze=False)
    for k, (lbl, ps) in enumerate(sets.items()):
        op = operating_point(model, f_ext=f_ext, p=ps.vector())
        for j, n in enumerate(loops):
            L = loop_model(model, n, op, outer="open")
            b, m = bode(L, f), margins(L)
            fc = ", ".join(f"{c['f_hz']:.3g}" for c in m.gain_crossovers)
            ax[0, j].semilogx(f, b["mag_db"], color=f"C{k}", label=f"{lbl}: crossover {fc} Hz, PM {m.pm_deg:.0f} deg")
            ax[1, j].semilogx(f, b["phase_deg"], color=f"C{k}")
            for c in m.gain_crossovers:
                ax[0, j].plot(c["f_hz"], 0.0, "o", color=f"C{k}")
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
    fig.suptitle(f"the cascade view, linearised at {_load_label(f_ext)}", fontsize=10)
    fig.tight_layout()
    return fig


def _plot_bode(result, model, sets, path):
    import matplotlib.pyplot as plt

    from ..plotting import save  # first: it selects the Agg backend

    f = frequency_grid(0.1, 1e4, 60)
    F = result.loads[0]
    fig, ax = plt.subplots(2, 4, figsize=(17, 7), sharex=True)
    titles = ["closed loop x_rod/x_cmd"] + [f"L, {n} loop (others closed)" for n in model.loops]
    for lbl, (ps, ls) in sets.items():
        op = operating_point(model, f_ext=F, p=ps.vector())
        systems = [closed_loop(model, op)] + [loop_model(model, n, op) for n in model.loops]
        for j, sys_ in enumerate(systems):
            b = bode(sys_, f)
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
    fig.suptitle(f"gain tuning ({result.objective}), linearised at {_load_label(F)}", fontsize=10)
    fig.tight_layout()
    return save(fig, path)


def _plot_step(result, model, sets, path):
    import matplotlib.pyplot as plt

    from ..plotting import save  # first: it selects the Agg backend

    fig, ax = plt.subplots(2, 1, figsize=(8, 7), sharex=True)
    amp = None
    for lbl, (ps, ls) in sets.items():
        key = {"before": "verification_before", "after": "verification_after"}.get(lbl)
        nl = getattr(result, key).get("nonlinear_step") if key else None
        if nl is None:
            done = [getattr(result, k)["nonlinear_step"] for k in ("verification_after", "verification_before")
                    if getattr(result, k).get("nonlinear_step")]
            amp = amp or (done[0]["amp_m"] if done else 1e-3)
            nl = step_metrics(model, ps, amp)
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
    return save(fig, path)
