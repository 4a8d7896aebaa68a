"""Input signals (the command line's syntax, docs: simulate): step, ramp, sine, chirp, constant, CSV table.

A :class:`Signal` is a sum of terms. Each term evaluates on a NumPy time grid (for the
fixed-step rollout, which feeds precomputed input samples to the compiled step) and
as a CasADi expression of t (for variable-step integration), and reports its
breakpoints (instants where the signal or its slope jumps) so that a variable-step
integrator can restart there instead of stumbling over them.

Text syntax, terms joined with ``+``::

    step:AMP[@T0]       AMP from T0 on (default T0 = 0)
    ramp:RATE[@T0]      RATE*(t - T0) from T0 on
    sine:AMP@FREQ[@T0]  AMP*sin(2 pi FREQ (t - T0)) from T0 on
    chirp:AMP@F0-F1     linear sweep F0 -> F1 over the simulated time
    <number>            a constant
    FILE.csv            a table: time and one signal column (linear interpolation,
                        held at the ends)
    FILE.csv:COLUMN     one column of a multi-column table (``run.csv:x_rod``)

Amplitudes take unit suffixes: ``1mm``, ``250um``, ``0.01m``, ``0.5%`` (of the stroke),
``10kN``, ``500N``; rates ``80mm/s``; frequencies ``2`` or ``2Hz``; times ``0.5`` or
``0.5s``. A bare number is read in the quantity's default unit, which the CLI states
(mm for positions, N for forces).

Tables (the file layout, docs: simulate) are UTF-8 (a byte-order mark is accepted) and in SI units
unless the header names another unit: the CLI's "bare numbers are mm" rule is for flag
values only, never for a file. Layout: a header row whose first column is the time,
named ``time`` or ``t``; an optional ``Unit:`` row under it (the MATLAB Simulation
Data Inspector layout the toolkit writes: ``Unit:`` in the time column, then each
signal column's unit); then one row per sample, time strictly increasing. A unit may
also follow a name in brackets (``x_cmd [mm]``, ``f_ext [kN]``, ``time [ms]``); other
metadata rows of the Simulation Data Inspector (``Type:``, ``Interp:``, ...) are
skipped, lines starting with ``#`` are comments. A file of two columns without a
header is read as time (s) and value (SI).
"""

from __future__ import annotations

import math
import numbers
import re
from dataclasses import dataclass, field
from functools import cached_property

import casadi as ca
import numpy as np

from .._util._errors import InputError

__all__ = ["Signal", "SignalError", "parse_quantity", "parse_list", "parse_range", "log_grid", "check_signal",
           "constant", "UNITS", "SI_UNIT", "KIND_OF_UNIT"]


class SignalError(InputError, ValueError):
    """A signal description cannot be read; the message says what was expected."""


_LENGTH = {"m": 1.0, "mm": 1e-3, "um": 1e-6, "µm": 1e-6}
_FORCE = {"N": 1.0, "kN": 1e3, "MN": 1e6}
_RATE = {"m/s": 1.0, "mm/s": 1e-3}
#: The one unit table: kind -> unit -> factor to SI (flags, signals, tables, records, parameter files).
UNITS = {
    "length": _LENGTH, "force": _FORCE, "rate": _RATE, "frequency": {"Hz": 1.0}, "time": {"s": 1.0, "ms": 1e-3},
    "dimensionless": {"1": 1.0}, "angular_velocity": {"rad/s": 1.0, "rpm": 2 * math.pi / 60}, "current": {"A": 1.0},
    "temperature": {"degC": 1.0, "°C": 1.0},  # degC throughout (steps and amplitudes are then in K)
    "angle": {"rad": 1.0, "deg": math.pi / 180},
}
#: SI unit of each quantity kind: the unit of a bare number unless the caller says otherwise.
SI_UNIT = {"length": "m", "force": "N", "rate": "m/s", "frequency": "Hz", "time": "s",
           "dimensionless": "1", "angular_velocity": "rad/s", "current": "A", "temperature": "degC",
           "angle": "rad"}
#: The quantity kind of each SI unit (the inverse of :data:`SI_UNIT`).
KIND_OF_UNIT = {unit: kind for kind, unit in SI_UNIT.items()}
_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"


def parse_quantity(text: str, kind: str, bare: str, stroke: float | None = None) -> float:
    """Read ``text`` as a quantity of ``kind`` and return it in SI.

    Parameters
    ----------
    text : str
        A number with an optional unit suffix (``"10kN"``, ``"2 mm"``, ``"5%"``).
    kind : {"length", "force", "rate", "frequency", "time", "dimensionless", "angular_velocity", "current"}
        Quantity; sets the allowed unit suffixes.
    bare : str
        Unit of a number without suffix (e.g. ``"mm"``).
    stroke : float, optional
        Stroke (m): ``%`` is a percentage of it (lengths only).
    """
    text = text.strip()
    m = re.fullmatch(rf"({_NUM})\s*([^\d\s]*)", text)
    if not m:
        raise SignalError(f"'{text}' is not a number with an optional unit")
    value, unit = float(m.group(1)), m.group(2)
    units = UNITS[kind]
    if unit == "":
        unit = bare
    if unit == "%" and kind == "length":
        if stroke is None:
            raise SignalError(f"'{text}': a percentage needs the stroke")
        return value / 100 * stroke
    if unit not in units:
        percent = ", %" if kind == "length" else ""
        raise SignalError(f"'{text}': unknown {kind} unit '{unit}' (use {', '.join(units)}{percent})")
    return value * units[unit]


def parse_list(text: str, kind: str, bare: str, stroke: float | None = None) -> list[float]:
    """Read a comma-separated list of quantities (``"0,10kN,500"``), each in SI.

    Parameters
    ----------
    text : str
        The list; every item is read by :func:`parse_quantity`.
    kind : {"length", "force", "rate", "frequency", "time"}
        Quantity of the items; sets the allowed unit suffixes.
    bare : str
        Unit of numbers without suffix (e.g. ``"mm"``, ``"N"``, ``"Hz"``).
    stroke : float, optional
        Stroke (m) for ``%`` lengths.

    Returns
    -------
    list of float
        The values in SI units (m, N, m/s, Hz or s).
    """
    items = [s.strip() for s in str(text).split(",")]
    if not items or any(not s for s in items):
        raise SignalError(f"'{text}': expected a comma-separated list")
    return [parse_quantity(s, kind, bare, stroke) for s in items]


def parse_range(text: str, kind: str, bare: str) -> tuple[float, float, int] | None:
    """Read a range ``Q0-Q1:N`` (``"0.1-30:40"``, ``"0.1Hz-30Hz:40"``).

    Parameters
    ----------
    text : str
        The range: two quantities joined by ``-``, then ``:`` and a count.
    kind : {"length", "force", "rate", "frequency", "time"}
        Quantity of the ends; sets the allowed unit suffixes.
    bare : str
        Unit of ends without suffix (e.g. ``"Hz"``).

    Returns
    -------
    tuple of (float, float, int) or None
        The ends in SI units (m, N, m/s, Hz or s) and the count, unchecked; None when
        ``text`` does not have the form of a range.
    """
    unit = "|".join(re.escape(u) for u in UNITS[kind])
    end = rf"{_NUM}\s*(?:{unit})?"
    m = re.fullmatch(rf"\s*({end})\s*-\s*({end})\s*:\s*(\d+)\s*", text)
    if not m:
        return None
    return parse_quantity(m.group(1), kind, bare), parse_quantity(m.group(2), kind, bare), int(m.group(3))


def log_grid(text: str, kind: str, bare: str, flag: str, error: type, limit: int):
    """The log-spaced grid of a range ``Q0-Q1:N`` (see :func:`parse_range`), or None when
    ``text`` is not a range: ends positive and increasing, ``2 <= N <= limit``, checked
    before the grid is allocated (the one check of every range flag).

    Parameters
    ----------
    text : str
        The flag's value.
    kind, bare : str
        As :func:`parse_range`.
    flag : str
        The flag, named in the message (``"--amplitudes"``).
    error : type
        The exception raised.
    limit : int
        Most points allowed.
    """
    from .._util._checks import budget

    rng = parse_range(text, kind, bare)
    if rng is None:
        return None
    q0, q1, n = rng
    if not (0 < q0 < q1) or n < 2:
        raise error(f"{flag} {text}: expected Q0-Q1:N with 0 < Q0 < Q1 (increasing) and N >= 2")
    budget(n, limit, f"{flag} {text}", error)
    return np.geomspace(q0, q1, n)


@dataclass(frozen=True)
class _Term:
    kind: str
    a: float = 0.0  # amplitude / rate / constant
    f0: float = 0.0
    f1: float = 0.0
    t0: float = 0.0
    T: float = 1.0  # chirp duration
    table: tuple = ()

    def np(self, t):
        """Values on a NumPy time grid."""
        t = np.asarray(t, dtype=float)
        if self.kind == "table":
            return np.interp(t, *self._arrays)
        return self._formula(t, np.sin, lambda c: np.where(c, 1.0, 0.0))

    @cached_property
    def _arrays(self):
        """The table as arrays, made once (not a field: equality and hash keep to the table)."""
        return tuple(np.asarray(c, float) for c in self.table)

    def sym(self, t):
        """CasADi expression of the symbol t (the same formula)."""
        if self.kind == "table":
            tt, vv = self.table
            interp = ca.interpolant("table", "linear", [list(tt)], list(vv))
            return interp(ca.fmin(ca.fmax(t, tt[0]), tt[-1]))
        return self._formula(t, ca.sin, lambda c: ca.if_else(c, 1, 0))

    def _formula(self, t, sin, indicator):
        on = indicator(t >= self.t0)
        tau = t - self.t0
        if self.kind == "const":
            return self.a + 0 * t
        if self.kind == "step":
            return self.a * on
        if self.kind == "ramp":
            return self.a * tau * on
        if self.kind == "sine":
            return self.a * sin(2 * np.pi * self.f0 * tau) * on
        if self.kind == "chirp":
            k = (self.f1 - self.f0) / self.T
            return self.a * sin(2 * np.pi * (self.f0 * tau + 0.5 * k * tau**2)) * on
        raise AssertionError(self.kind)

    def breakpoints(self):
        if self.kind == "table":
            return list(self.table[0])
        return [] if self.kind == "const" else [self.t0]


@dataclass(frozen=True)
class Signal:
    """A scalar input signal u(t) in SI units: a sum of terms.

    Build one with :meth:`step`, :meth:`ramp`, :meth:`sine`, :meth:`chirp`,
    :meth:`table`, :func:`constant` or :func:`parse_signal`, and add them with ``+``.

    Attributes
    ----------
    terms : tuple
        The terms summed (private term records).
    text : str
        The description the signal was built from (for reports).
    """

    terms: tuple = field(default_factory=tuple)
    text: str = ""

    def __call__(self, t):
        """Values on a NumPy time grid."""
        t = np.asarray(t, dtype=float)
        out = np.zeros_like(t)
        for term in self.terms:
            out += term.np(t)
        return out

    def sym(self, t):
        """CasADi expression of the symbol t.

        Parameters
        ----------
        t : casadi.SX or casadi.MX
            Time symbol (s).
        """
        out = 0 * t
        for term in self.terms:
            out = out + term.sym(t)
        return out

    def breakpoints(self) -> list[float]:
        return sorted({b for term in self.terms for b in term.breakpoints()})

    def windows(self) -> list[tuple]:
        """The signal as ``(lo, hi, shift, term)``: each term counts for t in [lo, hi)
        and is evaluated at t - shift (how a compiled solver evaluates it; subclasses
        that are not a plain sum of terms say how they are one). Here every term always,
        unshifted."""
        return [(-math.inf, math.inf, 0.0, term) for term in self.terms]

    def shifted(self, t0: float) -> Signal:
        """The same signal seen from ``t0`` on: ``s.shifted(t0)(t) == s(t + t0)``.

        Parameters
        ----------
        t0 : float
            The new time origin (s).
        """
        t0 = _real(t0, "Signal.shifted", "t0")

        def at(t):  # snap round-off to the new origin, so no breakpoint lands at +1e-17 s
            v = t - t0
            return 0.0 if abs(v) <= 1e-12 * max(1.0, abs(t), abs(t0)) else v

        terms = []
        for term in self.terms:
            if term.kind == "table":
                tt, vv = term.table
                terms.append(_Term("table", table=(tuple(at(t) for t in tt), vv)))
            elif term.kind == "const":
                terms.append(term)
            else:
                terms.append(_Term(term.kind, a=term.a, f0=term.f0, f1=term.f1, t0=at(term.t0), T=term.T))
        return Signal(tuple(terms), self.text)

    def span(self, t_end: float) -> tuple[float, float]:
        """Bounds (lo, hi) of u(t) over [0, t_end], cheap whatever t_end: steps, ramps
        and tables at every breakpoint and the ends (exact), widened by every sine's
        amplitude.

        Parameters
        ----------
        t_end : float
            End of the interval (s).
        """
        t = np.array(sorted({0.0, float(t_end), *(b for b in self.breakpoints() if 0 <= b <= t_end)}))
        rest = Signal(tuple(term for term in self.terms if term.kind not in ("sine", "chirp")))
        wave = sum(abs(u.a) for u in self.terms if u.kind in ("sine", "chirp"))
        with np.errstate(all="ignore"):
            v = rest(t)
            return float(np.min(v)) - wave, float(np.max(v)) + wave

    def peak(self, t_end: float) -> float:
        """An upper bound of |u(t)| over [0, t_end] (from :meth:`span`).

        Parameters
        ----------
        t_end : float
            End of the interval (s).
        """
        lo, hi = self.span(t_end)
        return max(abs(lo), abs(hi)) if lo == lo and hi == hi else math.nan

    def top_frequency(self, t_end: float) -> float:
        """The highest frequency of a sine or chirp term over [0, t_end] (Hz); 0 without.

        Parameters
        ----------
        t_end : float
            End of the interval (s).
        """
        out = 0.0
        for term in self.terms:
            if term.kind == "sine":
                out = max(out, term.f0)
            elif term.kind == "chirp":
                k = (term.f1 - term.f0) / term.T
                out = max(out, term.f0, term.f0 + k * min(max(t_end - term.t0, 0.0), term.T))
        return out

    def finite(self) -> bool:
        """Whether every number of every term is finite."""
        for term in self.terms:
            values = (term.a, term.f0, term.f1, term.t0, term.T, *(v for col in term.table for v in col))
            if not all(isinstance(v, numbers.Real) and math.isfinite(v) for v in values):
                return False
        return True

    def __add__(self, other: Signal) -> Signal:
        return Signal(self.terms + other.terms, f"{self.text}+{other.text}".strip("+"))

    def __repr__(self):
        return f"Signal({self.text!r})"

    @staticmethod
    def step(amp: float, t0: float = 0.0) -> Signal:
        """Step of ``amp`` at ``t0``.

        Parameters
        ----------
        amp : float
            Step height (SI unit of the input it drives: m, N, ...).
        t0 : float
            Step time (s).
        """
        amp, t0 = _real(amp, "Signal.step", "amp"), _real(t0, "Signal.step", "t0")
        return Signal((_Term("step", a=amp, t0=t0),), f"step:{amp}@{t0}")

    @staticmethod
    def ramp(rate: float, t0: float = 0.0) -> Signal:
        """Ramp of ``rate`` from ``t0``.

        Parameters
        ----------
        rate : float
            Slope (SI unit of the input per second, e.g. m/s).
        t0 : float
            Start time (s).
        """
        rate, t0 = _real(rate, "Signal.ramp", "rate"), _real(t0, "Signal.ramp", "t0")
        return Signal((_Term("ramp", a=rate, t0=t0),), f"ramp:{rate}@{t0}")

    @staticmethod
    def sine(amp: float, freq: float, t0: float = 0.0) -> Signal:
        """``amp`` sin(2 pi freq (t - t0)) from ``t0`` on.

        Parameters
        ----------
        amp : float
            Amplitude (SI unit of the input).
        freq : float
            Frequency (Hz).
        t0 : float
            Start time (s).
        """
        amp, t0 = _real(amp, "Signal.sine", "amp"), _real(t0, "Signal.sine", "t0")
        freq = _real(freq, "Signal.sine", "freq", positive=True)
        return Signal((_Term("sine", a=amp, f0=freq, t0=t0),), f"sine:{amp}@{freq}@{t0}")

    @staticmethod
    def chirp(amp: float, f0: float, f1: float, duration: float, t0: float = 0.0) -> Signal:
        """Linear frequency sweep from ``f0`` to ``f1``.

        Parameters
        ----------
        amp : float
            Amplitude (SI unit of the input).
        f0, f1 : float
            Start and end frequency (Hz).
        duration : float
            Sweep time (s).
        t0 : float
            Start time (s).
        """
        amp, t0 = _real(amp, "Signal.chirp", "amp"), _real(t0, "Signal.chirp", "t0")
        f0, f1 = _real(f0, "Signal.chirp", "f0"), _real(f1, "Signal.chirp", "f1")
        duration = _real(duration, "Signal.chirp", "duration", positive=True)
        return Signal((_Term("chirp", a=amp, f0=f0, f1=f1, t0=t0, T=duration),), f"chirp:{amp}@{f0}-{f1}")

    @staticmethod
    def table(t, values) -> Signal:
        """Linear interpolation of (t, values), held constant outside.

        Parameters
        ----------
        t : array_like
            Times (s), at least two, strictly increasing.
        values : array_like
            Values at ``t`` (SI unit of the input).
        """
        try:
            t = np.asarray(t, float)
            v = np.asarray(values, float)
        except (TypeError, ValueError):
            raise SignalError("Signal.table: t and values must be arrays of numbers") from None
        if t.ndim != 1 or t.shape != v.shape or len(t) < 2 or np.any(np.diff(t) <= 0):
            raise SignalError("Signal.table: a table needs at least two rows with strictly increasing t")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(v))):
            raise SignalError("Signal.table: non-finite value in the table")
        return Signal((_Term("table", table=(tuple(t.tolist()), tuple(v.tolist()))),), "table")


def check_signal(sig: Signal, what: str, error: type, t_end: float, *, limit: float | None = None, unit: str = "",
                 sampling: dict | None = None) -> Signal:
    """The one plausibility check of a driving signal before a run: its
    largest value within ``limit`` and its highest frequency below the Nyquist rate of
    every sampling in ``sampling`` (a sine above it is sampled as garbage: aliasing).

    Parameters
    ----------
    sig : Signal
        The signal.
    what : str
        How to name it in the message (``"--x-cmd"``).
    error : type
        The exception raised.
    t_end : float
        The run's length (s).
    limit : float, optional
        Largest meaningful |value| (SI).
    unit : str
        SI unit of the values, for the message.
    sampling : dict, optional
        Label (``"--dt 5e-06 s"``) -> sampling interval (s).
    """
    peak = sig.peak(t_end) if limit is not None else 0.0
    if limit is not None and not peak <= limit:
        raise error(f"{what} '{sig.text}': reaches {peak:.4g} {unit}, beyond the {limit:.4g} {unit} it can mean here")
    f = sig.top_frequency(t_end)
    for label, dt in (sampling or {}).items() if f > 0 else ():
        if f >= 0.5 / dt:
            raise error(f"{what} '{sig.text}': {f:.4g} Hz is at or above the Nyquist frequency {0.5 / dt:.4g} Hz "
                        f"of {label} (it would alias); sample faster or drive it slower")
    return sig


def constant(value: float) -> Signal:
    """A constant signal.

    Parameters
    ----------
    value : float
        The value (SI unit of the input).
    """
    value = _real(value, "constant", "value")
    return Signal((_Term("const", a=value),), f"{value}")


def _real(value, func: str, name: str, positive: bool = False) -> float:
    """A finite real number (not a bool or a string), or SignalError naming it."""
    ok = isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))
    if ok:
        value = float(value)
        ok = math.isfinite(value) and (value > 0 or not positive)
    if not ok:
        what = "a positive finite number" if positive else "a finite number"
        text = repr(value) if len(repr(value)) <= 40 else repr(value)[:37] + "..."
        raise SignalError(f"{func}: {name}: expected {what}, got {type(value).__name__} {text}")
    return value


def _terms(text: str) -> list[str]:
    """Split on '+' but not inside a number's exponent (``1e+3``)."""
    return re.split(r"(?<![0-9.][eE])\+", text)
