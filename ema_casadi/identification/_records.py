"""Test records: time series read from CSV or ``.mat`` files, checked against a model.

A record is what a rig writes: a time column and one column per signal. Columns named
after a model input (``model.inputs``: ``x_cmd``, ``f_ext``, ``eta``, ...) drive the
model, linearly interpolated between the samples as measured; columns named after a
model state or output (``x_rod``, ``phi``, ``omega``, ``i_q``, ``F_in``, ...) are
measurements. Anything else is an error naming the column (with the nearest name).

CSV: the layout the toolkit writes: a header whose first column is
``time`` (or ``t``), an optional ``Unit:`` row, or units in brackets in the header
(``x_rod [mm]``, ``time [ms]``); SI where no unit is named. Comment lines before the
header of the form ``# NAME: VALUE`` (or ``NAME = VALUE``) are file-level fields: a
time stamp for the health trend (``# flight_hours: 1200``) or a channel's noise
(``# sigma_x_rod: 3e-7``, SI). ``.mat``: one struct (or the file's top level) with
``time`` and one field per signal in SI; scalar fields are file-level fields, a
``units`` struct (as ``SimResult.to_mat`` writes it) is checked like a ``Unit:`` row.
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._util import _checks
from .._util._checks import nearest
from .._util._errors import InputError
from ..signals import KIND_OF_UNIT, Signal, SignalError, read_text, table_header, table_rows, unit_scale

__all__ = ["Record", "read_record", "record_list", "IdentificationError", "MAX_BYTES"]

#: Largest working set of one fit (samples x states x (free parameters + 1) x 8 bytes for
#: the trajectories and their sensitivities, plus the residual Jacobian): 2 GiB, or less
#: when the machine has less memory available.
MAX_BYTES = 2**31

_FIELD = re.compile(r"^#\s*([A-Za-z_][\w.]*)\s*[:=]\s*(\S.*?)\s*$")


class IdentificationError(InputError, ValueError):
    """A mistake in an identification request (a record, a free parameter, a bound, a
    flag): one line naming it. The command line reports it with exit status 2."""


@dataclass
class Record:
    """One test record, in SI units, time from 0.

    Attributes
    ----------
    path : str
        Where it came from (named in messages and reports).
    t : ndarray
        Sample times (s), from 0, strictly increasing.
    inputs : dict
        Model input name -> values at ``t`` (drive the model).
    channels : dict
        Model state or output name -> measured values at ``t``.
    fields : dict
        File-level fields (name -> float or str): time stamps, noise levels.
    t0 : float
        The record's own first time stamp (s), subtracted from ``t``.
    left_out : dict
        Channel -> bool per sample: samples the fit gives weight zero (the model's
        unsettled predictions, :mod:`._unsettled`); empty: every sample counts.
    """

    path: str
    t: np.ndarray
    inputs: dict
    channels: dict
    fields: dict = field(default_factory=dict)
    t0: float = 0.0
    left_out: dict = field(default_factory=dict)

    @property
    def n(self) -> int:
        """Number of samples."""
        return len(self.t)

    def signals(self) -> dict:
        """The input columns as piecewise-linear :class:`~ema_casadi.signals.Signal` tables."""
        return {name: Signal.table(self.t, v) for name, v in self.inputs.items()}

    def stamp(self, name: str) -> float:
        """A time stamp: the file-level field ``name``, or the first value of a column of
        that name (flight hours, cycles).

        Parameters
        ----------
        name : str
            The field or column.
        """
        value = self.fields.get(name)
        if value is None:
            raise IdentificationError(f"{self.path}: no field or column '{name}' for the time stamp "
                                      f"(fields: {', '.join(self.fields) or 'none'})")
        try:
            return float(value)
        except ValueError:
            raise IdentificationError(f"{self.path}: field '{name}' = {value!r} is not a number") from None


def _fields(text: str) -> dict:
    """``# NAME: VALUE`` lines before the header."""
    out = {}
    for line in text.splitlines():
        s = line.strip()
        if not s:
            continue
        if not s.startswith("#"):
            break
        m = _FIELD.match(s)
        if m:
            out[m.group(1)] = _number_or_text(m.group(2))
    return out


def _number_or_text(v: str):
    try:
        return float(v)
    except ValueError:
        return v


def _check_size(path: Path) -> None:
    """A file larger than the memory could hold parsed is refused before reading."""
    try:
        size = path.stat().st_size
    except OSError:
        return  # read_text names the problem
    if size * 8 > available_bytes():
        raise IdentificationError(f"{path}: {size / 1e9:.3g} GB; parsed it would need about "
                                  f"{8 * size / 1e9:.3g} GB, more than this machine has available "
                                  f"({available_bytes() / 1e9:.3g} GB)")


def available_bytes() -> float:
    """Memory one fit may use: :data:`MAX_BYTES`, or half the available memory if less."""
    try:
        avail = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE") / 2
    except (ValueError, OSError, AttributeError):  # pragma: no cover - not on Linux
        avail = math.inf
    return float(min(MAX_BYTES, avail))


def read_record(path: str | Path, model, extra=()) -> Record:
    """Read a record and check its columns against ``model``.

    Parameters
    ----------
    path : str or Path
        A ``.csv`` or ``.mat`` file (module docstring).
    model : Model
        The model whose inputs, states and outputs the columns must name.
    extra : iterable of str
        Further column names accepted and kept as fields (a time-stamp column).

    Raises
    ------
    IdentificationError
        One line naming the file and the problem: unreadable, no ``time`` column,
        time not strictly increasing, a unit that is not the channel's quantity, an
        unknown column (nearest name), fewer than two samples, non-finite values.
    """
    path = Path(path)
    _check_size(path)
    try:
        if path.suffix.lower() == ".mat":
            names, units, data, fields = _read_mat(path)
        else:
            names, units, data, fields = _read_csv(path)
    except SignalError as exc:
        raise IdentificationError(str(exc)) from None
    _check_fields(path, fields)
    return _record(path, model, names, units, data, fields, tuple(extra))


def _check_fields(path: Path, fields: dict) -> None:
    """A channel's noise field ``sigma_<channel>`` is a positive finite number (SI):
    a typo (``abc``) or a sign slip (``-3e-7``) is refused, never read as absent."""
    for key, value in fields.items():
        if not key.startswith("sigma_"):
            continue
        ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) and value > 0
        if not ok:
            raise IdentificationError(f"{path}: field '# {key}: {value}' is not a positive number "
                                      f"(the channel's noise, 1 sigma, in SI units, e.g. '# {key}: 3e-7')")


def _read_csv(path: Path):
    text = read_text(path, "record")
    rows = table_rows(path)
    if not rows:
        raise IdentificationError(f"{path}: empty record; expected a header 'time,NAME,...' and rows of numbers")
    names, bracket, unit_row, data = table_header(path, rows)
    units = []
    for j, name in enumerate(names):
        u = bracket[j]
        if j and unit_row is not None and unit_row[j]:
            if u and u != unit_row[j]:
                raise IdentificationError(f"{path}: column '{name}': unit [{u}] in the header but "
                                          f"'{unit_row[j]}' in the Unit: row")
            u = unit_row[j]
        units.append(u)
    if len(data) < 2:
        raise IdentificationError(f"{path}: {len(data)} sample(s); a record needs at least two rows of numbers")
    arr = np.empty((len(data), len(names)))
    for i, (line, row) in enumerate(data):
        if len(row) != len(names):
            raise IdentificationError(f"{path}: line {line} has {len(row)} cells, the header {len(names)}")
        try:
            arr[i] = [float(c) for c in row]
        except ValueError:
            bad = next(c for c in row if not _is_number(c))
            raise IdentificationError(f"{path}: line {line}: '{bad}' is not a number") from None
    return names, units, arr, _fields(text)


def _is_number(c: str) -> bool:
    try:
        float(c)
        return True
    except ValueError:
        return False


def _read_mat(path: Path):
    from scipy.io import loadmat

    try:
        raw = loadmat(str(path), squeeze_me=True, struct_as_record=False)
    except Exception as exc:  # noqa: BLE001 - any unreadable file is the user's
        raise IdentificationError(f"{path}: not a readable .mat file ({type(exc).__name__}: {exc})") from None
    top = {k: v for k, v in raw.items() if not k.startswith("__")}
    if "time" not in top:
        structs = [v for v in top.values() if hasattr(v, "_fieldnames")]
        if len(structs) == 1:
            top = {f: getattr(structs[0], f) for f in structs[0]._fieldnames}
    if "time" not in top:
        raise IdentificationError(f"{path}: no 'time' field (expected a struct with time and one field per signal)")
    units_struct = top.pop("units", None)
    unit_of = {f: str(getattr(units_struct, f)) for f in getattr(units_struct, "_fieldnames", [])}
    fields, cols = {}, {}
    for k, v in top.items():
        a = np.atleast_1d(np.asarray(v))
        if a.dtype.kind in "US" or (a.size == 1 and k != "time"):
            fields[k] = _number_or_text(str(a.ravel()[0])) if a.size else ""
        elif a.dtype.kind in "fiu":
            cols[k] = a.astype(float).ravel()
    names = ["time"] + [k for k in cols if k != "time"]
    n = len(cols["time"])
    for k in names:
        if len(cols[k]) != n:
            raise IdentificationError(f"{path}: field '{k}' has {len(cols[k])} samples, time {n}")
    if n < 2:
        raise IdentificationError(f"{path}: {n} sample(s); a record needs at least two")
    data = np.column_stack([cols[k] for k in names])
    units = [unit_of.get(k, "") for k in names]
    return names, units, data, fields


def _record(path, model, names, units, data, fields, extra) -> Record:
    if not np.all(np.isfinite(data)):
        i, j = np.argwhere(~np.isfinite(data))[0]
        raise IdentificationError(f"{path}: non-finite value in column '{names[j]}' (sample {i + 1})")
    t = data[:, 0] * unit_scale(units[0], "time", f"{path}: column '{names[0]}'", None)
    if not units[0] and len(t) > 1 and t[-1] - t[0] > MAX_SPAN_S:
        raise IdentificationError(f"{path}: column '{names[0]}' has no unit and spans {t[-1] - t[0]:.4g} s "
                                  f"(over an hour) read as seconds; if it is in milliseconds, write the header "
                                  f"as {names[0]} [ms]")
    bad = np.nonzero(np.diff(t) <= 0)[0]
    if len(bad):
        k = bad[0] + 1
        raise IdentificationError(f"{path}: the time must increase strictly (sample {k + 1}: {t[k]:g} s after "
                                  f"{t[k - 1]:g} s)")
    table = model.units
    known = [*model.inputs, *model.states, *(o for o in model.outputs if o not in model.states)]
    inputs, channels = {}, {}
    fields = dict(fields)
    for j, name in enumerate(names[1:], start=1):
        if name in extra:
            fields[name] = float(data[0, j])
            continue
        if name not in table or name in ("t", "time"):
            raise IdentificationError(f"{path}: column '{name}' is neither a model input nor a state or output"
                                      f"{_did_you_mean(name, known, model)}")
        scale = _scale(units[j], table[name], f"{path}: column '{name}'", model)
        if not units[j]:
            _plausible(path, name, table[name], data[:, j], model)
        (inputs if name in model.inputs else channels)[name] = data[:, j] * scale
    if not channels:
        raise IdentificationError(f"{path}: no measured channel (a column named after a model state or output, "
                                  f"e.g. {', '.join(model.states[-2:])})")
    _within_travel(path, model, inputs)
    return Record(str(path), t - t[0], inputs, channels, fields, float(t[0]))


def _within_travel(path, model, inputs: dict) -> None:
    """A rod command beyond the rod's travel (stroke and overtravel, the envelope of its
    position) is refused: the rod cannot follow it, a fit would explain the end stop."""
    for name in model.inputs_with("command"):
        pos = model.outputs_with("rod_position")
        reach = model.envelope().get(pos[0], math.inf) if pos else math.inf
        peak = float(np.max(np.abs(inputs[name]))) if name in inputs and len(inputs[name]) else 0.0
        if peak > reach:
            raise IdentificationError(f"{path}: column '{name}' reaches {peak * 1e3:.4g} mm, beyond the rod's travel "
                                      f"+-{reach * 1e3:.4g} mm (stroke and overtravel): the rod cannot follow it")


#: A unitless time column spanning more than this (s) is not in seconds: refused.
MAX_SPAN_S = 3600.0
#: A unitless column is implausible in SI beyond these factors on the stroke, the current
#: limit and the held load (:func:`~ema_casadi._util._checks.plausible_limit`).
STROKE_FACTOR, CURRENT_FACTOR, FORCE_FACTOR = _checks.STROKE_FACTOR, _checks.CURRENT_FACTOR, _checks.FORCE_FACTOR


def _plausible(path, name: str, si: str, values, model) -> None:
    """A column without a unit must be plausible in SI for its signal (module
    docstring's limits); else refused with the header that would read it right."""
    peak = float(np.max(np.abs(values))) if len(values) else 0.0
    kind = KIND_OF_UNIT.get(si)
    bound = _checks.plausible_limit(model, kind)
    if bound is None:
        return
    limit, what = bound
    if not peak > limit:
        return
    from ..signals import UNITS

    fits = [u for u, f in sorted(UNITS[kind].items(), key=lambda kv: -kv[1]) if f < 1 and peak * f <= limit]
    fix = f"write the header as {name} [{fits[0]}]" if fits else f"give its unit in brackets ({name} [UNIT])"
    raise IdentificationError(f"{path}: column '{name}' has no unit and reaches {peak:.4g} {si}, beyond "
                              f"{limit:.4g} {si} ({what}): not SI; {fix}")


#: Name parts that mark a measured signal (x_act, phi_meas, omega_fb): the suggestion is
#: then a measured channel (state or output) of the same symbol, never an input.
_MEASURED = re.compile(r"[_ ]?(act|actual|meas|measured|fb|feedback|sens|sensed|obs)$", re.IGNORECASE)


def _did_you_mean(name: str, known: list, model) -> str:
    """The hint for an unknown column: for a measurement-like name the measured channels
    of its symbol (``x_act`` -> ``x_rod``), else the nearest known name."""
    m = _MEASURED.search(name)
    if m and m.start() > 0:
        stem = name[:m.start()].lower()
        measured = [c for c in known if c not in model.inputs and c.lower().split("_")[0] == stem]
        if measured:
            return f" (a measurement? the measured channels of '{stem}' are {', '.join(map(repr, measured[:4]))})"
    return nearest(name, known)


def _scale(unit: str, si: str, where: str, model) -> float:
    """Factor to SI of a column's unit for a signal whose SI unit is ``si``."""
    if unit in ("", si):
        return 1.0
    kind = KIND_OF_UNIT.get(si)
    if kind is None:
        raise IdentificationError(f"{where}: unit '{unit}' is not '{si}', the signal's unit")
    try:
        return unit_scale(unit, kind, where, float(model.params.actuator.stroke))
    except SignalError as exc:
        raise IdentificationError(str(exc)) from None


def record_list(records) -> list:
    """``records`` as a list: one record (a path or a :class:`Record`) or a sequence of them."""
    if isinstance(records, (str, Record)) or hasattr(records, "__fspath__"):
        return [records]
    return list(records)
