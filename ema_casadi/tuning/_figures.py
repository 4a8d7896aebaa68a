"""The before/after curves of a tuning (closed-loop and loop-transfer Bode, nonlinear
step), computed here and drawn by :mod:`ema_casadi.plots._tuning`."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from ..frequency import bode, closed_loop, frequency_grid
from ..linearisation import loop_model, operating_point
from ..model.assembly import Model
from ..model.params import Parameters
from ..plots._tuning import cascade_figure, draw_bode, draw_step
from ._requirements import _load_label
from ._verify import step_metrics

if TYPE_CHECKING:
    from ._solve import TuneResult

__all__ = ["plot_tuning", "cascade_bode_figure"]


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
    folder : str or Path or None
        Existing folder the PNGs are written into; None: return the two figures.
    reference : Parameters, optional
        A further gain set drawn dotted.

    Returns
    -------
    list of Path or of matplotlib.figure.Figure
        The three PNG files (or, without a folder, the figures).
    """
    folder = None if folder is None else Path(folder)
    sets = {"before": (params_before, "--"), "after": (result.params, "-")}
    if reference is not None:
        sets["reference"] = (reference, ":")
    f = frequency_grid(0.1, 1e4, 60)
    F = result.loads[0]
    titles = ["closed loop x_rod/x_cmd"] + [f"L, {n} loop (others closed)" for n in model.loops]
    curves = {}
    for lbl, (ps, ls) in sets.items():
        op = operating_point(model, f_ext=F, p=ps.vector())
        systems = [closed_loop(model, op)] + [loop_model(model, n, op) for n in model.loops]
        curves[lbl] = (ls, [bode(sys_, f) for sys_ in systems])
    bode_png = draw_bode(f, curves, titles, f"gain tuning ({result.objective}), linearised at {_load_label(F)}",
                         None if folder is None else folder / "tune_bode.png")
    cascade = cascade_bode_figure(model, {k: v[0] for k, v in sets.items()}, F,
                                  path=None if folder is None else folder / "tune_cascade.png")
    return [bode_png, draw_step(_steps(result, model, sets), None if folder is None else folder / "tune_step.png"),
            cascade]


def cascade_bode_figure(model: Model, sets: dict, f_ext: float = 0.0, f=None, path=None):
    """Bode plots of every loop with its outer loops open (the cascade view), one
    column per loop, for each gain set, the gain crossovers marked.

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
    path : str or Path, optional
        PNG file, written atomically; without it the Figure is returned.
    """
    from ..frequency import margins

    f = frequency_grid(0.1, 1e4, 60) if f is None else f
    curves = {}
    for lbl, ps in sets.items():
        op = operating_point(model, f_ext=f_ext, p=ps.vector())
        curves[lbl] = []
        for n in model.loops:
            L = loop_model(model, n, op, outer="open")
            m = margins(L)
            curves[lbl].append((bode(L, f), [c["f_hz"] for c in m.gain_crossovers], m.pm_deg))
    return cascade_figure(f, curves, list(model.loops), f"the cascade view, linearised at {_load_label(f_ext)}", path)


def _steps(result, model, sets) -> dict:
    """``{label: (line style, nonlinear step)}``, reusing the tuning's own steps."""
    steps, amp = {}, None
    for lbl, (ps, ls) in sets.items():
        key = {"before": "verification_before", "after": "verification_after"}.get(lbl)
        nl = getattr(result, key).get("nonlinear_step") if key else None
        if nl is None:
            done = [getattr(result, k)["nonlinear_step"] for k in ("verification_after", "verification_before")
                    if getattr(result, k).get("nonlinear_step")]
            amp = amp or (done[0]["amp_m"] if done else 1e-3)
            nl = step_metrics(model, ps, amp)
        amp = nl["amp_m"]
        steps[lbl] = (ls, nl)
    return steps
