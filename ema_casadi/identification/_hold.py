"""Holding a free parameter at a value: an option the user asks for, never a silent
default.

A parameter whose robust 95 % interval is wider than +-50 % (:data:`._result.WIDE`) is
*poorly determined* by the records: it is reported with its estimate and interval and
marked so, and the others are fitted with it. Holding it instead is asked for by name
(``hold={"c_v": 260.0}``, ``--hold c_v=260``; ``None`` or a bare name: at its start
value) or for every poorly determined one at its start value (``hold_unidentifiable``,
``--hold-unidentifiable``). A held parameter is a constant the rig may not share, so
its effect on the others is shown as the type-B component of :mod:`._structural`: the
estimates' linearised shift over its plausible range, added to the robust covariance.
The range is the one the user names (``structural={"c_v": (lo, hi)}``, ``--structural
c_v=LO:HI``), else its 95 % interval while it was free, joined with the held value and
limited to a factor :data:`RANGE_FACTOR` either side of the held value (a positive
parameter; a signed one: +-RANGE_FACTOR times its magnitude), beyond which a linearised
shift means nothing.
"""

from __future__ import annotations

import math

import numpy as np

from .._util._checks import nearest
from ._records import IdentificationError

#: A held parameter's default type-B range reaches at most this factor from its value.
RANGE_FACTOR = 10.0


def check_hold(fr, hold, structural) -> tuple[dict, dict, dict]:
    """The hold request checked before any fit.

    Parameters
    ----------
    fr : Free
        The free parameters (their start values).
    hold : dict, sequence of str or None
        Name -> value (SI) or None (the start value); a sequence of names: each at its
        start value.
    structural : dict or None
        Name -> (lo, hi): a held parameter's entry is its type-B range.

    Returns
    -------
    tuple of dict
        (name -> held value, name -> its range (lo, hi) given by the user, the other
        structural entries).
    """
    if hold is None:
        hold = {}
    elif not isinstance(hold, dict):
        hold = {n: None for n in ([hold] if isinstance(hold, str) else hold)}
    values = {}
    for name, v in hold.items():
        if name not in fr.names:
            raise IdentificationError(f"--hold {name}: not a free parameter{nearest(name, fr.names)} (hold a free "
                                      "parameter; one not free is held at its file value already)")
        k = fr.names.index(name)
        if v is None or v == "start":
            values[name] = float(fr.theta0[k])
            continue
        try:
            val = float(v)
        except (TypeError, ValueError):
            raise IdentificationError(f"--hold {name}={v}: expected a number (SI)") from None
        if not math.isfinite(val) or (fr.log[k] and val <= 0):
            raise IdentificationError(f"--hold {name}={v}: expected a finite number"
                                      + (" > 0 (a positive parameter)" if fr.log[k] else ""))
        values[name] = val
    if len(values) >= len(fr.names):
        raise IdentificationError("--hold: every free parameter held; leave at least one free")
    ranges, rest = {}, {}
    for name, rng in dict(structural or {}).items():
        if name not in values:
            rest[name] = rng
            continue
        try:
            lo, hi = (float(v) for v in rng)
        except (TypeError, ValueError):
            raise IdentificationError(f"structural {name}: expected (LO, HI), two numbers (SI)") from None
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < values[name] < hi):
            raise IdentificationError(f"--structural {name}={lo:g}:{hi:g}: the range must hold the held value "
                                      f"{values[name]:g} strictly inside")
        if fr.log[fr.names.index(name)] and lo <= 0:
            raise IdentificationError(f"--structural {name}={lo:g}:{hi:g}: {name} is positive; LO must be > 0")
        ranges[name] = (lo, hi)
    return values, ranges, rest


def default_range(value: float, positive: bool, interval) -> tuple[float, float]:
    """A held parameter's type-B range without one named (module docstring).

    Parameters
    ----------
    value : float
        The held value (SI).
    positive : bool
        Log-scaled (positive) parameter.
    interval : (float, float)
        Its 95 % interval while free (SI; infinite ends allowed).
    """
    lo, hi = (float(v) for v in interval)
    if positive:
        lo = max(min(lo, value), value / RANGE_FACTOR) if np.isfinite(lo) else value / RANGE_FACTOR
        hi = min(max(hi, value), value * RANGE_FACTOR) if np.isfinite(hi) else value * RANGE_FACTOR
        lo, hi = min(lo, value * (1 - 1e-6)), max(hi, value * (1 + 1e-6))
        return lo, hi
    span = RANGE_FACTOR * max(abs(value), 1e-12)
    lo = max(min(lo, value), value - span) if np.isfinite(lo) else value - span
    hi = min(max(hi, value), value + span) if np.isfinite(hi) else value + span
    eps = 1e-6 * max(abs(value), 1e-12)
    return min(lo, value - eps), max(hi, value + eps)


def held_doc(fr, theta, unc, values: dict, ranges: dict) -> dict:
    """Per held parameter: the held value, whether it is the start value, the range of
    its type-B term, its estimate, interval and relative half-width while free."""
    out = {}
    for n, v in values.items():
        k = fr.names.index(n)
        rng = ranges.get(n) or default_range(v, bool(fr.log[k]), unc["interval"][k])
        out[n] = {"held_at": float(v), "start": float(fr.theta0[k]), "at_start": bool(v == fr.theta0[k]),
                  "range": [float(rng[0]), float(rng[1])], "range_given": n in ranges,
                  "estimate_when_free": float(theta[k]),
                  "interval_when_free": [float(x) for x in unc["interval"][k]],
                  "relative_halfwidth": float(unc["halfwidth"][k]),
                  "poorly_determined": bool(unc["wide"][k])}
    return out
