"""The sweep description (TOML): checked whole before any run, expanded into runs.

Format (docs: sweeps; ``models/sweep_hunting_backlash.toml`` is a
complete example)::

    [sweep]
    name = "hunting over backlash"
    seed = 2026                 # needed when a parameter is drawn from a distribution
    samples = 100               # Monte Carlo draws per grid point (default 1)

    [variants]                  # one value (all runs) or a list (a grid axis)
    friction = "hybrid"

    [parameters]                # flat names of the parameter file (SI), as model.p(...)
    B = { from = 2e-5, to = 5e-4, points = 10 }                       # grid
    F_seal = { distribution = "uniform", low = 0.5, high = 1.5, relative = true }
    C = { distribution = "normal", mean = 1.0, std = 0.1, low = 0.7, high = 1.3, relative = true }

    [scenario]                  # the simulation every run makes (when a metric needs it)
    duration = 4.0
    x_cmd = "step:1mm@0.01"     # signal syntax (docs: simulate); bare numbers mm (x_cmd), N (f_ext)
    solver = "rk4"
    dt = 1e-4

    [metrics]                   # names of the registry, each with its options
    hunting = { from = 2.0 }
    step = {}

Runs: the grid axes (variant lists first, then parameter grids, in file order) are
crossed; at every grid point ``samples`` draws are made. Draw ``s`` of parameter ``k``
comes from its own generator ``numpy.random.default_rng([seed, s, k])``: the values do
not depend on the number of workers, on the order the runs are made in, or on how
many samples are asked for (the first 100 of 1000 are the 100 of a smaller sweep), and
every grid point sees the same draws (common random numbers: differences between grid
points are the grid's, not the draws'). Bounds truncate a distribution (draws outside
are redrawn from the same generator).
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
from dataclasses import dataclass, field, fields
from pathlib import Path

import numpy as np

from .._util._checks import budget, nearest, read_toml
from .._util._errors import InputError
from ..model.components import SIGNAL_KEYS, VARIANTS, validate_variants
from ..model.params import GROUPS, ParameterError, Parameters
from ..signals import Signal, SignalError, parse_signal
from ..simulation import check_value_range
from ._metrics import METRICS, check_metrics

__all__ = ["SweepError", "SweepSpec", "Run", "load_sweep", "parse_sweep", "DISTRIBUTIONS"]

DISTRIBUTIONS = ("uniform", "normal", "lognormal")
#: Draws outside a distribution's bounds are redrawn at most this often.
MAX_REDRAWS = 1000
#: Most runs one sweep may hold.
MAX_RUNS = 10**6
_TABLES = ("sweep", "variants", "parameters", "scenario", "metrics")
#: The scenario's command and load: their roles, the signal kinds and bare units, and their keys in
#: the file (from the one key table); other inputs go by name under ``inputs``.
_DRIVEN = (("command", "length", "mm"), ("load", "force", "N"))
_SETTINGS = ("duration", "solver", "dt", "dt_out", "rtol", "atol", "event_tol", "zoh")
_SCENARIO_KEYS = (*_SETTINGS[:1], *(SIGNAL_KEYS[r] for r, _, _ in _DRIVEN), "inputs", *_SETTINGS[1:])
_GRID_KEYS = ("values", "from", "to", "points", "spacing", "relative", "unit")
_DIST_KEYS = ("distribution", "low", "high", "mean", "std", "median", "sigma", "relative", "unit")


class SweepError(InputError, ValueError):
    """A mistake in a sweep description or request (one line naming file and key)."""


@dataclass(frozen=True)
class Run:
    """One run of a sweep: its index, variant choice and parameter values (SI).

    Attributes
    ----------
    index : int
        Position in the sweep (the ``run`` column).
    variant : tuple
        (key, value) pairs of the complete variant choice.
    values : dict
        Swept parameter -> value (SI).
    """

    index: int
    variant: tuple
    values: dict


@dataclass
class SweepSpec:
    """A checked sweep description.

    Attributes
    ----------
    name : str
        Its name (the file's stem by default).
    source : str
        Where it came from.
    params : Parameters
        The parameter set the runs start from.
    variants : dict
        Variant key -> list of values (one value: fixed).
    parameters : dict
        Parameter -> its checked description (grid values or distribution).
    scenario : dict
        The simulation: ``duration``, ``signals`` (input role or name -> Signal: the
        command and load by role, other inputs by name), solver options.
    metrics : dict
        Metric name -> its options (:data:`~ema_casadi.sweeps.METRICS`).
    seed : int or None
        The Monte Carlo seed.
    samples : int
        Draws per grid point.
    runs : list of Run
        Every run, in order.
    """

    name: str
    source: str
    params: Parameters
    variants: dict
    parameters: dict
    scenario: dict
    metrics: dict
    seed: int | None
    samples: int
    runs: list = field(default_factory=list)

    @property
    def swept_variants(self) -> list[str]:
        """Variant keys with more than one value (columns of the table)."""
        return [k for k, v in self.variants.items() if len(v) > 1]

    def fingerprint(self) -> str:
        """A hash of everything that determines the rows: the runs, the parameter set,
        the scenario and the metrics (a journal of another sweep is refused)."""
        if getattr(self, "_fingerprint", None) is None:
            self._fingerprint = self._hash()
        return self._fingerprint

    def _hash(self) -> str:
        doc = {"params": self.params.as_dict(), "runs": [[r.index, list(r.variant), r.values] for r in self.runs],
               "scenario": {k: (v if k != "signals" else {SIGNAL_KEYS.get(n, n): s.text or repr(s)
                                                          for n, s in v.items()})
                            for k, v in self.scenario.items()},
               "metrics": self.metrics, "version": 1}
        return hashlib.sha256(json.dumps(doc, sort_keys=True, default=repr).encode()).hexdigest()[:16]


def load_sweep(path: str | Path, params: Parameters, variants: dict | None = None) -> SweepSpec:
    """Read and check a sweep description (TOML); every run expanded and validated.

    Parameters
    ----------
    path : str or Path
        The sweep file.
    params : Parameters
        The parameter set the runs start from.
    variants : dict, optional
        Variant choices under the file's ``[variants]`` (the command line's ``--variant``).
    """
    path = Path(path)
    data = read_toml(path, "sweep file", SweepError)
    return parse_sweep(data, params, str(path), variants, name=path.stem)


def parse_sweep(data: dict, params: Parameters, src: str = "<sweep>", variants: dict | None = None,
                name: str = "sweep") -> SweepSpec:
    """Check a sweep description given as the dict ``tomllib`` returns.

    Parameters
    ----------
    data : dict
        The description.
    params : Parameters
        The parameter set the runs start from.
    src : str
        Named in error messages.
    variants : dict, optional
        Variant choices under the description's.
    name : str
        Default name.
    """
    if not isinstance(params, Parameters):
        raise SweepError("params: expected a Parameters (from load_parameters)")
    if not isinstance(data, dict):
        raise SweepError(f"{src}: expected a table of tables")
    _known(src, data, _TABLES, "table")
    head = _table(data, "sweep", src)
    _known(f"{src} [sweep]", head, ("name", "seed", "samples"), "key")
    seed = head.get("seed")
    samples = head.get("samples", 1)
    if isinstance(samples, bool) or not isinstance(samples, int) or samples < 1:
        raise SweepError(f"{src} [sweep] samples: expected a positive integer, got {samples!r}")
    vspec = _variants(_table(data, "variants", src), params, variants or {}, src)
    pspec = {k: _parameter(f"{src} [parameters] {k}", k, v, params)
             for k, v in _table(data, "parameters", src).items()}
    metrics = _table(data, "metrics", src)
    return _assembled(str(head.get("name", name)), src, params, vspec, pspec, seed, samples, metrics,
                      lambda: _scenario(_table(data, "scenario", src), params, src, vspec))


def make_sweep(params: Parameters, scenario: dict, metrics: dict, *, parameters: dict | None = None,
               variants: dict | None = None, seed: int | None = None, samples: int = 1, name: str = "sweep",
               source: str = "<sweep>") -> SweepSpec:
    """A sweep built from Python objects (no file text): the scenario's signals as
    :class:`~ema_casadi.signals.Signal` objects, checked as :func:`parse_sweep` checks a file.

    Parameters
    ----------
    params : Parameters
        The parameter set the runs start from.
    scenario : dict
        ``duration``, ``dt``, ``dt_out``, ``rtol``, ``atol``, ``event_tol`` (s or -),
        ``solver``, ``zoh``, as a file's ``[scenario]``, and ``signals``: input role or
        name -> Signal (``{"command": Signal.step(1e-3, 0.01)}``).
    metrics : dict
        Metric name -> its options (:data:`~ema_casadi.sweeps.METRICS`), as ``[metrics]``.
    parameters : dict, optional
        Parameter -> its description (grid or distribution), as ``[parameters]``.
    variants : dict, optional
        Variant key -> a value or a list of values, as ``[variants]``.
    seed : int, optional
        The Monte Carlo seed (needed with a distribution).
    samples : int
        Draws per grid point.
    name, source : str
        The sweep's name, and where it came from (named in error messages).
    """
    if not isinstance(params, Parameters):
        raise SweepError("params: expected a Parameters (from load_parameters)")
    for what, value in (("scenario", scenario), ("metrics", metrics), ("parameters", parameters or {}),
                        ("variants", variants or {})):
        if not isinstance(value, dict):
            raise SweepError(f"{source} {what}: expected a dict, got {type(value).__name__}")
    vspec = _variants(dict(variants or {}), params, {}, source)
    pspec = {k: _parameter(f"{source} parameters {k}", k, v, params) for k, v in (parameters or {}).items()}

    def checked() -> dict:
        where = f"{source} scenario"
        _known(where, scenario, (*_SETTINGS, "signals"), "key")
        signals = scenario.get("signals", {})
        bad = [k for k, s in signals.items() if not isinstance(s, Signal)] if isinstance(signals, dict) else [None]
        if bad:
            raise SweepError(f"{where} signals: expected input (role or name) -> Signal, got {signals!r}")
        return {**_settings(scenario, where), "signals": dict(signals)}

    return _assembled(name, source, params, vspec, pspec, seed, samples, metrics, checked)


def _assembled(name, src, params, vspec, pspec, seed, samples, metrics, scenario) -> SweepSpec:
    """The checked sweep: its runs expanded and checked, then its scenario (``scenario()``)
    and its metrics."""
    if seed is not None and (isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer))
                             or seed < 0):
        raise SweepError(f"{src} [sweep] seed: expected a non-negative integer, got {seed!r}")
    if any("distribution" in d for d in pspec.values()) and seed is None:
        raise SweepError(f"{src} [sweep] seed: needed when a parameter is drawn from a distribution")
    if not any("distribution" in d for d in pspec.values()) and samples > 1:
        raise SweepError(f"{src} [sweep] samples = {samples}: no parameter is drawn from a distribution")
    if not metrics:
        raise SweepError(f"{src} [metrics]: name at least one metric ({', '.join(METRICS)})")
    spec = SweepSpec(name=name, source=src, params=params, variants=vspec, parameters=pspec,
                     scenario={}, metrics={}, seed=seed, samples=samples)
    spec.runs = _expand(spec)
    _check_runs(spec, src)
    spec.scenario = scenario()
    spec.metrics = check_metrics(spec, metrics, src, SweepError)
    return spec


def _known(where, table, keys, what):
    for k in table:
        if k not in keys:
            raise SweepError(f"{where}: unknown {what} '{k}'{nearest(k, keys)}; expected one of {', '.join(keys)}")


def _table(data, name, src) -> dict:
    t = data.get(name, {})
    if not isinstance(t, dict):
        raise SweepError(f"{src} [{name}]: expected a table, got {type(t).__name__}")
    return t


def _variants(table, params, given, src) -> dict:
    out = {k: [v] for k, v in validate_variants({**params.variants, **given}, f"{src} [variants]").items()}
    for key, value in table.items():
        values = value if isinstance(value, list) else [value]
        if not values or not all(isinstance(v, str) for v in values):
            raise SweepError(f"{src} [variants] {key}: expected a variant name or a list of them, got {value!r}")
        if key not in VARIANTS:
            raise SweepError(f"{src} [variants]: unknown variant key '{key}'{nearest(key, VARIANTS)}")
        for v in values:
            if v not in VARIANTS[key]:
                raise SweepError(f"{src} [variants] {key}: unknown value '{v}'; allowed: {', '.join(VARIANTS[key])}")
        if len(set(values)) != len(values):
            raise SweepError(f"{src} [variants] {key}: a value is repeated in {values}")
        out[key] = list(values)
    for combo in itertools.product(*out.values()):
        try:
            validate_variants(dict(zip(out, combo, strict=True)), f"{src} [variants]")
        except ParameterError as exc:
            raise SweepError(str(exc)) from None
    return out


def _num(where, d, key, required=True):
    if key not in d:
        if required:
            raise SweepError(f"{where}: missing '{key}'")
        return None
    v = d[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise SweepError(f"{where} {key}: expected a finite number, got {v!r}")
    return float(v)


def _parameter(where, name, d, params) -> dict:
    scalars = params.scalars()  # name -> (nominal, unit, check); with instances A.C, B.x_rig, ...
    if name not in scalars:
        raise SweepError(f"{where}: no parameter '{name}'{nearest(name, scalars)} (the flat names of the "
                         "parameter file, e.g. B, F_seal, C, K_i_x)")
    if not isinstance(d, dict):
        raise SweepError(f"{where}: expected a table such as {{ values = [...] }} or {{ distribution = \"uniform\", "
                         f"low = ..., high = ... }}, got {d!r}")
    unit = scalars[name][1]
    if "unit" in d and d["unit"] != unit:
        raise SweepError(f"{where} unit: '{d['unit']}' is not the parameter's SI unit '{unit}' (values are SI)")
    relative = d.get("relative", False)
    if not isinstance(relative, bool):
        raise SweepError(f"{where} relative: expected true or false, got {relative!r}")
    nominal = scalars[name][0]
    scale = nominal if relative else 1.0
    if "distribution" in d:
        return _distribution(where, d, scale) | {"relative": relative}
    _known(where, d, _GRID_KEYS, "key")
    if "values" in d:
        vals = d["values"]
        if not isinstance(vals, list) or not vals:
            raise SweepError(f"{where} values: expected a non-empty list of numbers, got {vals!r}")
        values = [_num(where, {"values": v}, "values") for v in vals]
    elif "from" in d:
        a, b = _num(where, d, "from"), _num(where, d, "to")
        n = d.get("points")
        if isinstance(n, bool) or not isinstance(n, int) or n < 2:
            raise SweepError(f"{where} points: expected an integer >= 2, got {n!r}")
        budget(n, MAX_RUNS, f"{where} points", SweepError, unit="runs", limit_name="MAX_RUNS")
        spacing = d.get("spacing", "linear")
        if spacing not in ("linear", "log"):
            raise SweepError(f"{where} spacing: expected 'linear' or 'log', got {spacing!r}")
        if spacing == "log" and not (a > 0 and b > 0):
            raise SweepError(f"{where}: log spacing needs positive from and to")
        values = list(np.geomspace(a, b, n) if spacing == "log" else np.linspace(a, b, n))
    else:
        raise SweepError(f"{where}: give 'values', 'from'/'to'/'points' (a grid) or 'distribution'")
    return {"grid": [float(v) * scale for v in values], "relative": relative}


def _distribution(where, d, scale) -> dict:
    _known(where, d, _DIST_KEYS, "key")
    kind = d["distribution"]
    if kind not in DISTRIBUTIONS:
        raise SweepError(f"{where} distribution: '{kind}' unknown{nearest(str(kind), DISTRIBUTIONS)}; "
                         f"choose one of {', '.join(DISTRIBUTIONS)}")
    low, high = _num(where, d, "low", kind == "uniform"), _num(where, d, "high", kind == "uniform")
    out = {"distribution": kind, "low": None if low is None else low * scale,
           "high": None if high is None else high * scale}
    if kind == "normal":
        out["mean"], out["std"] = _num(where, d, "mean") * scale, _num(where, d, "std") * abs(scale)
        if out["std"] <= 0:
            raise SweepError(f"{where} std: must be positive")
    elif kind == "lognormal":
        out["median"], out["sigma"] = _num(where, d, "median") * scale, _num(where, d, "sigma")
        if out["median"] <= 0 or out["sigma"] <= 0:
            raise SweepError(f"{where}: median and sigma of a lognormal must be positive")
    if low is not None and high is not None and not out["low"] < out["high"]:
        raise SweepError(f"{where}: low ({out['low']:g}) must be below high ({out['high']:g})")
    return out


def _draw(where, d, rng) -> float:
    for _ in range(MAX_REDRAWS):
        if d["distribution"] == "uniform":
            v = rng.uniform(d["low"], d["high"])
        elif d["distribution"] == "normal":
            v = rng.normal(d["mean"], d["std"])
        else:
            v = d["median"] * math.exp(rng.normal(0.0, d["sigma"]))
        if (d["low"] is None or v >= d["low"]) and (d["high"] is None or v <= d["high"]):
            return float(v)
    raise SweepError(f"{where}: no draw within [low, high] in {MAX_REDRAWS} tries; the bounds exclude the "
                     "distribution")


def _whole(name: str, v: float) -> float:
    """A draw of a parameter that is a whole number (a seed: floored, the stream the
    noise generator reads; a positive integer such as pole pairs: rounded, at least 1)."""
    from ..model.params import INT, WHOLE

    check = _CHECKS.get(name)
    if check == WHOLE:
        return float(math.floor(v))
    if check == INT:
        return float(max(1, round(v)))
    return v


_CHECKS = {f.name: f.metadata.get("check") for g in GROUPS.values() for f in fields(g)}


def _expand(spec: SweepSpec) -> list[Run]:
    axes = [("variant", k, v) for k, v in spec.variants.items() if len(v) > 1]
    axes += [("param", k, d["grid"]) for k, d in spec.parameters.items() if "grid" in d]
    drawn = [(k, j, d) for j, (k, d) in enumerate(spec.parameters.items()) if "distribution" in d]
    n = math.prod(len(a[2]) for a in axes) * spec.samples
    if n > MAX_RUNS:
        raise SweepError(f"{spec.source}: {n} runs, above the limit of {MAX_RUNS} (MAX_RUNS)")
    draws = [{k: _whole(k, _draw(f"{spec.source} [parameters] {k}", d, np.random.default_rng([spec.seed, s, j])))
              for k, j, d in drawn} for s in range(spec.samples)]
    fixed = {k: v[0] for k, v in spec.variants.items() if len(v) == 1}
    runs = []
    for point in itertools.product(*(a[2] for a in axes)):
        variant = dict(fixed)
        values = {}
        for (kind, key, _), v in zip(axes, point, strict=True):
            (variant if kind == "variant" else values)[key] = v
        variant = tuple((k, variant[k]) for k in spec.variants)
        for s in range(spec.samples):
            vals = {k: (values[k] if k in values else draws[s][k]) for k in spec.parameters}
            runs.append(Run(len(runs), variant, vals))
    return runs


def _check_runs(spec: SweepSpec, src: str) -> None:
    """Every run's values are a valid parameter set; every swept parameter is read by
    every model of the sweep."""
    from ..model.assembly import build_model

    for variant in {r.variant for r in spec.runs}:
        model = build_model(spec.params, dict(variant))
        unused = [k for k in spec.parameters if k not in model.used_params]
        if unused:
            raise SweepError(f"{src} [parameters] {unused[0]}: not read by the model: "
                             f"{model.unused_reason(unused[0])}; sweeping it changes nothing")
    for r in spec.runs:
        try:
            spec.params.replace(**r.values)
        except ParameterError as exc:
            raise SweepError(f"{src} run {r.index} ({_shown(r.values)}): {exc}") from None


def _shown(values: dict) -> str:
    return ", ".join(f"{k} = {v:.4g}" for k, v in values.items())


def _settings(table: dict, where: str) -> dict:
    """The scenario's run settings (duration, steps, tolerances, solver, zoh), checked."""
    out = {"duration": 1.0, "solver": table.get("solver", "auto"), "dt": None}  # None: _metrics.default_dt
    for key in ("duration", "dt", "dt_out", "rtol", "atol", "event_tol"):
        if key in table:
            out[key] = _num(where, table, key)
            if not out[key] > 0:  # a zero step or duration means nothing: never replaced by a default
                raise SweepError(f"{where} {key}: must be positive, got {out[key]:g}")
    if "zoh" in table:  # the ECU sampled at its rates (rk4)
        if not isinstance(table["zoh"], bool):
            raise SweepError(f"{where} zoh: expected true or false, got {table['zoh']!r}")
        out["zoh"] = table["zoh"]
    return out


def _scenario(table: dict, params: Parameters, src: str, variants: dict | None = None) -> dict:
    _known(f"{src} [scenario]", table, _SCENARIO_KEYS, "key")
    where = f"{src} [scenario]"
    out = _settings(table, where)
    stroke, T = params.actuator.stroke, out["duration"]
    sig = {}
    for role, kind, bare in _DRIVEN:
        key = SIGNAL_KEYS[role]
        if key in table:
            sig[role] = _signal(f"{where} {key}", table[key], kind, bare, stroke, T)
    inputs = table.get("inputs", {})
    if not isinstance(inputs, dict):
        raise SweepError(f"{where} inputs: expected a table input = signal, got {inputs!r}")
    from ..model.components import parts_for

    # the inputs of the swept models' parts (a fault input with faults = on, ...)
    info, faults = {}, {}
    for combo in itertools.product(*(variants or {k: [v] for k, v in params.variants.items()}).values()):
        parts, _ = parts_for(validate_variants(dict(zip(variants or params.variants, combo, strict=True))))
        info.update({i.name: i for part in parts for i in part.inputs})
        faults.update({f.kind: f for part in parts for f in part.faults})
    for name, value in inputs.items():
        if name not in info or {r for r, _, _ in _DRIVEN} & set(info[name].roles):  # those have their own keys
            raise SweepError(f"{where} inputs: '{name}' is not another model input{nearest(name, info)}")
        sig[name] = _signal(f"{where} inputs {name}", value, info[name].kind, None, stroke, T)
        check_value_range(info[name], [f for f in faults.values() if f.input == name], sig[name], T,
                          f"{where} inputs {name}", SweepError)
    out["signals"] = sig
    return out


def _signal(where, value, kind, bare, stroke, duration) -> Signal:
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise SweepError(f"{where}: expected a signal (a number or a string such as \"step:1mm@0.01\"), got {value!r}")
    try:
        return parse_signal(str(value), kind, bare=bare, stroke=stroke, duration=duration)
    except SignalError as exc:
        raise SweepError(f"{where}: {exc}") from None
