"""Parsing the signal syntax of the command line (docs: simulate; a sum of terms, CSV tables included) into a
:class:`~ema_casadi.signals.Signal`."""

from __future__ import annotations

import numbers

import numpy as np

from ._signal import SI_UNIT, Signal, SignalError, _real, _terms, constant, parse_quantity
from ._tables import _read_table, _table_reference

__all__ = ["parse_signal"]


def parse_signal(text: str | float | Signal, kind: str = "length", bare: str | None = None,
                 stroke: float | None = None, duration: float | None = None) -> Signal:
    """Parse the signal syntax of the command line (docs: simulate) into a :class:`Signal` in SI units.

    Parameters
    ----------
    text : str, float or Signal
        The description; a number or Signal is passed through (number in SI).
    kind : str
        Quantity of the signal (``length``, ``force``, ``dimensionless``,
        ``angular_velocity``, ``current``); sets the allowed unit suffixes and the
        units a table column may name.
    bare : str, optional
        Unit of numbers without suffix in the text (default: the SI unit, ``m`` or
        ``N``). Tables are always SI unless their header names a unit.
    stroke : float, optional
        Stroke (m) for ``%`` amplitudes.
    duration : float, optional
        Simulated time (s), the sweep time of a chirp.
    """
    if isinstance(text, Signal):
        return text
    if isinstance(text, numbers.Real) and not isinstance(text, (bool, np.bool_)):
        return constant(_real(text, "parse_signal", "text"))
    if not isinstance(text, str):
        raise SignalError(f"expected a signal string, a number or a Signal, got {type(text).__name__} {text!r}"[:160])
    if kind not in SI_UNIT:
        raise SignalError(f"unknown quantity kind '{kind}'; known: {', '.join(SI_UNIT)}")
    bare = bare or SI_UNIT[kind]
    rate_bare = bare + "/s"
    out = Signal()
    for part in _terms(text):
        part = part.strip()
        if not part:
            raise SignalError(f"'{text}': empty term")
        table = _table_reference(part)
        name, _, rest = part.partition(":")
        args = rest.split("@") if rest else []
        try:
            if table is not None:
                out = out + _read_table(table[0], table[1], kind, stroke)
            elif not rest:
                out = out + constant(parse_quantity(part, kind, bare, stroke))
            elif name == "step" and 1 <= len(args) <= 2:
                t0 = parse_quantity(args[1], "time", "s") if len(args) == 2 else 0.0
                out = out + Signal.step(parse_quantity(args[0], kind, bare, stroke), t0)
            elif name == "ramp" and 1 <= len(args) <= 2:
                t0 = parse_quantity(args[1], "time", "s") if len(args) == 2 else 0.0
                rate_kind = "rate" if kind == "length" else None
                if rate_kind is None:
                    raise SignalError(f"'{part}': a ramp of {kind} is not supported; use a table")
                out = out + Signal.ramp(parse_quantity(args[0], "rate", rate_bare), t0)
            elif name == "sine" and 2 <= len(args) <= 3:
                t0 = parse_quantity(args[2], "time", "s") if len(args) == 3 else 0.0
                freq = parse_quantity(args[1], "frequency", "Hz")
                if freq <= 0:
                    raise SignalError(f"'{part}': frequency must be positive")
                out = out + Signal.sine(parse_quantity(args[0], kind, bare, stroke), freq, t0)
            elif name == "chirp" and len(args) == 2:
                f0s, _, f1s = args[1].partition("-")
                if not f1s:
                    raise SignalError(f"'{part}': expected chirp:AMP@F0-F1")
                if duration is None:
                    raise SignalError(f"'{part}': a chirp needs the simulated duration")
                f0 = parse_quantity(f0s, "frequency", "Hz")
                f1 = parse_quantity(f1s, "frequency", "Hz")
                out = out + Signal.chirp(parse_quantity(args[0], kind, bare, stroke), f0, f1, duration)
            else:
                raise SignalError(
                    f"'{part}': expected step:AMP[@T0], ramp:RATE[@T0], sine:AMP@FREQ[@T0], "
                    "chirp:AMP@F0-F1, a number or a CSV file"
                )
        except SignalError as exc:
            msg = str(exc)
            named = msg.startswith("'") or table is not None
            raise SignalError(msg if named else f"'{part}': {msg}") from None
    if not out.finite():
        raise SignalError(f"'{text}': non-finite value")
    return Signal(out.terms, str(text))
