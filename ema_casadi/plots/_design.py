"""The figure of an experiment design: the designed command and load, the standard
test's, and the predicted 95 % interval widths of both (the numbers come from
:mod:`ema_casadi.design`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["design_figure"]


def design_figure(result, path: str | Path | None = None):
    """Three panels: the designed test's command (mm) and load (kN) against time, the
    standard test's records end to end, and the predicted relative 95 % interval widths
    per parameter (log scale), with the realised ones of a verification where given.

    Parameters
    ----------
    result : DesignResult
        The design.
    path : str or Path, optional
        PNG file, written atomically; without it the Figure is returned.
    """
    import matplotlib.pyplot as plt

    from ._base import finish  # first: it selects the Agg backend

    fig, ax = plt.subplots(3, 1, figsize=(10, 9))
    cmd, load = result.model.input_with("command"), result.model.input_with("load")
    for a, test in zip(ax[:2], (result.test, result.standard), strict=True):
        t0 = 0.0
        a2 = a.twinx()
        for k, rec in enumerate(test.records):
            t = rec["t"] + t0
            a.plot(t, 1e3 * rec["inputs"][cmd], "C0", lw=0.8, label="command (mm)" if k == 0 else None)
            a2.plot(t, 1e-3 * rec["inputs"][load], "C3", lw=1.0, label="load (kN)" if k == 0 else None)
            t0 = t[-1]
        a.set_ylabel("command (mm)", color="C0")
        a2.set_ylabel("load (kN)", color="C3")
        a.set_title(f"{test.name} ({test.duration:g} s)", fontsize=9)
        a.grid(True, alpha=0.3)
    ax[1].set_xlabel("time (s)")
    names = list(result.free.names)
    x = np.arange(len(names))
    w_d = np.asarray(result.predicted["width"], float)
    w_s = np.asarray(result.standard_predicted["width"], float)
    ax[2].bar(x - 0.2, 100 * w_s, 0.4, color="0.6", label=result.standard.name)
    ax[2].bar(x + 0.2, 100 * w_d, 0.4, color="C0", label="designed (predicted)")
    if result.verification is not None:
        real = [100 * result.verification["realised_width"][n] for n in names]
        ax[2].plot(x + 0.2, real, "k_", ms=18, mew=2, label=f"designed, realised ({result.verification['n']} fits)")
    ax[2].set_yscale("log")
    ax[2].set_xticks(x, names)
    ax[2].set_ylabel("95 % interval width (% of value)")
    ax[2].grid(True, which="both", axis="y", alpha=0.3)
    ax[2].legend(fontsize=8)
    g = result.comparison()["geometric_mean_ratio"]
    ax[2].set_title(f"predicted interval widths: geometric mean {g:.3g}x narrower than {result.standard.name}",
                    fontsize=9)
    fig.tight_layout()
    return finish(fig, path)
