"""Figures of a fit (matplotlib Figures) and the report folder."""

from __future__ import annotations

import json
from pathlib import Path

from .._util._files import atomic_dir
from ._data import plain

#: Display scale and unit of the usual channels (SI otherwise).
_DISPLAY = {"m": (1e3, "mm"), "rad": (1.0, "rad"), "rad/s": (1.0, "rad/s"), "A": (1.0, "A"), "N": (1e-3, "kN")}


def _scale(result, channel):
    unit = result.info.get("units", {}).get(channel, "")
    return _DISPLAY.get(unit, (1.0, unit))


def fit_figure(result, k: int):
    """Measured and fitted channels of record ``k`` over time, with the residuals (in
    units of the channel's noise level) below each.

    Parameters
    ----------
    result : IdentResult
        The fit.
    k : int
        Record index.
    """
    import matplotlib.pyplot as plt

    tr = result.trajectories[k]
    chans = list(tr["measured"])
    fig, axes = plt.subplots(2 * len(chans), 1, figsize=(8, 2.6 * len(chans) + 0.6), sharex=True, squeeze=False,
                             gridspec_kw={"height_ratios": [3, 1] * len(chans)})
    for j, c in enumerate(chans):
        s, unit = _scale(result, c)
        ax, ax_r = axes[2 * j, 0], axes[2 * j + 1, 0]
        ax.plot(tr["t"], tr["measured"][c] * s, ".", ms=1.5, color="0.55", label="measured")
        ax.plot(tr["t"], tr["fitted"][c] * s, "-", lw=1.0, color="C0", label="fitted")
        ax.set_ylabel(f"{c} ({unit})" if unit else c)
        ax.legend(loc="best", fontsize=8)
        r = (tr["measured"][c] - tr["fitted"][c]) / result.sigma[c]
        ax_r.plot(tr["t"], r, lw=0.5, color="C3")
        ax_r.axhline(0, color="k", lw=0.5)
        ax_r.set_ylabel("resid. / σ", fontsize=8)
    axes[-1, 0].set_xlabel("time (s)")
    fig.suptitle(f"{Path(tr['record']).name}: measured vs fitted", fontsize=10)
    fig.tight_layout()
    return fig


def correlation_figure(result):
    """Heat map of the correlation matrix of the estimates.

    Parameters
    ----------
    result : IdentResult
        The fit.
    """
    import matplotlib.pyplot as plt

    n = len(result.names)
    fig, ax = plt.subplots(figsize=(1.0 + 0.7 * n, 0.6 + 0.6 * n))
    im = ax.imshow(result.correlation, vmin=-1, vmax=1, cmap="RdBu_r")
    ax.set_xticks(range(n), result.names, rotation=45, ha="right")
    ax.set_yticks(range(n), result.names)
    for i in range(n):
        for j in range(n):
            ax.text(j, i, f"{result.correlation[i, j]:+.2f}", ha="center", va="center", fontsize=7)
    fig.colorbar(im, ax=ax, shrink=0.8, label="correlation")
    ax.set_title("correlation of the estimates", fontsize=10)
    fig.tight_layout()
    return fig


def intervals_figure(result, truth: dict | None = None):
    """Estimates and 95 % intervals relative to the start values (held parameters at
    their start, marked).

    Parameters
    ----------
    result : IdentResult
        The fit.
    truth : dict, optional
        Known true values (SI) to mark (records made by simulation).
    """
    import matplotlib.pyplot as plt

    names = list(result.names) + list(result.held)
    fig, ax = plt.subplots(figsize=(7, 0.5 + 0.45 * len(names)))
    for i, n in enumerate(names):
        if n in result.held:
            ax.plot([0], [i], "x", color="C3")
            ax.text(0.02, i, " not identifiable: held", va="center", fontsize=8, color="C3",
                    transform=ax.get_yaxis_transform())
            continue
        s = result.start[n]
        lo, hi = result.interval[n]
        ok = result.identifiable[n] is True
        col = "C0" if ok else "C3"
        ax.errorbar([100 * (result.estimate[n] / s - 1)], [i], xerr=[[100 * (result.estimate[n] - lo) / s],
                                                                   [100 * (hi - result.estimate[n]) / s]],
                    fmt="o", color=col, capsize=3)
        if truth and n in truth:
            ax.plot([100 * (truth[n] / s - 1)], [i], "k|", ms=14)
    ax.axvline(0, color="0.6", lw=0.8)
    ax.set_yticks(range(len(names)), names)
    ax.invert_yaxis()
    ax.set_xlabel("change from the start value (%), 95 % interval")
    ax.set_title("estimates" + (" (| = truth)" if truth else ""), fontsize=10)
    fig.tight_layout()
    return fig


def comparison_figure(comparison):
    """The residuals (in units of each channel's noise level) of every compared
    structure side by side: a column per structure (ranked, best on the left), a row
    per record and channel, the same vertical scale along a row.

    Parameters
    ----------
    comparison : Comparison
        From :func:`~ema_casadi.identification.compare`.
    """
    import matplotlib.pyplot as plt

    cols = [(row, res) for row, res in zip(comparison.rows, comparison.results, strict=True) if res is not None]
    if not cols:
        raise ValueError("no compared structure converged: nothing to plot")
    first = cols[0][1]
    lines = [(k, c) for k, tr in enumerate(first.trajectories) for c in tr["measured"]]
    fig, axes = plt.subplots(len(lines), len(cols), figsize=(3.2 * len(cols) + 0.8, 1.8 * len(lines) + 0.9),
                             sharex="row", sharey="row", squeeze=False)
    for j, (row, res) in enumerate(cols):
        for i, (k, c) in enumerate(lines):
            tr, ax = res.trajectories[k], axes[i, j]
            ax.plot(tr["t"], (tr["measured"][c] - tr["fitted"][c]) / res.sigma[c], lw=0.5,
                    color="C0" if row["adequate"] else "C3")
            ax.axhline(0, color="k", lw=0.5)
            if j == 0:
                ax.set_ylabel(f"{Path(tr['record']).name}\n{c} resid. / σ", fontsize=7)
        label = ", ".join(f"{key}={v}" for key, v in row["variants"].items())
        verdict = "adequate" if row["adequate"] else "inadequate"
        axes[0, j].set_title(f"{label}\nBIC {row['bic']:.6g}, {verdict}", fontsize=8)
        axes[-1, j].set_xlabel("time (s)")
    fig.suptitle("Compared structures: residuals, best first", fontsize=10)
    fig.tight_layout()
    return fig


def figures(result, truth: dict | None = None) -> dict:
    """Every figure of the report by name.

    Parameters
    ----------
    result : IdentResult
        The fit.
    truth : dict, optional
        Known true values marked on the intervals.
    """
    out = {f"fit_{k}": fit_figure(result, k) for k in range(len(result.trajectories))}
    if len(result.names) > 1:
        out["correlation"] = correlation_figure(result)
    out["intervals"] = intervals_figure(result, truth)
    return out


def report_names(n_records: int, n_free: int) -> list[str]:
    """The files of a report folder (checked before any work: the folder may hold only these).

    Parameters
    ----------
    n_records : int
        Records fitted (one figure each).
    n_free : int
        Free parameters (a correlation figure from two on).
    """
    names = [f"fit_{k}.png" for k in range(n_records)] + ["intervals.png", "summary.json", "summary.md"]
    return names + (["correlation.png"] if n_free > 1 else [])


def write_report(result, folder, extra: dict | None = None) -> Path:
    """The report folder, assembled aside and moved in whole.

    Parameters
    ----------
    result : IdentResult
        The fit.
    folder : str or Path
        The folder.
    extra : dict, optional
        More figures by name (``comparison``).
    """
    import matplotlib.pyplot as plt

    with atomic_dir(folder) as tmp:
        for name, fig in {**figures(result), **(extra or {})}.items():
            fig.savefig(Path(tmp) / f"{name}.png", dpi=110)
            plt.close(fig)
        (Path(tmp) / "summary.json").write_text(json.dumps(plain(result.to_dict()), indent=1) + "\n")
        (Path(tmp) / "summary.md").write_text("# Identification\n\n" + result.summary())
    return Path(folder)

