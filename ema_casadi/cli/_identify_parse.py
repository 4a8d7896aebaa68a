"""``ema identify``'s NAME=VALUE options parsed: bounds (LO:HI in SI) and quantities
with the unit of the signal or parameter they name (parsing only; the API checks)."""

from __future__ import annotations

import math

from . import UserError
from ._common import key_values
from ._flags import check_bare

__all__ = ["bounds", "quantities", "holds"]


def bounds(items, flag="--bounds") -> dict:
    out = {}
    for name, text in key_values(items, flag).items():
        lo, sep, hi = text.partition(":")
        try:
            a, b = float(lo), float(hi)
        except ValueError:
            raise UserError(f"{flag} {name}={text}: expected LO:HI, two numbers (SI)") from None
        if not sep or math.isnan(a) or math.isnan(b):
            raise UserError(f"{flag} {name}={text}: expected LO:HI, two numbers (SI)")
        if not a < b:
            raise UserError(f"{flag} {name}={text}: LO must be below HI")
        out[name] = (a, b)
    return out


def quantities(items, flag, model) -> dict:
    """NAME=VALUE with the unit of NAME's quantity (a signal's or a parameter's)."""
    from ..signals import KIND_OF_UNIT, SignalError, parse_quantity

    units = {**model.units, **model.params.units(), "gain_db": "dB", "phase_deg": "deg"}  # + frequency records
    out = {}
    for name, text in key_values(items, flag).items():
        if name not in units:
            from .._util._checks import nearest

            raise UserError(f"{flag} {name}: not a model signal or parameter{nearest(name, units)}")
        kind = KIND_OF_UNIT.get(units[name])
        try:
            out[name] = parse_quantity(text, kind, units[name]) if kind else float(text)
        except (SignalError, ValueError):
            raise UserError(f"{flag} {name}={text}: expected a number (SI) or a quantity in a "
                            f"{kind or units.get(name, 'SI')} unit") from None
        if name in model.units:  # a signal's value (a parameter's bounds are checked as parameters)
            check_bare(flag, name, text, out[name], kind, units[name], model)
    return out


def holds(items, model) -> dict:
    """--hold NAME[=VALUE]: name -> value (SI; a unit of the parameter's quantity) or None
    (its start value)."""
    bare = {s.strip(): None for s in items if "=" not in s}
    return {**bare, **quantities([s for s in items if "=" in s], "--hold", model)}
