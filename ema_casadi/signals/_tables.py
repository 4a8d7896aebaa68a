"""Signal tables (the file layout, docs: simulate): CSV files read as :class:`~ema_casadi.signals.Signal`
tables, UTF-8 (a byte-order mark accepted), SI unless a header names a unit; the
time column ``time`` or ``t``, an optional ``Unit:`` row (the MATLAB Simulation Data
Inspector layout), a column selector ``FILE.csv:COLUMN``. Used by
:func:`~ema_casadi.signals.parse_signal`."""

from __future__ import annotations

import csv
import io
import math
import re
from pathlib import Path

import numpy as np

from .._util._checks import nearest, read_text_file
from ._signal import _NUM, SI_UNIT, UNITS, Signal, SignalError

#: Names the time column of a table may have (the file layout: ``time``; ``t`` accepted).
TIME_NAMES = ("time", "t")
_HEADER_CELL = re.compile(r"^\s*(.*?)\s*(?:\[([^\]]*)\])?\s*$")


def read_text(path: str | Path, what: str = "file") -> str:
    """A file's text, decoded as UTF-8 (a byte-order mark is accepted and dropped).

    Raises :class:`SignalError` with one line naming the file when it cannot be read or
    is not UTF-8 (e.g. saved as Latin-1 or UTF-16).

    Parameters
    ----------
    path : str or Path
        The file.
    what : str
        What the file is, for the messages (``"signal table"``).
    """
    return read_text_file(path, what, SignalError)


def unit_scale(unit: str, kind: str, where: str, stroke: float | None) -> float:
    """Factor to SI of a column's unit (empty: SI) for a quantity ``kind``.

    Parameters
    ----------
    unit : str
        The column's unit (``"mm"``; ``""``: SI; ``"%"``: of the stroke, for a length).
    kind : str
        The quantity kind (a key of :data:`~ema_casadi.signals.UNITS`).
    where : str
        The file and column, for the message.
    stroke : float or None
        The stroke (m) a ``%`` length is a fraction of; None: ``%`` refused.
    """
    if unit in ("", SI_UNIT[kind]):
        return 1.0
    if kind == "length" and unit == "%":
        if stroke is None:
            raise SignalError(f"{where}: unit '%' needs the stroke")
        return stroke / 100
    units = UNITS[kind]
    if unit not in units:
        pct = ", %" if kind == "length" else ""
        raise SignalError(f"{where}: unit '{unit}' is not a {kind} unit (use {', '.join(units)}{pct})")
    return units[unit]


def separator(text: str) -> str:
    """The cell separator of a table: ``,``, or ``;`` or a tab when the first line that
    is neither empty nor a ``#`` comment (the header, or the first row) holds that and no
    comma (spreadsheets in locales with a decimal comma write ``;``).

    Parameters
    ----------
    text : str
        The table's text.
    """
    for line in text.splitlines():
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        if "," in s:
            return ","
        return ";" if ";" in s else ("\t" if "\t" in s else ",")
    return ","


def table_rows(path: Path) -> list[list[str]]:
    """The rows of a CSV table as ``(line number, stripped cells)``, empty and ``#`` rows left out;
    the separator ``,``, ``;`` or tab (:func:`separator`).

    Parameters
    ----------
    path : Path
        The table (UTF-8, a byte-order mark allowed).
    """
    text = read_text(path, "signal table")
    try:
        rows = list(csv.reader(io.StringIO(text, newline=""), delimiter=separator(text)))
    except csv.Error as exc:
        raise SignalError(f"{path}: not a CSV table ({exc})") from None
    numbered = [(i + 1, [c.strip() for c in r]) for i, r in enumerate(rows)]
    return [(n, r) for n, r in numbered if any(r) and not r[0].startswith("#")]


def table_header(path: Path, rows):
    """(names, units from brackets, units from a Unit: row, data rows) of a table.

    Parameters
    ----------
    path : Path
        The table, for the messages.
    rows : list
        Its rows from :func:`table_rows`.
    """
    if not rows:
        raise SignalError(f"{path}: empty table; expected a header 'time,NAME' and rows of numbers")
    first_line, first = rows[0]
    if re.fullmatch(_NUM, first[0]):
        names = ["t"] + [f"column {j + 1}" for j in range(1, len(first))]
        return names, [""] * len(first), None, rows
    names, bracket = [], []
    for j, cell in enumerate(first):
        name, unit = _HEADER_CELL.fullmatch(cell).groups()
        if not name:
            raise SignalError(f"{path}: column {j + 1} of the header has no name")
        names.append(name)
        bracket.append((unit or "").strip())
    if names[0].lower() not in TIME_NAMES:
        sep = next((f"; the columns are separated by ',' (this header looks {n}-separated)"
                    for c, n in ((";", "';'"), ("\t", "tab")) if c in names[0]), "")
        raise SignalError(f"{path}: the first column must be the time, named 'time' or 't' with its unit in "
                          f"brackets if not s ('time [ms]'), got {names[0]!r}{sep}")
    seen = set()
    for j, name in enumerate(names):
        if j and name.lower() in TIME_NAMES:
            raise SignalError(f"{path}: column {j + 1} '{name}' is a second time column; one time column only")
        if name in seen:
            raise SignalError(f"{path}: column '{name}' appears twice in the header")
        seen.add(name)
    unit_row, data = None, rows[1:]
    while data and data[0][1][0].endswith(":") and not re.fullmatch(_NUM, data[0][1][0]):
        line, meta = data.pop(0)
        if meta[0].lower() == "unit:":
            if unit_row is not None:
                raise SignalError(f"{path}: line {line}: a second 'Unit:' row")
            if len(meta) > len(names):
                raise SignalError(f"{path}: line {line}: the 'Unit:' row has {len(meta)} cells for "
                                  f"{len(names)} columns")
            unit_row = meta + [""] * (len(names) - len(meta))
    return names, bracket, unit_row, data


def _read_table(path: Path, column: str | None, kind: str, stroke: float | None) -> Signal:
    """A signal from one column of a CSV table (module docstring: layout and units)."""
    names, bracket, unit_row, data = table_header(path, table_rows(path))
    signals = names[1:]
    if column is None:
        if len(signals) != 1:
            raise SignalError(f"{path}: {len(signals)} signal columns ({', '.join(signals[:8])}"
                              f"{', ...' if len(signals) > 8 else ''}); pick one with {path.name}:COLUMN")
        j = 1
    else:
        if column not in signals:
            hint = nearest(column, signals, cutoff=0.6) or f"; columns: {', '.join(signals[:8])}"
            raise SignalError(f"{path}: no column '{column}'{hint}")
        j = names.index(column)
    where = f"{path}: column '{names[j]}'"
    unit = bracket[j]
    if unit_row is not None and unit_row[j]:
        if unit and unit != unit_row[j]:
            raise SignalError(f"{where}: unit [{unit}] in the header but '{unit_row[j]}' in the Unit: row")
        unit = unit_row[j]
    scale = unit_scale(unit, kind, where, stroke)
    t_scale = unit_scale(bracket[0], "time", f"{path}: column '{names[0]}'", None)
    if len(data) < 2:
        raise SignalError(f"{path}: expected at least two rows of numbers under the header")
    t, v = np.empty(len(data)), np.empty(len(data))
    for i, (line, row) in enumerate(data):
        if len(row) != len(names):
            raise SignalError(f"{path}: line {line} has {len(row)} cells, the header {len(names)}")
        for jj, out in ((0, t), (j, v)):
            try:
                out[i] = float(row[jj])
            except ValueError:
                raise SignalError(f"{path}: line {line}, column '{names[jj]}': '{row[jj]}' is not a number") from None
            if not math.isfinite(out[i]):
                raise SignalError(f"{path}: line {line}, column '{names[jj]}': non-finite value '{row[jj]}'")
    bad = np.nonzero(np.diff(t) <= 0)[0]
    if len(bad):
        raise SignalError(f"{path}: line {data[bad[0] + 1][0]}: the time must increase strictly "
                          f"({t[bad[0] + 1]:g} after {t[bad[0]]:g})")
    sig = Signal.table(t * t_scale, v * scale)
    return Signal(sig.terms, f"{path}" + (f":{column}" if column else ""))


_TABLE = re.compile(r"(?is)^(.+?\.csv)(?::([^:]+))?$")


def _table_reference(part: str) -> tuple[Path, str | None] | None:
    """(file, column or None) if a term names a table: ``FILE.csv``, ``FILE.csv:COLUMN``
    or an existing file (``FILE:COLUMN``)."""
    m = _TABLE.fullmatch(part)
    if m:
        return Path(m.group(1)), (m.group(2).strip() if m.group(2) else None)
    if Path(part).is_file():
        return Path(part), None
    head, sep, col = part.rpartition(":")
    if sep and head and Path(head).is_file():
        return Path(head), col.strip() or None
    return None


def write_series(path: str | Path, names: list[str], units: list[str], data: np.ndarray, fmt: str = "%.17g") -> Path:
    """Write a time series as CSV in the one layout every time series of the toolkit
    uses (and :func:`~ema_casadi.signals.parse_signal` reads back, ``FILE.csv:COLUMN``):
    the MATLAB Simulation Data Inspector layout, a header ``time,<name>,...``, a row
    ``Unit:,<unit>,...`` (``1`` for a dimensionless column), then one row per sample;
    atomic.

    Parameters
    ----------
    path : str or Path
        The CSV file.
    names : list of str
        Column names, the first ``time`` (s).
    units : list of str
        One unit per column (the time's is not written: ``Unit:`` stands in its cell).
    data : ndarray
        Samples x columns.
    fmt : str
        Number format (default 17 significant digits: a float written and read back is
        the same float).
    """
    from .._util._files import write_with

    if names[0] != "time" or len(units) != len(names):
        raise ValueError("write_series: the first column is 'time' and every column has a unit")
    head = ",".join(names) + "\n" + ",".join(["Unit:", *((u or "1") for u in units[1:])]) + "\n"

    def write(tmp):
        with open(tmp, "w", encoding="utf-8", newline="") as fh:
            fh.write(head)
            np.savetxt(fh, np.asarray(data, dtype=float).reshape(len(data), len(names)), delimiter=",", fmt=fmt)

    return write_with(path, write)
