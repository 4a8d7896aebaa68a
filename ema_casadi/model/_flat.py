"""One flat parameter value set from outside a file (a command-line flag), checked by
the rule its field declares: the same check a parameter file's value passes."""

from __future__ import annotations

from dataclasses import fields

import numpy as np

from .._util._checks import number
from .params import GROUPS, LOOP_FLAGS, ParameterError, UnknownParameterError, _check_value, _flat_names, _unknown

__all__ = ["checked"]


def checked(name: str, value, where: str | None = None) -> float:
    """``value`` (SI) for the flat parameter ``name``, checked as a parameter file's
    value is (a finite number in the field's range), else :class:`ParameterError`
    naming ``where``; a loop flag only as a finite number.

    Parameters
    ----------
    name : str
        Flat parameter name (``B``, ``K_i_x``, ``T_eta_2``); an unknown one raises
        :class:`UnknownParameterError`.
    value : float
        The value (SI).
    where : str, optional
        How to name it in the message (default the name; the command line passes its flag).
    """
    where = where or name
    rules = {n: {k: v for k, v in f.metadata.items() if k != "table"}
             for cls in GROUPS.values() for f in fields(cls) for n in _flat_names(f)}
    if name in LOOP_FLAGS:
        return number(value, where, ParameterError)
    if name not in rules:
        raise UnknownParameterError(_unknown("checked", name, rules))
    value = value.item() if isinstance(value, np.generic) else value
    return _check_value(where, "", "", rules[name], value, plain=True, bare=True)
