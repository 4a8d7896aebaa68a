"""SI unit strings of the toolkit -> FMI unit definitions (base-unit exponents).

The toolkit writes units as products and quotients of symbols with integer powers
(``N*s/m``, ``V/(A*s)``, ``kg*m^2``, ``1/s^2``, ``degC``). FMI describes a unit by the
exponents of the SI base units (kg, m, s, A, K, mol, cd, rad) with a factor and an
offset; :func:`unit_definition` computes them, so an importing tool can convert.
"""

from __future__ import annotations

import re
from collections import Counter

from .._errors import ExportError

#: Base-unit exponents (kg, m, s, A, K, mol, cd, rad) of every symbol the toolkit uses.
_SYMBOLS = {
    "1": {}, "kg": {"kg": 1}, "m": {"m": 1}, "s": {"s": 1}, "A": {"A": 1}, "K": {"K": 1},
    "mol": {"mol": 1}, "cd": {"cd": 1}, "rad": {"rad": 1},
    "N": {"kg": 1, "m": 1, "s": -2},
    "J": {"kg": 1, "m": 2, "s": -2},
    "W": {"kg": 1, "m": 2, "s": -3},
    "V": {"kg": 1, "m": 2, "s": -3, "A": -1},
    "Ohm": {"kg": 1, "m": 2, "s": -3, "A": -2},
    "Wb": {"kg": 1, "m": 2, "s": -2, "A": -1},
    "H": {"kg": 1, "m": 2, "s": -2, "A": -2},
    "F": {"kg": -1, "m": -2, "s": 4, "A": 2},
    "C": {"s": 1, "A": 1},
    "Hz": {"s": -1},
}
#: Symbols with a factor/offset to their base units (value_SI = factor * value + offset).
_AFFINE = {"degC": ({"K": 1}, 1.0, 273.15)}
BASE_ORDER = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")
_TOKEN = re.compile(r"\s*(\(|\)|\*|/|\^-?\d+|[A-Za-z_][A-Za-z_0-9]*|1)")


def symbol_powers(unit: str) -> Counter:
    """``"V/(A*s)"`` -> ``{"V": 1, "A": -1, "s": -1}`` (symbols, not base units).

    Parameters
    ----------
    unit : str
        A unit string of the toolkit.
    """
    tokens, pos = [], 0
    text = unit.strip()
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if not m:
            raise ExportError(f"unit '{unit}': cannot read it at '{text[pos:]}'")
        tokens.append(m.group(1))
        pos = m.end()
    out, _ = _product(tokens, 0, unit)
    return Counter({k: v for k, v in out.items() if v and k != "1"})


def _product(tokens, i, unit):
    """Parse ``factor ((*|/) factor)*`` from ``tokens[i]``; returns (powers, next i)."""
    total: Counter = Counter()
    sign = 1
    while i < len(tokens):
        tok = tokens[i]
        if tok == ")":
            break
        if tok in "*/":
            sign = 1 if tok == "*" else -1
            i += 1
            continue
        if tok == "(":
            inner, i = _product(tokens, i + 1, unit)
            if i >= len(tokens) or tokens[i] != ")":
                raise ExportError(f"unit '{unit}': unbalanced parenthesis")
            i += 1
        else:
            inner, i = Counter({tok: 1}), i + 1
        power = 1
        if i < len(tokens) and tokens[i].startswith("^"):
            power, i = int(tokens[i][1:]), i + 1
        for k, v in inner.items():
            total[k] += sign * power * v
        sign = 1
    return total, i


def format_powers(powers: Counter) -> str:
    """Symbols with powers back to a unit string (``m/s^2``, ``V/(A*s)``, ``1/s``).

    Parameters
    ----------
    powers : Counter
        Symbol -> integer power.
    """

    def part(items):
        return "*".join(k if v == 1 else f"{k}^{v}" for k, v in items)

    num = [(k, v) for k, v in powers.items() if v > 0]
    den = [(k, -v) for k, v in powers.items() if v < 0]
    text = part(num) or "1"
    if den:
        text += "/" + (part(den) if len(den) == 1 else f"({part(den)})")
    return text


def derivative_unit(unit: str) -> str:
    """Unit of the time derivative of a quantity in ``unit`` (``m`` -> ``m/s``).

    Parameters
    ----------
    unit : str
        Unit of the quantity.
    """
    if unit in _AFFINE:  # a temperature rate is in K/s
        return "K/s"
    powers = symbol_powers(unit)
    powers["s"] -= 1
    return format_powers(Counter({k: v for k, v in powers.items() if v}))


def unit_definition(unit: str) -> dict:
    """FMI ``BaseUnit`` attributes of ``unit``: base exponents, ``factor``, ``offset``.

    Parameters
    ----------
    unit : str
        A unit string of the toolkit.
    """
    if unit in _AFFINE:
        base, factor, offset = _AFFINE[unit]
        return {**{k: str(v) for k, v in base.items()}, "factor": repr(factor), "offset": repr(offset)}
    base: Counter = Counter()
    for sym, power in symbol_powers(unit).items():
        if sym not in _SYMBOLS:
            raise ExportError(f"unit '{unit}': symbol '{sym}' has no SI definition here")
        for b, e in _SYMBOLS[sym].items():
            base[b] += power * e
    return {b: str(base[b]) for b in BASE_ORDER if base[b]}
