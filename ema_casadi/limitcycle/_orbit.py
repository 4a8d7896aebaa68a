"""Periodic orbits of a closed loop by shooting, their Floquet multipliers, and their
continuation over a parameter (docs: periodic orbits).

The loop is held autonomous (its inputs constant at the values the loop's confirming run
ends at, :func:`~ema_casadi.limitcycle.setup`), and an orbit is a solution (x0, T) of

    phi(T; x0) - x0 = 0,        c . (x0 - x_s) = 0

with phi the flow of the model, and the second equation a Poincare section: the
hyperplane through a point x_s of the start guess, normal to the flow there (c = f(x_s),
in the states' full-scale units). Newton's matrix is exact: the monodromy matrix
M = d phi(T)/d x0 comes from the compiled RODAS4 with forward sensitivities (initial
directions the identity), d phi/dT = f(phi(T)). The eigenvalues of M are the Floquet
multipliers; one of them is 1 (the flow direction) and is reported as a check of the
accuracy; the orbit is stable when every other multiplier lies inside the unit circle.

Continuation (:func:`continue_orbit`) adds the parameter as an unknown (its sensitivity
direction from the same run) and a pseudo-arclength equation; folds of cycles show as a
turning of the parameter (a multiplier through +1), period doubling as a multiplier
through -1, a torus (Neimark-Sacker) as a complex pair leaving the circle, and the
orbit's birth (a Hopf point of the equilibrium) as the amplitude going to zero.

Switching models (hybrid friction, a sampled ECU) have no smooth flow; there the
monodromy matrix is taken by finite differences of the fixed-step RK4 rollout (the
stated fallback, ``method="rk4"``), with the accuracy that implies (see docs).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from .._util._notebook import Summarised
from ..model.assembly import Model
from ..optimisation import newton_step
from ..simulation import RunFailed, SimulationError
from ._df import cycle_of, switched_why
from ._flow import Flow, OrbitNotFound
from ._setup import setup

__all__ = ["PeriodicOrbit", "OrbitNotFound", "periodic_orbit", "summaries", "multipliers", "held_inputs",
           "checked_inputs", "checked_p", "unsupported"]

#: Smallest half peak-to-peak of the loop's signal (m) that counts as an oscillation to start from.
MIN_START = 1e-9
#: Newton steps without the residual halving after which the shooting gives up (not the
#: finite-difference fallback: its Newton wanders before it converges, measured on the
#: aircraft loop: 4e-5, 2e-3, 6e-4, 2e-4, 2e-5, 1e-5, 1e-5, 2e-5, 4e-7).
STALL = 3
#: Largest Newton step in any state (of its full scale): a longer one is shortened (the
#: finite-difference fallback's first step on the aircraft loop otherwise threw the play
#: state to 190 x its full scale).
STEP_MAX = 0.05
#: Periodicity residual reached by the finite-difference fallback (of full scale): its
#: fixed-step rollout is not smooth in the start state where the friction sticks and
#: slips (measured on the aircraft loop: over 25 Newton steps the residual wanders between
#: 1e-6 and 2e-5, below 1e-6 only by chance).
FD_TOL = 1e-5
#: Most halvings of a finite-difference Newton step (each tried by one rollout).
BACKTRACK = 3


@dataclass(repr=False)
class PeriodicOrbit(Summarised):
    """A periodic orbit of a closed loop (from :func:`periodic_orbit`).

    Parameters
    ----------
    loop : str
        The loop (``position``, ``aircraft``).
    T : float
        Period (s).
    x0 : ndarray
        State on the orbit at the phase section (SI).
    multipliers : ndarray of complex
        Floquet multipliers (eigenvalues of the monodromy matrix), the trivial one first.
    monodromy : ndarray
        The monodromy matrix dx(T)/dx(0).
    residual : float
        Periodicity residual max_i |x_i(T) - x_i(0)| / scale_i (scale: the state's full scale).
    signals : dict
        Per named signal: ``amplitude`` (first harmonic), ``peak_to_peak``, ``mean`` (SI).
    t, X, Y : ndarray
        The orbit over one period: time (s), states (nx x n), outputs (ny x n).
    states, outputs : tuple of str
        Names of the rows of X and Y.
    units : dict
        Signal name -> SI unit.
    prediction : dict or None
        The describing function's prediction given, with ``freq_error`` and
        ``amplitude_error`` (relative, against this orbit).
    info : dict
        ``iterations``, ``runs``, ``method``, ``wall_time``, ``start``, ``residuals``.
    """

    loop: str
    T: float
    x0: np.ndarray
    multipliers: np.ndarray
    monodromy: np.ndarray
    residual: float
    signals: dict
    t: np.ndarray
    X: np.ndarray
    Y: np.ndarray
    states: tuple
    outputs: tuple
    units: dict
    prediction: dict | None = None
    info: dict = field(default_factory=dict)

    @property
    def freq_hz(self) -> float:
        """Frequency 1/T (Hz)."""
        return 1.0 / self.T

    @property
    def trivial_multiplier(self) -> complex:
        """The multiplier of the flow direction (1 on an exact orbit)."""
        return complex(self.multipliers[0])

    @property
    def stable(self) -> bool:
        """Every nontrivial multiplier inside the unit circle."""
        return bool(np.all(np.abs(self.multipliers[1:]) < 1.0))

    def __getitem__(self, name: str) -> np.ndarray:
        if name in ("t", "time"):
            return self.t
        if name in self.outputs:
            return self.Y[self.outputs.index(name)]
        if name in self.states:
            return self.X[self.states.index(name)]
        raise KeyError(f"no signal '{name}'; have {', '.join((*self.outputs, *self.states))}")

    def as_dict(self) -> dict:
        """JSON-ready summary (no time series)."""
        mu = self.multipliers
        return {"loop": self.loop, "period_s": self.T, "freq_hz": self.freq_hz, "stable": self.stable,
                "trivial_multiplier": [mu[0].real, mu[0].imag],
                "multipliers": [[float(m.real), float(m.imag)] for m in mu],
                "multiplier_moduli": [float(abs(m)) for m in mu],
                "periodicity_residual": self.residual, "signals": self.signals, "prediction": self.prediction,
                "x0": dict(zip(self.states, map(float, self.x0), strict=True)),
                "info": {k: v for k, v in self.info.items() if k != "residuals"}
                | {"residuals": list(self.info.get("residuals", []))}}

    def to_csv(self, path):
        """Write the orbit over one period as CSV in the toolkit's layout (``time``, one column
        per output then the states not already outputs; a ``Unit:`` row); atomic.

        Parameters
        ----------
        path : str or Path
            The CSV file.
        """
        from ..signals import write_series

        extra = [s for s in self.states if s not in self.outputs]
        cols = [*self.outputs, *extra]
        data = np.column_stack([self.t, *(self[c] for c in cols)])
        return write_series(path, ["time", *cols], ["s", *(self.units.get(c, "") for c in cols)], data)

    def plot(self, path=None, signals=None):
        """The orbit's signals over one period and its multipliers on the unit circle.

        Parameters
        ----------
        path : str or Path, optional
            PNG file; the Figure is returned when not given.
        signals : sequence of str, optional
            Signals drawn (default the summarised ones).
        """
        from ..plots._limitcycle import plot_orbit

        return plot_orbit(self, path, signals=signals)

    def _facts(self) -> dict:
        return {"loop": repr(self.loop), "freq": f"{self.freq_hz:.6g} Hz", "stable": bool(self.stable),
                "residual": f"{self.residual:.2g}", "|mu|max": f"{np.max(np.abs(self.multipliers[1:])):.4g}"}


def summaries(flow: Flow, t, X, Y, names) -> dict:
    model = flow.model
    out = {}
    T = t[-1] - t[0]
    for n in names:
        y = Y[model.outputs.index(n)] if n in model.outputs else X[model.states.index(n)]
        yy = y[:-1]
        c = 2 * np.mean(yy * np.exp(-2j * np.pi * (t[:-1] - t[0]) / T))
        out[n] = {"amplitude": float(abs(c)), "peak_to_peak": float(np.ptp(y)), "mean": float(np.mean(yy)),
                  "unit": model.units.get(n, "")}
    return out


def multipliers(M, fT) -> np.ndarray:
    mu = np.linalg.eigvals(M)
    k = int(np.argmin(np.abs(mu - 1.0)))
    return np.concatenate([[mu[k]], np.delete(mu, k)[np.argsort(-np.abs(np.delete(mu, k)))]])


def _newton(flow: Flow, x0, T, tol, iterations, stop=None):
    """Newton on (x0, T) with the section through the start, normal to the flow."""
    D = flow.model.full_scale(flow.pv)
    xs = np.asarray(x0, float).copy()
    c = flow.f(xs) / D
    c = c / np.linalg.norm(c) / D  # section normal in scaled units
    x, T = xs.copy(), float(T)
    residuals = []
    nx = len(x)
    for it in range(iterations + 1):
        if stop is not None:
            stop()
        xT, M, _ = flow.run(x, T)
        r = np.concatenate([(xT - x) / D, [c @ (x - xs) * 1.0]])
        res = float(np.max(np.abs(r[:nx])))
        residuals.append(res)
        if res < tol:
            return x, T, M, xT, residuals, it
        if it == iterations:
            break
        if flow.method != "rk4" and it >= STALL and res > 0.5 * residuals[-1 - STALL]:  # no progress
            raise OrbitNotFound(f"no periodic orbit near the start: the periodicity residual stalls at {res:.2g} "
                                f"(need < {tol:g}) after {it} Newton steps")
        J = np.zeros((nx + 1, nx + 1))
        J[:nx, :nx] = (M - np.eye(nx)) * D[None, :] / D[:, None]
        J[:nx, nx] = flow.f(xT) / D * T
        J[nx, :nx] = c * D
        try:  # damped where the linear model is far off
            dz = newton_step(J, r, max_step=STEP_MAX, capped=nx)
        except np.linalg.LinAlgError as exc:
            raise OrbitNotFound(f"no periodic orbit near the start: singular shooting matrix at Newton step {it}") \
                from exc
        x, T = _backtracked(flow, x, T, dz, D, res) if flow.method == "rk4" else _stepped(x, T, dz, D)
    raise OrbitNotFound(f"no periodic orbit near the start: periodicity residual {residuals[-1]:.2g} after "
                        f"{iterations} Newton steps (need < {tol:g})")


def _stepped(x, T, dz, D, s=1.0):
    return x + s * dz[:len(x)] * D, T * math.exp(float(np.clip(s * dz[len(x)], -0.5, 0.5)))


def _backtracked(flow: Flow, x, T, dz, D, res):
    """The finite-difference fallback's Newton step, halved (at most :data:`BACKTRACK`
    times) until the residual at its end, from one rollout, is below ``res``; where none
    is, the trial with the smallest residual (the rollout is not smooth in its start: a
    full step can land on the far side of a stick or slip)."""
    best = None
    for k in range(BACKTRACK + 1):
        xn, Tn = _stepped(x, T, dz, D, 0.5**k)
        rn = float(np.max(np.abs((flow.run(xn, Tn, sens=False)[0] - xn) / D)))
        best = (rn, xn, Tn) if best is None or rn < best[0] else best
        if rn < res:
            break
    return best[1], best[2]


def _start_from_simulation(model, s, t_warm, signal, dt, inputs, zoh=False):
    res = s["confirm"](t_warm, dt, **inputs, **({"zoh": True} if zoh else {}))
    t = np.asarray(res.t)
    y = np.asarray(res[signal])
    cyc = cycle_of(t, y, t_warm / 2)
    if cyc["freq_hz"] is None or cyc["half_pp"] < MIN_START:
        raise OrbitNotFound(f"no oscillation in the {t_warm:g} s start run (the {signal} signal settles): "
                            "no periodic orbit to start from")
    sel = t >= t_warm / 2
    yy = y - np.mean(y[sel])
    ups = np.nonzero(sel[1:] & (yy[:-1] < 0) & (yy[1:] >= 0))[0] + 1
    k = int(ups[-1])
    x0 = np.array([res.states[n][k] for n in model.states])
    # where the run has settled onto one cycle (its last four crossing spacings, each
    # interpolated, agree within 1e-4), the last spacing is the period (the spectral
    # estimate of cycle_of is 2.5e-3 off on the hunting run, the spacing 4e-8: one Newton
    # step fewer); elsewhere (a stick-slip cycle, still drifting) the spectral estimate
    tc = t[ups - 1] - yy[ups - 1] * (t[ups] - t[ups - 1]) / (yy[ups] - yy[ups - 1])
    dT = np.diff(tc[-5:])
    settled = len(dT) == 4 and np.ptp(dT) < 1e-4 * np.mean(dT) and abs(dT[-1] * cyc["freq_hz"] - 1) < 0.05
    T0 = float(dT[-1]) if settled else 1 / cyc["freq_hz"]
    return x0, T0, cyc


def held_inputs(model: Model, loop: str, s: dict, inputs: dict | None = None) -> dict:
    """The loop's inputs held constant at the end of its confirming run, ``inputs`` over them."""
    base = {model.input_with("command"): 1e-3} if loop == "position" else dict(s["inputs"])  # position: the 1 mm step
    return {**base, **(inputs or {})}


def checked_inputs(model: Model, inputs, p) -> dict:
    """Held input values given by the caller: driven inputs of the model, finite, inside
    the model's physical envelope (ValueError naming the first that is not).

    Parameters
    ----------
    model : Model
    inputs : dict or None
        Input name -> value (SI).
    p : ndarray
        Parameter vector (the envelope's bounds depend on it).
    """
    out = {}
    bounds = model.envelope(p)
    for name, v in (inputs or {}).items():
        info = model.input_info.get(name)
        if info is None or info.injection:
            have = ", ".join(n for n, i in model.input_info.items() if not i.injection)
            raise ValueError(f"inputs: no driven input {name!r} in the model; have {have}")
        v = float(v)
        if not math.isfinite(v):
            raise ValueError(f"inputs: {name} = {v}: need a finite number ({info.unit})")
        if name in bounds and abs(v) > bounds[name]:
            raise ValueError(f"inputs: {name} = {v:.4g} {info.unit} is beyond the physical envelope "
                             f"{bounds[name]:.4g} {info.unit} ({info.bound.why})")
        out[name] = v
    return out


def unsupported(model: Model) -> str | None:
    """Why the model's orbits cannot be found by shooting (one line), or None.

    A hysteresis state (the screw's self-locking memory, ``screw_lock = memory``) is refused: it is a
    rate-independent hysteresis whose rate switches with the sign of the screw's speed and
    saturates at the band's edges, and Newton on its flow diverges (measured on the
    hunting case: the periodicity residual grows to 18 of full scale in three steps);
    ``screw_lock = blend`` is the supported form.

    Parameters
    ----------
    model : Model
    """
    if (why := switched_why(model)) is not None:
        return why
    if model.states_with("hysteresis"):
        return (f"screw_lock = memory: the hysteresis state {', '.join(model.states_with('hysteresis'))} is not "
                "supported by shooting (Newton diverges on it); use screw_lock = blend")
    return None


def checked_p(model: Model, p) -> np.ndarray:
    """The parameter vector given (default the model's): the model's length, each value
    that differs from the model's set inside its field's range (ValueError naming it).

    Parameters
    ----------
    model : Model
    p : array_like or None
        Parameter vector (SI).
    """
    from ..model import checked

    base = model.p()
    if p is None:
        return base
    pv = np.asarray(p, float)
    if pv.shape != base.shape:
        raise ValueError(f"p: {pv.size} values; the model has {base.size} parameters")
    for name, v, b in zip(model.param_names, pv, base, strict=True):
        if v != b:
            checked(name, float(v), f"p: {name}")
    return pv


def _default_step(model: Model, pv, loop: str, zoh: bool, inputs: dict) -> float:
    """The RK4 step of the start run and the fallback: at most 1e-5 s (position loop) or
    1e-4 s (aircraft loop), inside RK4's stability limit on the model at the held load
    (:meth:`~ema_casadi.simulation.StepLimit.inside` at its margin, dividing the ECU's
    sample periods)."""
    from ..simulation import rk4_step_limit, sample_periods

    cap = 1e-5 if loop == "position" else 1e-4
    load = abs(float((inputs or {}).get(model.input_with("load"), 0.0)))
    return rk4_step_limit(model, p=pv, load=load, zoh=zoh).inside(sample_periods(model, pv).values(), cap=cap)


def _start(model, s, start, t_warm, loop, sig_name, dt, inputs, zoh):
    """(x0, T0, the start run's cycle or None, t_warm) from ``start``."""
    if isinstance(start, dict):
        if "x0" not in start or "T" not in start:
            raise ValueError("start: a dict needs 'x0' (state) and 'T' (period, s)")
        return np.asarray(start["x0"], float), float(start["T"]), None, None
    if start == "simulation":
        t_warm = t_warm or (2.0 if loop == "position" else 60.0)
        return (*_start_from_simulation(model, s, t_warm, sig_name, dt, inputs, zoh), t_warm)
    raise ValueError(f"start: {start!r}; 'simulation' or {{'x0': ..., 'T': ...}}")


def _compare(prediction, summ, sig_name, T):
    """The prediction given, with its frequency and amplitude errors against the orbit."""
    if prediction is None:
        return None
    a = summ[sig_name]["amplitude"] if sig_name in summ else None
    return {**{k: v for k, v in prediction.items() if k in ("amplitude", "freq_hz", "stable", "method")},
            "signal": sig_name, "freq_error": prediction["freq_hz"] * T - 1.0,
            "amplitude_error": (prediction["amplitude"] / a - 1.0) if a else None}


def periodic_orbit(model: Model, loop: str = "position", *, p=None, condition: str = "cruise_sl",
                   start: str | dict = "simulation", t_warm: float | None = None, dt: float | None = None,
                   signals=None, prediction: dict | None = None, method: str = "auto", tol: float = 1e-10,
                   iterations: int = 25, inputs: dict | None = None, zoh: bool = False, stop=None) -> PeriodicOrbit:
    """The periodic orbit of a closed loop by shooting, with its Floquet multipliers.

    Parameters
    ----------
    model : Model
    loop : {"position", "aircraft"}
        The loop, set up as :func:`~ema_casadi.limitcycle.setup` does (position: 1 mm
        command held; aircraft: the trim at ``condition``, its trimmed inputs held).
    p : ndarray, optional
        Parameter vector (default the model's).
    condition : str
        Flight condition (aircraft).
    start : "simulation" or dict
        Start: the state at an upward mean crossing of the loop's signal late in a
        ``t_warm`` s confirming run, or ``{"x0": ..., "T": ...}``.
    t_warm : float, optional
        Start run length (s); default 2 s (position), 60 s (aircraft).
    dt : float, optional
        RK4 step of the start run and of the fallback (s); default 1e-5 / 1e-4 s or less:
        inside RK4's stability limit on the model.
    signals : sequence of str, optional
        Signals summarised (default x_rod and, for the aircraft loop, x_cmd).
    prediction : dict, optional
        A describing-function (or harmonic-balance) cycle (``amplitude``, ``freq_hz``) of
        the loop's break signal: reported beside the orbit with its relative errors.
    method : {"auto", "sensitivities", "rk4"}
        Monodromy matrix from the RODAS4 forward sensitivities (continuous models), or
        finite differences of the fixed-step RK4 rollout (switching models: hybrid
        friction, a sampled ECU); auto picks by the model.
    tol, iterations : float, int
        Periodicity residual to reach (of each state's full scale); Newton steps at most.
    inputs : dict, optional
        Driven inputs held at these values (SI) over the loop's own (e.g. the load
        ``{"f_ext": 2000.0}``), in the start run and on the orbit.
    zoh : bool
        The ECU sampled at its rates (zero-order hold): the finite-difference fallback
        on the RK4 rollout with the sampled ECU, each rollout from the ECU sampling at its
        start (the sample clock restarted each period: the hunting cycle of a sampled loop
        is locked to its clock only approximately; see docs for the measured effect).
    stop : callable, optional
        Called before each Newton step (raises to interrupt).

    Raises
    ------
    ValueError
        Unknown loop, method, input, a parameter or held input outside its range, or a
        start without ``x0``/``T``.
    OrbitNotFound
        No oscillation to start from, or Newton did not converge.
    """
    t_start = time.perf_counter()
    if loop not in ("position", "aircraft"):
        raise ValueError(f"loop: unknown loop {loop!r}; have position, aircraft")
    if method not in ("auto", "sensitivities", "rk4"):
        raise ValueError(f"method: {method!r}; have auto, sensitivities, rk4")
    why = unsupported(model)
    if why is not None:
        raise SimulationError(why)  # an InputError (and a ValueError, as before)
    switching = bool(model.switched) or bool(getattr(model, "hybrid", False)) or zoh
    if method == "auto":
        method = "rk4" if switching else "sensitivities"
    if method == "sensitivities" and switching:
        raise ValueError("method: the model switches (hybrid friction, a sampled ECU or a switched part): its "
                         "flow has no sensitivities; use method='rk4'")
    p = checked_p(model, p)
    inputs = checked_inputs(model, inputs, p)
    s = setup(model, loop, p, condition)
    dt = dt or _default_step(model, s["p"], loop, zoh, inputs)
    sig_name = s["signal"]
    names = tuple(signals) if signals else tuple(dict.fromkeys([model.output_with("rod_position"), sig_name]))
    for n in names:
        if n not in model.outputs and n not in model.states:
            raise ValueError(f"signals: no signal {n!r} in the model")
    x0, T0, warm, t_warm = _start(model, s, start, t_warm, loop, sig_name, dt, inputs, zoh)
    flow = Flow(model, held_inputs(model, loop, s, inputs), s["p"], method, dt, zoh)
    tol_eff = tol if method == "sensitivities" else max(tol, FD_TOL)
    try:
        x, T, M, xT, residuals, its = _newton(flow, x0, T0, tol_eff, iterations, stop)
    except RunFailed as exc:
        raise OrbitNotFound(f"a shooting run failed ({exc}): no periodic orbit near the start") from None
    mu = multipliers(M, flow.f(xT))
    t, X, Y = flow.series(x, T)
    summ = summaries(flow, t, X, Y, names)
    pred = _compare(prediction, summ, sig_name, T)
    units = dict(model.units)
    info = {"iterations": its, "runs": flow.runs, "method": method, "residuals": residuals, "inputs": inputs,
            "zoh": zoh, "dt": dt,
            "wall_time": time.perf_counter() - t_start, "start": "given" if warm is None else
            {"t_warm_s": t_warm, "freq_hz": warm["freq_hz"], "amplitude": warm["amplitude"]}}
    D = model.full_scale(s["p"])
    return PeriodicOrbit(loop, float(T), x, mu, M, float(np.max(np.abs((xT - x) / D))), summ, t, X, Y,
                         tuple(model.states), tuple(model.outputs), units, pred, info)
