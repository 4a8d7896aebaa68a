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

import casadi as ca
import numpy as np

from ..model.assembly import Model
from ..signals import constant
from ..simulation import RunFailed, simulate
from ._df import cycle_of
from ._setup import setup

__all__ = ["PeriodicOrbit", "OrbitNotFound", "periodic_orbit", "continue_orbit", "Continuation"]

#: Integrator tolerances of the shooting runs (relative; absolute, in full-scale units).
RTOL = 1e-11
ATOL = 1e-12
#: Samples per period at which the event indicators are checked for a sign change.
EVENT_GRID = 2000
#: Most switch events in one period.
MAX_EVENTS = 400
#: Samples of the orbit's time series over one period.
SAMPLES = 400


class OrbitNotFound(RuntimeError):
    """Newton did not converge to a periodic orbit from the start given (a named failure)."""


def _forward_sensitivities():
    try:  # the shared numeric sensitivity interface
        from ..simulation import forward_sensitivities
    except ImportError:  # pragma: no cover - before the interface moved into simulation
        from ..identification import _sensitivity

        forward_sensitivities = _sensitivity.run
    return forward_sensitivities


def _signals(model: Model, held: dict, pv) -> dict:
    """Every driven input as a constant Signal: the held values, the rest at their defaults."""
    P = model.pdict(pv)
    sig = {}
    for name, inp in model.input_info.items():
        if name in held:
            sig[name] = constant(float(held[name]))
        elif not inp.injection:
            v = getattr(P, inp.default) if isinstance(inp.default, str) else inp.default
            sig[name] = constant(float(v))
    return sig


def _u(model: Model, sig: dict) -> np.ndarray:
    return np.array([float(sig[n].terms[0].a) if n in sig and sig[n].terms else 0.0 for n in model.inputs])


class _Flow:
    """phi(T; x0, p) and its derivatives for one model and held inputs."""

    def __init__(self, model: Model, held: dict, pv, method: str, dt: float):
        self.model, self.held, self.method, self.dt = model, dict(held), method, dt
        self.set_p(pv)
        self.runs = 0

    def set_p(self, pv):
        self.pv = np.asarray(pv, float).copy()
        self.sig = _signals(self.model, self.held, self.pv)
        self.u = _u(self.model, self.sig)

    def f(self, x) -> np.ndarray:
        return np.asarray(self.model.f(x, self.u, self.pv)[0], float).ravel()

    def df_dx(self, x) -> np.ndarray:
        if not hasattr(self, "_jac"):
            X = ca.SX.sym("x", self.model.nx)
            U = ca.SX.sym("u", self.model.nu)
            Pp = ca.SX.sym("p", len(self.pv))
            xd = self.model.f(X, U, Pp)[0]
            self._jac = ca.Function("jac", [X, U, Pp], [ca.jacobian(xd, X)])
        return np.asarray(self._jac(x, self.u, self.pv), float)

    def _events(self):
        """The model's switches (event indicators, modes, the held model) and the held
        model as a model the sensitivity driver compiles (modes appended to p)."""
        if not hasattr(self, "_sw"):
            from ..export.fmu import switches

            sw = switches(self.model)
            self._sw = sw
            self._held = _HeldModel(self.model, sw)
            X = ca.SX.sym("x", self.model.nx)
            U = ca.SX.sym("u", self.model.nu)
            Pp = ca.SX.sym("p", len(self.pv))
            z = sw.z(X, U, Pp)
            self._zfun = ca.Function("zg", [X, U, Pp], [z, ca.jacobian(z, X), ca.jacobian(z, Pp)])
        return self._sw, self._held

    def _fheld(self, x, m):
        return np.asarray(self._sw.f(x, self.u, self.pv, m)[0], float).ravel()

    def _jheld(self, x, m):
        if not hasattr(self, "_jh"):
            X = ca.SX.sym("x", self.model.nx)
            U = ca.SX.sym("u", self.model.nu)
            Pp = ca.SX.sym("p", len(self.pv))
            mm = ca.SX.sym("m", self._held.nz)
            xd = self._sw.f(X, U, Pp, mm)[0]
            self._jh = ca.Function("jh", [X, U, Pp, mm], [ca.jacobian(xd, X)])
        return np.asarray(self._jh(x, self.u, self.pv, m), float)

    def modes(self, x) -> np.ndarray:
        sw, _ = self._events()
        nz = sw.z.size1_out(0)
        return np.asarray(sw.select(x, self.u, self.pv, np.zeros(nz)), float).ravel()

    def run(self, x0, T, k_param: int | None = None, samples: int = 0):
        """x(T), M = dx(T)/dx0 and (with k_param) dx(T)/dp_k: the held model integrated
        between events (located to round-off), a saltation matrix at each event."""
        self.runs += 1
        nx, npar = self.model.nx, len(self.pv)
        if self.method == "rk4":
            return self._run_fd(x0, T, k_param)
        sw, held = self._events()
        sens = _forward_sensitivities()
        nd = nx + (k_param is not None)
        W = np.zeros((npar + held.nz, nd))
        if k_param is not None:
            W[k_param, nx] = 1.0
        S = np.zeros((nx, nd))
        S[:, :nx] = np.eye(nx)
        x = np.asarray(x0, float).copy()
        m = self.modes(x)
        t, n_events = 0.0, 0
        self.events = []
        while True:
            left = T - t
            n = max(8, int(math.ceil(EVENT_GRID * left / T)))
            grid = np.linspace(0.0, left, n + 1)
            pm = np.concatenate([self.pv, m])
            X, SX, _ = sens(held, self.sig, grid, pm, x, W, S, RTOL, ATOL)
            Z = np.asarray(sw.z.map(n + 1)(X, np.tile(self.u[:, None], n + 1), np.tile(self.pv[:, None], n + 1)))
            flip = (m[:, None] != 0) & (np.sign(Z) == -m[:, None])
            flip[:, 0] = False  # at an event's own state the flipped indicator is still ~0
            hit = np.nonzero(flip.any(axis=0))[0]
            if len(hit) == 0:
                return X[:, -1], SX[-1].T[:, :nx], (SX[-1].T[:, nx] if k_param is not None else None)
            j = int(hit[0])
            ks = np.nonzero(flip[:, j])[0]
            # locate the first crossing in (grid[j-1], grid[j]) from the sample before it
            xa, Sa, ta = X[:, j - 1], SX[j - 1].T, grid[j - 1]
            k, tau = None, None
            for kk in ks:
                za, zb = Z[kk, j - 1], Z[kk, j]
                tt = (grid[j] - ta) * za / (za - zb)
                if tau is None or tt < tau:
                    k, tau = int(kk), tt
            def to(tau, xa=xa, Sa=Sa, pm=pm, m=m):
                if tau <= 1e-9 * T:  # too short a step for the driver: first order (error ~ tau^2)
                    return xa + tau * self._fheld(xa, m), Sa + tau * self._jheld(xa, m) @ Sa
                Xe, SXe, _ = sens(held, self.sig, np.array([0.0, tau]), pm, xa, W, Sa, RTOL, ATOL)
                return Xe[:, -1], SXe[-1].T

            for _ in range(8):  # Newton on z_k(x(tau)) = 0 along the held flow
                xe, _ = to(tau)
                z, g, zp = (np.asarray(v, float) for v in self._zfun(xe, self.u, self.pv))
                zdot = float(g[k] @ self._fheld(xe, m))
                dtau = -float(z.ravel()[k]) / zdot
                tau = min(max(tau + dtau, 0.0), grid[j] - ta)
                if abs(dtau) < 1e-13 * T:
                    break
            xe, Se = to(tau)
            z, g, zp = (np.asarray(v, float) for v in self._zfun(xe, self.u, self.pv))
            m_new = m.copy()
            m_new[k] = -m[k]
            fm, fp = self._fheld(xe, m), self._fheld(xe, m_new)
            gk = g[k]
            den = float(gk @ fm)
            # saltation: S+ = S- + (f- - f+) dt_e/d(.), dt_e/d(.) = -(g S- + z_p W)/(g f-)
            dte = -(gk @ Se + np.concatenate([zp[k], np.zeros(held.nz)]) @ W) / den
            S = Se + np.outer(fm - fp, dte)
            self.events.append((t + ta + tau, k, m[k]))
            x, m, t = xe, m_new, t + ta + tau
            n_events += 1
            if n_events > MAX_EVENTS:
                raise OrbitNotFound(f"more than {MAX_EVENTS} switch events in one period (the orbit slides "
                                    "along a switch): no smooth flow to shoot on; use method='rk4'")

    def end(self, x0, T, pv=None) -> np.ndarray:
        """x(T) by the fixed-step rollout (the RK4 fallback)."""
        n = max(1, math.ceil(T / self.dt))
        res = simulate(self.model, T, dt=T / n, dt_out=T, p=self.pv if pv is None else pv, x0=np.asarray(x0, float),
                       solver="rk4", **{k: v for k, v in self.sig.items()})
        return np.array([res.states[s][-1] for s in self.model.states])

    def _run_fd(self, x0, T, k_param):
        scale = self.model.full_scale(self.pv)
        xT = self.end(x0, T)
        nx = self.model.nx
        M = np.empty((nx, nx))
        for j in range(nx):  # central differences of the rollout, 1e-6 of full scale
            h = 1e-6 * scale[j]
            e = np.zeros(nx)
            e[j] = h
            M[:, j] = (self.end(x0 + e, T) - self.end(x0 - e, T)) / (2 * h)
        dp = None
        if k_param is not None:
            h = 1e-6 * max(abs(self.pv[k_param]), 1e-6)
            pp, pm = self.pv.copy(), self.pv.copy()
            pp[k_param] += h
            pm[k_param] -= h
            dp = (self.end(x0, T, pp) - self.end(x0, T, pm)) / (2 * h)
        return xT, M, dp

    def series(self, x0, T, n: int = SAMPLES):
        """Time, states (nx x n+1) and outputs (ny x n+1) over one period."""
        grid = np.linspace(0.0, T, n + 1)
        if self.method == "rk4":
            m = max(1, math.ceil(T / n / self.dt))
            res = simulate(self.model, T, dt=T / n / m, dt_out=T / n, p=self.pv, x0=np.asarray(x0, float),
                           solver="rk4", **self.sig)
            X = np.array([res.states[s] for s in self.model.states])
            grid = np.asarray(res.t)
        else:
            nx = self.model.nx
            X, _, _ = _forward_sensitivities()(self.model, self.sig, grid, self.pv, np.asarray(x0, float),
                                               np.zeros((len(self.pv), 1)), np.zeros((nx, 1)), RTOL, ATOL)
        fm = self.model.f.map(X.shape[1])
        Y = np.asarray(fm(X, np.tile(self.u[:, None], X.shape[1]), np.tile(self.pv[:, None], X.shape[1]))[1])
        return grid, X, Y


class _HeldModel:
    """The model with its switches held in given modes, the modes appended to the
    parameter vector: what the sensitivity driver compiles (smooth between events)."""

    def __init__(self, model: Model, sw):
        self.nx, self.nu, self.inputs = model.nx, model.nu, model.inputs
        self.nz = sw.z.size1_out(0)
        self.param_names = (*model.param_names, *(f"_mode_{k}" for k in range(self.nz)))
        x = ca.SX.sym("x", model.nx)
        u = ca.SX.sym("u", model.nu)
        p = ca.SX.sym("p", len(model.param_names))
        m = ca.SX.sym("m", self.nz)
        xdot, y = sw.f(x, u, p, m)
        self.f = ca.Function("f", [x, u, ca.vertcat(p, m)], [xdot, y], ["x", "u", "p"], ["xdot", "y"])
        self.cache = {}


@dataclass
class PeriodicOrbit:
    """A periodic orbit of a closed loop.

    Attributes
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
        per output then the states not already outputs; a ``Unit:`` row); atomic."""
        from ..signals._tables import write_series

        extra = [s for s in self.states if s not in self.outputs]
        cols = [*self.outputs, *extra]
        data = np.column_stack([self.t, *(self[c] for c in cols)])
        return write_series(path, ["time", *cols], ["s", *(self.units.get(c, "") for c in cols)], data)

    def plot(self, path=None, signals=None):
        """The orbit's signals over one period and its multipliers on the unit circle
        (a matplotlib Figure, or saved to ``path``)."""
        from ..plots._limitcycle import plot_orbit

        return plot_orbit(self, path, signals=signals)

    def __repr__(self) -> str:
        s = "stable" if self.stable else "unstable"
        return (f"PeriodicOrbit(loop={self.loop!r}, freq={self.freq_hz:.6g} Hz, {s}, "
                f"residual={self.residual:.2g}, |mu|max={np.max(np.abs(self.multipliers[1:])):.4g})")


def _summaries(flow: _Flow, t, X, Y, names) -> dict:
    model = flow.model
    out = {}
    T = t[-1] - t[0]
    for n in names:
        y = Y[model.outputs.index(n)] if n in model.outputs else X[model.states.index(n)]
        yy = y[:-1]
        c = 2 * np.mean(yy * np.exp(-2j * np.pi * (t[:-1] - t[0]) / T))
        out[n] = {"amplitude": float(abs(c)), "peak_to_peak": float(np.ptp(y)), "mean": float(np.mean(yy)),
                  "unit": model.units.get(n, "") if hasattr(model, "units") and isinstance(model.units, dict) else ""}
    return out


def _multipliers(M, fT) -> np.ndarray:
    mu = np.linalg.eigvals(M)
    k = int(np.argmin(np.abs(mu - 1.0)))
    return np.concatenate([[mu[k]], np.delete(mu, k)[np.argsort(-np.abs(np.delete(mu, k)))]])


def _newton(flow: _Flow, x0, T, tol, iterations, stop=None):
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
        J = np.zeros((nx + 1, nx + 1))
        J[:nx, :nx] = (M - np.eye(nx)) * D[None, :] / D[:, None]
        J[:nx, nx] = flow.f(xT) / D * T
        J[nx, :nx] = c * D
        try:
            dz = np.linalg.solve(J, -r)
        except np.linalg.LinAlgError as exc:
            raise OrbitNotFound(f"singular shooting matrix at iteration {it}") from exc
        x, T = x + dz[:nx] * D, T * math.exp(float(np.clip(dz[nx], -0.5, 0.5)))
    raise OrbitNotFound(f"no periodic orbit near the start: periodicity residual {residuals[-1]:.2g} after "
                        f"{iterations} Newton steps (need < {tol:g})")


def _start_from_simulation(model, s, t_warm, signal, dt):
    res = s["confirm"](t_warm, dt)
    t = np.asarray(res.t)
    y = np.asarray(res[signal])
    cyc = cycle_of(t, y, t_warm / 2)
    if cyc["freq_hz"] is None:
        raise OrbitNotFound(f"no oscillation in the {t_warm:g} s start run (the {signal} signal settles): "
                            "no periodic orbit to start from")
    sel = t >= t_warm / 2
    yy = y - np.mean(y[sel])
    ups = np.nonzero(sel[1:] & (yy[:-1] < 0) & (yy[1:] >= 0))[0] + 1
    k = int(ups[-1])
    x0 = np.array([res.states[n][k] for n in model.states])
    return x0, 1.0 / cyc["freq_hz"], cyc


def _held(model: Model, loop: str, s: dict) -> dict:
    """The loop's inputs held constant at the end of its confirming run."""
    if loop == "position":
        return {"x_cmd": 1e-3}  # the confirming run's 1 mm step, held
    return dict(s["inputs"])


def periodic_orbit(model: Model, loop: str = "position", *, p=None, condition: str = "cruise_sl",
                   start: str | dict = "simulation", t_warm: float | None = None, dt: float | None = None,
                   signals=None, prediction: dict | None = None, method: str = "auto", tol: float = 1e-10,
                   iterations: int = 25, stop=None) -> PeriodicOrbit:
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
        Start guess: the state at an upward mean crossing of the loop's signal late in a
        ``t_warm`` s confirming run (``"simulation"``), or ``{"x0": ..., "T": ...}``.
        A describing-function prediction is passed as ``prediction`` (its frequency
        sets nothing here; it is compared).
    t_warm : float, optional
        Start run length (s); default 2 s (position), 60 s (aircraft).
    dt : float, optional
        RK4 step of the start run and of the fallback (s); default 1e-5 / 1e-4.
    signals : sequence of str, optional
        Signals summarised (default x_rod and, for the aircraft loop, x_cmd).
    prediction : dict, optional
        A describing-function (or harmonic-balance) cycle (``amplitude``, ``freq_hz``) of
        the loop's break signal: reported beside the orbit with its relative errors.
    method : {"auto", "sensitivities", "rk4"}
        Monodromy matrix from the RODAS4 forward sensitivities (continuous models), or
        finite differences of the fixed-step RK4 rollout (switching models: hybrid
        friction, a sampled ECU); auto picks by the model.
    tol : float
        Periodicity residual to reach (of each state's full scale).
    iterations : int
        Newton steps at most.
    stop : callable, optional
        Called before each Newton step (raises to interrupt).

    Raises
    ------
    ValueError
        Unknown loop, method, or a start without ``x0``/``T``.
    OrbitNotFound
        No oscillation to start from, or Newton did not converge.
    """
    t_start = time.perf_counter()
    if loop not in ("position", "aircraft"):
        raise ValueError(f"loop: unknown loop {loop!r}; have position, aircraft")
    if method not in ("auto", "sensitivities", "rk4"):
        raise ValueError(f"method: {method!r}; have auto, sensitivities, rk4")
    switching = bool(model.switched) or bool(getattr(model, "hybrid", False))
    if method == "auto":
        method = "rk4" if switching else "sensitivities"
    if method == "sensitivities" and switching:
        raise ValueError("method: the model switches (hybrid friction or a switched part): its flow has no "
                         "sensitivities; use method='rk4'")
    s = setup(model, loop, p, condition)
    dt = dt or (1e-5 if loop == "position" else 1e-4)
    sig_name = s["signal"]
    names = tuple(signals) if signals else tuple(dict.fromkeys(["x_rod", sig_name]))
    for n in names:
        if n not in model.outputs and n not in model.states:
            raise ValueError(f"signals: no signal {n!r} in the model")
    if isinstance(start, dict):
        if "x0" not in start or "T" not in start:
            raise ValueError("start: a dict needs 'x0' (state) and 'T' (period, s)")
        x0, T0, warm = np.asarray(start["x0"], float), float(start["T"]), None
    elif start == "simulation":
        t_warm = t_warm or (2.0 if loop == "position" else 60.0)
        x0, T0, warm = _start_from_simulation(model, s, t_warm, sig_name, dt)
    else:
        raise ValueError(f"start: {start!r}; 'simulation' or {{'x0': ..., 'T': ...}}")
    flow = _Flow(model, _held(model, loop, s), s["p"], method, dt)
    tol_eff = tol if method == "sensitivities" else max(tol, 1e-7)
    try:
        x, T, M, xT, residuals, its = _newton(flow, x0, T0, tol_eff, iterations, stop)
    except RunFailed as exc:
        raise OrbitNotFound(f"a shooting run failed ({exc}): no periodic orbit near the start") from None
    mu = _multipliers(M, flow.f(xT))
    t, X, Y = flow.series(x, T)
    summ = _summaries(flow, t, X, Y, names)
    pred = None
    if prediction is not None:
        a = summ[sig_name]["amplitude"] if sig_name in summ else None
        pred = {**{k: v for k, v in prediction.items() if k in ("amplitude", "freq_hz", "stable", "method")},
                "signal": sig_name, "freq_error": prediction["freq_hz"] * T - 1.0,
                "amplitude_error": (prediction["amplitude"] / a - 1.0) if a else None}
    units = {n: model.output_info[n].unit for n in model.outputs} | dict(model.state_units)
    info = {"iterations": its, "runs": flow.runs, "method": method, "residuals": residuals,
            "wall_time": time.perf_counter() - t_start, "start": "given" if warm is None else
            {"t_warm_s": t_warm, "freq_hz": warm["freq_hz"], "amplitude": warm["amplitude"]}}
    D = model.full_scale(s["p"])
    return PeriodicOrbit(loop, float(T), x, mu, M, float(np.max(np.abs((xT - x) / D))), summ, t, X, Y,
                         tuple(model.states), tuple(model.outputs), units, pred, info)


@dataclass
class Continuation:
    """A branch of periodic orbits over one parameter (:func:`continue_orbit`).

    Attributes
    ----------
    name : str
        The parameter continued (SI unit ``unit``).
    values, periods : ndarray
        The parameter and the period (s) at each point of the branch.
    amplitudes : ndarray
        First-harmonic amplitude of ``signal`` at each point.
    multipliers : list of ndarray
        Floquet multipliers at each point (trivial one first).
    stable : ndarray of bool
        Stability at each point.
    bifurcations : list of dict
        Detected points: ``kind`` (``fold``, ``period doubling``, ``torus``, ``birth``),
        ``value`` (the parameter), ``amplitude``, ``index`` (the point after it).
    """

    name: str
    unit: str
    signal: str
    values: np.ndarray
    periods: np.ndarray
    amplitudes: np.ndarray
    multipliers: list
    stable: np.ndarray
    bifurcations: list
    info: dict = field(default_factory=dict)

    @property
    def onset(self) -> float | None:
        """The parameter value where the orbit is born (a birth or the fold that ends the branch), if found."""
        for b in self.bifurcations:
            if b["kind"] in ("birth", "fold"):
                return b["value"]
        return None

    def as_dict(self) -> dict:
        """JSON-ready."""
        return {"parameter": self.name, "unit": self.unit, "signal": self.signal, "values": self.values.tolist(),
                "periods_s": self.periods.tolist(), "freqs_hz": (1 / self.periods).tolist(),
                "amplitudes": self.amplitudes.tolist(), "stable": self.stable.tolist(),
                "max_multiplier": [float(np.max(np.abs(m[1:]))) for m in self.multipliers],
                "bifurcations": self.bifurcations, "onset": self.onset, "info": self.info}

    def plot(self, path=None):
        """Bifurcation diagram: amplitude against the parameter, stable branches solid,
        unstable dashed, the detected points marked (a Figure, or saved to ``path``)."""
        from ..plots._limitcycle import plot_bifurcation

        return plot_bifurcation(self, path)


def _amplitude(flow: _Flow, x, T, signal: str, n: int = 200) -> float:
    t, X, Y = flow.series(x, T, n)
    return _summaries(flow, t, X, Y, (signal,))[signal]["amplitude"]


def continue_orbit(model: Model, name: str, lo: float, hi: float, loop: str = "position", *, p=None,
                   condition: str = "cruise_sl", orbit: PeriodicOrbit | None = None, ds: float = 0.05,
                   ds_max: float = 0.2, steps: int = 200, tol: float = 1e-9, birth_amplitude: float = 1e-3,
                   stop=None, progress=None, **orbit_kw) -> Continuation:
    """Continue a periodic orbit over the parameter ``name`` between ``lo`` and ``hi`` by
    pseudo-arclength, with its multipliers, folds, period doubling, torus points and birth.

    The unknowns are the scaled state at the section, the period and the parameter; the
    section is re-anchored at each point (normal to the flow at the last orbit's start),
    the step is along the tangent of the branch (the null vector of the shooting
    matrix), and its length adapts to the Newton iterations. The branch ends where the
    parameter leaves [lo, hi], where the amplitude falls below ``birth_amplitude`` of
    the largest met (the orbit's birth from the equilibrium), or after ``steps`` points;
    the branch is followed both ways from the first orbit.

    Parameters
    ----------
    model : Model
    name : str
        A parameter of ``model.param_names`` (SI).
    lo, hi : float
        The range of the parameter (SI).
    loop, p, condition
        As in :func:`periodic_orbit`.
    orbit : PeriodicOrbit, optional
        The first orbit (at ``p``); computed by :func:`periodic_orbit` otherwise (with
        ``orbit_kw``).
    ds, ds_max : float
        First and largest step along the branch (scaled units: parameter by its range).
    steps : int
        Points at most.
    tol : float
        Periodicity residual of each point.
    birth_amplitude : float
        Relative amplitude below which the branch is taken to be born.
    stop, progress : callable, optional
        ``stop()`` before each point (raises to interrupt); ``progress(fraction, text)``.
    """
    if name not in model.param_names:
        raise ValueError(f"continue: no parameter {name!r} in the model")
    if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
        raise ValueError(f"continue: range {lo!r}..{hi!r}: need lo < hi")
    k = list(model.param_names).index(name)
    pv0 = (model.p() if p is None else np.asarray(p, float)).copy()
    if orbit is None:
        orbit = periodic_orbit(model, loop, p=pv0, condition=condition, **orbit_kw)
    s = setup(model, loop, pv0, condition)
    pv = s["p"].copy()
    if not lo <= pv[k] <= hi:
        raise ValueError(f"continue: {name} = {pv[k]:g} of the first orbit outside {lo:g}..{hi:g}")
    method = orbit.info.get("method", "sensitivities")
    flow = _Flow(model, _held(model, loop, s), pv, method, orbit_kw.get("dt") or 1e-5)
    sig = s["signal"]
    D = model.full_scale(pv)
    L = hi - lo
    T_ref = orbit.T
    nx = model.nx

    def unpack(u):
        return u[:nx] * D, u[nx] * T_ref, lo + u[nx + 1] * L

    def system(u, c, xs):
        x, T, lam = unpack(u)
        pp = pv.copy()
        pp[k] = lam
        flow.set_p(pp)
        xT, M, dp = flow.run(x, T, k)
        r = np.concatenate([(xT - x) / D, [c @ (x - xs)]])
        J = np.zeros((nx + 1, nx + 2))
        J[:nx, :nx] = (M - np.eye(nx)) * D[None, :] / D[:, None]
        J[:nx, nx] = flow.f(xT) / D * T_ref
        J[:nx, nx + 1] = dp / D * L
        J[nx, :nx] = c * D
        return r, J, M, xT

    def section(x):
        c = flow.f(x) / D
        return c / np.linalg.norm(c) / D

    def tangent(J, prev=None):
        _, _, vt = np.linalg.svd(J)
        t = vt[-1]
        if prev is not None and t @ prev < 0:
            t = -t
        return t

    u0 = np.concatenate([orbit.x0 / D, [1.0, (pv[k] - lo) / L]])
    r, J, M, xT = system(u0, section(orbit.x0), orbit.x0)
    t_first = tangent(J)
    first = (u0.copy(), orbit.multipliers, orbit.signals[sig]["amplitude"] if sig in orbit.signals else
             _amplitude(flow, orbit.x0, orbit.T, sig))
    t0 = time.perf_counter()
    a_max = [first[2]]
    done = [0]

    def branch(t):
        """Points along the branch from the first orbit in the direction t, and why it ended."""
        u, h, pts = u0.copy(), ds, []
        for _ in range(steps):
            if stop is not None:
                stop()
            u_prev, x_prev = u.copy(), unpack(u)[0]
            c = section(x_prev)
            ok = False
            while h >= 1e-4:
                v = u_prev + h * t
                for _it in range(8):
                    try:
                        r, J, M, xT = system(v, c, x_prev)
                    except (RunFailed, OrbitNotFound, np.linalg.LinAlgError):
                        break
                    res = float(np.max(np.abs(r[:nx])))
                    if res < tol and abs(r[nx]) < tol:
                        ok = True
                        break
                    A = np.vstack([J, t])
                    rr = np.concatenate([r, [t @ (v - u_prev) - h]])
                    try:
                        v = v - np.linalg.solve(A, rr)
                    except np.linalg.LinAlgError:
                        break
                if ok:
                    break
                h /= 2
            if not ok:
                return pts, "no convergence"
            u = v
            t = tangent(J, t)
            x, T, lam = unpack(u)
            mu = _multipliers(M, flow.f(xT))
            amp = _amplitude(flow, x, T, sig)
            a_max[0] = max(a_max[0], amp)
            pts.append((u.copy(), mu, amp))
            done[0] += 1
            h = min(ds_max, h * (1.5 if _it <= 2 else 1.0 if _it <= 4 else 0.5))
            if progress is not None:
                progress(min(1.0, done[0] / steps), f"{name} = {lam:.6g}, amplitude {amp:.4g}")
            if not lo <= lam <= hi:
                return pts, "range"
            if amp < birth_amplitude * a_max[0]:
                return pts, "birth"
        return pts, "steps"

    down, end_down = branch(-t_first if t_first[nx + 1] > 0 else t_first)
    up, end_up = branch(t_first if t_first[nx + 1] > 0 else -t_first)
    pts = [*down[::-1], first, *up]
    end = {"decreasing": end_down, "increasing": end_up}
    flow.set_p(pv)
    vals = np.array([lo + q[0][nx + 1] * L for q in pts])
    Ts = np.array([q[0][nx] * T_ref for q in pts])
    amps = np.array([q[2] for q in pts])
    mus = [q[1] for q in pts]
    stab = np.array([bool(np.all(np.abs(m[1:]) < 1.0)) for m in mus])
    bif = _bifurcations(vals, amps, mus)
    if end_down == "birth":
        bif.insert(0, {"kind": "birth", "value": float(vals[0]), "amplitude": float(amps[0]), "index": 0})
    if end_up == "birth":
        bif.append({"kind": "birth", "value": float(vals[-1]), "amplitude": float(amps[-1]), "index": len(vals) - 1})
    unit = "m" if name == "B" else ""
    return Continuation(name, unit, sig, vals, Ts, amps, mus, stab, bif,
                        {"end": end, "points": len(vals), "runs": flow.runs, "wall_time": time.perf_counter() - t0})


def _bifurcations(vals, amps, mus) -> list:
    """Folds (the parameter turns), period doubling (a real multiplier through -1) and
    torus points (a complex pair through the unit circle) between successive points."""
    out = []
    for i in range(1, len(vals)):
        if i >= 2 and (vals[i] - vals[i - 1]) * (vals[i - 1] - vals[i - 2]) < 0:
            out.append({"kind": "fold", "value": float(vals[i - 1]), "amplitude": float(amps[i - 1]), "index": i - 1})
        a, b = mus[i - 1][1:], mus[i][1:]
        for kind, sel in (("period doubling", lambda m: m[(np.abs(m.imag) < 1e-9) & (m.real < 0)]),
                          ("torus", lambda m: m[np.abs(m.imag) >= 1e-9])):
            ra, rb = sel(a), sel(b)
            na, nb = int(np.sum(np.abs(ra) > 1)), int(np.sum(np.abs(rb) > 1))
            if na != nb:
                out.append({"kind": kind, "value": float(0.5 * (vals[i] + vals[i - 1])),
                            "amplitude": float(0.5 * (amps[i] + amps[i - 1])), "index": i})
    return out
