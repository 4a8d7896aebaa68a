"""Input signals of a run: every model input by name, with its quantity kind."""

from __future__ import annotations

import numpy as np

from .._util._checks import describe
from .._util._kwargs import check_keywords
from ..model.assembly import Model
from ..signals import Signal, SignalError, constant, parse_signal


def _as_signal(value, name: str, kind: str) -> Signal:
    """A model input's value as a Signal; SignalError naming the input otherwise (a
    non-finite number or Signal, a string that does not parse, another type)."""
    if isinstance(value, Signal):
        if not value.finite():
            raise SignalError(f"{name}: non-finite value in the signal {value.text or value!r}")
        return value
    if isinstance(value, (int, float, np.floating, np.integer)) and not isinstance(value, (bool, np.bool_)):
        if not np.isfinite(value):
            raise SignalError(f"{name}: expected a finite number, a Signal or a signal string, got {float(value)}")
        return constant(float(value))
    if isinstance(value, str):
        try:
            return parse_signal(value, kind)
        except SignalError as exc:
            raise SignalError(f"{name}: {exc}") from None
    raise SignalError(f"{name}: expected a number, a Signal or a signal string, got {describe(value)}")


def _input_signals(model: Model, given: dict, pv: np.ndarray) -> dict:
    """Every model input that is driven (given, or not an injection) as a Signal, by
    name; the quantity kind of each input selects its units."""
    check_keywords("simulate", given, model.inputs)
    P = model.pdict(pv)
    sig = {}
    for name, inp in model.input_info.items():
        value = given.get(name)
        if value is None and inp.injection:
            continue
        if value is None:
            value = getattr(P, inp.default) if isinstance(inp.default, str) else inp.default
        sig[name] = _as_signal(value, name, inp.kind)
    return sig


def _input_matrix(model, sig, t):
    """Inputs (nu x len(t)) from the signals; injections zero."""
    U = np.zeros((model.nu, len(t)), order="F")  # column-major, as the compiled code reads it
    for name, s in sig.items():
        U[model.inputs.index(name)] = s(t)
    return U


def _initial_projection(model, sig, pv, x0):
    """Hybrid models start in a consistent mode: (x0 projected, stick flag)."""
    if not model.hybrid:
        return x0, 0.0
    u0 = _input_matrix(model, sig, [0.0])[:, 0]
    xp, stick = model.project(x0, x0, u0, pv)
    return np.asarray(xp, float).ravel(), float(stick)
