"""Describing function of a nonlinear open loop at a break, and its limit cycles (docs: aircraft).

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

from .._util._notebook import Summarised
from ..model.assembly import Model
from ..signals import Signal, constant
from ..simulation import SimulationError, simulate
from ..sinestream import coefficients

__all__ = ["answered", "NO_ANSWER", "break_response", "describing_function", "predict", "refine",
           "DescribingFunction", "cycle_of"]

SAMPLES = 64  # kept samples per period


def _injection(meas0: float, f: float, coeffs: dict):
    """meas0 + Re sum_k c_k exp(j k 2 pi f t) as a Signal (c_1 real: a cosine)."""
    inj = constant(meas0)
    for k, c in coeffs.items():
        if abs(c) > 0:
            w = 2 * math.pi * k * f
            # |c| cos(k w t + arg c) = |c| sin(k w (t - t0)) with t0 <= 0: on from the start
            inj = inj + Signal.sine(abs(c), k * f, -((np.angle(c) + math.pi / 2) % (2 * math.pi)) / w)
    return inj


def switched_why(model: Model) -> str | None:
    """Why a switched model (the PWM bridge) has no limit-cycle analysis (one line), or
    None: it steps whole carrier periods, and the periods of an excitation or of an
    orbit are not whole carrier periods.

    Parameters
    ----------
    model : Model
    """
    if not model.switched:
        return None
    return (f"variant inverter={model.variants.get('inverter')}: the limit-cycle analyses run the averaged bridge "
            "(a switched model steps whole carrier periods, which an excitation's or an orbit's period is not); "
            "use inverter=ideal")


def _periodic_runner(model: Model, loop: str, p, x0, inputs: dict, meas0: float, dt: float, periods: int,
                     settle: int, extra: tuple = ()):
    """``run(f, coeffs) -> (Y, D, amplitudes)``: the open loop driven at the break by a
    periodic injection (harmonic k of frequency f with complex amplitude coeffs[k]);
    Y and D the harmonic coefficients 0..SAMPLES/2 of the measurement and the injection
    over the kept whole periods (detrended: Y[0] = 0), ``amplitudes`` the first-harmonic
    amplitudes of the ``extra`` signals. A switched model is refused (:func:`switched_why`)."""
    if (why := switched_why(model)) is not None:
        raise SimulationError(why)
    lp = model.loops[loop]
    names = list(model.param_names)
    p_open = np.array(p, float).copy()
    p_open[names.index(lp.flag)] = 0.0

    def run(f: float, coeffs: dict):
        T = 1.0 / f
        m = max(1, math.ceil(T / SAMPLES / dt))
        h = T / SAMPLES / m
        res = simulate(model, periods * SAMPLES * m * h, dt=h, dt_out=m * h, p=p_open, x0=x0,
                       **{**inputs, lp.injection: _injection(meas0, f, coeffs)})
        t = np.asarray(res.t)[1:]
        keep = slice(settle * SAMPLES, periods * SAMPLES)

        def of(name):
            y = np.asarray(res[name])[1:][keep]
            y = y - np.polyval(np.polyfit(t[keep], y, 1), t[keep])
            return coefficients(y.reshape(-1, SAMPLES)).mean(axis=0)

        return of(lp.measured), of(lp.injection), {n: float(abs(of(n)[1])) for n in extra}

    return run


def _runner(model: Model, loop: str, p, x0, inputs: dict, meas0: float, dt: float, periods: int, settle: int,
            extra: tuple = ()):
    """``run(A, f) -> L_N`` (and the ``extra`` amplitudes): the cosine injection."""
    periodic = _periodic_runner(model, loop, p, x0, inputs, meas0, dt, periods, settle, extra)

    def run(A: float, f: float) -> complex:
        Y, D, amp = periodic(f, {1: A})
        L = complex(-Y[1] / D[1])
        return (L, amp) if extra else L

    return run


def break_response(model: Model, loop: str, A: float, f: float, *, p, x0, inputs=None, meas0: float = 0.0,
                   dt: float = 1e-4, periods: int = 16, settle: int = 8, signals: tuple = ()):
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
    signals : tuple of str
        Also return the first-harmonic amplitudes of these signals (by name): then the
        result is ``(L_N, {name: amplitude})`` (e.g. the surface and the attitude in a
        predicted cycle).
    """
    return _runner(model, loop, p, x0, dict(inputs or {}), meas0, dt, periods, settle, tuple(signals))(A, f)


@dataclass(repr=False)
class DescribingFunction(Summarised):
    """L_N on a grid: ``L[i, k]`` at ``amplitudes[i]``, ``freqs[k]`` (Hz).

    Parameters
    ----------
    loop : str
        The loop break.
    amplitudes, freqs : ndarray
        Grid axes (the break signal's unit; Hz).
    L : ndarray of complex
        L_N on the grid.
    cycles : list of dict
        Predicted limit cycles (``amplitude``, ``freq_hz``, ``stable``; refined ones more).
    """

    loop: str
    amplitudes: np.ndarray
    freqs: np.ndarray
    L: np.ndarray
    cycles: list = field(default_factory=list)

    def _facts(self) -> dict:
        return {"loop": self.loop, "grid": f"{len(self.amplitudes)} amplitudes x {len(self.freqs)} frequencies",
                "cycles": len(self.cycles)}

    @property
    def answered(self) -> np.ndarray:
        """Where ``L`` is a response, not round-off (:func:`answered` on the grid)."""
        return answered(self.L)

    def as_dict(self) -> dict:
        """JSON-ready: gain (dB) and phase (deg) on the grid, None where there was no answer."""
        ok = self.answered
        gain = np.where(ok, 20 * np.log10(np.where(ok, np.abs(self.L), 1.0)), np.nan)
        phase = np.where(ok, np.degrees(np.angle(self.L)), np.nan)
        return {"loop": self.loop, "amplitudes": self.amplitudes.tolist(), "freqs_hz": self.freqs.tolist(),
                "gain_db": [[None if np.isnan(v) else float(v) for v in row] for row in gain],
                "phase_deg": [[None if np.isnan(v) else float(v) for v in row] for row in phase],
                "cycles": self.cycles}


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


#: Below this |L_N| the open loop has not answered (a rod held by stiction moves by round-off).
NO_ANSWER = 1e-8


def answered(L):
    """Where L_N is a response, not round-off: finite and above :data:`NO_ANSWER`.

    Parameters
    ----------
    L : ndarray of complex
        L_N values.
    """
    L = np.asarray(L)
    return np.isfinite(L) & (np.abs(L) > NO_ANSWER)


def _crossing(F, Lrow):
    """(f, gain dB) where the phase of L crosses -180 deg (first from low frequency)."""
    ok = answered(Lrow)
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
    best = (abs(r), z)
    for _ in range(iterations):
        if abs(r) < tol:
            break
        h = 0.05
        J = np.empty((2, 2))
        for j in range(2):
            dz = np.zeros(2)
            dz[j] = h
            rj = F(z + dz)
            J[:, j] = [(rj - r).real / h, (rj - r).imag / h]
        try:
            step = np.linalg.solve(J, -np.array([r.real, r.imag]))
        except np.linalg.LinAlgError:
            break
        z = z + np.clip(step, -0.3, 0.3)
        r = F(z)
        if abs(r) < best[0]:
            best = (abs(r), z)
    # a stick-slip open loop answers with some scatter: keep the best point met; a residual
    # above 0.1 (|log L_N + j pi|: ~0.9 dB or ~6 deg) says the grid estimate was kept
    res, z = best
    return {**cycle, "amplitude": float(math.exp(z[0])), "freq_hz": float(math.exp(z[1])),
            "residual": float(res), "refined": bool(res < 0.1)}


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
