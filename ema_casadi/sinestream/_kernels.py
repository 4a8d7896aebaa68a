"""Per-point numerics of the sine stream (method: :mod:`ema_casadi.sinestream`).

The period maps (CVODES in normalised time for smooth models, the compiled RK4 of
:func:`ema_casadi.simulation.simulate` for hybrid friction), built once per process and
variant; the first-harmonic extraction; the period-by-period settling loop.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass

import casadi as ca
import numpy as np

from .._util import _interrupts
from .._util._compiled import BufferCall
from ..model.assembly import Model, build_model
from ..model.components import SIGNAL_KEYS
from ..model.params import Parameters
from ..signals import Signal
from ..simulation import (
    STEPS_PER_CALL,
    GaveUp,
    Monitor,
    RunFailed,
    captured_stderr,
    inside_limit,
    integrator_failure,
    simulate,
)

#: What a sine stream measures, by role: the rod position and the motor current (the
#: harmonics' channels, in this order).
MEASURED = ("rod_position", "motor_current")
#: Largest contraction ratio assumed for a settling transient (also the value taken
#: while only one period-to-period change is known).
Q_MAX = 0.9


def _inputs(model: Model, pa, tau, PA, taus):
    """The model's inputs by name: the command A sin(2 pi tau), the load F_ext, every
    other input at its declared default (eta from p, injections 0). ``u`` at one
    normalised time ``tau`` from the SX parameters ``pa = [p; A; f; F_ext]``; ``U`` on
    the sample grid ``taus`` from their MX counterpart ``PA``."""
    npar = len(model.param_names)
    cmd, load = model.input_with("command"), model.input_with("load")
    u = model.u_expr(pa[:npar], **{cmd: pa[npar] * ca.sin(2 * ca.pi * tau), load: pa[npar + 2]})
    held = model.u_expr(PA[:npar], **{cmd: 0, load: PA[npar + 2]})
    unit_cmd = ca.DM([1.0 if n == model.input_with("command") else 0.0 for n in model.inputs])
    wave = PA[npar] * ca.DM(np.sin(2 * np.pi * np.asarray(taus))).T
    U = ca.repmat(held, 1, len(taus)) + ca.mtimes(unit_cmd, wave)
    return u, U


class _PeriodMap:
    """The one simulator of a model variant: ``(x0, [p; A; f; F_ext]) -> (x(1 period),
    x_rod and i_q at tau = k/K, k = 1..K)`` by CVODES in normalised time.

    :meth:`period` also returns every state, output and input at the K samples, for
    the envelope check (``monitored``; the integration itself is the same)."""

    def __init__(self, model: Model, samples: int, rtol: float, atol: float, monitored: bool = True):
        nx, npar = model.nx, len(model.param_names)
        self.nx, self.npar, self.K = nx, npar, samples
        x = ca.SX.sym("x", nx)
        pa = ca.SX.sym("pa", npar + 3)
        tau = ca.SX.sym("tau")
        X0 = ca.MX.sym("x0", nx)
        PA = ca.MX.sym("pa", npar + 3)
        grid = [k / samples for k in range(1, samples + 1)]
        u, U = _inputs(model, pa, tau, PA, np.array(grid))
        p, freq = pa[:npar], pa[npar + 1]
        dae = {"x": x, "p": pa, "t": tau, "ode": model.f(x, u, p)[0] / freq}
        opts = {"abstol": atol, "reltol": rtol, "max_num_steps": 10**6}
        integ = ca.integrator("sine_period_cvodes", "cvodes", dae, 0.0, grid, opts)
        Xk = integ(x0=X0, p=PA)["xf"]
        Y = model.f.map(samples)(Xk, U, PA[:npar])[1]
        sel = [model.outputs.index(model.output_with(r)) for r in MEASURED]
        outs, names = [Xk[:, -1], Y[sel, :]], ["x1", "y"]
        if monitored:
            outs, names = outs + [ca.vertcat(Xk, Y, U)], names + ["z"]
        self.F = ca.Function("sine_period", [X0, PA], outs, ["x0", "pa"], names)
        self.call = BufferCall(self.F)  # per-thread buffers, one shared Function
        self.model, self.monitored = model, monitored

    def __call__(self, x0, pa):
        """One period from x0; returns (x at the period's end, (2, K) samples), NaN if
        the integrator failed."""
        try:
            return self.period(x0, pa)[:2]
        except GaveUp:
            return np.full(self.nx, np.nan), np.full((2, self.K), np.nan)

    def period(self, x0, pa):
        """One period from x0: (x at its end, (2, K) samples, states/outputs/inputs at
        the samples or None); an integrator failure is ``GaveUp(what, tau)`` (CVODES's normalised time)."""
        with captured_stderr() as log:
            try:
                out = self.call(x0, pa)
            except RuntimeError as exc:
                _interrupts.check()
                raise GaveUp(*integrator_failure(exc, log.getvalue())) from None
        return out[0].ravel(), out[1], (out[2] if self.monitored else None)

    def first_outside(self, monitor: Monitor, z, freq, k):
        """The first sample of period k (1-based) outside the envelope, as (what, t), or None."""
        m = self.model
        taus = (k - 1) + np.arange(1, self.K + 1) / self.K
        bad = monitor.first(taus / freq, z[: m.nx], z[m.nx : m.nx + m.ny], z[m.nx + m.ny :])
        return None if bad is None else (bad.what, bad.time)


class _HybridPeriods:
    """Period-by-period stepping of a hybrid-friction model through :func:`simulate`
    (compiled RK4 with the stick projection).

    Every frequency uses the same output decimation and at least one full rollout
    chunk of samples per period, so one compiled rollout serves the whole grid; the
    harmonics then come from that finer (still uniform, whole-period) grid."""

    DECIMATE = 16

    def __init__(self, model: Model, samples: int, dt_max: float):
        self.model, self.K, self.dt_max = model, samples, dt_max
        self.npar = len(model.param_names)
        self.k_min = max(samples, -(-STEPS_PER_CALL // self.DECIMATE))
        self._caps: dict = {}

    def cap(self, p, f_ext: float, zoh: bool = False) -> float:
        """The largest step (s): ``dt_max`` inside RK4's stability limit at the point's
        parameters and load (:func:`~ema_casadi.simulation.inside_limit`), per point."""
        key = (np.asarray(p, float).tobytes(), float(f_ext), zoh)
        if key not in self._caps:
            self._caps[key] = inside_limit(self.model, {"load": float(f_ext)}, 1.0, zoh, self.dt_max, pv=p)
        return self._caps[key]

    def samples(self, pa) -> int:
        """Output samples of one period of the point ``pa`` = [p; A; f; F_ext] (even;
        ``DECIMATE`` RK4 steps each)."""
        p = pa[: self.npar]
        _, freq, f_ext = pa[self.npar :]
        n = max(self.k_min, math.ceil(1.0 / (freq * self.cap(p, f_ext) * self.DECIMATE) - 1e-9))
        return n + n % 2

    def steps_per_period(self, pa) -> int:
        """RK4 steps of one period of the point ``pa`` (its cost)."""
        return self.samples(pa) * self.DECIMATE

    def __call__(self, x0, pa):
        """One period from x0; returns (x at the period's end, samples), NaN if the run failed."""
        try:
            return self.period(x0, pa)[:2]
        except RunFailed:
            return np.full(self.model.nx, np.nan), np.full((2, self.K), np.nan)

    def period(self, x0, pa):
        """One period: (x at its end, samples, None); :func:`simulate` checks the
        envelope itself and raises RunFailed."""
        p = pa[: self.npar]
        A, freq, f_ext = pa[self.npar :]
        n = self.samples(pa)
        res = simulate(self.model, 1.0 / freq, inputs={"command": Signal.sine(A, freq), "load": float(f_ext)}, p=p,
                       x0=x0, dt=1.0 / (freq * n * self.DECIMATE), decimate=self.DECIMATE, solver="rk4")
        x1 = np.array([res.states[name][-1] for name in self.model.states])
        y = np.vstack([res[self.model.output_with(r)][1 : n + 1] for r in MEASURED])
        return x1, y, None


class _SwitchedPeriods(_HybridPeriods):
    """Period-by-period stepping of a switched (PWM) model through :func:`simulate`,
    carrier synchronous: each sine period is a whole number N = round(f_c / f) of
    carrier periods (f_c the carrier frequency the model declares; the command's
    frequency f_c / N, within 0.5/N of the asked one:
    0.5 % at 30 Hz, 1e-5 at 0.1 Hz at 16 kHz), sampled at every carrier period's end
    (N uniform samples over the whole period: the harmonics' grid)."""

    def __init__(self, model: Model, samples: int, dt_max: float):
        super().__init__(model, samples, dt_max)
        self.i_carrier = model.param_names.index(model.carrier)

    def steps_per_period(self, pa) -> int:
        """RK4 steps of one period of the point ``pa`` = [p; A; f; F_ext] (its cost)."""
        p = pa[: self.npar]
        _, freq, f_ext = pa[self.npar :]
        f_c = float(p[self.i_carrier])
        return math.ceil(max(1, round(f_c / freq)) / f_c / min(self.cap(p, f_ext, True), 0.5 / f_c))

    def period(self, x0, pa):
        p = pa[: self.npar]
        A, freq, f_ext = pa[self.npar :]
        f_c = float(p[self.i_carrier])
        n = max(1, round(f_c / freq))
        res = simulate(self.model, n / f_c, inputs={"command": Signal.sine(A, f_c / n), "load": float(f_ext)}, p=p,
                       x0=x0,
                       dt=min(self.cap(p, f_ext, True), 0.5 / f_c), dt_out=1.0 / f_c, solver="rk4")
        x1 = np.array([res.states[name][-1] for name in self.model.states])
        y = np.vstack([res[self.model.output_with(r)][1 : n + 1] for r in MEASURED])
        return x1, y, None


def coefficients(y: np.ndarray) -> np.ndarray:
    """Fourier coefficients c_0..c_(K/2) of sampled periodic signals, c_n = (2/K) sum_k
    y_k exp(-2 pi j n k/K), so that y = Re sum_n c_n exp(2 pi j n tau) (c_0 is twice the
    mean); the one discrete Fourier transform of the sine stream and the limit cycles.

    Parameters
    ----------
    y : ndarray, shape (..., K)
        Samples at tau = k/K, k = 1..K, over one whole period (each row in its own unit).
    """
    y = np.roll(y, 1, axis=-1)  # sample K (tau = 1) is tau = 0 of a periodic signal
    return np.fft.rfft(y, axis=-1) * (2.0 / y.shape[-1])


def harmonics(y: np.ndarray):
    """First harmonic, distortion and mean of sampled periodic signals.

    On the uniform grid of one whole period the rectangle rule is the discrete Fourier
    transform, ``c_n = (2/K) sum_k y_k exp(-2 pi j n k/K)``; the distortion is
    ``sqrt(sum_(n=2..K/2-1) |c_n|^2) / |c_1|``.

    Parameters
    ----------
    y : ndarray, shape (..., K)
        Samples at tau = k/K, k = 1..K, over one whole period (each row in its own
        unit, e.g. m or A).

    Returns
    -------
    c1 : ndarray of complex
        First-harmonic coefficient of each row (unit of y); a sine ``A sin(2 pi tau)``
        gives ``-j A``.
    thd : ndarray
        Total harmonic distortion up to the grid's Nyquist order (-).
    mean : ndarray
        Mean over the period (unit of y).
    """
    K = y.shape[-1]
    c = coefficients(y)
    c1 = c[..., 1]
    higher = np.sqrt(np.sum(np.abs(c[..., 2 : K // 2]) ** 2, axis=-1))
    with np.errstate(divide="ignore", invalid="ignore"):
        thd = higher / np.abs(c1)
    return c1, thd, np.roll(y, 1, axis=-1).mean(axis=-1)  # summed from tau = 0, as always (same bits)


@dataclass(frozen=True)
class _Settle:
    tol_db: float = 0.01
    tol_deg: float = 0.1
    max_periods: int = 60


def _settle(step, x0, pa, A, freq, s: _Settle, keep: bool, stop=None) -> dict:
    """Run periods until the x_rod harmonic settles (package docstring); return the point.

    Every period is checked against the model's envelope: a point that leaves it, goes
    non-finite or whose integrator fails is returned ``failed`` with the reason and
    its time (its values NaN). ``stop`` (an Event) or an interrupt ends the loop."""
    x = np.asarray(x0, float)
    monitor = Monitor(step.model, pa[: len(step.model.param_names)])
    u0 = step.model.u(pa[: len(step.model.param_names)], f_ext=pa[-1], x_cmd=0.0)
    bad = monitor.first([0.0], x, None, u0)
    if bad is not None:
        return _failed(0, f"{bad.what} at the start: the actuator cannot hold the load at rest (the state after "
                          "1 s at rest under it is outside the envelope)")
    H_prev, e_prev = None, None
    kept = []
    converged = False
    k = 0
    for k in range(1, s.max_periods + 1):
        if (stop is not None and stop.is_set()) or _interrupts.requested() is not None:
            raise _interrupts.Interrupted(_interrupts.requested() or 2)
        try:
            x, y, z = step.period(x, pa)
        except GaveUp as exc:
            return _failed(k, f"{exc.what} at t = {(k - 1 + exc.time) / freq:.6g} s (period {k})")
        except RunFailed as exc:  # the hybrid points' simulate()
            return _failed(k, f"{exc.what} at t = {(k - 1) / freq + exc.time:.6g} s (period {k})")
        if z is not None:
            out = step.first_outside(monitor, z, freq, k)
            if out is not None:
                return _failed(k, f"{out[0]} at t = {out[1]:.6g} s (period {k})")
        if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
            return _failed(k, f"non-finite x_rod or i_q in period {k}")
        if keep:
            kept.append(y)
        c1, thd, mean = harmonics(y)
        H = 1j * c1[0] / A
        if H_prev is not None and H != 0 and H_prev != 0:
            ratio = H / H_prev
            e = max(abs(20 * math.log10(abs(ratio))) / s.tol_db, abs(math.degrees(np.angle(ratio))) / s.tol_deg)
            q = Q_MAX if not e_prev else min(e / e_prev, Q_MAX)
            if e / (1 - q) <= 1.0:
                converged = True
                break
            e_prev = e
        H_prev = H
    I = 1j * c1[1]  # i_q harmonic (A), phase relative to x_cmd (whose harmonic is -j A)
    out = {
        "H": H, "distortion": float(thd[0]), "I": I, "i_q_distortion": float(thd[1]),
        "x_offset": float(mean[0]), "periods": k, "converged": converged, "failed": False,
        "status": "converged" if converged else "not_converged",
        "reason": "" if converged else f"not settled within {s.max_periods} periods",
    }
    if keep:
        out["samples"] = _kept_samples(kept, A, freq)
    return out


def _kept_samples(kept: list, A: float, freq: float) -> dict:
    """The measured samples (:data:`MEASURED`) of all simulated periods, with t (s) and the
    command (m), under their report keys (``x_cmd``, ``x_rod``, ``i_q``)."""
    Y = np.hstack(kept)
    t = np.arange(1, Y.shape[1] + 1) / (freq * kept[-1].shape[1])
    return {"t": t, SIGNAL_KEYS["command"]: A * np.sin(2 * np.pi * freq * t),
            **{SIGNAL_KEYS[role]: Y[k] for k, role in enumerate(MEASURED)}}


def _failed(k, reason: str):
    """A failed point: no values (NaN), never converged, with the reason."""
    return {"H": complex(np.nan, np.nan), "distortion": np.nan, "I": complex(np.nan, np.nan),
            "i_q_distortion": np.nan, "x_offset": np.nan, "periods": k, "converged": False, "failed": True,
            "status": "failed", "reason": reason}


_STEPPERS: dict = {}
_STEPPERS_LOCK = threading.Lock()


def _stepper(variants: dict, params: Parameters, samples: int, rtol: float, atol: float, hybrid_dt: float):
    """The period map of a variant, built once per process (the model's structure
    depends on the variants only; parameter values are inputs)."""
    key = (tuple(sorted(variants.items())), samples, rtol, atol, hybrid_dt)
    with _STEPPERS_LOCK:
        if key not in _STEPPERS:
            model = build_model(params, variants)
            if model.switched:
                _STEPPERS[key] = (model, _SwitchedPeriods(model, samples, hybrid_dt))
            elif _is_hybrid(model):
                _STEPPERS[key] = (model, _HybridPeriods(model, samples, hybrid_dt))
            else:
                _STEPPERS[key] = (model, _PeriodMap(model, samples, rtol, atol))
        return _STEPPERS[key]


def _is_hybrid(model: Model) -> bool:
    return model.hybrid
