"""Numbers as an engineer reads them: the one formatting of the commands' text reports.

A value is held in SI everywhere (results, JSON, files); a report prints it in the unit
an engineer reads for its quantity (µm and mm, kN, A, V, °, Hz, ms), chosen by size
from a short ladder per kind, with its unit written after it. A value within
:data:`NOISE` of the kind's reference unit (``-2.7e-17 A``, a solver's round-off) is
printed as ``0``: it is numerical noise, not a reading. A table column keeps one unit
(:func:`column_unit`, chosen from the column's largest value) and names it in its
heading.

``format_quantity(5.523e-6, "m")`` -> ``"5.523 µm"``; ``format_quantity(0.1397, "s")``
-> ``"139.7 ms"``; ``format_quantity(-2.68e-17, "A")`` -> ``"0 A"``.
"""

from __future__ import annotations

import math

__all__ = ["ENGINEERING", "NOISE", "format_quantity", "format_number", "format_fixed", "column_unit", "in_unit",
           "is_noise", "unit_text"]

#: Relative noise floor: a value below ``NOISE`` times its kind's reference unit (the
#: last rung of its ladder below, or the one given) prints as 0. Round-off of a double is
#: 1e-16 of the numbers it came from; the models' quantities are 1e-6 .. 1e6 of their
#: units, so a real reading is never this small and a residue of a cancellation is.
NOISE = 1e-12

#: SI unit -> the units a report uses, largest first: (unit, its size in SI, the smallest
#: magnitude, in SI, it is used for). The last rung takes every smaller value.
ENGINEERING: dict[str, tuple[tuple[str, float, float], ...]] = {
    "m": (("mm", 1e-3, 1e-3), ("µm", 1e-6, 0.0)),
    "m/s": (("mm/s", 1e-3, 0.0),),
    "N": (("kN", 1e3, 1e3), ("N", 1.0, 0.0)),
    "s": (("s", 1.0, 1.0), ("ms", 1e-3, 0.0)),
    "A": (("A", 1.0, 0.0),),
    "V": (("V", 1.0, 0.0),),
    "W": (("kW", 1e3, 1e3), ("W", 1.0, 0.0)),
    "J": (("kJ", 1e3, 1e3), ("J", 1.0, 0.0)),
    "Hz": (("Hz", 1.0, 0.0),),
    "rad": (("°", math.pi / 180, 0.0),),
    "rad/s": (("rpm", 2 * math.pi / 60, 0.0),),
    "degC": (("°C", 1.0, 0.0),),
    "N/m": (("N/µm", 1e6, 0.0),),
    "1": (("", 1.0, 0.0),),
}
#: The reference unit of each SI unit's noise floor (SI): a mm, a N, a ms, ...
_REFERENCE = {"m": 1e-3, "m/s": 1e-3, "s": 1e-3, "N/m": 1e6}


def unit_text(unit: str) -> str:
    """A unit as a report writes it: ``N*s/m`` -> ``N·s/m``, ``kg*m^2`` -> ``kg·m²``,
    ``degC`` -> ``°C``, the pure number ``1`` -> ``""``.

    Parameters
    ----------
    unit : str
        The unit as the parameter tables and the model declare it.
    """
    if unit in ("1", ""):
        return ""
    return unit.replace("*", "·").replace("^2", "²").replace("^3", "³").replace("degC", "°C")


def is_noise(value: float, si_unit: str = "1", scale: float | None = None) -> bool:
    """Whether ``value`` (SI) is numerical noise: its magnitude below :data:`NOISE` times
    ``scale`` (default the reference unit of ``si_unit``: 1 mm for a length, 1 A, 1 N).

    Parameters
    ----------
    value : float
        The value, in SI.
    si_unit : str
        Its SI unit (``"m"``, ``"A"``; ``"1"``: a pure number).
    scale : float, optional
        The size the value is read against (SI), e.g. the limit it is compared with.
    """
    ref = _REFERENCE.get(si_unit, 1.0) if scale is None else abs(scale)
    return math.isfinite(value) and abs(value) < NOISE * ref


def format_number(value: float, digits: int = 4, *, scale: float = 1.0) -> str:
    """``value`` to ``digits`` significant digits, numerical noise as ``0`` (below
    :data:`NOISE` times ``scale``), ``inf`` and ``nan`` as words.

    Parameters
    ----------
    value : float
        The number.
    digits : int
        Significant digits.
    scale : float
        The size the number is read against (the noise floor is ``NOISE * scale``).
    """
    value = float(value)
    if not math.isfinite(value):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf")
    if abs(value) < NOISE * abs(scale):
        return "0"
    return f"{value:.{digits}g}"


def format_fixed(value: float, decimals: int) -> str:
    """``value`` with ``decimals`` decimals, a value that rounds to zero as ``0.000``
    rather than ``-0.000`` (a residue of the sign is noise, not a reading).

    Parameters
    ----------
    value : float
        The number (in the unit printed).
    decimals : int
        Decimals shown.
    """
    text = f"{float(value):.{decimals}f}"
    return text[1:] if text.startswith("-") and float(text) == 0.0 else text


def column_unit(si_unit: str, values=()) -> tuple[str, float]:
    """(unit, its size in SI) a column of ``values`` (SI) is printed in: the rung of
    ``si_unit``'s ladder that its largest finite magnitude reaches (the first rung for
    a column of zeros and noise); an SI unit without a ladder is kept.

    Parameters
    ----------
    si_unit : str
        The SI unit of the values (``"m"``).
    values : iterable of float
        The column (empty: the ladder's first rung).
    """
    ladder = ENGINEERING.get(si_unit)
    if ladder is None:
        return si_unit, 1.0
    finite = [abs(float(v)) for v in values
              if v is not None and math.isfinite(float(v)) and not is_noise(float(v), si_unit)]
    big = max(finite, default=math.inf)
    for unit, size, lowest in ladder:
        if big >= lowest:
            return unit, size
    return ladder[-1][0], ladder[-1][1]


def in_unit(value: float, size: float, digits: int = 4, *, si_unit: str = "1", scale: float | None = None) -> str:
    """``value`` (SI) as a number of a unit of ``size`` (SI), without the unit (a table's
    cell); noise as ``0`` (:func:`is_noise`).

    Parameters
    ----------
    value : float
        The value, in SI.
    size : float
        The unit's size in SI (``1e-3`` for mm).
    digits : int
        Significant digits.
    si_unit : str
        The value's SI unit, for the noise floor.
    scale : float, optional
        The size the value is read against (SI), for the noise floor.
    """
    value = float(value)
    if is_noise(value, si_unit, scale):
        return "0"
    return format_number(value / size, digits, scale=0.0)


def format_quantity(value: float, si_unit: str, digits: int = 4, *, unit: str | None = None,
                    scale: float | None = None) -> str:
    """``value`` (SI) with the unit an engineer reads: ``"5.523 µm"``, ``"8.256 A"``,
    ``"15 kN"``; noise as ``"0 A"``.

    Parameters
    ----------
    value : float
        The value, in SI.
    si_unit : str
        Its SI unit (``"m"``, ``"N"``, ``"A"``, ``"s"``, ``"rad"``, ...). A unit without
        a ladder in :data:`ENGINEERING` is printed as it is.
    digits : int
        Significant digits.
    unit : str, optional
        Force this unit of the ladder (``"mm"``) rather than choose by size.
    scale : float, optional
        The size the value is read against (SI), for the noise floor.
    """
    if si_unit not in ENGINEERING and unit is None:  # printed as it is, written as read: N·s/m, kg·m²
        text = in_unit(value, 1.0, digits, si_unit=si_unit, scale=scale)
        return text if si_unit in ("", "1") else f"{text} {unit_text(si_unit)}"
    if unit is None:
        name, size = column_unit(si_unit, [value])
    else:
        sizes = {u: s for u, s, _ in ENGINEERING.get(si_unit, ((si_unit, 1.0, 0.0),))}
        if unit not in sizes:
            raise ValueError(f"unit {unit!r} is not one of {', '.join(sizes)} for {si_unit}")
        name, size = unit, sizes[unit]
    text = in_unit(value, size, digits, si_unit=si_unit, scale=scale)
    if name in ("", "1"):
        return text
    return f"{text}{'' if name in ('°', '%') else ' '}{name}"
