"""Test signals of a designed experiment: multisine segments, smooth slews, load levels,
and the standard tests a design is compared with.

A test is a sequence of segments of one length ``tau`` (the period of the lowest
multisine frequency ``1 / tau``). A segment holds one load level (reached by a
raised-cosine ramp over its first :data:`RAMP` of a second from the level before) and
drives one command shape around zero, tapered in and out (raised cosine over
:data:`TAPER` of the segment at either end) so that segments join with a continuous
command and rate:

- ``multisine``: harmonics ``f_k = k / tau`` of a band, equal amplitudes, Schroeder
  phases ``phi_k = -pi k (k - 1) / K`` (a low crest factor: the most amplitude in the
  stroke for the least peak);
- ``slews``: ``n`` moves between ``-A`` and ``+A`` per segment at constant speed, the
  speed reversed over a share ``c`` of each move (a trapezoid velocity: the
  piecewise-smooth command; the constant speed loads the friction, the reversals
  the inertia and the backlash);
- ``steps``: ``n`` moves between ``-A`` and ``+A`` per segment, the rod at rest at
  either end for a share ``r`` of the time (stop and go: each move starts from rest,
  breaking the friction away at a speed where the viscous term is nil: the seal
  friction seen apart from the viscous one).

Every array is sampled on the record's grid (the table the rig controller plays, and
the very input ``identify`` interpolates).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

#: Load ramp at a segment's start (s).
RAMP = 0.1
#: Fraction of a segment over which the command is tapered in, and again out.
TAPER = 0.08

#: ``steps``: the speed's rise from rest, a share of the excursion of |cos| of the
#: move's phase above its rest threshold.
STEP_RAMP = 0.1

#: The standard test's commanded speed, a fraction of the rod speed bound (room for the
#: speed loop's overshoot of a ramp: none measurable at 0.8 on the reference set).
STANDARD_SPEED = 0.95
#: The standard test's records and their shares of its length.
STANDARD_PARTS = (("steps", 0.24), ("chirp", 0.32), ("slews_push", 0.24), ("slews_pull", 0.20))

__all__ = ["STANDARD_PARTS", "STANDARD_SPEED",
           "output_names", "Segment", "Test", "segment_command", "realise", "standard_test", "RAMP",
           "TAPER"]


@dataclass(frozen=True)
class Segment:
    """One segment of a test: a command shape and a load level.

    Attributes
    ----------
    kind : str
        ``multisine``, ``slews`` or ``steps``.
    band : tuple of float
        ``multisine``: lowest and highest frequency (Hz); ``slews``: (moves per
        segment, the share of a move spent reversing the speed); ``steps``: (moves
        per segment, the share of the time at rest).
    load : float
        The load level held (N, + pushes the rod in).
    amplitude : float
        The command's peak (m), set to the limits by the design.
    """

    kind: str
    band: tuple
    load: float
    amplitude: float = 0.0

    def label(self) -> str:
        """A short name (``multisine 1-4 Hz @ +15 kN``)."""
        shape = (f"multisine {self.band[0]:g}-{self.band[1]:g} Hz" if self.kind == "multisine"
                 else f"{self.kind} x{int(self.band[0])} {'ramp' if self.kind == 'slews' else 'rest'} "
                      f"{self.band[1]:g}")
        return f"{shape} @ {self.load / 1e3:+g} kN, {self.amplitude * 1e3:.3g} mm"

    def with_amplitude(self, a: float) -> Segment:
        """The segment at amplitude ``a`` (m).

        Parameters
        ----------
        a : float
            Command peak (m).
        """
        return Segment(self.kind, self.band, self.load, float(a))


@dataclass
class Test:
    """A test to run on the rig: the command and load sampled on one grid, possibly in
    several records (a standard test's chirp, steps and slews are separate runs).

    Attributes
    ----------
    name : str
        What it is (``designed``, ``chirp+steps+slews``).
    records : list of dict
        Per record: ``name``, ``t`` (s, from 0) and ``inputs`` (input name -> values, SI).
    segments : list of Segment
        The segments, for a designed test.
    """

    name: str
    records: list
    segments: list = field(default_factory=list)

    @property
    def duration(self) -> float:
        """Total length of the records (s)."""
        return float(sum(r["t"][-1] for r in self.records))


def output_names() -> tuple:
    """The files a design's output folder holds (:meth:`DesignResult.write`)."""
    return ("design.csv", *(f"standard_{n}.csv" for n, _ in STANDARD_PARTS), "summary.json", "comparison.md",
            "design.png")


def _taper(s: np.ndarray) -> np.ndarray:
    """Raised-cosine window on the segment's phase ``s`` in [0, 1]: 0 at both ends, 1 in
    between, continuous rate."""
    w = np.ones_like(s)
    a = s < TAPER
    b = s > 1 - TAPER
    w[a] = 0.5 - 0.5 * np.cos(np.pi * s[a] / TAPER)
    w[b] = 0.5 - 0.5 * np.cos(np.pi * (1 - s[b]) / TAPER)
    return w


def segment_command(seg: Segment, t: np.ndarray, tau: float) -> np.ndarray:
    """The command of ``seg`` at times ``t`` (s, from the segment's start) with peak
    ``seg.amplitude`` (before the taper, which only lowers it).

    Parameters
    ----------
    seg : Segment
        The segment.
    t : ndarray
        Times from the segment's start (s), within [0, tau].
    tau : float
        Segment length (s).
    """
    s = np.clip(t / tau, 0.0, 1.0)
    if seg.kind == "multisine":
        k = np.arange(max(1, round(seg.band[0] * tau)), max(1, round(seg.band[1] * tau)) + 1)
        phase = -np.pi * k * (k - 1) / len(k)
        shape = np.sin(2 * np.pi * np.outer(s, k) + phase).sum(axis=1)
        grid = np.linspace(0, 1, 4001)
        peak = np.max(np.abs(np.sin(2 * np.pi * np.outer(grid, k) + phase).sum(axis=1)))
        shape = shape / peak
    elif seg.kind in ("slews", "steps"):
        n, c = int(seg.band[0]), float(seg.band[1])
        # n moves between -1 and +1 at constant speed, the velocity's reversals ramped
        # over the fraction c of each move (a trapezoid velocity: the acceleration
        # phases load the inertia, the constant-speed ones the friction); steps: the
        # speed nil where |cos| < d = sin(pi r / 2) (a share r of the time), ramped up
        # over STEP_RAMP of the rest of |cos| beyond it
        grid = np.linspace(0.0, 1.0, 8001)
        wave = np.cos(np.pi * n * grid)
        if seg.kind == "slews":
            v = np.clip(wave / max(c, 1e-3), -1.0, 1.0)
        else:
            d = math.sin(0.5 * math.pi * c)
            v = np.sign(wave) * np.clip((np.abs(wave) - d) / (STEP_RAMP * (1 - d)), 0.0, 1.0)
        pos = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(grid))])
        pos -= 0.5 * (pos.max() + pos.min())
        shape = np.interp(s, grid, pos / np.max(np.abs(pos)))
    else:
        raise ValueError(f"unknown segment kind {seg.kind!r}")
    return seg.amplitude * shape * _taper(s)


def realise(segments, tau: float, rate: float, command: str, load: str, name: str = "designed") -> Test:
    """The one record of a sequence of segments: the command and the load sampled at
    ``rate`` (the load ramps to each segment's level over its first :data:`RAMP` s).

    Parameters
    ----------
    segments : sequence of Segment
        In the order they run.
    tau : float
        Segment length (s).
    rate : float
        Sample rate (Hz).
    command, load : str
        The model's command and load input names.
    name : str
        The test's name.
    """
    n_seg = int(round(tau * rate))
    t = np.arange(len(segments) * n_seg + 1) / rate
    x = np.zeros_like(t)
    f = np.zeros_like(t)
    prev = 0.0
    for j, seg in enumerate(segments):
        sl = slice(j * n_seg, (j + 1) * n_seg + 1)
        ts = t[sl] - j * tau
        x[sl] = segment_command(seg, ts, tau)
        r = np.clip(ts / RAMP, 0.0, 1.0)
        f[sl] = prev + (seg.load - prev) * (0.5 - 0.5 * np.cos(np.pi * r))
        prev = seg.load
    return Test(name, [{"name": name, "t": t, "inputs": {command: x, load: f}}], list(segments))


def _slewed_steps(heights, times, speed: float):
    """Steps of ``heights`` at ``times`` (s), each a ramp at ``speed`` (m/s)."""
    from ..signals import Signal

    sig = Signal.step(0.0)
    for h, t0 in zip(heights, times, strict=True):
        r = math.copysign(speed, h)
        sig = sig + Signal.ramp(r, t0) + Signal.ramp(-r, t0 + abs(h) / speed)
    return sig


def standard_test(duration: float, stroke: float, max_load: float, rate: float, command: str, load: str,
                  max_speed: float = math.inf) -> Test:
    """The standard tests of the same total length: steps, a small chirp, and slews under
    a pushing and a pulling load, as four records (the recovery case of ``identify``
    scaled to ``duration``: 24 %, 32 %, 24 %, 20 % of it), kept within the rod speed
    bound: the steps are commanded as ramps at :data:`STANDARD_SPEED` of it (a step the
    ECU's rate limiter slews would let the speed loop overshoot the limit: 14 % on the
    reference set), the chirp's amplitude at most that speed over 2 pi times its top
    frequency.

    - steps of +stroke/5, -2 stroke/5, +stroke/5 (unloaded);
    - a chirp of stroke/20 from 0.5 to 25 Hz (unloaded);
    - steps of +-stroke/2 under +max_load/2;
    - the same under -max_load.

    Parameters
    ----------
    duration : float
        Total length (s).
    stroke : float
        The test's stroke (m, the command stays within +-stroke).
    max_load : float
        The load capability (N).
    rate : float
        Sample rate (Hz).
    command, load : str
        The model's command and load input names.
    max_speed : float
        The rod speed bound (m/s).
    """
    from ..signals import Signal

    v = STANDARD_SPEED * max_speed
    slew = (lambda h, ts: _slewed_steps(h, ts, v)) if math.isfinite(v) else \
        (lambda h, ts: sum((Signal.step(a, t0) for a, t0 in zip(h, ts, strict=True)), Signal.step(0.0)))
    records = []
    for name, share in STANDARD_PARTS:
        T = duration * share
        t = np.arange(int(round(T * rate)) + 1) / rate
        a = stroke / 5
        if name == "steps":
            x = slew((a, -2 * a, a), (0.03 * T, 0.36 * T, 0.69 * T))(t)
            f = np.zeros_like(t)
        elif name == "chirp":
            x = Signal.chirp(min(stroke / 20, v / (2 * math.pi * 25.0)), 0.5, 25.0, t0=0.125 * T,
                             duration=0.875 * T)(t)
            f = np.zeros_like(t)
        else:
            h = stroke / 2
            level = max_load / 2 if name == "slews_push" else -max_load
            x = slew((h, -2 * h, h), (0.12 * T, 0.45 * T, 0.78 * T))(t)
            r = np.clip(t / (0.04 * T), 0, 1)
            f = level * (0.5 - 0.5 * np.cos(np.pi * r))
        records.append({"name": name, "t": t, "inputs": {command: x, load: f}})
    return Test("chirp+steps+slews", records)
