"""Argument checks of the public entry points (the reliability contract, docs: reliability).

A wrong type or value handed to a public function is reported as the toolkit's own
exception type (the caller passes it: ``SimulationError``, ``OperatingPointError``, ...)
with a one-line message that names the argument and says what was expected, instead
of an ``AttributeError`` or a reshape error from deep inside. Each helper returns the
value converted (a float, an int, a float array).
"""

from __future__ import annotations

import difflib
import math
import numbers

import numpy as np

__all__ = ["describe", "number", "integer", "vector", "instance", "choice", "closest", "nearest", "budget",
           "size_text", "plausible_limit", "STROKE_FACTOR", "CURRENT_FACTOR", "FORCE_FACTOR"]


def describe(value) -> str:
    """``"str 'abc'"``, ``"list [0, 0]"``: a value's type and a short repr for messages."""
    text = repr(value)
    if len(text) > 40:
        text = text[:37] + "..."
    return f"{type(value).__name__} {text}"


def number(value, name: str, error: type, *, unit: str = "", positive: bool = False,
           nonneg: bool = False, negative: bool = False, finite: bool = True) -> float:
    """``value`` as a float: a real number (not a bool, a string or an array), finite
    unless ``finite`` is False, > 0 with ``positive``, >= 0 with ``nonneg``, < 0 with
    ``negative``."""
    u = f" ({unit})" if unit else ""
    what = "a positive" if positive else ("a non-negative" if nonneg else ("a negative" if negative else "a"))
    fin = " finite" if finite else ""
    if isinstance(value, np.ndarray) and value.shape == ():
        value = value[()]
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise error(f"{name}: expected {what}{fin} number{u}, got {describe(value)}")
    v = float(value)
    if (finite and not math.isfinite(v)) or math.isnan(v):
        raise error(f"{name}: expected {what}{fin} number{u}, got {v}")
    if (positive and not v > 0) or (nonneg and not v >= 0) or (negative and not v < 0):
        raise error(f"{name}: expected {what}{fin} number{u}, got {v:g}")
    return v


def integer(value, name: str, error: type, *, minimum: int | None = None) -> int:
    """``value`` as an int (an integral number, not a bool), at least ``minimum``."""
    at_least = f" >= {minimum}" if minimum is not None else ""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Integral):
        if isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_)) \
                and math.isfinite(float(value)) and float(value) == int(value):
            value = int(value)
        else:
            raise error(f"{name}: expected an integer{at_least}, got {describe(value)}")
    value = int(value)
    if minimum is not None and value < minimum:
        raise error(f"{name}: expected an integer{at_least}, got {value}")
    return value


def vector(value, name: str, error: type, size: int, what: str = "") -> np.ndarray:
    """``value`` as a finite float vector of ``size`` entries (``what`` names them)."""
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise error(f"{name}: expected {size} numbers{what}, got {describe(value)}") from None
    if a.ndim > 1 and a.size == size and max(a.shape) == size:
        a = a.ravel()  # a column or row vector
    if a.shape != (size,):
        raise error(f"{name}: expected {size} numbers{what}, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise error(f"{name}: non-finite entry at index {int(np.argmin(np.isfinite(a)))}")
    return a


def instance(value, cls, name: str, error: type, hint: str = ""):
    """``value`` itself if it is a ``cls`` (a class or a tuple of classes)."""
    if not isinstance(value, cls):
        names = " or ".join(c.__name__ for c in (cls if isinstance(cls, tuple) else (cls,)))
        raise error(f"{name}: expected a {names}{hint}, got {describe(value)}")
    return value


def choice(value, name: str, options, error: type) -> str:
    """``value`` if it is one of ``options`` (strings)."""
    if not isinstance(value, str) or value not in options:
        raise error(f"{name}: expected one of {', '.join(options)}, got {describe(value)}")
    return value


def closest(name: str, options, cutoff: float = 0.0) -> str | None:
    """The option closest to ``name`` (difflib's ratio at least ``cutoff``), or None: the
    one did-you-mean of the package.

    Parameters
    ----------
    name : str
        What was given.
    options : iterable of str
        What is allowed.
    cutoff : float
        Least similarity (0..1) for a suggestion; 0 always suggests one.
    """
    match = difflib.get_close_matches(name, list(options), n=1, cutoff=cutoff)
    return match[0] if match else None


def nearest(name: str, options, cutoff: float = 0.0) -> str:
    """`` (did you mean 'X'?)`` for the option closest to ``name`` (:func:`closest`), or ``""``.

    Parameters
    ----------
    name : str
        What was given.
    options : iterable of str
        What is allowed.
    cutoff : float
        Least similarity (0..1) for a suggestion.
    """
    match = closest(name, options, cutoff)
    return f" (did you mean '{match}'?)" if match else ""


def decode_utf8(data: bytes, path, error: type) -> str:
    """``data`` decoded as UTF-8 with an optional byte-order mark, or ``error`` naming
    ``path``, the offending byte and its offset.

    Parameters
    ----------
    data : bytes
        The file's content.
    path : str or Path
        The file, named in the message.
    error : type
        Exception raised (the caller's toolkit type).
    """
    if data[:2] in (b"\xff\xfe", b"\xfe\xff"):
        raise error(f"{path}: UTF-16 text; save the file as UTF-8")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise error(f"{path}: not UTF-8 text (byte 0x{data[exc.start]:02x} on line {line}); "
                    "save the file as UTF-8") from None


def read_text_file(path, what: str, error: type) -> str:
    """The text of an input file (UTF-8, a byte-order mark accepted), or ``error`` with
    one line naming the file: missing, a folder, unreadable, not UTF-8.

    Parameters
    ----------
    path : str or Path
        The file.
    what : str
        What the file is, for the messages (``"parameter file"``).
    error : type
        Exception raised (the caller's toolkit type).
    """
    from pathlib import Path

    path = Path(path)
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        hint = "" if path.suffix else " (a value's unit apart from it? write it joined, e.g. 500ms)"
        raise error(f"{path}: no such {what}{hint}") from None
    except IsADirectoryError:
        raise error(f"{path}: is a folder, not a {what}") from None
    except OSError as exc:
        raise error(f"{path}: cannot read ({exc.strerror or exc})") from None
    return decode_utf8(data, path, error)


def read_toml(path, what: str, error: type) -> dict:
    """An input TOML file as a dict, or ``error`` with one line naming the file (as
    :func:`read_text_file`, or not valid TOML).

    Parameters
    ----------
    path : str or Path
        The file.
    what : str
        What the file is, for the messages (``"mission file"``).
    error : type
        Exception raised (the caller's toolkit type).
    """
    import tomllib

    text = read_text_file(path, what, error)
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise error(f"{path}: not valid TOML{_toml_where(text, str(exc))} ({exc})") from None


def _toml_where(text: str, message: str) -> str:
    """`` at key 'f_ext' (line 3: f_ext = 5kN; a text value is quoted: "5kN")`` for a
    TOML error at a line that assigns a key; the key and the line as written."""
    import re

    m = re.search(r"at line (\d+)", message)
    lines = text.splitlines()
    if not m or not 0 < int(m.group(1)) <= len(lines):
        return ""
    line = lines[int(m.group(1)) - 1].split("#", 1)[0].strip()
    key, eq, value = line.partition("=")
    if not eq or not key.strip():
        return f" at line {m.group(1)}: {line[:80]}" if line else ""
    value = value.strip()
    bare_text = re.fullmatch(r"[-+]?[0-9.]+\s*[A-Za-z%/]+[\w/]*|[A-Za-z_][\w:@.+%/-]*", value) and \
        value not in ("true", "false", "nan", "inf")  # 5kN, sine:1mm@2, real: text without its quotes
    quote = f"; a text value is quoted: \"{value}\"" if bare_text else ""
    return f" at key '{key.strip()}' (line {m.group(1)}: {line[:80]}{quote})"


def size_text(n: float) -> str:
    """``n`` bytes as ``"7.28 TB"`` (decimal units) for messages."""
    for unit, size in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6)):
        if n >= size:
            return f"{n / size:.3g} {unit}"
    return f"{n / 1e3:.3g} kB"


def budget(count: float, limit: float, what: str, error: type, *, unit: str = "points", item_bytes: float = 8.0,
           limit_name: str = "", hint: str = "") -> int:
    """``count`` as an int when it is at most ``limit``; otherwise ``error`` with the
    estimate (count and memory), before anything is allocated (the reliability contract:
    work the machine cannot do is refused up front).

    Parameters
    ----------
    count : float
        How many items the work would allocate or run (may be a float estimate).
    limit : float
        The most allowed.
    what : str
        What is counted, named in the message (``"--freqs 0.1-30:1e12"``).
    error : type
        The exception raised (the caller's toolkit type).
    unit : str
        What an item is (``"points"``, ``"samples"``, ``"runs"``).
    item_bytes : float
        Memory of one item (B), for the estimate; 0 leaves it out.
    limit_name : str
        The constant holding the limit (``"MAX_RUNS"``), named in the message.
    hint : str
        What to do instead.
    """
    if not math.isfinite(float(count)) or count > limit:
        mem = f" x {item_bytes:g} B = {size_text(count * item_bytes)}" if item_bytes else ""
        name = f" ({limit_name})" if limit_name else ""
        tail = f"; {hint}" if hint else ""
        raise error(f"{what}: {count:.3g} {unit}{mem}, above the limit of {limit:.3g} {unit}{name}{tail}")
    return int(count)


#: A value given without a unit (a record's column, a bare number on a flag) is
#: implausible in SI when a length exceeds this factor on the stroke (the end stops and a
#: command's overshoot fit well inside), a current this factor on the current limit, a
#: force this factor on what the screw holds.
STROKE_FACTOR, CURRENT_FACTOR, FORCE_FACTOR = 1.5, 10.0, 10.0


def plausible_limit(model, kind: str):
    """``(limit, what)``: the largest magnitude (SI) a value of the quantity ``kind``
    (``length``, ``current``, ``force``) read in SI is plausible up to on ``model``, and
    what it is measured on (``1.5 x the stroke``); None for other quantities.

    Parameters
    ----------
    model : Model
        The assembled model (its stroke, current limit and held load).
    kind : str
        The quantity.
    """
    if kind == "length":
        return STROKE_FACTOR * float(model.params.actuator.stroke), f"{STROKE_FACTOR:g} x the stroke"
    if kind == "current":
        return CURRENT_FACTOR * float(model.limit_values().get("current", math.inf)), \
            f"{CURRENT_FACTOR:g} x the current limit"
    if kind == "force":
        return FORCE_FACTOR * float(model.envelope_limits().get("held_load", math.inf)), \
            f"{FORCE_FACTOR:g} x what the screw holds"
    return None
