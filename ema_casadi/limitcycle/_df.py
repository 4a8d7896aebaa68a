"""Describing function of a nonlinear open loop at a break, and its limit cycles (SPEC §4.9).

L_N(A, w): the loop is opened with its break flag (``loop_x``, ``loop_a``, ...), the
injection is the operating-point value of the measurement plus A cos(w t) (a cosine,
so that the integrators the open loop contains see a zero-mean error and do not ramp),
the nonlinear model is simulated (the compiled RK4 of :func:`ema_casadi.simulate`,
hybrid friction included) for ``periods`` periods, the first ``settle`` dropped, the
linear drift of the rest removed, and the first harmonics of injection and
measurement over each remaining whole period taken with the sine stream's
:func:`~ema_casadi.sinestream.harmonics` and averaged: L_N = -Y_1 / D_1 (the
negative-feedback convention of :func:`~ema_casadi.linearisation.loop_model`).

A limit cycle is a root of L_N(A, w) = -1: on the grid, for each amplitude the phase
crossing -180 deg is interpolated in log w, then the gain there (dB) in log A; a root
is *stable* when the gain falls through 0 dB as A grows (a larger cycle is damped, a
smaller one grows: the crossing rule). :func:`refine` polishes a root by Newton on the
two real equations with finite-difference slopes (each evaluation one simulation).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..assembly import Model
from ..signals import Signal, constant
from ..simulation import simulate
from ..sinestream import harmonics

__all__ = ["break_response", "describing_function", "predict", "refine", "DescribingFunction", "cycle_of"]

SAMPLES = 64  # kept samples per period


def _runner(model: Model, loop: str, p, x0, inputs: dict, meas0: float, dt: float, periods: int, settle: int):
    lp = model.loops[loop]
    names = list(model.param_names)
    p_open = np.array(p, float).copy()
    p_open[names.index(lp.flag)] = 0.0

    def run(A: float, f: float) -> complex:
        T = 1.0 / f
        m = max(1, math.ceil(T / SAMPLES / dt))
        h = T / SAMPLES / m
        inj = Signal.sine(A, f, -T / 4) + constant(meas0)
        res = simulate(model, periods * SAMPLES * m * h, dt=h, dt_out=m * h, p=p_open, x0=x0,
                       **{**inputs, lp.injection: inj})
        y = np.asarray(res[lp.measured])[1:]
        d = np.asarray(res[lp.injection])[1:] if lp.injection in res.inputs else None
        t = np.asarray(res.t)[1:]
        keep = slice(settle * SAMPLES, periods * SAMPLES)
        y, t = y[keep], t[keep]
        y = y - np.polyval(np.polyfit(t, y, 1), t)
        c_y = harmonics(y.reshape(-1, SAMPLES))[0].mean()
        if d is not None:
            c_d = harmonics((d[keep] - meas0).reshape(-1, SAMPLES))[0].mean()
        else:
            c_d = A  # A cos(2 pi tau): first-harmonic coefficient A
        return complex(-c_y / c_d)

    return run


def break_response(model: Model, loop: str, A: float, f: float, *, p, x0, inputs=None, meas0: float = 0.0,
                   dt: float = 1e-4, periods: int = 16, settle: int = 8) -> complex:
    """L_N(A, f) of ``loop`` at one amplitude (the measurement's unit, m) and frequency (Hz).

    Parameters
    ----------
    model : Model
    loop : str
        A loop of ``model.loops`` (``position``, ``aircraft``, ...).
    A, f : float
        Injection amplitude and frequency.
    p, x0 : ndarray
        Parameter vector (loops closed; this one is opened here) and initial state (the
        operating point).
    inputs : dict, optional
        Other inputs by name (SI), e.g. the trimmed throttle.
    meas0 : float
        The measurement at the operating point (added to the injection).
    dt : float
        Largest RK4 step (s).
    periods, settle : int
        Periods simulated, and dropped as transient.
    """
    return _runner(model, loop, p, x0, dict(inputs or {}), meas0, dt, periods, settle)(A, f)


@dataclass
class DescribingFunction:
    """L_N on a grid: ``L[i, k]`` at ``amplitudes[i]``, ``freqs[k]`` (Hz)."""

    loop: str
    amplitudes: np.ndarray
    freqs: np.ndarray
    L: np.ndarray
    cycles: list = field(default_factory=list)

    def as_dict(self) -> dict:
        return {"loop": self.loop, "amplitudes": self.amplitudes.tolist(), "freqs_hz": self.freqs.tolist(),
                "gain_db": (20 * np.log10(np.abs(self.L))).tolist(),
                "phase_deg": np.degrees(np.angle(self.L)).tolist(), "cycles": self.cycles}


def describing_function(model: Model, loop: str, amplitudes, freqs, *, p, x0, inputs=None, meas0: float = 0.0,
                        dt: float = 1e-4, periods: int = 16, settle: int = 8, stop=None) -> DescribingFunction:
    """L_N on the grid amplitudes x freqs, and the limit cycles it predicts (:func:`predict`).

    Parameters
    ----------
    model, loop, p, x0, inputs, meas0, dt, periods, settle
        As in :func:`break_response`.
    amplitudes, freqs : array_like
        The grid (measurement unit; Hz), increasing.
    stop : callable, optional
        Called before each point (raises to interrupt).
    """
    run = _runner(model, loop, p, x0, dict(inputs or {}), meas0, dt, periods, settle)
    A, F = np.asarray(amplitudes, float), np.asarray(freqs, float)
    L = np.empty((len(A), len(F)), complex)
    for i, a in enumerate(A):
        for k, f in enumerate(F):
            if stop is not None:
                stop()
            L[i, k] = run(a, f)
    df = DescribingFunction(loop, A, F, L)
    df.cycles = predict(A, F, L)
    return df


def _crossing(F, Lrow):
    """(f, gain dB) where the phase of L crosses -180 deg (first from low frequency)."""
    ok = np.isfinite(Lrow) & (np.abs(Lrow) > 0)  # a rod held by stiction answers nothing
    F, Lrow = np.asarray(F)[ok], np.asarray(Lrow)[ok]
    ph = np.degrees(np.unwrap(np.angle(Lrow)))
    s = ph + 180.0
    s = (s + 180.0) % 360.0 - 180.0  # distance from -180, wrapped
    for k in range(len(F) - 1):
        if s[k] == 0 or (s[k] * s[k + 1] < 0 and abs(s[k] - s[k + 1]) < 180):
            w = s[k] / (s[k] - s[k + 1]) if s[k] != s[k + 1] else 0.0
            lf = math.log(F[k]) + w * (math.log(F[k + 1]) - math.log(F[k]))
            g = 20 * math.log10(abs(Lrow[k])) * (1 - w) + 20 * math.log10(abs(Lrow[k + 1])) * w
            return math.exp(lf), g
    return None


def predict(amplitudes, freqs, L) -> list[dict]:
    """Limit cycles L_N(A, w) = -1 from a grid, with their stability (crossing rule).

    Parameters
    ----------
    amplitudes, freqs : ndarray
        Grid axes (increasing).
    L : ndarray of complex
        L_N on the grid, shape (amplitudes, freqs).
    """
    rows = [_crossing(freqs, L[i]) for i in range(len(amplitudes))]
    out = []
    for i in range(len(amplitudes) - 1):
        a, b = rows[i], rows[i + 1]
        if a is None or b is None or a[1] * b[1] > 0 or a[1] == b[1]:
            continue
        w = a[1] / (a[1] - b[1])
        la = math.log(amplitudes[i]) + w * (math.log(amplitudes[i + 1]) - math.log(amplitudes[i]))
        lf = math.log(a[0]) + w * (math.log(b[0]) - math.log(a[0]))
        out.append({"amplitude": math.exp(la), "freq_hz": math.exp(lf), "stable": bool(b[1] < a[1])})
    return out


def refine(model: Model, loop: str, cycle: dict, *, p, x0, inputs=None, meas0: float = 0.0, dt: float = 1e-4,
           periods: int = 16, settle: int = 8, iterations: int = 6, tol: float = 1e-3) -> dict:
    """Newton on L_N(A, f) + 1 = 0 in (log A, log f) from a grid prediction.

    Parameters
    ----------
    model, loop, p, x0, inputs, meas0, dt, periods, settle
        As in :func:`break_response`.
    cycle : dict
        A root from :func:`predict` (``amplitude``, ``freq_hz``).
    iterations : int
        Newton steps at most.
    tol : float
        Stop when |L_N + 1| is below this.
    """
    run = _runner(model, loop, p, x0, dict(inputs or {}), meas0, dt, periods, settle)
    z = np.log([cycle["amplitude"], cycle["freq_hz"]])

    def F(z):
        v = run(math.exp(z[0]), math.exp(z[1]))
        return np.log(v / -1 + 0j)  # log L_N - log(-1): zero at the root (gain dB and phase together)

    r = F(z)
    for _ in range(iterations):
        if abs(r) < tol:
            break
        h = 0.02
        J = np.empty((2, 2))
        for j in range(2):
            dz = np.zeros(2)
            dz[j] = h
            rj = F(z + dz)
            J[:, j] = [(rj - r).real / h, (rj - r).imag / h]
        step = np.linalg.solve(J, -np.array([r.real, r.imag]))
        z = z + np.clip(step, -0.5, 0.5)
        r = F(z)
    return {**cycle, "amplitude": float(math.exp(z[0])), "freq_hz": float(math.exp(z[1])),
            "residual": float(abs(r)), "refined": True}


def cycle_of(t, y, t_from: float) -> dict:
    """Amplitude (first harmonic over whole cycles, and half peak-to-peak) and frequency
    of a sustained oscillation of y over t >= t_from, its linear trend removed; amplitude
    0 when fewer than three upward zero crossings are seen.

    Parameters
    ----------
    t, y : ndarray
        Time (s) and the signal.
    t_from : float
        Start of the measured window (s).
    """
    sel = np.asarray(t) >= t_from
    t, y = np.asarray(t)[sel], np.asarray(y)[sel]
    y = y - np.polyval(np.polyfit(t, y, 1), t)  # mean and slow drift (a phugoid) removed
    half = 0.5 * float(np.ptp(y))
    ups = t[1:][(y[:-1] < 0) & (y[1:] >= 0)]
    if len(ups) < 3 or half == 0:
        return {"amplitude": 0.0, "half_pp": half, "freq_hz": None}
    t0, t1 = ups[0], ups[-1]
    w = (t >= t0) & (t < t1)
    f = (len(ups) - 1) / (t1 - t0)
    c = 2 * np.mean(y[w] * np.exp(-2j * np.pi * f * t[w]))
    return {"amplitude": float(abs(c)), "half_pp": half, "freq_hz": float(f)}
