"""Rows on disk: the append-only journal of a sweep in progress and the final table.

The table (``--out results.csv``) is written once, whole, by the one atomic writer
(:mod:`ema_casadi._util._files`). While the sweep runs, every finished row is appended to
its *journal* ``.results.csv.journal`` beside it (one JSON object per line, flushed
and synced after each batch); the journal's first line names the sweep
(:meth:`SweepSpec.fingerprint`). After an interruption or a crash the journal holds
every row finished until then — a line cut short by a crash is ignored — and
``--resume`` takes them from it (or from the finished table) instead of running
them again. The journal is removed once the table is in place.

Numbers are written with 17 significant digits (``repr``): a row read back from the
journal or the table is the row computed, bit for bit.
"""

from __future__ import annotations

import csv
import json
import math
import os
from pathlib import Path

from .._util._files import OutputPathError

__all__ = ["Journal", "journal_path", "read_table", "write_table", "format_value"]

_VERSION = 1


def journal_path(out: str | Path) -> Path:
    """The journal beside the table ``out``.

    Parameters
    ----------
    out : str or Path
        The table.
    """
    out = Path(out)
    return out.with_name(f".{out.name}.journal")


class Journal:
    """The append-only journal of one sweep.

    Parameters
    ----------
    path : Path
        The journal file.
    fingerprint : str
        The sweep's fingerprint (first line).
    """

    def __init__(self, path: Path, fingerprint: str):
        self.path, self.fingerprint = Path(path), fingerprint
        self._fh = None

    def read(self, error: type) -> dict:
        """Run index -> row of the journal (empty when there is none); ``error`` when
        it belongs to another sweep or is damaged before its last line."""
        if not self.path.exists():
            return {}
        lines = self.path.read_text(encoding="utf-8").split("\n")
        try:
            head = json.loads(lines[0])
        except ValueError:
            head = {}
        if head.get("journal") != "ema sweep":
            raise error(f"{self.path}: not a sweep journal; remove it")
        if head.get("fingerprint") != self.fingerprint:
            raise error(f"{self.path}: the journal of another sweep (other runs, scenario, metrics or parameter "
                        "file); remove it to start afresh")
        rows = {}
        body = lines[1:]
        for i, line in enumerate(body):
            if not line:
                continue
            try:
                row = json.loads(line)
            except ValueError:
                if i >= len(body) - 2:  # the last line, cut short by a crash
                    break
                raise error(f"{self.path}: line {i + 2} is damaged; remove the journal") from None
            rows[int(row["run"])] = row
        return rows

    def open(self) -> None:
        """Open for appending (a new journal gets its first line)."""
        try:
            self._open()
        except OSError as exc:  # a full disk: one line naming the journal
            raise OutputPathError(f"{self.path}: cannot write the journal ({exc.strerror or exc})") from None

    def _open(self) -> None:
        new = not self.path.exists() or self.path.stat().st_size == 0
        self._fh = open(self.path, "a", encoding="utf-8")
        if not new:
            # a line cut short by a crash: end it, so that the next row starts a line
            with open(self.path, "rb") as fh:
                fh.seek(-1, os.SEEK_END)
                if fh.read(1) != b"\n":
                    self._fh.write("\n")
        else:
            self._fh.write(json.dumps({"journal": "ema sweep", "version": _VERSION,
                                       "fingerprint": self.fingerprint}) + "\n")
        self.sync()

    def append(self, rows) -> None:
        """Append finished rows, then flush and sync them to disk."""
        try:
            for row in rows:
                self._fh.write(json.dumps(row) + "\n")
            self.sync()
        except OSError as exc:  # a full disk: one line naming the journal
            raise OutputPathError(f"{self.path}: cannot write the journal ({exc.strerror or exc})") from None

    def sync(self) -> None:
        self._fh.flush()
        os.fsync(self._fh.fileno())

    def close(self) -> None:
        if self._fh is not None:
            fh, self._fh = self._fh, None
            try:
                fh.close()
            except OSError:  # what did not reach the disk was reported by append()
                pass

    def remove(self) -> None:
        """Close and delete the journal (its table is in place)."""
        self.close()
        self.path.unlink(missing_ok=True)


def format_value(v) -> str:
    """A table cell: 17 significant digits (repr), empty for NaN, ``inf``/``-inf``."""
    if v is None:
        return ""
    if isinstance(v, bool):
        return "1" if v else "0"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return ""
        return repr(v)
    return str(v)


def write_table(path, rows: list, columns: list, stage: bool = True) -> Path:
    """Write the rows as CSV (one header row, then one row per run), atomically.

    Parameters
    ----------
    path : str or Path
        The table.
    rows : list of dict
        The rows, in order.
    columns : list of str
        The header.
    stage : bool
        Defer the rename to the end of an open transaction (default).
    """
    from .._util._files import write_with

    def write(tmp):
        with open(tmp, "w", encoding="utf-8", newline="") as fh:
            w = csv.writer(fh, lineterminator="\n")
            w.writerow(columns)
            w.writerows([format_value(r.get(c)) for c in columns] for r in rows)

    return write_with(path, write, stage=stage)


def read_table(path: Path, columns: list, text_columns: set, error: type) -> dict:
    """Run index -> row of a table written by :func:`write_table` with these columns;
    ``error`` when its header differs (another sweep's table).

    Parameters
    ----------
    path : Path
        The table.
    columns : list of str
        The header expected.
    text_columns : set of str
        Columns that hold text (variants, status, reason); the others are numbers.
    error : type
        The exception raised.
    """
    with open(path, encoding="utf-8", newline="") as fh:
        reader = csv.reader(fh)
        header = next(reader, None)
        if header != columns:
            raise error(f"{path}: its columns are not this sweep's; remove it or choose another --out")
        rows = {}
        for cells in reader:
            row = {}
            for c, v in zip(columns, cells, strict=True):
                if c == "run":
                    row[c] = int(v)
                elif c in text_columns:
                    row[c] = v
                else:
                    row[c] = math.nan if v == "" else float(v)
            rows[row["run"]] = row
    return rows
