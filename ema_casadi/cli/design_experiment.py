"""Design a rig test that pins named parameters down (optimal experiment design).

The command and load profile of --duration seconds whose 95 % intervals of the --free
parameters are smallest (D: the confidence ellipsoid's volume, A: the sum of the
relative variances, E: the largest; --weights NAME=W,... weights them, 0 leaves one
out), within +-stroke, the rig's load capability and the limits the parts declare
(motor current, rod speed (--max-speed), voltage, temperatures), from the Fisher information of the exact
forward sensitivities identify fits with. The test is a sequence of 1 s segments
(multisines of 1-50 Hz, constant-speed slews and stop-and-go steps at five load
levels); IPOPT chooses their shares (a convex problem), --prior FITTED.toml averages
the information over draws from an earlier fit's intervals. --out DIR writes design.csv (time, x_cmd,
f_ext: what the rig plays; ema simulate plays it as design.csv:x_cmd), the standard
test's records, summary.json, comparison.md and design.png. --verify N simulates
the designed and the standard test N times each with the noise, fits each with
identify and reports the realised intervals and their coverage against the predicted
ones, and the designed test's realised widths against the standard test's.
Example: ema design-experiment --free F_seal,c_v,J_m,psi --duration 10s --stroke 10mm --max-load 15kN --out test
"""

from __future__ import annotations

import sys

from . import UserError, add_progress, check_output_dir, load, progress_of
from ._common import key_values
from ._flags import NoEffect, check_bare

COMMAND = "design-experiment"
ORDER = 14
HELP = "design a rig test: the command and load profile that makes the parameters' intervals smallest"

#: The default free parameters (the seven of the recovery case).
FREE = "F_seal,C_bear,c_v,B,C,J_m,psi"


def add_arguments(p):
    p.add_argument("--free", default=FREE, metavar="NAME[,NAME...]",
                   help=f"parameters to pin down (flat names); default {FREE}")
    p.add_argument("--duration", default="10s", metavar="T", help="test length, whole seconds (10s, 8); default 10 s")
    p.add_argument("--criterion", default="DC", metavar="DC|D|A|E",
                   help="DC (D with no parameter's interval wider than the standard test's), D (ellipsoid "
                        "volume), A (sum of variances), E (largest variance); default DC")
    p.add_argument("--weights", default=None, metavar="NAME=W[,NAME=W...]",
                   help="weights of the parameters in the criterion (default 1 each; 0 leaves one out)")
    p.add_argument("--stroke", default="10mm", metavar="X", help="the rod stays within +-X; default 10 mm")
    p.add_argument("--max-load", default="15kN", metavar="F",
                   help="load capability of the rig (0: none); default 15 kN")
    p.add_argument("--max-speed", default=None, metavar="V",
                   help="bound on the rod speed, the speed loop's overshoot included; default and at most the "
                        "rated rod speed the model declares")
    p.add_argument("--sigma", action="append", default=[], metavar="CHANNEL=VALUE",
                   help="sensor noise of a channel, repeatable (0.3um, 0.05A); default a typical rig's")
    p.add_argument("--channels", default=None, metavar="NAME[,NAME...]",
                   help="measured channels (states or outputs); default the rod position and the motor current")
    p.add_argument("--prior", default=None, metavar="FITTED.toml",
                   help="average over draws from an earlier fit's 95 %% intervals (the file ema identify --out wrote)")
    p.add_argument("--draws", type=int, default=None, metavar="N",
                   help="parameter draws the information is averaged over; default 1, 4 with --prior")
    p.add_argument("--seed", type=int, default=0, metavar="N", help="seed of the draws and of --verify; default 0")
    p.add_argument("--verify", type=int, default=0, metavar="N",
                   help="simulate the designed and the standard test N times each with the noise, fit each "
                        "(identify) and compare their realised widths")
    p.add_argument("--out", default=None, metavar="DIR",
                   help="folder for design.csv, the standard test, summary.json, comparison.md, design.png")
    add_progress(p)


#: Where a flag has no effect (every other flag acts in every combination): --seed seeds
#: the prior's draws and --verify's noise, so without either it would change nothing.
NO_EFFECT = {
    **{f: () for f in ("--free", "--duration", "--criterion", "--weights", "--stroke", "--max-load", "--max-speed",
                       "--sigma", "--channels", "--prior", "--draws", "--verify", "--out")},
    "--seed": (NoEffect(("--seed", "3"), "without --draws above 1, --prior or --verify (it seeds the prior's draws "
                        "and the simulated noise)",
                        lambda a: not a.verify and a.prior is None and (a.draws or 1) <= 1),),
}


def _quantity(text: str, kind: str, flag: str) -> float:
    from ..signals import SI_UNIT, SignalError, parse_quantity

    try:
        return parse_quantity(str(text), kind, SI_UNIT[kind])
    except (SignalError, ValueError):
        raise UserError(f"{flag} {text}: expected a {kind} (a number in SI or with a unit)") from None


def _weights(text):
    if text is None:
        return None
    out = {}
    for key, value in key_values(text.split(","), "--weights", "NAME=W").items():
        try:
            out[key] = float(value)
        except ValueError:
            raise UserError(f"--weights {key}={value}: expected NAME=W, W a number") from None
    return out


def _sigma(items, model) -> dict:
    from ..signals import KIND_OF_UNIT, SignalError, parse_quantity

    units = model.units
    out = {}
    for key, value in key_values(items, "--sigma", "CHANNEL=VALUE").items():
        if key not in units:
            from .._util._checks import nearest

            raise UserError(f"--sigma {key}: not a model signal{nearest(key, units)}")
        kind = KIND_OF_UNIT.get(units[key])
        try:
            out[key] = parse_quantity(value, kind, units[key]) if kind else float(value)
        except (SignalError, ValueError):
            what = f"a number (SI) or a quantity in a {kind} unit" if kind else f"a number in {units[key]} (SI)"
            raise UserError(f"--sigma {key}={value}: expected {what}") from None
        check_bare("--sigma", key, value, out[key], kind, units[key], model)
    return out


def run(args) -> dict:
    from ..design import design_experiment, output_names

    if args.verify < 0:
        raise UserError(f"--verify must be at least 0, got {args.verify}")
    if args.draws is not None and args.draws < 1:
        raise UserError(f"--draws must be at least 1, got {args.draws}")
    out = check_output_dir(args.out, output_names(), "--out")
    duration = _quantity(args.duration, "time", "--duration")
    stroke = _quantity(args.stroke, "length", "--stroke")
    max_load = _quantity(args.max_load, "force", "--max-load")
    max_speed = None if args.max_speed is None else _quantity(args.max_speed, "rate", "--max-speed")
    params, model = load(args)
    kw = {"criterion": args.criterion.strip().upper(),
          "weights": _weights(args.weights), "stroke": stroke, "max_load": max_load, "max_speed": max_speed,
          "sigma": _sigma(args.sigma, model), "channels": args.channels, "prior": args.prior, "draws": args.draws,
          "seed": args.seed, "variants": None, "progress": progress_of(args)}
    res = design_experiment(params, args.free, duration, **kw)
    doc = res.to_json()
    if args.verify:
        doc["verification"] = res.verify(args.verify, seed=args.seed, progress=progress_of(args))
    doc["written"] = [str(res.write(out))] if out is not None else []
    doc["table"] = res.table()
    return doc


def _segment(s: dict) -> str:
    """A segment in words: ``multisine 4-16 Hz, 9.2 mm peak, at +15 kN``; ``6 slews
    between -9.2 and +9.2 mm at constant speed, 30 % of each move reversing it, at 0 kN``."""
    from ..signals import format_quantity as q

    level = float(s["load"])  # N, + pushes the rod in
    load = ("+" if level > 0 else "") + q(level, "N", unit="kN")
    if s["kind"] == "multisine":
        return f"multisine {s['band'][0]:g}-{s['band'][1]:g} Hz, {q(s['amplitude'], 'm', 3)} peak, at {load}"
    if s["kind"] == "steps":
        return (f"{int(s['band'][0])} moves between -{q(s['amplitude'], 'm', 3)} and +{q(s['amplitude'], 'm', 3)}, "
                f"at rest {100 * s['band'][1]:.3g} % of the time, at {load}")
    return (f"{int(s['band'][0])} slews between -{q(s['amplitude'], 'm', 3)} and +{q(s['amplitude'], 'm', 3)} at "
            f"constant speed, {100 * s['band'][1]:.3g} % of each move reversing it, at {load}")


def report(result: dict) -> None:
    """The comparison table, the segments, the limits used, the verification."""
    w = sys.stdout.write
    c = result["comparison"]
    w(f"{result['criterion']}-optimal {result['duration']:g} s test, {len(result['segments'])} kinds of segment "
      f"(IPOPT: {result['info']['ipopt']['status']}, {result['info']['admissible']} of "
      f"{result['info']['candidates']} candidates within the limits)\n")
    w(f"  segments of {result['info']['segment']:g} s, each at one load level (+ pushes the rod in):\n")
    for s in result["segments"]:
        if s["count"]:
            w(f"  {s['count']} x {_segment(s)}\n")
    w(result["table"] + "\n")
    ref = result["info"].get("reference")
    if ref:
        ok = ref["width_ratio_realised"] <= 1.0
        w(f"{'every' if ok else 'NOT every'} parameter's predicted interval within the standard test's: the widest "
          f"{ref['width_ratio_realised']:.3g} x it (target {ref['width_ratio_target']:g}; round "
          f"{ref['chosen_round'] + 1} of {len(ref['rounds'])})\n")
    lc = c["largest_correlation"]
    w(f"largest correlation: designed {lc['designed']['pair'][0]}-{lc['designed']['pair'][1]} "
      f"{lc['designed']['corr']:+.3f}, standard {lc['standard']['pair'][0]}-{lc['standard']['pair'][1]} "
      f"{lc['standard']['corr']:+.3f}\n")
    w("share of each limit the designed test reaches (100 %: on it): "
      + ", ".join(f"{k} {100 * v:.3g} %" for k, v in result["limits_used"].items()) + "\n")
    v = result.get("verification")
    if v:
        w(f"verify: {v['converged']} of {v['n']} fits converged ({v['restarted']} refitted from more starts), "
          f"{v['adequate']} adequate; coverage of the truth {100 * v['coverage']:.3g} % of their "
          f"{v['intervals_checked']} intervals ({100 * v['coverage_adequate']:.3g} % over the adequate fits), "
          f"limits {'respected' if v['limits_respected'] else 'LEFT'}\n")
        for n, r in v["width_ratio"].items():
            w(f"  {n}: realised width {100 * v['realised_width'][n]:.3g} % (median of the fits) / predicted "
              f"{100 * v['predicted_width'][n]:.3g} % = {r:.3f}\n")
        st = v.get("standard")
        if st:
            w(f"verify, the standard test: {st['converged']} of {v['n']} fits converged, {st['adequate']} adequate; "
              f"coverage {100 * st['coverage']:.3g} %; robust scale factor above 1 in {st['scale_factor_above_1']} "
              f"fits (designed test: {v['scale_factor_above_1']})\n")
            w("| parameter | realised width (median): designed | standard | designed / standard (<= 1: the design "
              "is narrower) | the same of the means |\n|---|---|---|---|---|\n")
            for n, r in v["against_standard"].items():
                w(f"| {n} | {100 * v['realised_width'][n]:.3g} % | {100 * v['standard_width'][n]:.3g} % | {r:.3f} | "
                  f"{v['against_standard_mean'][n]:.3f} |\n")
            w(f"| geometric mean, standard / designed | | | {v['geometric_mean_ratio']:.3g} | "
              f"{v['geometric_mean_ratio_mean']:.3g} |\n")
    for p in result.get("written", []):
        w(f"wrote {p}\n")
