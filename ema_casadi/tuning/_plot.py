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
    set; PNGs ``tune_bode.png`` and ``tune_step.png`` written atomically.

    Parameters
    ----------
    result : TuneResult
        The tuning; its nonlinear steps are reused where it has them.
    model : Model
        The assembled model.
    params_before : Parameters
        The parameter set with the start gains.
    folder : str or Path or None
        Existing folder the PNGs are written into; None: return the two figures.
    reference : Parameters, optional
        A further gain set drawn dotted.

    Returns
    -------
    list of Path or of matplotlib.figure.Figure
        The two PNG files (or figures).
    """
    sets = {"before": (params_before, "--"), "after": (result.params, "-")}
    if reference is not None:
        sets["reference"] = (reference, ":")
    if folder is None:  # the figures themselves (a notebook)
        return [_plot_bode(result, model, sets, None), _plot_step(result, model, sets, None)]
    folder = Path(folder)
    return [_plot_bode(result, model, sets, folder / "tune_bode.png"),
            _plot_step(result, model, sets, folder / "tune_step.png")]


def _plot_bode(result, model, sets, path):
    import matplotlib.pyplot as plt

    from ..plotting import finish  # first: it selects the Agg backend

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
    return finish(fig, path)


def _plot_step(result, model, sets, path):
    import matplotlib.pyplot as plt

    from ..plotting import finish  # first: it selects the Agg backend

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
    return finish(fig, path)
