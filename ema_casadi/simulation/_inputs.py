"""Input signals of a run: every model input by name, with its quantity kind."""

from __future__ import annotations

import dataclasses
import zlib

import numpy as np

from .._util._checks import describe
from .._util._kwargs import check_keywords
from ..model.assembly import Model
from ..signals import Signal, SignalError, check_signal, constant, parse_signal

__all__ = ["noise_signal"]


def noise_signal(seed: int, name: str, rate: float, t_end: float) -> Signal:
    """A seeded unit white-noise sequence held at ``rate`` (Hz) over [0, t_end] s.

    Sample k (held over [k/rate, (k+1)/rate)) is the k-th standard normal value of
    NumPy's PCG64 generator seeded with ``(seed, crc32(name))``: one independent stream
    per input name, the same numbers in every run with the same seed. Realised as a
    table (each held value at both ends of its interval, the next one starting a
    millionth of a period later), so every solver reads it.

    Parameters
    ----------
    seed : int
        The seed (a whole number >= 0).
    name : str
        The input's name (selects the stream).
    rate : float
        Sample rate (Hz).
    t_end : float
        End of the run (s).
    """
    n = int(np.floor(t_end * rate + 1e-9)) + 1
    values = np.random.default_rng([int(seed), zlib.crc32(name.encode())]).standard_normal(n)
    k = np.arange(n, dtype=float)
    t = np.column_stack([k / rate, (k + 1 - 1e-6) / rate]).ravel()
    return Signal.table(t, np.repeat(values, 2))


def as_signal(value, name: str, kind: str) -> Signal:
    """A model input's value as a Signal; SignalError naming the input otherwise (a
    non-finite number or Signal, a string that does not parse, another type).

    Parameters
    ----------
    value : float, str or Signal
        The value (SI), a signal text (``"step(1mm, 0.01)"``) or a Signal.
    name : str
        The input, for the message.
    kind : str
        Its quantity kind (selects the units of a text).
    """
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


def input_signals(model: Model, given: dict, pv: np.ndarray, t_end: float | None = None) -> dict:
    """Every model input that is driven (given, or not an injection) as a Signal, by
    name; the quantity kind of each input selects its units. Undriven noise inputs get
    their seeded sequence over [0, t_end] (:func:`noise_signal`; the seed from the
    parameter the input names, the sample rate of the input's loop).

    Parameters
    ----------
    model : Model
        The model.
    given : dict
        Input name -> value (see :func:`as_signal`); others at their defaults.
    pv : ndarray
        The parameter vector.
    t_end : float, optional
        The run's length (s), for the noise inputs' sequences.
    """
    check_keywords("simulate", given, model.inputs)
    P = model.pdict(pv)
    sig = {}
    for name, inp in model.input_info.items():
        value = given.get(name)
        if value is None and inp.injection:
            continue
        if value is None and inp.noise is not None and t_end is not None:
            # built here from checked numbers (Signal.table checks them): no second check
            seed = int(getattr(P, inp.seed)) if inp.seed else 0
            sig[name] = noise_signal(seed, name, float(getattr(P, model.loops[inp.noise].rate)), t_end)
            continue
        if value is None:
            value = getattr(P, inp.default) if isinstance(inp.default, str) else inp.default
        sig[name] = as_signal(value, name, inp.kind)
    return sig


def check_inputs(model: Model, sig: dict, t_end: float, sampling: dict, labels: dict | None = None,
                 error: type = SignalError, limits: dict | None = None) -> None:
    """Every driving signal against the Nyquist frequency of the run's sampling, for
    the inputs in ``limits`` against the largest value it can mean, and by the rule of
    what it is (:func:`check_range`), before the run. (A signal beyond its input's
    declared bound is left to the run's envelope monitor: a failed run at once.)

    Parameters
    ----------
    model : Model
        The model.
    sig : dict
        Input name -> Signal.
    t_end : float
        The run's length (s).
    sampling : dict
        Label -> sampling interval (s), e.g. ``{"dt 5e-06 s": 5e-6}``.
    labels : dict, optional
        Input name -> how to name it (``{"x_cmd": "--x-cmd"}``).
    error : type
        The exception raised.
    limits : dict, optional
        Input name -> (largest meaningful magnitude in its SI unit, why).
    """
    labels, limits = labels or {}, limits or {}
    for name, s in sig.items():
        limit, why = limits.get(name, (None, ""))
        try:
            check_signal(s, labels.get(name, name), SignalError, t_end, limit=limit,
                         unit=model.input_info[name].unit, sampling=sampling)
        except SignalError as exc:
            raise error(f"{exc} ({why})" if why and "beyond the" in str(exc) else str(exc)) from None
        check_range(model, name, s, t_end, labels.get(name, name), error)


def check_range(model: Model, name: str, sig: Signal, t_end: float, where: str, error: type = SignalError) -> None:
    """A driving signal of ``model``'s input ``name`` by the rule of what it is
    (:func:`check_value_range`).

    Parameters
    ----------
    model : Model
        The model.
    name : str
        The input.
    sig : Signal
        Its signal.
    t_end : float
        The run's length (s).
    where : str
        How to name it in the message (``"--input eta"``).
    error : type
        The exception raised.
    """
    faults = [f for part in model.parts for f in part.faults if f.input == name]
    check_value_range(model.input_info[name], faults, sig, t_end, where, error)
    if any(v != 0 for v in sig.span(t_end)):  # driven: a fault that would run and mean nothing
        for f in faults:
            f.check_requires(model.variants, where, error)


def check_value_range(inp, faults, sig: Signal, t_end: float, where: str, error: type = SignalError) -> None:
    """A driving signal's values over [0, t_end] (:meth:`Signal.span`) by the rule of
    what the input is, the same rule that checks that value in a file: an input that
    stands for a parameter (``eta``) by the parameter's rule; a temperature above
    absolute zero; a fault's severity within the fault's range (or 0, healthy; a
    drift's input, which grows with time, not). ``error`` naming ``where`` otherwise.

    Parameters
    ----------
    inp : Input
        The input's declaration.
    faults : list of Fault
        The faults that drive it (none: not a fault input).
    sig : Signal
        Its signal.
    t_end : float
        The run's length (s).
    where : str
        How to name it in the message (``"--input eta"``).
    error : type
        The exception raised.
    """
    from ..model.params import TEMP, ParameterError, checked, checked_rule, is_parameter

    label = f"{where} '{sig.text}'" if sig.text else where
    for value in sig.span(t_end):
        try:
            if isinstance(inp.default, str):
                if is_parameter(inp.default):  # an instance's own name (A_eta): checked as finite only
                    checked(inp.default, value, label)
            elif inp.kind == "temperature":
                checked_rule(TEMP, value, label)
            elif faults and not any(f.rate for f in faults):
                faults[0].check(value, label, error, healthy=True)
        except ParameterError as exc:
            raise error(str(exc)) from None


def check_effect(model: Model, names, pv, labels: dict | None = None, error: type = SignalError) -> None:
    """Refuse a driven input the model does not read at the parameters ``pv`` (its
    rates and outputs do not depend on it: ``eta`` where the thermal network computes
    the screw efficiency from its table), naming it by ``labels``.

    Parameters
    ----------
    model : Model
        The model.
    names : iterable of str
        The inputs driven.
    pv : ndarray
        The numeric parameter vector.
    labels : dict, optional
        Input name -> how to name it (``{"eta": "--input eta"}``).
    error : type
        The exception raised.
    """
    import casadi as ca

    from ..model.components import DEFAULT_VARIANTS
    from ..model.params import FLAG, GROUPS

    FLAGS = {f.name for cls in GROUPS.values() for f in dataclasses.fields(cls) if f.metadata.get("check") == FLAG}

    # a loop-break injection and the rod's command and load are read by construction
    read = {"command", "load"}
    names = [n for n in names if not model.input_info[n].injection and not read & set(model.input_info[n].roles)]
    if not names:
        return
    x, u = ca.SX.sym("x", model.nx), ca.SX.sym("u", model.nu)
    pv = np.asarray(pv, float)

    def reads(name, p) -> bool:
        return ca.depends_on(ca.vertcat(*model.f(x, u, ca.DM(p))), u[model.inputs.index(name)])

    for name in names:
        if not reads(name, pv):
            chosen = ", ".join(f"{k}={v}" for k, v in model.variants.items() if DEFAULT_VARIANTS.get(k) != v)
            switches = [n for k, n in enumerate(model.param_names) if n in FLAGS and pv[k] in (0.0, 1.0)
                        and reads(name, np.where(np.arange(len(pv)) == k, 1.0 - pv[k], pv))]
            how = "; it does with " + " or ".join(f"{n} = {1 - pv[model.param_names.index(n)]:g}"
                                                  for n in switches) if switches else ""
            raise error(f"{(labels or {}).get(name, name)}: has no effect: the model ({chosen or 'default variants'})"
                        f" does not read the input {name} ({model.input_info[name].doc}) with these parameters{how}")


def input_matrix(model, sig, t):
    """Inputs (nu x len(t)) from the signals; injections zero.

    Parameters
    ----------
    model : Model
        The model.
    sig : dict
        Input name -> Signal (from :func:`input_signals`).
    t : array_like
        Times (s).
    """
    U = np.zeros((model.nu, len(t)), order="F")  # column-major, as the compiled code reads it
    for name, s in sig.items():
        U[model.inputs.index(name)] = s(t)
    return U


def _initial_projection(model, sig, pv, x0):
    """Hybrid models start in a consistent mode: (x0 projected, stick flag)."""
    if not model.hybrid:
        return x0, 0.0
    u0 = input_matrix(model, sig, [0.0])[:, 0]
    xp, stick = model.project(x0, x0, u0, pv)
    return np.asarray(xp, float).ravel(), float(stick)
