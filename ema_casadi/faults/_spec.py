"""A fault file: the scenario and the fault cases, checked before any run.

Layout (TOML, SI units; ``models/faults_reference.toml`` is the reference)::

    [scenario]
    duration = 0.6            # s
    x_cmd = "sine:5mm@1"      # signals as for ema simulate (bare numbers: mm, N)
    f_ext = "5kN"
    dt = 1.25e-5              # RK4 step (s): divides every ECU sample period
    sensor = "real"           # what the ECU reads: ideal | real
    friction = "hybrid"       # any variant key chooses the model

    [[fault]]
    kind = "jam"              # one of the model's fault kinds (ema faults --list)
    onset = [0.1, 0.3]        # s: a number or a list (an axis of cases)
    severity = 1.0            # in the kind's unit: a number or a list
    ramp = 0.0                # s, optional: the severity is reached over this time

    [[fault]]
    kind = "stuck"
    target = "x_s"            # sensor faults: the sensed signal

    [monitor]                 # optional: thresholds over the parameter file's
    t_jam = { value = 0.02, unit = "s" }

A mission segment as the scenario: ``mission = "models/mission_regional.toml"`` and
``segment = "<name>"`` take the segment's command and load (and, with
``thermal = lumped``, its cavity temperature); ``duration`` defaults to the segment's.

In the aircraft loop (``airframe = "transport"`` or ``"b747"``, ``condition`` a flight
condition of :data:`~ema_casadi.aircraft.CONDITIONS`) the flight-control law provides
the rod command, so the scenario gives ``theta_cmd`` (added to the trim's attitude;
bare numbers in deg) and optionally a gust ``w_g`` (m/s) instead of ``x_cmd``; every
run starts from the trim of the whole loop.

    [healthy]                 # optional: the healthy runs (--healthy-runs) of the scenario
    duration = 0.3            # s (default the scenario's)
    dt = 1.5625e-5            # s (default the scenario's)
    tolerance = 0.05          # +- relative (uniform) on the parameters of vary
    vary = ["F_seal", "C_bear", "C"]

Every [[fault]] gives kind x onset x severity cases; the no-fault case is always run.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from pathlib import Path

from .._util._checks import nearest, read_toml
from .._util._errors import InputError
from ..model.components import REGISTRY, SIGNAL_KEYS, Fault, parts_for, served_by, validate_variants
from ..model.params import ParameterError, Parameters
from ..signals import Signal, SignalError, parse_signal

__all__ = ["FaultError", "FaultCase", "FaultSpec", "load_faults", "parse_faults", "fault_kinds", "fault_variants"]

_TABLES = ("scenario", "fault", "monitor", "healthy")
_HEALTHY = ("duration", "dt", "dt_out", "tolerance", "vary")
#: The scenario's signal keys (the file's, from the one key table): rod command, load, attitude command, gust.
X_CMD, F_EXT, THETA_CMD, W_G = (SIGNAL_KEYS[r] for r in ("command", "load", "attitude_command", "gust"))
_SCENARIO = ("duration", X_CMD, F_EXT, "dt", "dt_out", "condition", THETA_CMD, W_G, "mission", "segment")
_FAULT = ("kind", "target", "onset", "severity", "ramp")


class FaultError(InputError, ValueError):
    """A mistake in a fault file or a fault request (one line naming file and key)."""


@dataclass(frozen=True)
class FaultCase:
    """One run: a fault (or none) with its onset, severity and ramp.

    Attributes
    ----------
    label : str
        ``kind[ target]`` (``none`` for the no-fault case).
    fault : Fault or None
        The model's declaration (its input, unit, range).
    onset, severity, ramp : float
        Onset (s), severity (the fault's unit), ramp time (s).
    """

    label: str
    fault: Fault | None = None
    onset: float = math.nan
    severity: float = 0.0
    ramp: float = 0.0

    def signals(self) -> dict:
        """The fault's input as a Signal, by input name (empty for the no-fault case)."""
        f = self.fault
        if f is None:
            return {}
        if f.rate:
            return {f.input: Signal.ramp(self.severity, self.onset)}
        if self.ramp > 0:
            k = self.severity / self.ramp
            return {f.input: Signal.ramp(k, self.onset) + Signal.ramp(-k, self.onset + self.ramp)}
        return {f.input: Signal.step(self.severity, self.onset)}


@dataclass
class FaultSpec:
    """A checked fault file.

    Attributes
    ----------
    source : str
        Where it came from.
    params : Parameters
        The parameter set with the file's [monitor] thresholds.
    variants : dict
        The variant choice of every run (faults and monitors on).
    scenario : dict
        ``duration``, ``dt``, ``dt_out`` (s), ``signals`` (input role -> Signal: ``command``,
        ``load``, ...) and ``text`` (the file's key -> its value).
    healthy : dict
        The healthy runs' ``duration``, ``dt``, ``dt_out`` (s), ``tolerance`` (-) and
        ``vary`` (the parameters drawn within it).
    healthy_variants : dict
        The variant choice of the healthy runs (no fault injection).
    cases : list of FaultCase
        The no-fault case first, then every fault case.
    """

    source: str
    params: Parameters
    variants: dict
    scenario: dict
    cases: list = field(default_factory=list)
    healthy: dict = field(default_factory=dict)
    healthy_variants: dict = field(default_factory=dict)


def fault_variants(params: Parameters, given: dict | None = None, chosen: dict | None = None) -> dict:
    """The variant choice of a fault run: the parameter set's, ``given`` and ``chosen``
    (the fault file's) with ``faults`` and ``monitors`` on, and every option of the
    chosen parts that adds fault kinds switched on (the PMSM's ``winding_short``).

    Parameters
    ----------
    params : Parameters
        The parameter set (its ``[model]`` variants).
    given : dict, optional
        Variant choices on top (``--variant``).
    chosen : dict, optional
        Variant choices of the fault file's ``[scenario]`` (``sensor``, ``airframe``).
    """
    off = [f"{k}={c[k]}" for c in (given or {}, chosen or {}) for k in ("faults", "monitors") if c.get(k, "on") != "on"]
    if off:  # switched off by the user: refused, not switched back on behind them
        raise FaultError(f"variant {off[0]}: a fault study injects the faults and reads the monitors; leave them on")
    v = validate_variants({**params.variants, **(given or {}), **(chosen or {}), "faults": "on", "monitors": "on"})
    for key, values in REGISTRY.items():
        for cls in served_by(values[v[key]]):  # an option whose form of the part brings faults is turned on
            for opt, allowed in cls.options.items():
                base = {o: v[o] for o in cls.options}
                for value in allowed[1:]:
                    if cls.form({**base, opt: value}).faults and not cls.form(base).faults:
                        v[opt] = value
    return v


def healthy_variants(params: Parameters, given: dict | None = None, chosen: dict | None = None) -> dict:
    """The variant choice of the healthy runs: as :func:`fault_variants` without the
    fault injection (its inputs would be 0): the monitors on.

    Parameters
    ----------
    params : Parameters
        The parameter set (its ``[model]`` variants).
    given, chosen : dict, optional
        Variant choices on top (``--variant``, the fault file's ``[scenario]``).
    """
    return validate_variants({**params.variants, **(given or {}), **(chosen or {}), "monitors": "on"})


def fault_kinds(variants: dict, params: Parameters | None = None) -> dict:
    """Fault kind -> {target or None: Fault} a model of ``variants`` (and ``params``) can inject.

    Parameters
    ----------
    variants : dict
        A variant choice (completed with the defaults).
    params : Parameters, optional
        The parameter set (with ``[instances]``: each channel's faults, its name their target).
    """
    from ..model import build_model
    v = validate_variants(variants)  # several actuators: each channel's faults, targets "A", "B"
    parts = build_model(params, v).parts if getattr(params, "system", None) else parts_for(v)[0]
    out: dict = {}
    for part in parts:
        for f in part.faults:
            out.setdefault(f.kind, {})[f.target] = f
    return out


def load_faults(path: str | Path, params: Parameters, variants: dict | None = None) -> FaultSpec:
    """Read and check a fault file (module docstring).

    Parameters
    ----------
    path : str or Path
        The fault file (TOML).
    params : Parameters
        The parameter set (its [monitor] thresholds are the defaults).
    variants : dict, optional
        Variant choices (``--variant``).
    """
    data = read_toml(path, "fault file", FaultError)
    return parse_faults(data, params, str(path), variants)


def parse_faults(data: dict, params: Parameters, src: str = "<faults>", variants: dict | None = None) -> FaultSpec:
    """Check a fault description given as the dict ``tomllib`` returns.

    Parameters
    ----------
    data : dict
        The description.
    params : Parameters
        The parameter set.
    src : str
        Named in error messages.
    variants : dict, optional
        Variant choices under the file's.
    """
    if not isinstance(data, dict):
        raise FaultError(f"{src}: expected a table of tables")
    _known(src, data, _TABLES, "table")
    scenario = data.get("scenario", {})
    if not isinstance(scenario, dict):
        raise FaultError(f"{src} [scenario]: expected a table")
    _known(f"{src} [scenario]", scenario, (*_SCENARIO, *REGISTRY), "key")
    # variant keys in the scenario (sensor, airframe, ...) choose the model
    chosen = {k: val for k, val in scenario.items() if k in REGISTRY}
    for k, val in chosen.items():  # neither choice silently overrides the other
        if k in (variants or {}) and variants[k] != val:
            raise FaultError(f"variant {k}={variants[k]} and {src} [scenario] {k} = {val!r} disagree; give one")
    params = _monitor(data.get("monitor", {}), params, src)
    try:
        v = fault_variants(params, variants, chosen)
        kinds = fault_kinds(v, params)
        hv = healthy_variants(params, variants, chosen)
    except ParameterError as exc:
        raise FaultError(f"{src} [scenario]: {exc}") from None
    sc = _scenario(scenario, params, src, _aircraft(v))
    if "mission" not in scenario and "segment" not in scenario:  # a segment is checked as its mission's
        _check_envelope(f"{src} [scenario]", sc, params, v)
    if "dt" not in scenario and "signals" in sc:  # the default inside RK4's stability limit (DEFAULT_DT)
        from ..model.assembly import build_model
        from ..simulation import inside_limit

        model = build_model(params, v)
        lengths = (sc["duration"], scenario.get("dt_out", 1e-4))
        sc["dt"] = inside_limit(model, sc["signals"], sc["duration"], True, DEFAULT_DT, lengths)
        sc["dt_out"] = _positive(f"{src} [scenario] dt_out", scenario.get("dt_out"), _whole(1e-4, sc["dt"]))
    faults = data.get("fault", [])
    if not isinstance(faults, list) or not all(isinstance(f, dict) for f in faults):
        raise FaultError(f"{src} [[fault]]: expected an array of tables")
    if not faults:
        raise FaultError(f"{src}: no [[fault]] table; give at least one case (ema faults --list names the kinds)")
    cases, seen = [FaultCase("none")], {}
    for k, entry in enumerate(faults):
        for case in _cases(f"{src} [[fault]] {k + 1}", entry, kinds, sc["duration"], v):
            key = (case.label, case.onset, case.severity, case.ramp)
            if key in seen:  # every case is one row of the result: the same case twice is a slip
                raise FaultError(f"{src} [[fault]] {k + 1}: {case.label} at onset {case.onset:g} s, severity "
                                 f"{case.severity:g} is already the case of [[fault]] {seen[key]}; remove one")
            seen[key] = k + 1
            cases.append(case)
    return FaultSpec(source=src, params=params, variants=v, scenario=sc, cases=cases,
                     healthy=_healthy(data.get("healthy", {}), sc, src, params), healthy_variants=hv)


def _check_envelope(where: str, sc: dict, params: Parameters, variants: dict) -> None:
    """The scenario's command within the stroke and its load within what the actuator
    holds at standstill (the ``held_load`` its parts declare), sampled at 1 kHz over the
    run before any simulation (as a mission's segments are); the run's step count
    within the simulator's limit, named by the file's keys."""
    from types import SimpleNamespace

    import numpy as np

    from .._util._checks import budget
    from ..simulation import MAX_STEPS

    budget(sc["duration"] / sc["dt"], MAX_STEPS, f"{where} duration {sc['duration']:g} s / dt {sc['dt']:g} s",
           FaultError, unit="RK4 steps", item_bytes=0, limit_name="MAX_STEPS", hint="shorten duration or raise dt")
    t = np.linspace(0.0, sc["duration"], max(2, min(10**6, int(sc["duration"] * 1e3) + 1)))
    stroke = params.actuator.stroke
    P = SimpleNamespace(**params.as_dict())
    parts = parts_for(variants)[0]
    held = [float(part.limits["held_load"](P)) for part in parts if "held_load" in part.limits]
    roles = {r for part in parts for i in part.inputs for r in i.roles}  # the model's input roles
    for role, limit, unit, scale, what in (
            ("command", stroke, "mm", 1e3, "beyond the stroke"),
            ("load", max(held) if held else math.inf, "kN", 1e-3,
             "more than the actuator holds at standstill at its current limit")):
        sig, key = (sc["signals"].get(role) if role in roles else None), SIGNAL_KEYS[role]
        if sig is None or not math.isfinite(limit):
            continue
        v = np.asarray(sig(t), dtype=float) * np.ones_like(t)
        k = int(np.argmax(np.abs(v)))
        if not np.isfinite(v[k]) or abs(v[k]) > limit:
            raise FaultError(f"{where} {key}: reaches {v[k] * scale:.4g} {unit} at {t[k]:.4g} s, {what} "
                             f"(+-{limit * scale:.4g} {unit})")


def _aircraft(variants: dict) -> bool:
    """Whether the model flies: an input of its parts is the attitude command."""
    parts, _ = parts_for(variants)
    return any("attitude_command" in i.roles for part in parts for i in part.inputs)


def _healthy(table, sc: dict, src: str, params: Parameters) -> dict:
    where = f"{src} [healthy]"
    if not isinstance(table, dict):
        raise FaultError(f"{where}: expected a table")
    _known(where, table, _HEALTHY, "key")
    out = {k: _positive(f"{where} {k}", table.get(k), sc[k]) for k in ("duration", "dt")}
    # a latch stays set: one sample per ms finds every alarm of a run
    out["dt_out"] = _positive(f"{where} dt_out", table.get("dt_out"), _whole(1e-3, out["dt"]))
    tol = table.get("tolerance", 0.05)
    if isinstance(tol, bool) or not isinstance(tol, (int, float)) or not 0 <= tol < 1:
        raise FaultError(f"{where} tolerance: expected a fraction in [0, 1), got {tol!r}")
    out["tolerance"] = float(tol)
    vary = table.get("vary", [])
    names = params.as_dict()
    if not isinstance(vary, list) or not all(isinstance(n, str) for n in vary):
        raise FaultError(f"{where} vary: expected a list of parameter names, got {vary!r}")
    for n in vary:
        if n not in names:
            raise FaultError(f"{where} vary: unknown parameter '{n}'{nearest(n, names)}")
    out["vary"] = list(vary)
    return out


def _known(where, table, keys, what):
    for k in table:
        if k not in keys:
            raise FaultError(f"{where}: unknown {what} '{k}'{nearest(k, keys)}; expected one of {', '.join(keys)}")


def _monitor(table, params: Parameters, src: str) -> Parameters:
    """The parameter set with the fault file's [monitor] values (checked like a file's)."""
    from dataclasses import fields

    from ..model import raw_value
    from ..model.params import GROUPS

    if not isinstance(table, dict):
        raise FaultError(f"{src} [monitor]: expected a table")
    meta = {f.name: f.metadata for f in fields(GROUPS["monitor"])}
    values = {}
    for key, raw in table.items():
        if key not in meta:
            raise FaultError(f"{src} [monitor]: unknown threshold '{key}'{nearest(key, meta)}")
        # as in a parameter file: the SI unit or one the flags accept for the quantity
        values[key] = raw_value(f"{src} [monitor] {key}", raw, meta[key]["unit"], FaultError)
    try:
        return params.replace(**values) if values else params
    except ParameterError as exc:
        raise FaultError(f"{src} [monitor]: {exc}") from None


#: The largest RK4 step of a scenario without ``dt`` (s): the largest step under 0.8 x
#: RK4's stability limit on the model at the scenario's largest load that divides the
#: ECU's sample periods, at most this (:func:`~ema_casadi.simulation.inside_limit`):
#: 12.5 us with hybrid friction (0.26 ms limit), 1.95 us with the smooth law held under
#: 5 kN (2.46 us).
DEFAULT_DT = 1.25e-5


def _whole(spacing: float, dt: float) -> float:
    """The smallest whole number of steps dt at least ``spacing`` long (s)."""
    return dt * max(1, math.ceil(spacing / dt - 1e-9))


def _positive(where, value, default=None) -> float:
    if value is None:
        value = default
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
        raise FaultError(f"{where}: expected a positive number of seconds, got {value!r}")
    return float(value)


def _scenario(table: dict, params: Parameters, src: str, aircraft: bool = False) -> dict:
    where = f"{src} [scenario]"
    out = {"duration": _positive(f"{where} duration", table.get("duration"), 0.6),
           "dt": _positive(f"{where} dt", table.get("dt"), DEFAULT_DT), "condition": None}
    out["dt_out"] = _positive(f"{where} dt_out", table.get("dt_out"), _whole(1e-4, out["dt"]))
    if aircraft:
        from ..aircraft import CONDITIONS

        if X_CMD in table:
            raise FaultError(f"{where} {X_CMD}: in the aircraft loop the flight-control law commands the rod; "
                             f"give {THETA_CMD} (and {W_G}) instead")
        cond = out["condition"] = table.get("condition", "cruise_sl")
        if cond not in CONDITIONS:
            raise FaultError(f"{where} condition: '{cond}' unknown{nearest(str(cond), CONDITIONS)}; choose one of "
                             f"{', '.join(CONDITIONS)}")
        inputs = (("attitude_command", "angle", "deg"), ("gust", None, None), ("load", "force", "N"))
    else:
        for key in ("condition", THETA_CMD, W_G):
            if key in table:
                raise FaultError(f"{where} {key}: only with an airframe (airframe = \"transport\" or \"b747\")")
        inputs = (("command", "length", "mm"), ("load", "force", "N"))
    if "mission" in table or "segment" in table:
        return _segment(table, params, out, where)
    sig, text = {}, {}
    for role, kind, bare in inputs:  # the signals by the role they drive, the text by the file's key
        key = SIGNAL_KEYS[role]
        value = table.get(key, 0)
        text[key] = value
        if role == "gust":  # a speed in m/s: parsed as a plain number of its unit
            kind, bare = "dimensionless", None
        if isinstance(value, bool) or not isinstance(value, (int, float, str)):
            raise FaultError(f"{where} {key}: expected a signal such as \"step:1mm@0.01\", got {value!r}")
        try:
            sig[role] = parse_signal(str(value), kind, bare=bare, stroke=params.actuator.stroke,
                                    duration=out["duration"])
        except SignalError as exc:
            raise FaultError(f"{where} {key}: {exc}") from None
    out["signals"], out["text"] = sig, text
    return out


def _segment(table: dict, params: Parameters, out: dict, where: str) -> dict:
    """The scenario of one segment of a mission file (its command, load, cavity)."""
    from ..mission import MissionError, load_mission

    for key in (X_CMD, F_EXT, "condition", THETA_CMD, W_G):
        if key in table:
            raise FaultError(f"{where} {key}: the mission segment gives the scenario's signals")
    if not isinstance(table.get("mission"), str) or not isinstance(table.get("segment"), str):
        raise FaultError(f"{where}: give both mission (a mission file) and segment (one of its segment names)")
    try:
        mission = load_mission(table["mission"], params)
    except MissionError as exc:
        raise FaultError(f"{where} mission: {exc}") from None
    names = {seg.name: seg for seg in mission.segments}
    seg = names.get(table["segment"])
    if seg is None:
        raise FaultError(f"{where} segment: '{table['segment']}' unknown{nearest(table['segment'], names)}; the "
                         f"mission has {', '.join(names)}")
    if "duration" not in table:
        out["duration"] = float(seg.duration)
    out["signals"] = {"command": seg.x_cmd, "load": seg.f_ext, "ambient_temperature": seg.T_amb}
    out["text"] = {k: seg.text.get(k, "0") for k in (X_CMD, F_EXT)}
    return out


def _axis(where, value, default=None) -> list[float]:
    if value is None:
        value = default
    values = value if isinstance(value, list) else [value]
    if not values or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                             for v in values):
        raise FaultError(f"{where}: expected a number or a list of numbers, got {value!r}")
    return [float(v) for v in values]


def _cases(where: str, entry: dict, kinds: dict, duration: float, variants: dict) -> list[FaultCase]:
    _known(where, entry, _FAULT, "key")
    kind = entry.get("kind")
    if not isinstance(kind, str):
        raise FaultError(f"{where} kind: expected a fault kind ({', '.join(kinds)}), got {kind!r}")
    if kind not in kinds:
        raise FaultError(f"{where} kind: unknown fault kind '{kind}'{nearest(kind, kinds)}; the model injects "
                         f"{', '.join(kinds)}")
    targets = kinds[kind]
    target = entry.get("target")
    if None in targets and target is not None:
        raise FaultError(f"{where} target: a {kind} fault has no target, got {target!r}")
    if None not in targets and target not in targets:
        raise FaultError(f"{where} target: unknown target {target!r}{nearest(str(target), targets)} for a {kind} "
                         f"fault; choose one of {', '.join(targets)}")
    fault = targets[target]
    fault.check_requires(variants, f"{where} kind", FaultError)  # a case that would run and mean nothing
    onsets = _axis(f"{where} onset", entry.get("onset"), duration / 4)
    for t in onsets:
        if not 0 < t < duration:
            raise FaultError(f"{where} onset: {t:g} s is outside the run (0, {duration:g}) s")
    whole = fault.unit == "1" and fault.hi == 1.0  # 0..1 faults default to 1 (the full fault)
    sev = _axis(f"{where} severity", entry.get("severity"), 1.0 if whole else None)
    for s in sev:
        fault.check(s, f"{where} severity", FaultError)
    ramp = entry.get("ramp", 0.0)
    if isinstance(ramp, bool) or not isinstance(ramp, (int, float)) or not math.isfinite(ramp) or ramp < 0:
        raise FaultError(f"{where} ramp: expected a non-negative number of seconds, got {ramp!r}")
    label = kind if target is None else f"{kind} {target}"
    return [FaultCase(label, fault, t, s, float(ramp)) for t, s in itertools.product(onsets, sev)]
