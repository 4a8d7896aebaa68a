"""The flow of a closed loop held autonomous, with its monodromy matrix (docs: periodic
orbits): the compiled RODAS4 with forward sensitivities on the model with its switches
held between events (each located to round-off, a saltation matrix applied at it), or,
for a switching model (hybrid friction, a sampled ECU), central differences of the
fixed-step RK4 rollout."""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from .._util._errors import RunError
from ..model.assembly import Model
from ..signals import constant
from ..simulation import forward_sensitivities, simulate

__all__ = ["OrbitNotFound", "Flow", "input_value", "RTOL", "ATOL", "EVENT_GRID", "WINDOWS", "MAX_EVENTS", "SAMPLES",
           "FD_STEP"]

#: Integrator tolerances of the shooting runs (relative; absolute, in full-scale units).
RTOL = 1e-10
ATOL = 1e-11
#: Samples per period at which the event indicators are checked for a sign change.
EVENT_GRID = 2000
#: Integration windows per period: after an event the integration goes on to the end of
#: the window it lies in (not of the period).
WINDOWS = 16
#: Most switch events in one period.
MAX_EVENTS = 100
#: Samples of the orbit's time series over one period.
SAMPLES = 400
#: Step of the finite-difference fallback's central differences (of each state's full
#: scale). Measured on the aircraft loop at RK4's default step: 1e-4 also converges but
#: loses the sampled ECU's trivial multiplier (4e-4 instead of 0.93); 1e-5 wanders.
FD_STEP = 1e-6

class OrbitNotFound(RunError, RuntimeError):
    """Newton did not converge to a periodic orbit from the start given (a named failure)."""


def input_value(model: Model, name: str, pv) -> float:
    """The default value of a driven input (a number, or the parameter it names), SI.

    Parameters
    ----------
    model : Model
    name : str
        A driven input of the model.
    pv : ndarray
        Parameter vector.
    """
    d = model.input_info[name].default
    return float(getattr(model.pdict(pv), d) if isinstance(d, str) else d)


def _signals(model: Model, held: dict, pv) -> dict:
    """Every driven input as a constant Signal: the held values, the rest at their defaults."""
    sig = {}
    for name, inp in model.input_info.items():
        if name in held:
            sig[name] = constant(float(held[name]))
        elif not inp.injection:
            sig[name] = constant(input_value(model, name, pv))
    return sig


def _u(model: Model, sig: dict) -> np.ndarray:
    return np.array([float(sig[n].terms[0].a) if n in sig and sig[n].terms else 0.0 for n in model.inputs])


class Flow:
    """phi(T; x0, p) and its derivatives for one model and held inputs."""

    def __init__(self, model: Model, held: dict, pv, method: str, dt: float, zoh: bool = False):
        self.model, self.held, self.method, self.dt, self.zoh = model, dict(held), method, dt, zoh
        self.set_p(pv)
        self.runs = 0

    def set_p(self, pv):
        self.pv = np.asarray(pv, float).copy()
        self.sig = _signals(self.model, self.held, self.pv)
        self.u = _u(self.model, self.sig)

    def set_input(self, name: str, value: float):
        """Hold the input ``name`` at ``value``.

        Parameters
        ----------
        name : str
            A driven input of the model.
        value : float
            Its held value (SI).
        """
        self.held[name] = float(value)
        self.set_p(self.pv)

    def _direction(self, var, npar: int, nz: int) -> int:
        """Row of the sensitivity directions for ``var``: a parameter's index, or an input
        name (its additive offset, appended after the parameters and the modes)."""
        return var if isinstance(var, int | np.integer) else npar + nz + self.model.inputs.index(var)

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
            if "orbit_switches" not in self.model.cache:  # kept with the model: one build per model
                from ..export.fmu import switches

                sw = switches(self.model)
                X = ca.SX.sym("x", self.model.nx)
                U = ca.SX.sym("u", self.model.nu)
                Pp = ca.SX.sym("p", len(self.pv))
                z = sw.z(X, U, Pp)
                zfun = ca.Function("zg", [X, U, Pp], [z, ca.jacobian(z, X), ca.jacobian(z, Pp), ca.jacobian(z, U)])
                self.model.cache["orbit_switches"] = (sw, _HeldModel(self.model, sw), zfun)
            self._sw, self._held, self._zfun = self.model.cache["orbit_switches"]
        return self._sw, self._held

    def _z_samples(self, X) -> np.ndarray:
        """The indicators at the columns of X (inputs and parameters substituted: ten times
        faster than mapping the general function; one map kept per number of columns)."""
        key = (self.pv.tobytes(), self.u.tobytes())
        if getattr(self, "_zbase", None) is None or self._zbase[0] != key:
            Xs = ca.SX.sym("x", self.model.nx)
            self._zbase = (key, ca.Function("zx", [Xs], [self._sw.z(Xs, self.u, self.pv)]), {})
        maps = self._zbase[2]
        if X.shape[1] not in maps:
            maps[X.shape[1]] = self._zbase[1].map(X.shape[1])
        return np.asarray(maps[X.shape[1]](X), float)

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

    def _salt(self, k, xe, Se, m, W):
        """Switch k flipped at the state xe: the new modes and the saltation-corrected
        sensitivities S+ = S- + (f- - f+) dt_e/d(.), dt_e/d(.) = -(g S- + z_p W)/(g f-)
        (none where the flow does not move the indicator, g f- = 0)."""
        _, held = self._events()
        _, g, zp, zu = (np.asarray(v, float) for v in self._zfun(xe, self.u, self.pv))
        m_new = m.copy()
        m_new[k] = -m[k]
        fm, fp = self._fheld(xe, m), self._fheld(xe, m_new)
        den = float(g[k] @ fm)
        zw = np.concatenate([zp[k], np.zeros(held.nz), zu[k]])
        dte = -(g[k] @ Se + zw @ W) / den if den else np.zeros(W.shape[1])
        return m_new, Se + np.outer(fm - fp, dte)

    def run(self, x0, T, k_param: int | str | None = None, sens: bool = True):
        """x(T), M = dx(T)/dx0 and (with k_param) dx(T)/dp_k (k_param a parameter's index)
        or dx(T)/du (k_param a held input's name); with ``sens=False`` x(T) alone (M and
        the derivative None: the same steps and events, one zero direction instead of
        nx, several times cheaper). The held model integrated
        between events, window by window (:data:`WINDOWS` per period, the indicators
        checked at :data:`EVENT_GRID` samples per period), each event located to
        round-off along the held flow, a saltation matrix applied at it (a switch that
        flips with it is found by a short probe window after each event)."""
        self.runs += 1
        nx, npar = self.model.nx, len(self.pv)
        if self.method == "rk4":
            return self._run_fd(x0, T, k_param) if sens else (self.end(x0, T), None, None)
        sw, held = self._events()
        derivs, fs = sens, forward_sensitivities
        nd = (nx + (k_param is not None)) if derivs else 1
        W = np.zeros((npar + held.nz + self.model.nu, nd))
        if k_param is not None and derivs:
            W[self._direction(k_param, npar, held.nz), nx] = 1.0
        S = np.zeros((nx, nd))
        if derivs:
            S[:, :nx] = np.eye(nx)
        x = np.asarray(x0, float).copy()
        m = self.modes(x)
        t, n_events = 0.0, 0
        self.events = []
        probe = False
        while True:
            left = T - t
            # after an event a short probe first: a switch flipping with it shows within a few samples
            # (the flow in the not-yet-consistent modes can be stiff)
            wide = 8 * T / EVENT_GRID if probe else T / WINDOWS
            span = left if left <= 1.25 * wide else wide
            probe = False
            n = max(8, int(math.ceil(EVENT_GRID * span / T)))
            grid = np.linspace(0.0, span, n + 1)
            pm = np.concatenate([self.pv, m, np.zeros(self.model.nu)])
            X, SX, _ = fs(held, self.sig, grid, pm, x, W, S, RTOL, ATOL)
            Z = self._z_samples(X)
            flip = (m[:, None] != 0) & (np.sign(Z) == -m[:, None])
            flip[:, 0] = False  # at an event's own state the flipped indicator is still ~0
            hit = np.nonzero(flip.any(axis=0))[0]
            if len(hit) == 0:
                x, S = X[:, -1], SX[-1].T
                t += span
                if span == left:
                    if not derivs:
                        return x, None, None
                    return x, S[:, :nx], (S[:, nx] if k_param is not None else None)
                continue
            j = int(hit[0])
            ks = np.nonzero(flip[:, j])[0]
            # locate the first crossing in (grid[j-1], grid[j]) from the sample before it
            xa, Sa, ta = X[:, j - 1], SX[j - 1].T, grid[j - 1]
            k, tau = None, None
            for kk in ks:
                za, zb = Z[kk, j - 1], Z[kk, j]
                tt = (grid[j] - ta) * (za / (za - zb) if za != zb else 0.5)
                if tau is None or tt < tau:
                    k, tau = int(kk), tt

            def to(tau, xa=xa, Sa=Sa, pm=pm, m=m, ns=nd):
                if tau <= 1e-9 * T:  # too short a step for the driver: first order (error ~ tau^2)
                    return xa + tau * self._fheld(xa, m), Sa + tau * self._jheld(xa, m) @ Sa
                Ww, Ss = (W, Sa) if ns else (W[:, :1] * 0, Sa[:, :1] * 0)
                Xe, SXe, _ = fs(held, self.sig, np.array([0.0, tau]), pm, xa, Ww, Ss, RTOL, ATOL)
                return Xe[:, -1], SXe[-1].T

            for _ in range(8):  # Newton on z_k(x(tau)) = 0 along the held flow (the state alone)
                xe, _ = to(tau, ns=0)
                z, g = (np.asarray(v, float) for v in self._zfun(xe, self.u, self.pv)[:2])
                zdot = float(g[k] @ self._fheld(xe, m))
                if zdot == 0:  # the indicator does not move along the flow: its crossing is where found
                    break
                dtau = -float(z.ravel()[k]) / zdot
                tau = min(max(tau + dtau, 0.0), grid[j] - ta)
                if abs(dtau) < 1e-13 * T:
                    break
            xe, Se = to(tau)
            m, S = self._salt(k, xe, Se, m, W)
            x, t = xe, t + ta + tau
            self.events.append((t, k, -m[k]))
            n_events += 1
            probe = True
            if n_events > MAX_EVENTS:
                raise OrbitNotFound(f"more than {MAX_EVENTS} switch events in one period (the orbit slides "
                                    "along a switch): no smooth flow to shoot on; use method='rk4'")

    def end(self, x0, T, pv=None, sig=None) -> np.ndarray:
        """x(T) by the fixed-step rollout (the RK4 fallback)."""
        n = max(1, math.ceil(T / self.dt))
        res = simulate(self.model, T, dt=T / n, dt_out=T, p=self.pv if pv is None else pv, x0=np.asarray(x0, float),
                       solver="rk4", zoh=self.zoh, **(self.sig if sig is None else sig))
        return np.array([res.states[s][-1] for s in self.model.states])

    def _run_fd(self, x0, T, k_param):
        scale = self.model.full_scale(self.pv)
        xT = self.end(x0, T)
        nx = self.model.nx
        M = np.empty((nx, nx))
        for j in range(nx):  # central differences of the rollout, FD_STEP of full scale
            h = FD_STEP * scale[j]
            e = np.zeros(nx)
            e[j] = h
            M[:, j] = (self.end(x0 + e, T) - self.end(x0 - e, T)) / (2 * h)
        dp = None
        if isinstance(k_param, str):  # a held input: central difference of its held value
            v = self.held.get(k_param, float(self.u[self.model.inputs.index(k_param)]))
            h = 1e-6 * max(abs(v), 1.0)
            ends = [self.end(x0, T, sig={**self.sig, k_param: constant(v + d)}) for d in (h, -h)]
            dp = (ends[0] - ends[1]) / (2 * h)
        elif k_param is not None:
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
                           solver="rk4", zoh=self.zoh, **self.sig)
            X = np.array([res.states[s] for s in self.model.states])
            grid = np.asarray(res.t)
        else:
            nx = self.model.nx
            X, _, _ = forward_sensitivities(self.model, self.sig, grid, self.pv, np.asarray(x0, float),
                                               np.zeros((len(self.pv), 1)), np.zeros((nx, 1)), RTOL, ATOL)
        fm = self.model.f.map(X.shape[1])
        Y = np.asarray(fm(X, np.tile(self.u[:, None], X.shape[1]), np.tile(self.pv[:, None], X.shape[1]))[1])
        return grid, X, Y


class _HeldModel:
    """The model with its switches held in given modes, the modes and an offset of each
    input appended to the parameter vector (the offsets 0 in a run: their sensitivity
    directions are those of the held inputs): what the sensitivity driver compiles
    (smooth between events)."""

    def __init__(self, model: Model, sw):
        self.nx, self.nu, self.inputs = model.nx, model.nu, model.inputs
        self.nz = sw.z.size1_out(0)
        self.param_names = (*model.param_names, *(f"_mode_{k}" for k in range(self.nz)),
                            *(f"_offset_{n}" for n in model.inputs))
        x = ca.SX.sym("x", model.nx)
        u = ca.SX.sym("u", model.nu)
        p = ca.SX.sym("p", len(model.param_names))
        m = ca.SX.sym("m", self.nz)
        du = ca.SX.sym("du", model.nu)
        xdot, y = sw.f(x, u + du, p, m)
        self.f = ca.Function("f", [x, u, ca.vertcat(p, m, du)], [xdot, y], ["x", "u", "p"], ["xdot", "y"])
        self.cache = {}
