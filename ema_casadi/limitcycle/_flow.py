"""The flow of a closed loop held autonomous, with its monodromy matrix (docs: periodic
orbits): the compiled RODAS4 with forward sensitivities on the model with its switches
held between events (each located to round-off, a saltation matrix applied at it), or,
for a switching model (hybrid friction, a sampled ECU), central differences of the
fixed-step RK4 rollout."""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from ..model.assembly import Model
from ..signals import constant
from ..simulation import forward_sensitivities, simulate

__all__ = ["OrbitNotFound", "Flow", "RTOL", "ATOL", "EVENT_GRID", "MAX_EVENTS", "SAMPLES"]

#: Integrator tolerances of the shooting runs (relative; absolute, in full-scale units).
RTOL = 1e-11
ATOL = 1e-12
#: Samples per period at which the event indicators are checked for a sign change.
EVENT_GRID = 2000
#: Most switch events in one period.
MAX_EVENTS = 100
#: Samples of the orbit's time series over one period.
SAMPLES = 400

class OrbitNotFound(RuntimeError):
    """Newton did not converge to a periodic orbit from the start given (a named failure)."""


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


class Flow:
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
        sens = forward_sensitivities
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
                tt = (grid[j] - ta) * (za / (za - zb) if za != zb else 0.5)
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
            X, _, _ = forward_sensitivities(self.model, self.sig, grid, self.pv, np.asarray(x0, float),
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
