"""Mission files: TOML -> a validated :class:`Mission` of segments (format in the
package docstring)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace

import casadi as ca
import numpy as np

from .._util._checks import budget, nearest, read_toml
from .._util._errors import InputError
from ..model.components import PART_CLASSES, SIGNAL_KEYS, VariantError, parts_for, validate_variants
from ..model.params import Parameters
from ..signals import Signal, SignalError, constant, parse_quantity, parse_signal

__all__ = ["MissionError", "Segment", "Mission", "load_mission", "parse_mission", "Piecewise", "Ramp", "node_limits",
           "MISSION_VARIANTS"]

#: Temperature state -> its thermal node, as the registered parts declare them
#: (:class:`~ema_casadi.model.components.Node`: heat capacity and rated temperature).
NODES = {s.name: s.node for cls in PART_CLASSES for s in cls.states if s.node is not None}


def node_limits(params: Parameters) -> dict[str, float]:
    """Temperature limits (degC) a mission is judged against when its file names none:
    each node's rated temperature as its part declares it (the winding's from the
    parameter file, T_max_w).

    Parameters
    ----------
    params : Parameters
        The parameter set.
    """
    P = SimpleNamespace(**params.as_dict())
    return {n: float(node.limit(P)) for n, node in NODES.items()}

#: The run's variants unless the mission file or the caller say otherwise.
MISSION_VARIANTS = {"thermal": "lumped", "friction": "hybrid", "iron_loss": "on"}

_TOP = {"mission", "model", "limits", "segment"}
_MISSION_KEYS = {"name", "T_start", "description"}
#: A segment's signal keys (the file's, from the one key table): command, load, cavity temperature.
X_CMD, F_EXT, T_AMB = (SIGNAL_KEYS[r] for r in ("command", "load", "ambient_temperature"))
_SEGMENT_KEYS = {"name", "duration", X_CMD, F_EXT, T_AMB}
_SAMPLE_RATE = 1000.0  # Hz: commands and loads are checked against the envelope on this grid
_CHUNK = 1_000_000  # samples checked at a time
#: Most envelope samples of one segment: 1e5 s, the MAX_STEPS of the full model's step.
_MAX_CHECKED = 1e8


class MissionError(InputError, ValueError):
    """A mission file or request is invalid; the one-line message names the file, the
    segment and the key."""


@dataclass(frozen=True)
class Segment:
    """One mission segment; its signals run in the segment's own time (from 0).

    Attributes
    ----------
    name : str
        Label (plots, tables).
    duration : float
        Length (s).
    x_cmd, f_ext, T_amb : Signal
        Rod command (m), rod load (N, positive pushes the rod in), cavity temperature (degC).
    text : dict
        The descriptions the signals were read from (for reports).
    """

    name: str
    duration: float
    x_cmd: Signal
    f_ext: Signal
    T_amb: Signal
    text: dict = field(default_factory=dict)


@dataclass(frozen=True)
class Mission:
    """A flight mission: segments run back to back.

    Attributes
    ----------
    name : str
        Title.
    segments : tuple of Segment
        In flight order.
    T_start : float
        Initial temperature of every thermal node (degC): soaked at it.
    limits : dict
        Temperature state name -> limit (degC), e.g. ``{"T_w": 180.0}``.
    variants : dict
        Variant choices of the file's ``[model]`` table.
    source : str
        Where the mission came from (named in messages).
    """

    name: str
    segments: tuple
    T_start: float
    limits: dict
    variants: dict = field(default_factory=dict)
    source: str = "<memory>"

    @property
    def duration(self) -> float:
        """Total length (s)."""
        return float(sum(s.duration for s in self.segments))

    @property
    def starts(self) -> np.ndarray:
        """Start time of every segment (s)."""
        return np.concatenate([[0.0], np.cumsum([s.duration for s in self.segments])[:-1]])

    def signal(self, name: str) -> Piecewise:
        """One input over the whole mission (``x_cmd``, ``f_ext`` or ``T_amb``), in
        mission time.

        Parameters
        ----------
        name : str
            The segment attribute.
        """
        return Piecewise.of(self.starts, [getattr(s, name) for s in self.segments], name)


@dataclass(frozen=True)
class Piecewise(Signal):
    """Signals one after the other: piece k, in its own time t - starts[k], from
    starts[k] until the next piece starts (the last one holds to the end).

    Attributes
    ----------
    terms, text : tuple, str
        As :class:`~ema_casadi.signals.Signal` (no terms of its own; the description).
    starts : tuple of float
        Start of each piece (s), increasing.
    pieces : tuple of Signal
        The signals.
    """

    starts: tuple = ()
    pieces: tuple = ()

    @staticmethod
    def of(starts, pieces, text: str = "piecewise") -> Piecewise:
        """Build one from start times and signals.

        Parameters
        ----------
        starts : sequence of float
            Start times (s), increasing.
        pieces : sequence of Signal
            One signal per start.
        text : str
            Description.
        """
        return Piecewise(terms=(), text=text, starts=tuple(float(s) for s in starts), pieces=tuple(pieces))

    def shifted(self, t0: float) -> Piecewise:
        """The same signal with time counted from ``t0`` (s): ``shifted(t0)(t) = self(t + t0)``.

        Parameters
        ----------
        t0 : float
            The new time origin (s).
        """
        return Piecewise(terms=(), text=self.text, starts=tuple(s - t0 for s in self.starts), pieces=self.pieces)

    def _index(self, t):
        return np.clip(np.searchsorted(self.starts, t, side="right") - 1, 0, len(self.pieces) - 1)

    def __call__(self, t):
        t = np.asarray(t, dtype=float)
        if t.ndim == 1 and len(t) >= 6 and len(t) % 3 == 0:
            # an RK4 rollout samples each step at t, t + h/2 and t + h, and the end of one
            # step is the start of the next (to rounding): evaluate each time once
            ends, nexts = t[2:-1:3], t[3::3]
            if np.all(np.abs(ends - nexts) <= 1e-9 * (nexts[-1] - t[0])):
                grid = np.empty(2 * (len(t) // 3) + 1)
                grid[0:-1:2], grid[1::2], grid[-1] = t[0::3], t[1::3], t[-1]
                v = self._sorted(grid)
                out = np.empty_like(t)
                out[0::3], out[1::3], out[2::3] = v[0:-1:2], v[1::2], v[2::2]
                return out
        if t.ndim == 1 and np.all(t[1:] >= t[:-1]):
            return self._sorted(t)
        out = np.empty_like(t)
        k = self._index(t)
        for i in range(len(self.pieces)):
            sel = k == i
            if sel.any():
                out[sel] = self.pieces[i](t[sel] - self.starts[i])
        return out

    def _sorted(self, t):
        """Values on an increasing grid: each piece on its slice."""
        out = np.empty_like(t)
        cuts = np.searchsorted(t, self.starts[1:], side="left")
        edges = [0, *cuts.tolist(), len(t)]
        for i, (a, b) in enumerate(zip(edges, edges[1:], strict=False)):
            if b > a:
                out[a:b] = self.pieces[i](t[a:b] - self.starts[i])
        return out

    def sym(self, t):
        out = self.pieces[-1].sym(t - self.starts[-1])
        for k in range(len(self.pieces) - 2, -1, -1):
            out = ca.if_else(t < self.starts[k + 1], self.pieces[k].sym(t - self.starts[k]), out)
        return out

    def breakpoints(self) -> list[float]:
        pts = set(self.starts)
        for start, piece in zip(self.starts, self.pieces, strict=True):
            pts.update(start + b for b in piece.breakpoints())
        return sorted(pts)

    def windows(self) -> list[tuple]:
        out = []
        for k, (start, piece) in enumerate(zip(self.starts, self.pieces, strict=True)):
            lo = start if k > 0 else -math.inf  # piece 0 also before the first start
            hi = self.starts[k + 1] if k + 1 < len(self.starts) else math.inf
            for a, b, shift, term in piece.windows():
                out.append((max(lo, a + start), min(hi, b + start), start + shift, term))
        return out

    def __add__(self, other):
        raise TypeError("a Piecewise signal cannot be added to; add the segments' signals")


@dataclass(frozen=True)
class Ramp(Signal):
    """A linear change from ``a`` at t = 0 to ``b`` at t = ``T``, held outside (a
    constant when a = b): a segment's cavity temperature, evaluated without temporaries.

    Attributes
    ----------
    terms, text : tuple, str
        As :class:`~ema_casadi.signals.Signal` (no terms of its own; the description).
    a, b : float
        Values at the start and the end (the input's unit).
    T : float
        Duration of the change (s).
    """

    a: float = 0.0
    b: float = 0.0
    T: float = 1.0

    def __call__(self, t):
        t = np.asarray(t, dtype=float)
        if self.a == self.b:
            return np.full(t.shape, self.a)
        return np.interp(t, [0.0, self.T], [self.a, self.b])

    def sym(self, t):
        if self.a == self.b:
            return self.a + 0 * t
        return self.a + (self.b - self.a) * ca.fmin(ca.fmax(t / self.T, 0), 1)

    def breakpoints(self) -> list[float]:
        return [] if self.a == self.b else [0.0, self.T]

    def windows(self) -> list[tuple]:
        if self.a == self.b:
            return constant(self.a).windows()
        return Signal.table([0.0, self.T], [self.a, self.b]).windows()  # np.interp, held outside

    def __add__(self, other):
        raise TypeError("a Ramp signal cannot be added to")


def _nearest(name, options) -> str:
    return nearest(name, sorted(options))


def _keys(where: str, table: dict, allowed: set) -> None:
    for key in table:
        if key not in allowed:
            raise MissionError(f"{where}: unknown key '{key}'{_nearest(key, allowed)}; "
                               f"expected {', '.join(sorted(allowed))}")


def _number(where: str, value, kind: str, bare: str) -> float:
    """A number, or a string with a unit (``"90s"``), in SI (degC for temperatures)."""
    if isinstance(value, bool):
        raise MissionError(f"{where}: expected a number, got {value!r}")
    if isinstance(value, (int, float)):
        out = float(value)
    elif isinstance(value, str):
        try:
            out = parse_quantity(value, kind, bare)
        except SignalError as exc:
            raise MissionError(f"{where}: {exc}") from None
    else:
        raise MissionError(f"{where}: expected a number, got {type(value).__name__} {value!r}")
    if not math.isfinite(out):
        raise MissionError(f"{where}: expected a finite number, got {out}")
    return out


def _temperature(where: str, value) -> float:
    T = _number(where, value, "temperature", "degC")
    if not -100.0 <= T <= 300.0:
        raise MissionError(f"{where}: {T:g} degC is outside -100...300 degC")
    return T


def _signal(where: str, value, kind: str, bare: str, stroke: float, duration: float) -> Signal:
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise MissionError(f"{where}: expected a signal (a number or a string such as \"sine:1mm@0.5\"), "
                           f"got {value!r}")
    if not isinstance(value, str):
        value = str(value)
    try:
        return parse_signal(value, kind, bare=bare, stroke=stroke, duration=duration)
    except SignalError as exc:
        raise MissionError(f"{where}: {exc}") from None


def _cavity(where: str, value, duration: float) -> Signal:
    """T_amb: a number or signal string (degC), or [start, end] for a linear change."""
    if isinstance(value, list):
        if len(value) != 2:
            raise MissionError(f"{where}: expected [start, end] (degC) for a linear change, got {value!r}")
        a, b = (_temperature(where, v) for v in value)
        return Ramp(terms=(), text=f"[{a:g}, {b:g}]", a=a, b=b, T=duration)
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        T = _temperature(where, value)
        return Ramp(terms=(), text=f"{T:g}", a=T, b=T, T=duration)
    sig = _signal(where, value, "temperature", "degC", None, duration)
    for T in sig.span(duration):  # a signal's extremes by the numbers' rule
        _temperature(f"{where} '{sig.text}'", T)
    return sig


def _held_load(source: str, params: Parameters, variants: dict) -> float:
    """The load (N) the mission's model holds at standstill: the envelope limit
    ``held_load`` its parts declare (the screw: the current limit at the middle of the
    efficiency blend)."""
    try:
        full = validate_variants({**params.variants, **MISSION_VARIANTS, **variants}, where=f"{source}: [model]")
    except VariantError as exc:
        raise MissionError(str(exc)) from None
    P = SimpleNamespace(**params.as_dict())
    return max(float(part.limits["held_load"](P)) for part in parts_for(full)[0] if "held_load" in part.limits)


def _check_envelope(where: str, seg: Segment, params: Parameters, F_hold: float) -> None:
    """Commands within the stroke, loads within what the actuator holds, cavity
    temperatures in range: sampled over the segment before any simulation."""
    n = max(2, int(seg.duration * _SAMPLE_RATE) + 1)
    for start in range(0, n, _CHUNK):  # a long segment in pieces: never one huge grid
        t = np.linspace(0.0, seg.duration, n)[start:start + _CHUNK] if n <= _CHUNK else \
            np.arange(start, min(n, start + _CHUNK)) * (seg.duration / (n - 1))
        _check_samples(where, seg, params, F_hold, t)


def _check_samples(where: str, seg: Segment, params: Parameters, F_hold: float, t: np.ndarray) -> None:
    stroke = params.actuator.stroke
    x = seg.x_cmd(t)
    if np.max(np.abs(x)) > stroke:
        k = int(np.argmax(np.abs(x)))
        raise MissionError(f"{where} {X_CMD}: reaches {x[k] * 1e3:.4g} mm at {t[k]:.4g} s, beyond the stroke "
                           f"+-{stroke * 1e3:.4g} mm")
    f = seg.f_ext(t)
    if np.max(np.abs(f)) > F_hold:
        k = int(np.argmax(np.abs(f)))
        raise MissionError(f"{where} {F_EXT}: reaches {f[k] / 1e3:.4g} kN at {t[k]:.4g} s, more than the "
                           f"{F_hold / 1e3:.3g} kN the actuator holds at standstill at its current limit")
    T = seg.T_amb(t)
    if not np.all(np.isfinite(T)) or T.min() < -100 or T.max() > 300:
        raise MissionError(f"{where} {T_AMB}: goes outside -100...300 degC ({T.min():.4g}...{T.max():.4g} degC)")
    for name, v in ((X_CMD, x), (F_EXT, f)):
        if not np.all(np.isfinite(v)):
            raise MissionError(f"{where} {name}: non-finite value")


def parse_mission(data: dict, params: Parameters, source: str = "<memory>") -> Mission:
    """Validate a mission read from TOML (the dict ``tomllib`` returns).

    Parameters
    ----------
    data : dict
        The parsed file.
    params : Parameters
        The parameter set it will run on (stroke for ``%`` and the envelope checks,
        T_max_w as the default winding limit).
    source : str
        Named in error messages.
    """
    _keys(source, data, _TOP)
    head = data.get("mission", {})
    if not isinstance(head, dict):
        raise MissionError(f"{source}: [mission] must be a table")
    _keys(f"{source}: [mission]", head, _MISSION_KEYS)
    name = str(head.get("name", Path(source).stem))
    variants = data.get("model", {})
    if not isinstance(variants, dict) or not all(isinstance(v, str) for v in variants.values()):
        raise MissionError(f"{source}: [model] must be a table of variant names (strings)")
    raw = data.get("segment")
    if not isinstance(raw, list) or not raw or not all(isinstance(s, dict) for s in raw):
        raise MissionError(f"{source}: expected one or more [[segment]] tables")
    stroke = params.actuator.stroke
    held = _held_load(source, params, variants)
    segments = []
    seen = {}
    for k, tab in enumerate(raw, 1):
        label = str(tab.get("name", f"segment {k}"))
        where = f"{source}: segment {k} ('{label}')"
        if label in seen:  # the report's rows are by name: two of one name cannot both be read
            raise MissionError(f"{where} name: '{label}' is also the name of segment {seen[label]}; names must differ")
        seen[label] = k
        _keys(where, tab, _SEGMENT_KEYS)
        if "duration" not in tab:
            raise MissionError(f"{where}: missing key 'duration' (s)")
        if T_AMB not in tab:
            raise MissionError(f"{where}: missing key '{T_AMB}' (cavity temperature, degC, or [start, end])")
        dur = _number(f"{where} duration", tab["duration"], "time", "s")
        if dur <= 0:
            raise MissionError(f"{where} duration: must be positive, got {dur:g} s")
        # the envelope is sampled at _SAMPLE_RATE: its grid refused before it is allocated
        budget(dur * _SAMPLE_RATE, _MAX_CHECKED, f"{where} duration {dur:g} s", MissionError,
               unit="envelope samples", item_bytes=0, hint=f"at most {_MAX_CHECKED / _SAMPLE_RATE:g} s, "
               "as long as MAX_STEPS steps of the full model's 1e-4 s")
        seg = Segment(
            name=label, duration=dur,
            x_cmd=_signal(f"{where} {X_CMD}", tab.get(X_CMD, "0"), "length", "mm", stroke, dur),
            f_ext=_signal(f"{where} {F_EXT}", tab.get(F_EXT, "0"), "force", "N", stroke, dur),
            T_amb=_cavity(f"{where} {T_AMB}", tab[T_AMB], dur),
            text={key: tab.get(key, "0") for key in (X_CMD, F_EXT, T_AMB)},
        )
        _check_envelope(where, seg, params, held)
        segments.append(seg)
    T_start = (_temperature(f"{source}: [mission] T_start", head["T_start"]) if "T_start" in head
               else float(segments[0].T_amb(np.array([0.0]))[0]))
    limits = _limits(source, data.get("limits", {}), params)
    return Mission(name=name, segments=tuple(segments), T_start=T_start, limits=limits, variants=dict(variants),
                   source=source)


def _limits(source: str, table, params: Parameters) -> dict:
    if not isinstance(table, dict):
        raise MissionError(f"{source}: [limits] must be a table of temperatures (degC)")
    out = node_limits(params)
    _keys(f"{source}: [limits]", table, set(out))
    out.update({k: _temperature(f"{source}: [limits] {k}", v) for k, v in table.items()})
    return out


def load_mission(path: str | Path, params: Parameters) -> Mission:
    """Read and validate a mission file (format in :mod:`ema_casadi.mission`).

    Parameters
    ----------
    path : str or Path
        The TOML file.
    params : Parameters
        The parameter set the mission will run on.

    Raises
    ------
    MissionError
        One line naming the file, segment and key.
    """
    src = str(path)
    data = read_toml(path, "mission file", MissionError)
    return parse_mission(data, params, src)
