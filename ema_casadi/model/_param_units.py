"""Values of a parameter file: in convertible units, ``B = "20 um"``,
``F_max = { value = 30, unit = "kN" }``, ``T_max = "150 degC"``, read with the command
line's own unit parser (:func:`~ema_casadi.signals.parse_quantity`), so a file takes
the units a flag takes. Units without a family of prefixes there (``N/m``,
``kg*m^2``, ...) are given in their SI unit."""

from __future__ import annotations

import math
from typing import Any

from ..signals import KIND_OF_UNIT as _KINDS
from ..signals import UNITS, SignalError, parse_quantity

__all__ = ["KIND_OF_UNIT", "raw_value", "absent"]

#: The SI unit of a parameter -> the quantity kind whose units the flags accept (the signals'
#: one table; a dimensionless parameter is given as a bare number).
KIND_OF_UNIT = {unit: kind for unit, kind in _KINDS.items() if kind != "dimensionless"}


def raw_value(where: str, raw: Any, unit: str, error: type) -> Any:
    """The value of a file entry in the parameter's SI unit ``unit`` (unchecked number,
    or a list for a table): ``{ value = X, unit = U }`` with U the SI unit or one the
    flags accept for that quantity, or a string ``"X U"`` (a bare number in a string is
    in the SI unit).

    Parameters
    ----------
    where : str
        The file and key, for messages.
    raw : object
        The TOML value.
    unit : str
        The parameter's SI unit.
    error : type
        The exception raised (one line naming ``where``).
    """
    if isinstance(raw, str):
        return _converted(where, raw, unit, error)
    if not isinstance(raw, dict) or "value" not in raw or "unit" not in raw:
        raise error(f'{where}: expected a table {{ value = <number>, unit = "{unit}" }} or a string such as '
                    f'"1.5 {unit}", got {raw!r}')
    extra = set(raw) - {"value", "unit"}
    if extra:
        raise error(f"{where}: unexpected field(s) {sorted(extra)}; expected value and unit")
    given = raw["unit"]
    if given == unit:
        return raw["value"]
    value, kind = raw["value"], KIND_OF_UNIT.get(unit)
    if kind is None:
        raise error(f"{where}: unit '{given}' is not the expected SI unit '{unit}' (other units are read for "
                    f"{', '.join(KIND_OF_UNIT)})")
    if not isinstance(given, str) or given not in UNITS[kind]:
        raise error(f"{where}: unit '{given}' is not the expected SI unit '{unit}' nor another {kind} unit "
                    f"({', '.join(UNITS[kind])})")
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise error(f"{where}: expected a number, got {type(value).__name__} {value!r}")
    return _converted(where, f"{value!r} {given}", unit, error)


def _converted(where: str, text: str, unit: str, error: type) -> float:
    kind = KIND_OF_UNIT.get(unit)
    if kind is None:
        raise error(f"{where}: '{text}': give this parameter in its SI unit '{unit}' (converted units are read for "
                    f"{', '.join(KIND_OF_UNIT)})")
    try:
        return parse_quantity(text.strip(), kind, bare=unit)
    except SignalError as exc:
        units = ", ".join(u for u in UNITS[kind])
        raise error(f"{where}: {exc}; a {kind} takes {units}") from None


def absent(f) -> Any:
    """The value of a key whose table the file does not have: its default, else NaN
    (never read: a model whose parts read it is refused, naming the table).

    Parameters
    ----------
    f : dataclasses.Field
        The parameter's field (its metadata: ``default``, ``table``).
    """
    if "default" in f.metadata:
        return f.metadata["default"]
    return (math.nan, math.nan) if f.metadata.get("table") else math.nan
