"""The candidate segments, their information and their use of the limits.

Candidates: multisines in :data:`BANDS`, slews of :data:`SLEWS` and steps of
:data:`STEPS`, at every load
level of :data:`LOAD_LEVELS` (fractions of the load capability) and every amplitude of
:data:`AMPLITUDES` (fractions of the stroke). Each is run alone from rest with
forward sensitivities (:func:`~ema_casadi.design.information`), first
:data:`LEAD_IN` copies of itself, then once more: its information per segment counted on the last copy,
which starts where a test's segment starts (moving, at its load level) rather than at
rest at zero load, and the largest use of every limit along the whole run. A
candidate is admissible when its rod stays within :data:`STROKE_MARGIN` of the stroke
and the motor current, the rod speed and the voltage within their limits to
:data:`LIMIT_TOLERANCE` (the ECU's limiters hold them there; what they let through,
the current loop's overshoot above I_max, counts).
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np

from .._util._parallel import cores
from ..simulation import RunFailed
from ._excitation import Segment, realise
from ._fisher import information

__all__ = ["BANDS", "SLEWS", "STEPS", "LOAD_LEVELS", "AMPLITUDES", "STROKE_MARGIN", "LIMIT_TOLERANCE", "AIM",
           "LEAD_IN", "candidates", "admissible", "at_limits", "evaluate"]

#: Multisine bands (Hz): harmonics of the segment's base frequency within each.
BANDS = ((1.0, 4.0), (4.0, 16.0), (15.0, 50.0))
#: Slew segments: moves per segment and the share of a move spent reversing.
SLEWS = ((2, 0.1), (4, 0.1), (6, 0.3))
#: Step segments (stop and go): moves per segment and the share of the time at rest.
#: A move from rest at the rod speed the ECU allows, then a rest: the seal friction's
#: information apart from the viscous term's (with the lead-in below, a 4-move segment
#: at 9.2 mm unloaded carries 1.1x the conditional information per second of the
#: standard test; multisines and slews at most 0.4x).
STEPS = ((2, 0.8), (4, 0.8))
#: Load levels, fractions of the load capability.
LOAD_LEVELS = (-1.0, -0.5, 0.0, 0.5, 1.0)
#: Command amplitudes, fractions of the stroke (the rod then stays about that far in).
AMPLITUDES = (0.92, 0.3, 0.08)
#: The predicted rod position stays within this fraction of the stroke (room for the
#: parameters' uncertainty: the truth is not the prediction).
STROKE_MARGIN = 0.95
#: The motor current, rod speed and voltage at most this fraction of their limits.
LIMIT_TOLERANCE = 1.005
#: Copies of a candidate run before the one whose information counts. Counted from
#: rest, a loaded candidate's information holds its load ramp from zero (the rod's
#: deflection under a changing load: the stiffness, the backlash crossed, the seal
#: friction's breakaway at low speed), which a test whose segments run at one level
#: after another does not repeat: on the acceptance case the sum over the segments
#: overstated the stiffness's information 3.9x, and the seal friction's share of it
#: separated from the viscous term.
LEAD_IN = 1
#: A candidate scaled to the limits (:func:`at_limits`) aims at this fraction of the
#: first bound it reaches (room for the segments' joins: at 0.97 the realised test of
#: --max-speed 80mm/s reached 1.01 of the rod speed bound).
AIM = 0.93


def candidates(tau: float, stroke: float, max_load: float) -> list[Segment]:
    """The candidate segments.

    Parameters
    ----------
    tau : float
        Segment length (s).
    stroke : float
        The test's stroke (m).
    max_load : float
        Load capability (N).
    """
    out = []
    loads = sorted({round(f * max_load, 6) for f in LOAD_LEVELS}) if max_load > 0 else [0.0]
    shapes = [("multisine", (max(lo, 1 / tau), hi)) for lo, hi in BANDS if hi * tau >= 1]
    shapes += [("slews", s) for s in SLEWS] + [("steps", s) for s in STEPS]
    for F in loads:
        for kind, band in shapes:
            for a in AMPLITUDES:
                out.append(Segment(kind, band, float(F), a * stroke))
    return out


def admissible(usage: dict) -> bool:
    """Whether a predicted trajectory's limit use (:func:`~ema_casadi.design.limit_usage`)
    keeps every limit.

    Parameters
    ----------
    usage : dict
        Limit name -> largest value as a fraction of the limit.
    """
    return all(v <= _bound(k) for k, v in usage.items())


def _bound(name: str) -> float:
    return STROKE_MARGIN if name == "stroke" else LIMIT_TOLERANCE


def at_limits(segs, evaluated) -> list[Segment]:
    """Per command shape and load level whose largest amplitude leaves a limit: the
    largest admissible amplitude scaled up until the first limit's use reaches
    :data:`AIM` of its bound, each use taken proportional to the amplitude. Below the
    ECU's limiters the rod's motion is linear in the amplitude: its speed and travel
    are proportional to it; the current and voltage start from the load's share, so the
    proportion overestimates them and the scaling is conservative. Beyond the limiters
    the use is far from linear (the rod speed jumps by the speed loop's overshoot once
    the rate limiter clips), so the step is never interpolated towards the inadmissible
    amplitude above. Evaluated and checked like the others.

    Parameters
    ----------
    segs : sequence of Segment
        The candidates.
    evaluated : sequence
        :func:`evaluate`'s result for them.
    """
    groups: dict = {}
    for seg, e in zip(segs, evaluated, strict=True):
        if e is not None:
            groups.setdefault((seg.kind, tuple(seg.band), seg.load), []).append((seg.amplitude, e[1]))
    out = []
    for (kind, band, load), pts in groups.items():
        pts.sort(key=lambda p: p[0])
        ok = [p for p in pts if admissible(p[1])]
        if not ok or ok[-1] is pts[-1]:
            continue
        (a0, u0), a1 = ok[-1], pts[pts.index(ok[-1]) + 1][0]
        scale = min(AIM * _bound(name) / v for name, v in u0.items() if v > 0 and name != "load")
        a = min(a0 * scale, a1)
        if a > 1.05 * a0:
            out.append(Segment(kind, band, load, float(a)))
    return out


def evaluate(model, segs, tau: float, rate: float, free, sigma: dict, thetas, limits: dict, names: tuple,
             progress=None) -> list:
    """Per candidate: ``(M averaged over thetas, worst usage over thetas)`` or None
    where a run fails; candidates run on the cores at once.

    Parameters
    ----------
    model : Model
        The model.
    segs : sequence of Segment
        The candidates.
    tau, rate : float
        Segment length (s) and sample rate (Hz).
    free : Free
        The free parameters.
    sigma : dict
        Channel -> noise (SI).
    thetas : sequence of ndarray
        Parameter values of the prior's draws (SI).
    limits : dict
        ``stroke`` (m), ``max_load`` (N) and ``max_speed`` (m/s) of the test.
    names : tuple of str
        The command and load input names.
    progress : callable, optional
        Called with the fraction done.
    """
    jobs = [(k, th) for k in range(len(segs)) for th in range(len(thetas))]
    done = [0]

    def one(job):
        k, d = job
        try:
            info = information(model, realise([segs[k]] * (1 + LEAD_IN), tau, rate, *names), free, sigma,
                               thetas[d], threads=1, lead_in=LEAD_IN * tau, **limits)
        except RunFailed:
            info = None
        done[0] += 1
        if progress is not None:
            progress(done[0] / len(jobs))
        return info

    infos = [one(jobs[0])]  # the first alone: the compiled functions are built (and cached) once
    with ThreadPoolExecutor(max(1, min(cores(), len(jobs))), thread_name_prefix="ema-design") as pool:
        infos += list(pool.map(one, jobs[1:]))
    out = []
    for k in range(len(segs)):
        mine = infos[k * len(thetas) : (k + 1) * len(thetas)]
        if any(i is None for i in mine):
            out.append(None)
            continue
        M = np.mean([i.M for i in mine], axis=0)
        usage = {n: max(i.usage[n] for i in mine) for n in mine[0].usage}
        out.append((M, usage))
    return out
