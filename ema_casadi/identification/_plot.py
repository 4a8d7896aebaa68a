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
    units of the channel's noise level) below each; the windows left out of the fit
    (``info["unsettled"]``) shaded.

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
    left = {c["channel"]: c["windows"] for c in (result.info.get("unsettled") or {}).get("channels", [])
            if c["record"] == tr["record"]}
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
        for n, (a, b) in enumerate(left.get(c, [])):  # the samples left out of the fit (weight zero)
            ax.axvspan(a, b, color="0.88", zorder=0, label=None if n else "left out (unsettled)")
            ax_r.axvspan(a, b, color="0.88", zorder=0)
        if c in left:
            ax.legend(loc="best", fontsize=8)
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


def misfit_figure(result):
    """Where the misfit is: per channel (a row each) the residual's running mean (in
    noise levels) against time for every record, the samples of each segment (hold,
    reversal, saturation) shaded where its systematic part is largest, and the
    tolerated model error as dashed lines.

    Parameters
    ----------
    result : IdentResult
        The fit (its :attr:`misfits`).
    """
    import matplotlib.pyplot as plt

    found = result.misfits
    chans = sorted({m["channel"] for m in found})
    fig, axes = plt.subplots(max(1, len(chans)), 1, figsize=(8, 2.2 * max(1, len(chans)) + 0.6), squeeze=False)
    tol = (result.adequacy.get("model_error") or {}).get("threshold_sigma")
    for ax, c in zip(axes[:, 0], chans, strict=False):
        for k, m in enumerate(m for m in found if m["channel"] == c):
            line, = ax.plot(m["t"], m["mean"] / m["noise"], lw=0.8, color=f"C{k}",
                            label=f"{Path(m['record']).name}: {m['systematic_sigma']:.2f} σ, {m['mostly']}")
            if m["systematic_sigma"] > 0.05:
                ax.axvspan(*m["span"], color=line.get_color(), alpha=0.12)
        if tol:
            for s in (-tol, tol):
                ax.axhline(s, color="k", lw=0.6, ls="--")
        ax.axhline(0, color="k", lw=0.4)
        ax.set_ylabel(f"{c}: mean resid. / σ", fontsize=8)
        ax.set_xlabel("time (s)", fontsize=8)
        ax.legend(fontsize=7, loc="best")
    fig.suptitle(f"systematic misfit (running mean over {1e3 * found[0]['window_s']:.0f} ms; shaded: where most of "
                 f"it sits)" if found else "systematic misfit", fontsize=10)
    fig.tight_layout()
    return fig


def records_figure(result):
    """Each record's own estimates side by side: per parameter (a panel each) the
    record's estimate alone (the consistency test's re-fit) against the joint estimate
    and its robust 95 % interval, relative to the joint estimate.

    Parameters
    ----------
    result : IdentResult
        A fit of several records (with the consistency test).
    """
    import matplotlib.pyplot as plt

    recs = (result.adequacy.get("consistency") or {}).get("records", [])
    names = list(result.names)
    fig, axes = plt.subplots(1, len(names), figsize=(2.0 * len(names) + 1, 3.2), squeeze=False)
    for ax, n in zip(axes[0], names, strict=True):
        est = result.estimate[n]
        lo, hi = result.interval[n]
        ax.axhspan(100 * (lo / est - 1), 100 * (hi / est - 1), color="C0", alpha=0.15, label="joint, robust 95 %")
        ax.axhline(0, color="C0", lw=1)
        for k, r in enumerate(recs):
            v = r.get("estimate_alone", {}).get(n)
            if v is not None:
                ax.plot([k], [100 * (v / est - 1)], "o", color=f"C{k + 1}", label=Path(r["record"]).stem)
        ax.set_title(n, fontsize=9)
        ax.set_xticks([])
        ax.tick_params(labelsize=7)
    axes[0, 0].set_ylabel("record alone vs joint (%)", fontsize=8)
    axes[0, -1].legend(fontsize=7, loc="best")
    fig.suptitle("each record's own estimates", fontsize=10)
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
    if result.misfits:
        out["misfit"] = misfit_figure(result)
    if (result.adequacy.get("consistency") or {}).get("records"):
        out["records"] = records_figure(result)
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
    names = [f"fit_{k}.png" for k in range(n_records)] + ["intervals.png", "summary.json", "summary.md",
                                                          "misfit.png"]
    return names + (["correlation.png"] if n_free > 1 else []) + (["records.png"] if n_records > 1 else [])


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

