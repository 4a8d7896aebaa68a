"""The metric registry of the sweeps: each metric is the toolkit's own analysis applied
to one run (nothing computed a second way).

=================  ==============================================  ================================
name               columns (SI)                                    computed by
=================  ==============================================  ================================
step               step_overshoot (-), step_rise_time_s,           ``simulation.step_response_metrics``
                   step_settling_time_s                            on x_rod of the scenario from ``at``
                                                                   to ``until`` (default: the next
                                                                   change of x_cmd, or the end)
hunting            hunting_amplitude_m, hunting_frequency_hz       ``simulation.hunting_metrics`` of
                                                                   x_rod - x_cmd over t >= ``from``
margins            margins_<loop>_gm_db, _gm_down_db, _pm_deg,     ``frequency.loop_margins`` at the
                   _f_gc_hz, _f_pc_hz, _f_down_hz, _disk_margin    operating point under ``f_ext``
bandwidth          bandwidth_hz                                    ``frequency.bandwidth`` of the
                                                                   closed loop (``level_db``)
sine_stream        sine_<f>Hz_gain_db, sine_<f>Hz_phase_deg        ``sinestream.sine_stream`` at
                                                                   ``amplitude``, ``freqs``, ``load``
peak_temperature   peak_<T>_degC per temperature state             max of the state (thermal=lumped)
energy             energy_in_J, energy_loss_J                      trapezoid of P_dc and of the sum
                                                                   of the losses over the kept samples
                                                                   (at most ENERGY_SPACING apart)
peak               peak_<signal> (its unit)                        max |signal| over the scenario
=================  ==============================================  ================================
"""

from __future__ import annotations

import math

import numpy as np

from .._util._checks import nearest, number
from .._util._errors import RunError
from ..model.components import SIGNAL_KEYS

__all__ = ["METRICS", "check_metrics", "metric_columns", "compute_metrics", "PointFailed"]


class PointFailed(RunError):
    """A metric whose analysis reported a failed point (the run is failed)."""

#: The metric option of the margins and the bandwidth: the load of their operating point (N), by its file key.
F_EXT = SIGNAL_KEYS["load"]
_LOOP_FIELDS = (("gm_db", "dB"), ("gm_down_db", "dB"), ("pm_deg", "deg"), ("f_gc_hz", "Hz"), ("f_pc_hz", "Hz"),
                ("f_down_hz", "Hz"), ("disk_margin", "1"))


def _opts(where, given, allowed, error) -> dict:
    if given is True:
        given = {}
    if not isinstance(given, dict):
        raise error(f"{where}: expected a table of options (or {{}}), got {given!r}")
    for k in given:
        if k not in allowed:
            raise error(f"{where}: unknown option '{k}'{nearest(k, allowed)}; expected one of "
                        f"{', '.join(allowed) or 'none'}")
    return dict(given)


def _number(where, opts, key, error, default=None, positive=False):
    v = opts.get(key, default)
    if v is None:
        return None
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or (positive and v <= 0):
        raise error(f"{where} {key}: expected a {'positive ' if positive else ''}finite number, got {v!r}")
    return float(v)


def _names(where, opts, key, allowed, error, default):
    v = opts.get(key, default)
    v = [v] if isinstance(v, str) else v
    if not isinstance(v, list) or not v or not all(isinstance(s, str) for s in v):
        raise error(f"{where} {key}: expected a name or a list of names, got {v!r}")
    for s in v:
        if s not in allowed:
            raise error(f"{where} {key}: '{s}' unknown{nearest(s, allowed)}; choose from {', '.join(allowed)}")
    return v


# -- option checks: (spec, options, where, error) -> (checked options, [(column, unit)]) --
def _step(spec, o, where, error, models):
    o = _opts(where, o, ("at", "amplitude", "band", "until"), error)
    x_cmd, key = spec.scenario["signals"].get("command"), SIGNAL_KEYS["command"]
    if x_cmd is None:
        raise error(f"{where}: the scenario has no {key} step")
    at = _number(where, o, "at", error, next(iter(x_cmd.breakpoints()), None))
    if at is None:
        raise error(f"{where} at: give the time of the step ({key} has no breakpoint)")
    amp = _number(where, o, "amplitude", error,
                  float(x_cmd(np.array([at + 1e-12]))[0] - x_cmd(np.array([max(at - 1e-12, 0.0)]))[0]))
    if amp == 0:
        raise error(f"{where} amplitude: {key} does not jump at t = {at:g} s; give the step's amplitude (m)")
    band = _number(where, o, "band", error, 0.02, positive=True)
    # the step's window: up to the next change of the command (a sine starting, a second
    # step), where the response stops being the step's; else the end of the scenario
    later = [b for b in x_cmd.breakpoints() if b > at]
    until = _number(where, o, "until", error, min(later) if later else spec.scenario["duration"])
    if until <= at:
        raise error(f"{where} until: the window ends at {until:g} s, not after the step at {at:g} s")
    return ({"at": at, "amplitude": amp, "band": band, "until": until},
            [("step_overshoot", "1"), ("step_rise_time_s", "s"), ("step_settling_time_s", "s")])


def _hunting(spec, o, where, error, models):
    o = _opts(where, o, ("from",), error)
    t_from = _number(where, o, "from", error, spec.scenario["duration"] / 2)
    if not 0 <= t_from < spec.scenario["duration"]:
        raise error(f"{where} from: {t_from:g} s is not inside the scenario (0 ... {spec.scenario['duration']:g} s)")
    return {"from": t_from}, [("hunting_amplitude_m", "m"), ("hunting_frequency_hz", "Hz")]


def _margins(spec, o, where, error, models):
    # the loops every swept model closes (the aircraft loop only with an airframe)
    common = [lp for lp in models[0].loops if all(lp in m.loops for m in models)]
    o = _opts(where, o, ("loops", F_EXT, "outer"), error)
    loops = _names(where, o, "loops", common, error, common)
    outer = _names(where, o, "outer", ["closed", "open"], error, "closed")[0]
    f_ext = _number(where, o, F_EXT, error, 0.0)
    cols = [(f"margins_{lp}_{k}", u) for lp in loops for k, u in _LOOP_FIELDS]
    return {"loops": loops, F_EXT: f_ext, "outer": outer}, cols


def _bandwidth(spec, o, where, error, models):
    o = _opts(where, o, ("level_db", F_EXT), error)
    level = number(o.get("level_db", -3.0), f"{where} level_db", error, unit="dB below the low-frequency gain",
                   negative=True)  # the same check as bandwidth()'s
    return ({"level_db": level, F_EXT: _number(where, o, F_EXT, error, 0.0)},
            [("bandwidth_hz", "Hz")])


def _sine(spec, o, where, error, models):
    o = _opts(where, o, ("amplitude", "freqs", "load"), error)
    amp = _number(where, o, "amplitude", error, None, positive=True)
    if amp is None:
        raise error(f"{where}: missing 'amplitude' (m)")
    freqs = o.get("freqs")
    if not isinstance(freqs, list) or not freqs or not all(
            isinstance(f, (int, float)) and not isinstance(f, bool) and f > 0 for f in freqs):
        raise error(f"{where} freqs: expected a list of positive frequencies (Hz), got {freqs!r}")
    freqs = sorted({float(f) for f in freqs})
    cols = [c for f in freqs for c in ((f"sine_{f:g}Hz_gain_db", "dB"), (f"sine_{f:g}Hz_phase_deg", "deg"))]
    return {"amplitude": amp, "freqs": freqs, "load": _number(where, o, "load", error, 0.0)}, cols


def _temperature(spec, o, where, error, models):
    temps = [s for s in models[0].states_with("temperature")]
    if not temps or any(not m.states_with("temperature") for m in models):
        raise error(f"{where}: the model has no temperatures (choose thermal = \"lumped\" in [variants])")
    o = _opts(where, o, ("nodes",), error)
    nodes = _names(where, o, "nodes", temps, error, temps)
    return {"nodes": nodes}, [(f"peak_{n}_degC", "degC") for n in nodes]


#: Longest sample spacing the energy metric integrates over (s). The power spikes of a
#: step are short: on the 1 mm step of the hybrid PI loop, 1 ms samples miss 32 % of
#: the electrical energy, 0.1 ms samples close the energy balance within 0.15 %.
ENERGY_SPACING = 1e-4


def _energy(spec, o, where, error, models):
    _opts(where, o, (), error)
    sc = spec.scenario
    spacing = sc.get("dt_out") or sc["dt"]
    if spacing > ENERGY_SPACING * (1 + 1e-9):
        raise error(f"{where}: integrates the kept samples, which are {spacing:g} s apart; keep one at least every "
                    f"{ENERGY_SPACING:g} s ([scenario] dt_out; at 1 ms a step's current spike is missed)")
    return {}, [("energy_in_J", "J"), ("energy_loss_J", "J")]


def _peak(spec, o, where, error, models):
    o = _opts(where, o, ("signals",), error)
    m = models[0]
    names = [*m.outputs, *(s for s in m.states if s not in m.outputs), *m.inputs]
    sigs = _names(where, o, "signals", names, error, None if "signals" in o else m.output_with("rod_position"))
    return {"signals": sigs}, [(f"peak_{s}", m.units.get(s, "")) for s in sigs]


def _maximum(spec, o, where, error, models):
    o, _ = _peak(spec, o, where, error, models)
    m = models[0]
    return o, [(f"max_{s}", m.units.get(s, "")) for s in o["signals"]]


#: name -> (option check, needs the scenario's simulation)
METRICS = {
    "step": (_step, True), "hunting": (_hunting, True), "margins": (_margins, False),
    "bandwidth": (_bandwidth, False), "sine_stream": (_sine, False), "peak_temperature": (_temperature, True),
    "energy": (_energy, True), "peak": (_peak, True), "maximum": (_maximum, True),
}


def check_metrics(spec, metrics: dict, src: str, error: type) -> dict:
    """The checked options of every metric (``metric_columns`` lists their columns);
    the scenario is checked like ``simulate`` would when a metric needs it.

    Parameters
    ----------
    spec : SweepSpec
        The description (runs and scenario already checked).
    metrics : dict
        Metric name -> options, as in the file.
    src : str
        Named in error messages.
    error : type
        The exception raised.
    """
    from ..model.assembly import build_model
    from ..simulation import check_effect, check_run

    models = [build_model(spec.params, dict(v)) for v in sorted({r.variant for r in spec.runs})]
    if spec.scenario.get("dt") is None:  # not in the file
        spec.scenario["dt"] = default_dt(models, spec.scenario)
    out = {}
    for name, given in metrics.items():
        if name not in METRICS:
            raise error(f"{src} [metrics]: unknown metric '{name}'{nearest(name, METRICS)}; the registry: "
                        f"{', '.join(METRICS)}")
        opts, cols = METRICS[name][0](spec, given, f"{src} [metrics] {name}", error, models)
        out[name] = {**opts, "columns": cols}
    if any(METRICS[n][1] for n in out):
        sc = spec.scenario
        labels = {k: f"{src} [scenario] {k}" for k in ("duration", "dt", "dt_out", "solver", "rtol", "atol")}
        labels["t_end"] = labels["duration"]
        for m in models:
            check_run(m, sc["duration"], dt=sc["dt"], dt_out=sc.get("dt_out"), solver=sc["solver"],
                      rtol=sc.get("rtol", 1e-8), atol=sc.get("atol", 1e-11), event_tol=sc.get("event_tol", 1e-7),
                      zoh=bool(sc.get("zoh")), labels=labels, error=error)
            _check_step(m, sc, labels["dt"], error)
            names = [m.input_name(k) for k in sc["signals"]]  # each read by the model (its nominal parameters)
            check_effect(m, names, m.p(), {n: f"{src} [scenario] inputs {n}" for n in names}, error)
    return out


#: The largest RK4 step of a sweep whose file gives no ``dt`` (s): the hybrid friction's.
SWEEP_DT = 1e-4


def default_dt(models, sc) -> float:
    """The RK4 step of a scenario without ``dt``: the largest step under 0.8 x RK4's
    stability limit on each model where rk4 runs (at the nominal parameters and the
    scenario's largest load), at most :data:`SWEEP_DT`, dividing the ECU's sample
    periods with ``zoh`` (and the duration and ``dt_out`` where one does;
    :meth:`~ema_casadi.simulation.StepLimit.inside`). SWEEP_DT where no model runs rk4."""
    from ..simulation import choose_solver, inside_limit

    zoh = bool(sc.get("zoh"))
    lengths = (sc["duration"],) + ((sc["dt_out"],) if sc.get("dt_out") else ())
    steps = [inside_limit(m, sc["signals"], sc["duration"], zoh, SWEEP_DT, lengths) for m in models
             if choose_solver(m, sc["solver"], zoh)[0] == "rk4"]
    return min(steps, default=SWEEP_DT)


def _check_step(model, sc, label, error) -> None:
    """With rk4: the step against the ECU's sample periods (refused where one step would
    hold two instants) and RK4's
    stability limit at the nominal parameters and the scenario's largest load (warned:
    the runs then skip the check, one limit stands for the sweep)."""
    from ..simulation import choose_solver, input_signals, sampling_split, step_check

    zoh = bool(sc.get("zoh"))
    if choose_solver(model, sc["solver"], zoh)[0] != "rk4":
        return
    pv = model.p()
    if zoh:
        sampling_split(model, sc["dt"], pv, error, label)
    given = {model.input_name(k): v for k, v in sc["signals"].items()}
    step_check(model, sc["dt"], input_signals(model, given, pv, sc["duration"]), pv, zoh, sc["duration"], label)


def metric_columns(metrics: dict) -> list[tuple[str, str]]:
    """(column, unit) of every metric, in order.

    Parameters
    ----------
    metrics : dict
        The checked metrics of a :class:`SweepSpec`.
    """
    return [c for m in metrics.values() for c in m["columns"]]


def needs_simulation(metrics: dict) -> bool:
    """Whether a metric reads the scenario's simulation."""
    return any(METRICS[n][1] for n in metrics)


def simulate_scenario(model, pv, scenario):
    """The scenario's run of ``model`` at parameter vector ``pv``."""
    from ..simulation import simulate

    kw = {k: scenario[k] for k in ("dt_out", "rtol", "atol", "event_tol", "zoh") if k in scenario}
    return simulate(model, scenario["duration"], p=pv, solver=scenario["solver"], dt=scenario["dt"],
                    check_step=False, **kw, inputs=scenario["signals"])  # the step is checked once, at the spec


def compute_metrics(name: str, opts: dict, model, params, pv, res) -> dict:
    """Column -> value of metric ``name`` on one run (NaN where a value does not exist).

    Parameters
    ----------
    name : str
        The metric.
    opts : dict
        Its checked options.
    model : Model
        The run's model.
    params : Parameters
        The parameter set (for the sine stream, which builds its own models).
    pv : ndarray
        The run's parameter vector.
    res : SimResult or None
        The scenario's run (metrics that need it).
    """
    return _COMPUTE[name](opts, model, params, pv, res)


def _c_step(o, model, params, pv, res):
    from ..simulation import step_response_metrics

    t, x = res.t, res[model.output_with("rod_position")]
    x0 = float(np.interp(o["at"], t, x))
    after = (t >= o["at"]) & (t <= o.get("until", math.inf))
    m = step_response_metrics(t[after] - o["at"], (x[after] - x0) / o["amplitude"], o["band"])
    return {"step_overshoot": m["overshoot"], "step_rise_time_s": m["rise_time_s"],
            "step_settling_time_s": m["settling_time_s"]}


def _c_hunting(o, model, params, pv, res):
    from ..simulation import hunting_metrics

    h = hunting_metrics(res.t, res[model.output_with("rod_position")] - res[model.input_with("command")], o["from"])
    return {"hunting_amplitude_m": h["amplitude"],
            "hunting_frequency_hz": math.nan if h["frequency"] is None else h["frequency"]}


def _c_margins(o, model, params, pv, res):
    from ..frequency import loop_margins
    from ..linearisation import operating_point

    op = operating_point(model, inputs={"load": o[F_EXT]}, p=pv)
    lm = loop_margins(model, op, o["loops"], outer=o["outer"])
    return {f"margins_{lp}_{k}": (math.nan if getattr(m, k) is None else float(getattr(m, k)))
            for lp, m in lm.items() for k, _ in _LOOP_FIELDS}


def _c_bandwidth(o, model, params, pv, res):
    from ..frequency import bandwidth, closed_loop
    from ..linearisation import operating_point

    op = operating_point(model, inputs={"load": o[F_EXT]}, p=pv)
    return {"bandwidth_hz": float(bandwidth(closed_loop(model, op), o["level_db"]))}


def _c_sine(o, model, params, pv, res):
    from ..sinestream import sine_stream

    fr = sine_stream(params, [o["amplitude"]], o["freqs"], [o["load"]], variants=dict(model.variants), p=pv, jobs=1)
    out = {}
    for j, f in enumerate(o["freqs"]):
        if fr.data["status"][0, 0, 0, j] == "failed":
            raise PointFailed(f"sine stream at {f:g} Hz: {fr.data['reason'][0, 0, 0, j]}")
        out[f"sine_{f:g}Hz_gain_db"] = float(fr.data["gain_db"][0, 0, 0, j])
        out[f"sine_{f:g}Hz_phase_deg"] = float(fr.data["phase_deg"][0, 0, 0, j])
    return out


def _c_temperature(o, model, params, pv, res):
    return {f"peak_{n}_degC": float(np.max(res[n])) for n in o["nodes"]}


def _c_energy(o, model, params, pv, res):
    loss = sum(res[n] for n in model.outputs_of("loss"))
    return {"energy_in_J": float(np.trapezoid(res[model.output_with("electrical_power")], res.t)),
            "energy_loss_J": float(np.trapezoid(loss, res.t))}


def _c_peak(o, model, params, pv, res):
    return {f"peak_{s}": float(np.max(np.abs(res[s]))) for s in o["signals"]}


def _c_maximum(o, model, params, pv, res):
    return {f"max_{s}": float(np.max(res[s])) for s in o["signals"]}


_COMPUTE = {"step": _c_step, "hunting": _c_hunting, "margins": _c_margins, "bandwidth": _c_bandwidth,
            "sine_stream": _c_sine, "peak_temperature": _c_temperature, "energy": _c_energy, "peak": _c_peak,
            "maximum": _c_maximum}
