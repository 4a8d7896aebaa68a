"""The result of a fit: estimates, Fisher-information uncertainty, identifiability,
residual statistics per channel and record, fitted trajectories; JSON, the fitted
parameter file, figures and the report folder."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._util._files import write_text
from .._util._notebook import Summarised
from ._data import plain
from ._residual_tests import adequacy, channel_stats
from ._write import write_fitted

#: A parameter is not identifiable from the records when its 95 % interval is wider than
#: this fraction of its value on either side ...
WIDE = 0.5
#: ... or when it is correlated with another beyond this.
CORRELATED = 0.95
#: Two-sided 95 % quantile of the normal distribution.
Z95 = 1.959963984540054


def uncertainty(free, z, J, r, estimated: bool, robust: dict | None = None, samples: int | None = None) -> dict:
    """Covariance in optimiser coordinates: the robust one of :mod:`._robust` when
    given (the headline), beside the textbook s^2 (J^T J)^-1 (s^2 = sum r^2 / (N - n)
    when noise levels were estimated, else 1); 95 % intervals (log-scaled parameters
    on log theta), correlation, weak directions (small singular values of J) and the
    identifiability verdicts (by the marginal interval; a strong correlation is a note).

    Parameters
    ----------
    free : Free
        The free parameters.
    z : ndarray
        The optimum in optimiser coordinates.
    J : ndarray
        Weighted residual Jacobian at the optimum (N x n).
    r : ndarray
        Weighted residuals at the optimum.
    estimated : bool
        Some noise levels were estimated from the residuals.
    robust : dict, optional
        :func:`._robust.robust_covariance` at this optimum: its ``cov`` gives the intervals.
    samples : int, optional
        The residuals that count (default: every row of J; rows left out are zeros).
    """
    N, n = samples or J.shape[0], J.shape[1]
    s2 = float(r @ r) / max(1, N - n) if estimated else 1.0
    U, sv, Vt = np.linalg.svd(J, full_matrices=False)
    tiny = sv <= sv[0] * 1e-12 if len(sv) else np.zeros(0, bool)
    inv = np.where(tiny, np.inf, 1.0 / np.where(tiny, 1.0, sv) ** 2)
    with np.errstate(invalid="ignore"):
        cov_tb = (Vt.T * np.where(np.isinf(inv), 1e300, inv)) @ Vt * s2
    singular = [bool(np.any(np.abs(Vt[tiny][:, k]) > 1e-6)) for k in range(n)] if tiny.any() else [False] * n
    std_tb = np.where(singular, np.inf, np.sqrt(np.diag(cov_tb)))
    cov_z = cov_tb if robust is None else np.asarray(robust["cov"], float)
    std_z = np.where(singular, np.inf, np.sqrt(np.maximum(np.diag(cov_z), 0.0)))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov_z / np.outer(std_z, std_z)
    corr = np.where(np.isfinite(corr), corr, 0.0)
    np.fill_diagonal(corr, 1.0)
    theta = free.theta(z)
    lo, hi, rel = _intervals(free, theta, std_z)
    lo_tb, hi_tb, _ = _intervals(free, theta, std_tb)
    D = free.dtheta_dz(theta)
    with np.errstate(invalid="ignore", over="ignore"):
        cov = cov_z * np.outer(D, D)
    offdiag = np.abs(corr - np.eye(n))
    partner = [int(np.argmax(offdiag[k])) if n > 1 else -1 for k in range(n)]
    correlated = [bool(n > 1 and offdiag[k, partner[k]] > CORRELATED) for k in range(n)]
    rel_id = rel
    if robust is not None and "cov_structural" in robust:  # identifiable: by what the records determine
        std_id = np.where(singular, np.inf, np.sqrt(np.maximum(np.diag(cov_z - robust["cov_structural"]), 0.0)))
        rel_id = _intervals(free, theta, std_id)[2]
    wide = [bool(not np.isfinite(rel_id[k]) or rel_id[k] > WIDE) for k in range(n)]
    weak = []
    for i in range(len(sv)):
        h = Z95 * np.sqrt(s2) / sv[i] if sv[i] > 0 else np.inf
        if h > np.log1p(WIDE):
            v = Vt[i] / np.max(np.abs(Vt[i]))
            weak.append({"singular_value": float(sv[i]), "halfwidth_log": float(h),
                         "direction": {free.names[k]: float(v[k]) for k in np.argsort(-np.abs(v)) if abs(v[k]) > 0.05}})
    return {"s2": s2, "cov_z": cov_z, "cov": cov, "std_z": std_z, "corr": corr, "interval": np.column_stack([lo, hi]),
            "halfwidth": rel, "wide": wide, "correlated": correlated, "partner": partner, "singular_values": sv,
            "weak": weak, "std_z_textbook": std_tb, "interval_textbook": np.column_stack([lo_tb, hi_tb]),
            "std_textbook": std_tb * np.abs(D), "std": std_z * np.abs(D),
            "combination": [_combination(free, cov_z, k, partner[k], theta) if correlated[k] else None
                            for k in range(n)], "robust": robust}


def _intervals(free, theta, std_z):
    """95 % intervals (lo, hi) and relative half-widths from standard deviations in
    optimiser coordinates (log-scaled parameters on log theta)."""
    half = Z95 * std_z
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        lo = np.where(free.log, theta * np.exp(-half), theta - half * free.dtheta_dz(theta))
        hi = np.where(free.log, theta * np.exp(half), theta + half * free.dtheta_dz(theta))
        rel = np.where(free.log, np.expm1(half), half * free.dtheta_dz(theta) / np.abs(theta))
    return lo, hi, rel


def _combination(free, cov_z, k, j, theta) -> dict:
    """The well-determined combination of two strongly correlated parameters: the
    eigenvector of their 2 x 2 covariance (optimiser coordinates: log theta for positive
    ones) with the smaller variance, as exponents theta_k^a theta_j^b (log-scaled) or a
    linear combination, with its 95 % relative half-width."""
    C = cov_z[np.ix_([k, j], [k, j])]
    w, V = np.linalg.eigh(0.5 * (C + C.T))
    v = V[:, 0] / V[np.argmax(np.abs(V[:, 0])), 0]
    names = (free.names[k], free.names[j])
    both_log = bool(free.log[k] and free.log[j])
    half = float(Z95 * np.sqrt(max(w[0], 0.0)) * np.linalg.norm(v))  # v^T z has variance w0 |v|^2
    text = (f"{names[0]}^{v[0]:.3g} * {names[1]}^{v[1]:+.3g}".replace("^+", "^") if both_log
            else f"{v[0]:.3g} {names[0]} {v[1]:+.3g} {names[1]} (scaled)")
    return {"names": list(names), "exponents": [float(v[0]), float(v[1])], "log": both_log, "expression": text,
            "halfwidth": float(np.expm1(half) if both_log else half)}


def _robust_doc(rob, records) -> dict:
    """The robust covariance's account for the result (plain data)."""
    if rob is None:
        return {"kind": "textbook"}
    recs = [{"record": rec.path, "bandwidth_samples": r["bandwidth"], "directions": r["directions"],
             "shift_sd": r["shift_sd"], "shift_robust_sd": r.get("shift_robust_sd", r["shift_sd"])}
            for rec, r in zip(records, rob["records"], strict=True)]
    return {"kind": "robust (Newey-West sandwich per record, x the scale factor of the records' parts)",
            "scale_factor": rob["scale_factor"], "tau2": rob.get("tau2", 0.0), "parts": rob.get("parts"),
            "records_chi2": rob["chi2"], "records_dof": rob["dof"], "records_p": rob.get("p"),
            "records": recs, **({"structural": rob["structural"], "structural_relative_sd": rob["structural_sd"]}
                                if "structural" in rob else {})}


@dataclass(repr=False)
class IdentResult(Summarised):
    """What :func:`~ema_casadi.identification.identify` found.

    Attributes
    ----------
    names : tuple of str
        The parameters fitted (those held on request are in :attr:`held`).
    start, estimate : dict
        Name -> start value and estimate (SI).
    interval : dict
        Name -> (lo, hi), the 95 % confidence interval (SI): the robust one
        (:mod:`._robust`, the sandwich of the residuals' autocorrelation, inflated by the
        disagreement of the records' parts), the textbook one in :attr:`interval_textbook`.
    std : dict
        Name -> standard deviation (SI, first order, robust).
    covariance, correlation : ndarray
        In :attr:`names` order (SI).
    identifiable : dict
        Name -> True, or the reason it is not: poorly determined (a robust 95 %
        interval wider than +-50 %, the estimate reported), or held on request; a
        strong correlation alone is a note, :attr:`notes`.
    held : dict
        Parameters held on request while the others were fitted again: name -> the
        value held, its type-B range, its estimate while free (:func:`._hold.held_doc`).
    weak_directions : list of dict
        Directions in log-parameter space the records determine poorly (from the SVD).
    channels : list of dict
        Residual statistics per record and channel (:func:`channel_stats`).
    sigma : dict
        Channel -> noise level used (SI).
    sigma_estimated : list of str
        The channels whose noise level came from the residuals.
    trajectories : list of dict
        Per record: ``t``, ``measured`` and ``fitted`` per channel (SI).
    notes : dict
        Name -> a note on an identifiable parameter (a strong correlation and the
        combination the records determine best).
    combinations : dict
        Name -> the best-determined combination with its strongly correlated partner:
        ``names``, ``exponents`` (theta_a^x theta_b^y for log-scaled ones), ``halfwidth``
        (95 %, relative).
    interval_textbook, std_textbook : dict
        The textbook s^2 (J^T J)^-1 intervals and standard deviations (white noise of
        the stated level, exact model), beside the headline robust ones.
    misfits : list of dict
        Per record and channel the systematic misfit, its running mean and where it
        sits (:func:`._misfit.misfits`).
    robust : dict
        How the robust covariance was made (:mod:`._robust`): the scale factor, the
        records' chi-square, each record's bandwidth and shift in robust sd.
    status : str
        ``converged``.
    adequacy : dict
        ``adequate`` and the ``reasons`` when the residuals are not explained by the
        noise (:func:`adequacy`); the intervals of an inadequate fit are not
        trustworthy (they assume the model's structure is right).
    info : dict
        Cost, evaluations, wall time, the model's variants, records, noise factor s^2.
    params, fitted_params : Parameters
        The set fitted and the set with the estimates in place (held parameters at
        their held values).
    """

    names: tuple
    start: dict
    estimate: dict
    interval: dict
    std: dict
    covariance: np.ndarray
    correlation: np.ndarray
    identifiable: dict
    held: dict
    weak_directions: list
    channels: list
    sigma: dict
    sigma_estimated: list
    trajectories: list
    status: str = "converged"
    adequacy: dict = field(default_factory=lambda: {"adequate": True, "reasons": []})
    info: dict = field(default_factory=dict)
    params: object = field(default=None, repr=False)
    fitted_params: object = field(default=None, repr=False)
    notes: dict = field(default_factory=dict)
    combinations: dict = field(default_factory=dict)
    interval_textbook: dict = field(default_factory=dict)
    std_textbook: dict = field(default_factory=dict)
    robust: dict = field(default_factory=dict)
    misfits: list = field(default_factory=list, repr=False)

    def _facts(self) -> dict:
        return {"fitted": ", ".join(self.names), "held": ", ".join(self.held) or None,
                "adequate": self.adequacy.get("adequate"), "records": len(self.info.get("records", [])) or None,
                "evaluations": self.info.get("evaluations")}

    @classmethod
    def _build(cls, *, model, params, free, theta, unc, out, records, preds, errors, held, wall_time, evaluations,
              start):
        """The result from the pieces of :func:`identify` (internal)."""
        names = free.names
        ident = {}
        for k, n in enumerate(names):
            if unc["wide"][k]:
                ident[n] = (f"poorly determined: 95 % interval +-{100 * unc['halfwidth'][k]:.3g} % (wider than "
                            f"+-{100 * WIDE:g} %)")
            else:
                ident[n] = True
        notes, combos = {}, {}
        for k, n in enumerate(names):
            if unc["correlated"][k] and not unc["wide"][k]:
                j, comb = unc["partner"][k], unc["combination"][k]
                combos[n] = comb
                notes[n] = (f"correlated with {names[j]} ({unc['corr'][k, j]:+.3f}); each is determined to its "
                            f"interval, and {comb['expression']} to +-{100 * comb['halfwidth']:.2g} %")
        for n, h in held.items():
            how, half = "its start value" if h["at_start"] else "the value named", 100 * h["relative_halfwidth"]
            ident[n] = f"held at {h['held_at']:.6g} on request ({how}); 95 % interval +-{half:.3g} % when free"
        traj = [{"record": rec.path, "t": rec.t, "measured": dict(rec.channels),
                 "fitted": {c: pr["y"][c] for c in rec.channels}} for rec, pr in zip(records, preds, strict=True)]
        fitted = params.replace(**{n: float(v) for n, v in zip(names, theta, strict=True)},
                                **{n: h["held_at"] for n, h in held.items()})
        stats = channel_stats(records, preds, errors, out["sigma"])
        return cls(names=tuple(names), start={n: float(start[n]) for n in names},
                   estimate={n: float(v) for n, v in zip(names, theta, strict=True)},
                   interval={n: (float(a), float(b)) for n, (a, b) in zip(names, unc["interval"], strict=True)},
                   std={n: float(v) for n, v in zip(names, unc["std"], strict=True)},
                   covariance=unc["cov"], correlation=unc["corr"], identifiable=ident, held=held,
                   weak_directions=unc["weak"], channels=stats, adequacy=adequacy(stats, out["estimated"]),
                   notes=notes, combinations=combos, interval_textbook={n: (float(a), float(b)) for n, (a, b)
                                                   in zip(names, unc["interval_textbook"], strict=True)},
                   std_textbook={n: float(v) for n, v in zip(names, unc["std_textbook"], strict=True)},
                   robust=_robust_doc(unc.get("robust"), records),
                   sigma=dict(out["sigma"]), sigma_estimated=list(out["estimated"]), trajectories=traj,
                   info={"cost": out["cost"], "s2": unc["s2"], "evaluations": int(evaluations),
                         "wall_time": wall_time, "variants": dict(model.variants),
                         "records": [r.path for r in records],
                         "units": {c: model.units.get(c, "") for r in records for c in r.channels},
                         "samples": int(sum(len(v) for v in errors.values())),
                         "solver": "Levenberg-Marquardt, exact Jacobian (RODAS4 forward sensitivities)",
                         "optimizer_message": out["message"]},
                   params=params, fitted_params=fitted)

    # -- views ---------------------------------------------------------------------
    def to_dict(self) -> dict:
        """The result as plain data (the ``--json`` document; no trajectories)."""
        params = {}
        for n in self.names:
            params[n] = {"start": self.start[n], "estimate": self.estimate[n], "interval": list(self.interval[n]),
                         "std": self.std[n], "identifiable": self.identifiable[n] is True,
                         **({} if self.identifiable[n] is True else {"reason": self.identifiable[n],
                             "poorly_determined": self.identifiable[n].startswith("poorly")}),
                         **({"note": self.notes[n], "combination": self.combinations.get(n)}
                            if n in self.notes else {}),
                         **({"interval_textbook": list(self.interval_textbook[n]),
                             "std_textbook": self.std_textbook[n]} if n in self.interval_textbook else {})}
        for n, h in self.held.items():
            params[n] = {"start": h["start"], "estimate": None, "identifiable": False, "reason": self.identifiable[n],
                         **{k: v for k, v in h.items() if k != "start"}}
        return {"status": self.status, "adequate": self.adequacy["adequate"],
                "verdict": self.adequacy.get("verdict", "adequate" if self.adequacy["adequate"] else "inadequate"),
                "misfit": self.adequacy["reasons"], "intervals_trustworthy": self.adequacy["adequate"],
                "model_error": self.adequacy.get("model_error"), "interval_kind": self.robust.get("kind", "textbook"),
                "robust": self.robust, "consistency": self.adequacy.get("consistency"),
                "parameters": params, "correlation": {
                    "names": list(self.names), "matrix": np.round(self.correlation, 6).tolist()},
                "weak_directions": self.weak_directions, "channels": self.channels,
                "sigma": self.sigma, "sigma_estimated": self.sigma_estimated, **self.info}

    def to_json(self, path: str | Path) -> Path:
        """Write :meth:`to_dict` as JSON (atomically).

        Parameters
        ----------
        path : str or Path
            The file.
        """
        return write_text(path, json.dumps(plain(self.to_dict()), indent=1) + "\n")

    def summary(self) -> str:
        """A Markdown summary: the parameters with intervals and verdicts, the channels."""
        lines = [f"Verdict: **{self.adequacy.get('verdict', 'adequate')}**", "",
                 "| parameter | start | estimate | 95 % interval (robust) | 95 % (textbook) | identifiable |",
                 "|---|---|---|---|---|---|"]
        for n in self.names:
            lo, hi = self.interval[n]
            a, b = self.interval_textbook.get(n, (float("nan"),) * 2)
            ok = "yes" if self.identifiable[n] is True else f"**no**: {self.identifiable[n]}"
            ok += f" ({self.notes[n]})" if n in self.notes else ""
            lines.append(f"| {n} | {self.start[n]:.5g} | {self.estimate[n]:.5g} | {lo:.5g} .. {hi:.5g} | "
                         f"{a:.5g} .. {b:.5g} | {ok} |")
        for n, h in self.held.items():
            lines.append(f"| {n} | {h['start']:.5g} | (held at {h['held_at']:.5g}) | - | - | **no**: "
                         f"{self.identifiable[n]} |")
        for m in (self.adequacy.get("model_error") or {}).get("misfits", []):
            lines.append(f"\nModel error: {m['text']}")
        if "structural" in self.robust:
            sd = ", ".join(f"{k} {100 * v:.2g} %" for k, v in self.robust["structural_relative_sd"].items())
            rng = ", ".join(f"{k} {c['range'][0]:g}..{c['range'][1]:g}" for k, c in self.robust["structural"].items())
            lines.append(f"\nStructural (type B, in the robust intervals; ranges {rng}): sd {sd}")
        lines += ["", "| record | channel | samples | RMS residual | sigma | RMS/sigma | lag-1 autocorr. |",
                  "|---|---|---|---|---|---|---|"]
        for c in self.channels:
            lines.append(f"| {Path(c['record']).name} | {c['channel']} | {c['samples']} | {c['rms']:.4g} | "
                         f"{c['sigma']:.4g} | {c['rms_over_sigma']:.3f} | {c['autocorr_lag1']:+.3f} |")
        for w in self.weak_directions:
            d = ", ".join(f"{v:+.2f} {k}" for k, v in w["direction"].items())
            lines.append(f"\nWeak direction (log-parameters): {d} (95 % half-width {w['halfwidth_log']:.3g} in log)")
        return "\n".join(lines) + "\n"

    def write(self, path: str | Path, note: str = "") -> Path:
        """Write the fitted parameter file: the input file's text with the estimates put
        in place of the values (comments and layout kept), a header naming the fit;
        parameters held on request get their held values (and say so).

        Parameters
        ----------
        path : str or Path
            The ``.toml`` file.
        note : str
            An extra line for the header (the command that made it).
        """
        head = ["Fitted by ema identify (weighted least squares, exact sensitivities) to: "
                + ", ".join(Path(r).name for r in self.info["records"])]
        if note:
            head.append(note)
        if not self.adequacy["adequate"]:
            head.append("INADEQUATE FIT: the residuals are not explained by the noise; the intervals are not "
                        "trustworthy: " + "; ".join(self.adequacy["reasons"][:3]))
        elif self.adequacy.get("verdict") == "adequate within model error":
            head.append("ADEQUATE WITHIN MODEL ERROR (robust intervals): "
                        + "; ".join(m["text"] for m in self.adequacy["model_error"]["misfits"][:3]))
        for n in self.names:
            lo, hi = self.interval[n]
            tag = "" if self.identifiable[n] is True else f"  {self.identifiable[n].upper()}"
            head.append(f"  {n}: {self.start[n]:.6g} -> {self.estimate[n]:.6g} (95 %: {lo:.6g} .. {hi:.6g}){tag}")
        for n in self.held:
            head.append(f"  {n}: HELD: {self.identifiable[n]}")
        values = {**self.estimate, **{n: h["held_at"] for n, h in self.held.items()}}
        return write_fitted(self.params, values, path, "\n".join(head), self.info.get("variant_overrides"))

    def plot(self, truth: dict | None = None) -> dict:
        """The report's figures (matplotlib Figures by name): ``fit_<k>`` measured vs
        fitted and residuals per record, ``correlation`` the heat map, ``intervals``
        the estimates with their intervals relative to the start.

        Parameters
        ----------
        truth : dict, optional
            Known true values (SI) marked on ``intervals`` (records made by simulation).
        """
        from ._plot import figures

        return figures(self, truth)

    def write_report(self, folder: str | Path) -> Path:
        """Write the report folder (assembled aside and moved in): the figures as PNG,
        ``summary.json`` and ``summary.md``.

        Parameters
        ----------
        folder : str or Path
            The folder (replaced whole).
        """
        from ._plot import write_report

        return write_report(self, folder)


def initial_states(fit, out: dict) -> dict:
    """How each record started: ``{"estimated": [states], "records": [{state: value}]}``
    (SI), the estimated offsets' standard deviations alongside (``std``)."""
    pred = fit.pred
    states = pred.x0_states
    if not states:
        return {"estimated": [], "rule": "at rest at the first sample"}
    n, m = len(pred.free.names), len(states)
    J, r = out["J_full"], out["r"]
    s2 = float(r @ r) / max(1, out.get("samples", len(r)) - J.shape[1]) if out["estimated"] else 1.0
    cov = s2 * np.linalg.pinv(J.T @ J)
    std = np.sqrt(np.maximum(np.diag(cov)[n:], 0)).reshape(len(pred.records), m) * pred.x0_scale
    rows = []
    for k in range(len(pred.records)):
        x0 = pred.x0(k, pred.p(pred.free.theta(out["z"])))
        rows.append({"record": pred.records[k].path,
                     "x0": {s: float(x0[i]) for s, i in zip(states, pred.x0_index, strict=True)},
                     "std": {s: float(v) for s, v in zip(states, std[k], strict=True)}})
    return {"estimated": list(states), "rule": "estimated (offsets from rest at the first sample)", "records": rows}
