"""The text report of ``ema identify`` without --json: one fit, a trend, the example's records."""

from __future__ import annotations

import sys
from functools import partial
from pathlib import Path

from ..signals import column_unit, in_unit, unit_text
from ..signals import format_quantity as q


def _parameters(result: dict, w) -> None:
    """The parameter table: each row in its parameter's engineering unit (the unit column)."""
    from ..model.params import Parameters

    si = Parameters.units()
    w(f"{'parameter':<10} {'unit':>6} {'start':>11} {'estimate':>11} {'95 % interval (robust)':>25} "
      f"{'(textbook)':>25}  identifiable\n")
    for n, d in result["parameters"].items():
        u = si.get(n, "1")
        name, size = column_unit(u, [d["start"], d.get("estimate") or 0.0])
        name = unit_text(name)
        f = partial(in_unit, size=size, digits=5, si_unit=u)
        if d.get("estimate") is None:
            w(f"{n:<10} {name:>6} {f(d['start']):>11} {'(held)':>11} {'':>25}  no: {d['reason']}\n")
            continue
        lo, hi = d["interval"]
        ok = "yes" if d["identifiable"] else f"no: {d['reason']}"
        a, b = d.get("interval_textbook", (float("nan"), float("nan")))
        w(f"{n:<10} {name:>6} {f(d['start']):>11} {f(d['estimate']):>11} {f(lo):>12}..{f(hi):<12} "
          f"{f(a):>12}..{f(b):<12}  {ok}\n")
        if d.get("note"):
            w(f"{'':<10}   note: {d['note']}\n")


def _coarse(cf, w) -> None:
    """Coarse to fine's line: each level's block length and cost."""
    if cf:
        w("coarse to fine: residuals averaged over blocks of "
          + ", ".join(f"{1e3 * lv['block_s']:g} ms (cost {lv['cost']:.6g})" for lv in cf["levels"])
          + f", then every sample; {cf['evaluations']} coarse evaluations"
          + (f" ({cf['starts']} starts at the coarsest level)" if cf["starts"] > 1 else "")
          + f"; kept the {cf['kept']} end (" + ", ".join(f"{k} {v:.6g}" for k, v in cf["costs"].items())
          + " at the first weights)\n")


def _unsettled(doc, w) -> None:
    """The samples left out (``--unsettled leave-out``): the rule, each channel's windows."""
    if doc is None:
        return
    w(f"unsettled samples left out: {doc['samples']} ({doc['rule']})"
      + "".join(f"; {Path(c['record']).name} {c['channel']} " + ", ".join(f"{a:.3f}-{b:.3f} s" for a, b in c["windows"])
                for c in doc["channels"]) + "\n")


def fit_text(result: dict) -> str:
    """The parameter table, the channels' residuals, the verdict and what was written.

    Parameters
    ----------
    result : dict
        The fit's document (``IdentResult.to_dict`` and what the command added).
    """
    parts = []
    w = parts.append
    truth = result.get("example", {}).get("truth", {})
    if truth:
        w("example: records simulated with " + ", ".join(f"{k} = {v:.4g}" for k, v in truth.items()) + "\n")
    fs = result.get("friction_start") or {}
    if fs.get("used"):
        w(f"friction start: steady-state curve on {fs['segments']} steady segments ({fs['slow_segments']} slow, "
          f"{1e3 * fs['speeds'][0]:.3g}-{1e3 * fs['speeds'][1]:.3g} mm/s): "
          + ", ".join(f"{k} = {v:.4g}" for k, v in fs["values"].items())
          + "".join(f"; {k} kept ({why})" for k, why in fs["kept"].items()) + "\n")
        costs = fs.get("start_costs", [])
        if len(costs) > 1:
            w(f"  {len(costs)} starts (Latin hypercube over the friction parameters), costs"
              + (" at the coarsest level " if result.get("coarse_to_fine") else " ")
              + ", ".join("not converged" if c is None else f"{c:.6g}" for c in costs) + "\n")
    _coarse(result.get("coarse_to_fine"), w)
    _unsettled(result.get("unsettled"), w)
    _parameters(result, w)
    units = result.get("channel_units", {})
    for c in result["channels"]:
        u = units.get(c["channel"]) or "1"
        w(f"  {Path(c['record']).name}: {c['channel']} RMS residual {q(c['rms'], u)} (sensor noise sigma "
          f"{q(c['sigma'], u)}, x{c['rms_over_sigma']:.3f}), lag-1 autocorrelation {c['autocorr_lag1']:+.3f}\n")
    test = result.get("consistency")
    if test:
        w(f"records {'consistent' if test['consistent'] else 'DISAGREE'}: fitted alone they lower the cost by "
          f"{test['statistic']:.4g} (expected {test['expected']:.3g}, p = {test['p']:.2g})\n")
    for rec in (result.get("initial_state") or {}).get("records", []):
        w(f"  {Path(rec['record']).name} starts at " + ", ".join(f"{k} {v:.4g}" for k, v in rec["x0"].items()) + "\n")
    rob = result.get("robust") or {}
    if rob.get("scale_factor", 1.0) > 1.0:
        pc = rob.get("parts") or {}
        w(f"scale factor {rob['scale_factor']:.3g}: the records' {pc.get('count')} parts disagree (chi-square "
          f"{pc.get('chi2', float('nan')):.4g} for {pc.get('dof')} directions, p = {pc.get('p', 1.0):.2g}); "
          "a model error they share is taken as large as the one in which they differ; robust intervals "
          "inflated by it\n")
    me = result.get("model_error") or {}
    for m in me.get("misfits", [])[:6]:
        w(f"  systematic: {m['text']}\n")
    if result.get("verdict") == "adequate within model error":
        w(f"adequate within model error: systematic misfit at most {me['largest_sigma']:.2f} sigma (tolerated "
          f"{me['threshold_sigma']:g}), records' shifts at most {me['largest_shift_sd']:.2g} robust sd (tolerated "
          f"{me['threshold_shift_sd']:g}); robust intervals; failed tests: " + "; ".join(result["misfit"][:2]) + "\n")
    elif result.get("adequate", True):
        tests = "chi-square, whiteness" + (", consistency" if test else "")
        w(f"adequate: the residuals are explained by the noise ({tests})\n")
    else:
        for reason in result["misfit"]:
            w(f"INADEQUATE: {reason}\n")
    for hint in result.get("hints") or []:
        w(f"hint: {hint['text']}\n")
    for row in result.get("comparison", []):
        verdict = row.get("verdict") or ("adequate" if row["adequate"] else "INADEQUATE")
        state = "failed: " + row["failed"] if "failed" in row else verdict.replace("inadequate", "INADEQUATE")
        w(f"compared {row['variants']}: BIC {row['bic']:.6g}, {state}\n")
    for name, prof in result.get("profiles", {}).items():
        w(f"profile {name}: 95 % interval {prof['interval'][0]:.5g} .. {prof['interval'][1]:.5g}\n")
    for v in result.get("validation", []):
        w(f"validation {Path(v['record']).name}: {v['channel']} NRMSE {v['nrmse']:.4g}, "
          f"lag-1 autocorrelation {v['autocorr_lag1']:+.3f}\n")
    acc = result.get("prediction_accuracy") or {}
    checks = acc.get("checks", ())
    if len(checks) > 1:
        w(f"predictions tightened to rtol {acc['rtol']:.0e} (coarser ones moved the estimates)\n")
    num = acc.get("numerical")
    if num:
        name, sd = max(num["relative_sd"].items(), key=lambda kv: kv[1])
        w(f"predictions at rtol {acc['rtol']:.0e}: a tenth of it would still move {checks[-1]['parameter']} by "
          f"{checks[-1]['largest_shift_sd']:.2g} sd (a hundredth: {num['parameter']} by "
          f"{num['largest_shift_sd']:.2g} sd at most); the intervals include this numerical term "
          f"(largest: {name} +-{100 * sd:.2g} % sd)\n")
    w(f"{result['evaluations']} model evaluations, {result['wall_time']:.2f} s\n")
    for p in result.get("written", []):
        w(f"wrote {p}\n")
    return "".join(parts)


def failure_text(result: dict) -> str:
    """A fit without a result: its status, the last iterate, the cost's course, the
    hints (the reason itself is the command's line on stderr).

    Parameters
    ----------
    result : dict
        The document of ``FitFailed.to_dict`` (or of a comparison none of whose
        combinations converged).
    """
    parts = [f"status: {result['status']}\n"]
    it = result.get("last_iterate") or {}
    if it:
        parts.append("last iterate: " + ", ".join(f"{k} = {v:.6g}" for k, v in it.items()) + "\n")
    hist = [h["cost"] for h in result.get("cost_history") or []]
    if hist:
        parts.append(f"cost over {len(hist)} evaluations: {hist[0]:.6g} -> {min(hist):.6g} (last {hist[-1]:.6g})\n")
    for row in result.get("comparison", []):
        parts.append(f"compared {row['variants']}: failed: {row.get('failed', '')}\n")
    for hint in result.get("hints", []):
        parts.append(f"hint: {hint['text']}\n")
    return "".join(parts)


def text_report(result: dict) -> None:
    """Print the parameter table and the channels' residuals."""
    w = sys.stdout.write
    if "trend_truth" in result:  # --example-records
        w("example records: " + ", ".join(f"{k} = {v:.4g}" for k, v in result["truth"].items()) + "\n")
        for p in result["written"]:
            w(f"wrote {p}\n")
        return
    if "trend" in result:
        from ..identification import report_text

        w(report_text(result))
        return
    if result.get("converged") is False:  # the reason goes to stderr; the last iterate here
        w(failure_text(result))
        return
    w(fit_text(result))
