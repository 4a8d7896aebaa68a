"""Continuation of a periodic orbit over one parameter by pseudo-arclength (docs:
periodic orbits): the unknowns are the scaled state at a section, the period and the
parameter, the step goes along the branch's tangent (the null vector of the shooting
matrix, the parameter's sensitivity from the same integrator run), its length adapts to
Newton's iterations. Where the corrector fails even at a short step (a grazing contact
makes the return map non-smooth), a natural-parameter step is taken instead: the
previous orbit relaxed by a few periods at the new value, then Newton at fixed
parameter (a stable branch only). Folds, period doubling, torus points and the orbit's
birth are read off the branch and its multipliers."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from .._util._notebook import Summarised
from ..model.assembly import Model
from ..simulation import RunFailed
from ._flow import Flow, OrbitNotFound, input_value
from ._orbit import (
    PeriodicOrbit,
    _newton,
    checked_inputs,
    checked_p,
    held_inputs,
    multipliers,
    periodic_orbit,
    summaries,
)
from ._setup import setup

__all__ = ["Continuation", "continue_orbit"]


@dataclass(repr=False)
class Continuation(Summarised):
    """A branch of periodic orbits over one parameter (:func:`continue_orbit`).

    Parameters
    ----------
    name, unit : str
        The parameter continued and its SI unit.
    signal : str
        The signal whose amplitude is kept.
    values, periods : ndarray
        The parameter and the period (s) at each point of the branch, in branch order.
    amplitudes : ndarray
        First-harmonic amplitude of ``signal`` at each point.
    multipliers : list of ndarray
        Floquet multipliers at each point (trivial one first).
    stable : ndarray of bool
        Stability at each point.
    bifurcations : list of dict
        Detected points: ``kind`` (``fold``, ``period doubling``, ``torus``, ``birth``),
        ``value`` (the parameter), ``amplitude``, ``index``.
    info : dict
        ``end`` (why each direction stopped), ``points``, ``runs``, ``wall_time``, ``natural_steps``.
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

    def _facts(self) -> dict:
        v = np.asarray(self.values, float)
        return {"parameter": self.name, "range": f"{v.min():.4g} .. {v.max():.4g} {self.unit}" if v.size else None,
                "orbits": int(v.size), "bifurcations": ", ".join(b["kind"] for b in self.bifurcations) or "none"}

    @property
    def onset(self) -> float | None:
        """Where the orbit is born: a detected birth or fold, else the zero of the amplitude
        extrapolated linearly from the two points of smallest amplitude at the branch's
        low-amplitude end (None when the amplitude does not fall towards it)."""
        for b in self.bifurcations:
            if b["kind"] in ("birth", "fold"):
                return b["value"]
        i = np.argsort(self.values)
        v, a = self.values[i], self.amplitudes[i]
        if len(v) < 2:
            return None
        end = (v[:2], a[:2]) if a[0] <= a[-1] else (v[-2:], a[-2:])
        (v0, v1), (a0, a1) = end
        if a1 == a0 or v1 == v0:
            return None
        return float(v0 - a0 * (v1 - v0) / (a1 - a0))

    def as_dict(self) -> dict:
        """JSON-ready."""
        return {"parameter": self.name, "unit": self.unit, "signal": self.signal, "values": self.values.tolist(),
                "periods_s": self.periods.tolist(), "freqs_hz": (1 / self.periods).tolist(),
                "amplitudes": self.amplitudes.tolist(), "stable": self.stable.tolist(),
                "max_multiplier": [float(np.max(np.abs(m[1:]))) for m in self.multipliers],
                "bifurcations": self.bifurcations, "onset": self.onset, "info": self.info}

    def plot(self, path=None):
        """Bifurcation diagram: amplitude against the parameter, stable points solid,
        unstable dashed, the detected points marked.

        Parameters
        ----------
        path : str or Path, optional
            PNG file; the Figure is returned when not given.
        """
        from ..plots._limitcycle import plot_bifurcation

        return plot_bifurcation(self, path)


class _Branch:
    """The extended shooting system in scaled unknowns u = (x / D, T / T_scale, (lam - lo) / L)."""

    def __init__(self, model, flow: Flow, k: int | str, lo: float, hi: float, T_scale: float, signal: str,
                 tol: float):
        self.model, self.flow, self.k, self.lo, self.hi, self.signal, self.tol = model, flow, k, lo, hi, signal, tol
        self.pv = flow.pv.copy()
        self.D = model.full_scale(self.pv)
        self.L, self.T_scale, self.nx = hi - lo, T_scale, model.nx

    def unpack(self, u):
        return u[:self.nx] * self.D, u[self.nx] * self.T_scale, self.lo + u[self.nx + 1] * self.L

    def pack(self, x, T, lam):
        return np.concatenate([x / self.D, [T / self.T_scale, (lam - self.lo) / self.L]])

    def set_lam(self, lam):
        if isinstance(self.k, str):  # a held input
            self.flow.set_input(self.k, lam)
            return
        pp = self.pv.copy()
        pp[self.k] = lam
        self.flow.set_p(pp)

    def system(self, u, c, xs):
        """Residual (periodicity, section) and its Jacobian in the scaled unknowns."""
        nx, D = self.nx, self.D
        x, T, lam = self.unpack(u)
        self.set_lam(lam)
        xT, M, dp = self.flow.run(x, T, self.k)
        r = np.concatenate([(xT - x) / D, [c @ (x - xs)]])
        J = np.zeros((nx + 1, nx + 2))
        J[:nx, :nx] = (M - np.eye(nx)) * D[None, :] / D[:, None]
        J[:nx, nx] = self.flow.f(xT) / D * self.T_scale
        J[:nx, nx + 1] = dp / D * self.L
        J[nx, :nx] = c * D
        return r, J, M, xT

    def section(self, x):
        c = self.flow.f(x) / self.D
        return c / np.linalg.norm(c) / self.D

    @staticmethod
    def tangent(J, prev=None):
        t = np.linalg.svd(J)[2][-1]
        return -t if prev is not None and t @ prev < 0 else t

    def amplitude(self, x, T):
        t, X, Y = self.flow.series(x, T, 200)
        return summaries(self.flow, t, X, Y, (self.signal,))[self.signal]["amplitude"]

    def correct(self, u_prev, t, h):
        """Pseudo-arclength corrector from u_prev + h t: (u, J, M, xT, iterations) or None."""
        x_prev = self.unpack(u_prev)[0]
        c = self.section(x_prev)
        v = u_prev + h * t
        for it in range(8):
            try:
                r, J, M, xT = self.system(v, c, x_prev)
            except (RunFailed, OrbitNotFound, np.linalg.LinAlgError):
                return None
            if np.max(np.abs(r[:self.nx])) < self.tol and abs(r[self.nx]) < self.tol:
                return v, J, M, xT, it
            try:
                v = v - np.linalg.solve(np.vstack([J, t]), np.concatenate([r, [t @ (v - u_prev) - h]]))
            except np.linalg.LinAlgError:
                return None
        return None

    def natural(self, u_prev, sign, dlam):
        """A natural-parameter step: the orbit relaxed by three periods at lam + sign dlam
        (a stable orbit attracts), then Newton at fixed parameter; (u, J, M, xT, 3) or None."""
        x, T, lam = self.unpack(u_prev)
        lam = lam + sign * dlam
        self.set_lam(lam)
        try:
            for _ in range(3):
                x = self.flow.run(x, T, sens=False)[0]
            x, T, M, xT, _, _ = _newton(self.flow, x, T, self.tol, 12)
            u = self.pack(x, T, lam)
            _, J, M, xT = self.system(u, self.section(x), x)
        except (RunFailed, OrbitNotFound, np.linalg.LinAlgError):
            return None
        return u, J, M, xT, 3  # counted as a good step: the step length is kept


    def follow(self, u0, t, opts: dict, state: dict):
        """Points from u0 along the direction t, and why the branch ended."""
        br, flow = self, self.flow
        ds, ds_max, steps, stop, progress = (opts[k] for k in ("ds", "ds_max", "steps", "stop", "progress"))
        lo, hi, name = self.lo, self.hi, opts["name"]
        u, h, pts, natural = u0.copy(), ds, [], False
        sign = np.sign(t[-1]) or 1.0
        for _ in range(steps):
            if stop is not None:
                stop()
            got = None
            lam_prev = br.unpack(u)[2]
            bound = hi if t[-1] > 0 else lo
            if t[-1] != 0 and (bound - lam_prev) / (t[-1] * br.L) < h:  # land on the range's end
                h = max((bound - lam_prev) / (t[-1] * br.L), 0.0)
            room = (hi - lam_prev) if sign > 0 else (lam_prev - lo)
            while got is None and h >= ds / 16:
                got = None if natural else br.correct(u, t, h)
                if got is None and room > 1e-6 * br.L:  # a non-smooth stretch: a natural step inside the range
                    got = br.natural(u, sign, min(h * abs(t[-1]) * br.L, 0.5 * room))
                    natural = got is not None
                    state["natural"] += natural
                h = h if got is not None else h / 2
            if got is None:
                return pts, "no convergence"
            u, J, M, xT, its = got
            t = br.tangent(J, t)
            sign = np.sign(t[-1]) or sign
            x, T, lam = br.unpack(u)
            amp = br.amplitude(x, T)
            state["a_max"] = max(state["a_max"], amp)
            pts.append((u.copy(), multipliers(M, flow.f(xT)), amp))
            state["done"] += 1
            h = min(ds_max, h * (1.5 if its <= 2 else 1.0 if its <= 4 else 0.5))
            if progress is not None:
                progress(min(1.0, state["done"] / opts["total"]), f"{name} = {lam:.6g}, amplitude {amp:.4g}")
            if not lo + 1e-9 * br.L < lam < hi - 1e-9 * br.L:
                return pts, "range"
            if amp < opts["birth_amplitude"] * state["a_max"]:
                return pts, "birth"
        return pts, "steps"


def continue_orbit(model: Model, name: str, lo: float, hi: float, loop: str = "position", *, p=None,
                   condition: str = "cruise_sl", orbit: PeriodicOrbit | None = None, dt: float | None = None,
                   ds: float = 0.05, ds_max: float = 0.2, steps: int = 200, tol: float = 1e-9,
                   birth_amplitude: float = 1e-3, direction: str = "both", stop=None,
                   progress=None) -> Continuation:
    """Continue a periodic orbit over the parameter ``name`` between ``lo`` and ``hi``, with
    its multipliers, folds, period doubling, torus points and birth (module docstring).

    The branch ends where the parameter leaves [lo, hi], where the amplitude falls below
    ``birth_amplitude`` of the largest met (the orbit's birth), where no step converges,
    or after ``steps`` points per direction.

    Parameters
    ----------
    model : Model
    name : str
        A parameter of ``model.param_names`` (a gain ``K_i_x``, the backlash ``B``), or a
        driven input held constant (the load ``f_ext``, or the role ``"load"``), SI.
    lo, hi : float
        The range (SI), inside the parameter's declared range or the input's physical envelope.
    loop, p, condition, dt
        As in :func:`periodic_orbit`.
    orbit : PeriodicOrbit, optional
        The first orbit (at ``p``); computed by :func:`periodic_orbit` otherwise.
    ds, ds_max : float
        First and largest step along the branch (scaled units: the parameter by its range).
    steps : int
        Points at most per direction.
    tol : float
        Periodicity residual of each point.
    birth_amplitude : float
        Relative amplitude below which the branch is taken to be born.
    direction : {"both", "down", "up"}
        Follow the branch both ways from the first orbit, or towards lower / higher values.
    stop, progress : callable, optional
        ``stop()`` before each point (raises to interrupt); ``progress(fraction, text)``.
    """
    from ..model import checked

    name = model.input_with(name) if name in ("load",) else name
    driven = [n for n, i in model.input_info.items() if not i.injection]
    if name not in model.param_names and name not in driven:
        raise ValueError(f"continue: no parameter or driven input {name!r} in the model")
    if direction not in ("both", "down", "up"):
        raise ValueError(f"direction: {direction!r}; have both, down, up")
    if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
        raise ValueError(f"continue: range {lo!r}..{hi!r}: need lo < hi")
    pv0 = checked_p(model, p).copy()
    if name in model.param_names:
        k = list(model.param_names).index(name)
        for v in (lo, hi):
            checked(name, float(v), f"continue: {name} = {v:g}")
        start = pv0[k]
        inputs = dict(orbit.info.get("inputs") or {}) if orbit is not None else {}
    else:
        k = name
        checked_inputs(model, {name: lo}, pv0)
        checked_inputs(model, {name: hi}, pv0)
        inputs = dict(orbit.info.get("inputs") or {}) if orbit is not None else {}
        inputs.setdefault(name, input_value(model, name, pv0))
        start = inputs[name]
    if not lo <= start <= hi:
        raise ValueError(f"continue: {name} = {start:g} of the first orbit outside {lo:g}..{hi:g}")
    if orbit is None:
        orbit = periodic_orbit(model, loop, p=pv0, condition=condition, dt=dt, inputs=inputs)
    s = setup(model, loop, pv0, condition)
    flow = Flow(model, held_inputs(model, loop, s, inputs), s["p"], orbit.info.get("method", "sensitivities"),
                dt or orbit.info.get("dt", 1e-5), bool(orbit.info.get("zoh")))
    br = _Branch(model, flow, k, lo, hi, orbit.T, s["signal"], tol)
    t0 = time.perf_counter()
    u0 = br.pack(orbit.x0, orbit.T, start)
    t_up = br.tangent(br.system(u0, br.section(orbit.x0), orbit.x0)[1])
    t_up = t_up if t_up[-1] > 0 else -t_up
    first = (u0, orbit.multipliers, br.amplitude(orbit.x0, orbit.T))
    state = {"a_max": first[2], "done": 0, "natural": 0}
    opts = {"ds": ds, "ds_max": ds_max, "steps": steps, "stop": stop, "progress": progress, "name": name,
            "birth_amplitude": birth_amplitude, "total": steps * (2 if direction == "both" else 1)}

    down, end_down = br.follow(u0, -t_up, opts, state) if direction in ("both", "down") else ([], "not followed")
    up, end_up = br.follow(u0, t_up, opts, state) if direction in ("both", "up") else ([], "not followed")
    flow.set_p(s["p"])
    pts = [*down[::-1], first, *up]
    vals = np.array([br.unpack(q[0])[2] for q in pts])
    Ts = np.array([br.unpack(q[0])[1] for q in pts])
    amps = np.array([q[2] for q in pts])
    mus = [q[1] for q in pts]
    stab = np.array([bool(np.all(np.abs(m[1:]) < 1.0)) for m in mus])
    bif = _bifurcations(vals, amps, mus)
    if end_down == "birth":
        bif.insert(0, {"kind": "birth", "value": float(vals[0]), "amplitude": float(amps[0]), "index": 0})
    if end_up == "birth":
        bif.append({"kind": "birth", "value": float(vals[-1]), "amplitude": float(amps[-1]), "index": len(vals) - 1})
    unit = model.params.units().get(name, "") if isinstance(k, int) else model.input_info[name].unit
    return Continuation(name, unit, s["signal"], vals, Ts, amps, mus, stab, bif,
                        {"end": {"decreasing": end_down, "increasing": end_up}, "points": len(vals),
                         "runs": flow.runs, "natural_steps": state["natural"], "wall_time": time.perf_counter() - t0})


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
