"""The cascade's constraint groups: each loop with its outer loops open (the classic
cascade view) unconditionally stable with the margins, the loop separation between
neighbouring loops, and the bound on the current command's response to position-sensor
noise. Each is a block of normalised constraints ``expr >= 0`` in the gains."""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from ._closed_loop import _LOOP_ORDER
from ._constraints import _current_limit, _disk_expr, _Group
from ._requirements import Requirements, exclusion_disk

#: Loops opened to see each loop of the cascade with its outer loops open.
OUTER_OPEN = {"position": (), "velocity": ("position",), "current": ("position", "velocity")}
#: Lowest frequency (Hz) of each loop's outer-open constraints. With both outer loops
#: open the drive's position and the opened integrators are free (eigenvalues 0), and the
#: real-arithmetic response (A^2 + w^2 I)^-1 (-A - jw I) loses accuracy at low w: the
#: current loop's S against a fresh linearisation was off by 8.6e-4 at 0.5 Hz (|S| ~
#: 5e-4), 2.4e-5 at 1 Hz, 1.1e-6 at 2 Hz, 5e-9 at 4 Hz. Below 4 Hz that loop is two
#: decades under its crossover (|L| > 100, phase near -90 deg): nothing to constrain;
#: the verification checks every crossing from 0.01 Hz.
_OPEN_F_MIN = {"current": 4.0}
#: The optimiser's noise bound lies this far (relative) inside the requirement: its grid
#: (14 per decade, refined at 100 per decade) and the verification's (100 per decade
#: from 0.01 Hz) sample the peak at different frequencies; with the bound met exactly on
#: the first the second found it exceeded by ~1e-4 on eight of the 32 variant-matrix
#: tunes (all over 0/15/30 kN, the noise bound active), which the safety net then
#: answered with the start gains.
_NOISE_MARGIN = 2e-3
#: Relative grids of the separation test around each gap frequency g (Hz): the outer
#: loop's |L| <= 1 on g/sqrt(s) x _ABOVE, the inner one's |L| >= 1 on g sqrt(s) x _BELOW.
_ABOVE = np.logspace(0, 1.5, 13)
_BELOW = np.logspace(-1.5, 0, 13)
#: Smoothing (in the normalised units, each in [-1, 1]) of the maximum in the
#: unconditional-stability and separation tests: the smooth maximum lies between
#: max - _EPS/2 and max, so the constraint is conservative by at most _EPS/2.
_EPS = 1e-3


def _smooth_max(a, b):
    """A lower bound of max(a, b), within _EPS/2 of it: (a + b + sqrt((a-b)^2 + eps^2) - eps)/2."""
    return (a + b + ca.sqrt((a - b) ** 2 + _EPS**2) - _EPS) / 2


def _parts(G, j):
    """(Sr, Si, s2, l2) of loop j's sensitivity S = 1 + G_jj: |S|^2 and |1 - S|^2 = |L|^2 |S|^2."""
    Sr, Si = 1 + G[0, j::3], G[1, j::3]
    s2 = Sr**2 + Si**2
    return Sr, Si, s2, (1 - Sr) ** 2 + Si**2


def _unconditional(G, j, a: float):
    """L stays out of its second quadrant (Re L < 0 < Im L: past -180 deg of phase)
    wherever |L| >= a: max((a^2 - |L|^2)/(a^2 + |L|^2), -Im L/|L|, Re L/|L|) >= 0. L
    crossing the negative real axis moves it from the third quadrant into the second,
    so every phase crossover then has |L| <= a (no lower gain margin, the upper one at
    least -20 log10 a)."""
    Sr, Si, s2, l2 = _parts(G, j)
    r = ca.sqrt(s2 * l2 + 1e-300)  # |L| |S|^2
    mag = (a * a * s2 - l2) / (a * a * s2 + l2)
    below = Si / r                 # -Im L / |L|:  Im L = -Im S / |S|^2
    right = (Sr - s2) / r          #  Re L / |L|:  Re L = (Re S - |S|^2) / |S|^2
    return _smooth_max(mag, _smooth_max(below, right))


def _above_one(G, j):
    """(|L|^2 - 1)/(|L|^2 + 1) of loop j, in [-1, 1]: >= 0 where |L| >= 1."""
    _, _, s2, l2 = _parts(G, j)
    return (l2 - s2) / (l2 + s2)


def open_grid(loop: str, freqs: np.ndarray) -> np.ndarray:
    """The frequencies (Hz) of ``freqs`` at which the loop's outer-open constraints are
    taken: from :data:`_OPEN_F_MIN` up."""
    return freqs[freqs >= _OPEN_F_MIN.get(loop, 0.0)]


def outer_open_groups(G_open: dict, req: Requirements, F: float, case: int) -> list[_Group]:
    """Margin disk and unconditional stability of every loop with its outer loops open
    (``G_open[loop]`` = (G, f): G = S - 1 of the configuration :data:`OUTER_OPEN` of that
    loop on the frequencies f, Hz, :func:`open_grid`)."""
    c, R = exclusion_disk(req)
    a = 10 ** (-req.margin_targets()[0] / 20)
    groups = []
    for loop in _LOOP_ORDER:
        j = _LOOP_ORDER.index(loop)
        G, freqs = G_open[loop]
        if loop != "position":  # the position loop has no outer loop: its disk is the margin group's
            groups.append(_Group("cascade_margin", [F], loop, _disk_expr(G, j, c, R).T, freqs, case))
        groups.append(_Group("unconditional", [F], loop, _unconditional(G, j, a).T, freqs, case))
    return groups


def separation_groups(S: ca.Function, cfg: dict, gaps, req: Requirements, F: float, case: int) -> list[_Group]:
    """Loop separation s between each pair of neighbouring loops, through a gap
    frequency g_k (``gaps``, Hz, decision variables): the outer loop's |L| <= 1 from
    g_k / sqrt(s) over 1.5 decades, the inner loop's |L| >= 1 over 1.5 decades up to
    g_k sqrt(s) (each with its outer loops open: ``cfg[loop]``, the reduced closed-loop
    matrices of that configuration). Then the outer loop's crossover lies below g_k /
    sqrt(s) and the inner one's above g_k sqrt(s): their ratio is at least s (for loops
    whose gain stays above 1 below and below 1 above those bands, which the verification
    checks on every crossover)."""
    groups, r = [], math.sqrt(req.separation)
    for k, (outer, inner) in enumerate(zip(_LOOP_ORDER[:-1], _LOOP_ORDER[1:], strict=True)):
        for loop, rel, sign in ((outer, _ABOVE / r, -1.0), (inner, _BELOW * r, 1.0)):
            w = 2 * np.pi * gaps[k] * ca.DM(rel).T
            G = S.map(len(rel))(*cfg[loop], w)
            groups.append(_Group("separation", [F], inner, sign * _above_one(G, _LOOP_ORDER.index(loop)).T,
                                 None, case))
    return groups


def gap_start(model, op) -> list[float]:
    """Start values (Hz) of the gap frequencies: the geometric mean of each pair's
    crossovers with the outer loops open (highest of the outer loop, lowest of the
    inner; 10 Hz for a loop without one) at the operating point ``op``."""
    from ..frequency import loop_margins

    lm = loop_margins(model, op, list(_LOOP_ORDER), outer="open")
    fc = {k: [c["f_hz"] for c in m.gain_crossovers] or [10.0] for k, m in lm.items()}
    return [math.sqrt(max(fc[o]) * min(fc[i])) for o, i in zip(_LOOP_ORDER[:-1], _LOOP_ORDER[1:], strict=True)]


def noise_group(S1: ca.Function, noise, freqs: np.ndarray, bound: float, F: float, case: int) -> _Group:
    """|i_cmd / n_x| <= bound (A/m) on the grid ``freqs`` (Hz): log(bound^2 / |H|^2) >= 0,
    H the closed-loop response of the current command to the position loop's injection
    (``noise`` = (A, b, c, d), reduced and balanced)."""
    H = S1.map(len(freqs))(*noise, (2 * np.pi * freqs).reshape(1, -1))
    h2 = H[0, :] ** 2 + H[1, :] ** 2
    return _Group("noise", [F], None, ca.log(bound**2 / (h2 + 1e-300)).T, freqs, case)


def noise_gain_bound(req: Requirements, limits: dict) -> float | None:
    """The bound (A/m) of :func:`noise_group` for the current limit (A) of ``limits``
    (:func:`~ema_casadi.tuning._constraints.ecu_limits`), :data:`_NOISE_MARGIN` inside
    the requirement's."""
    bound = req.noise_gain_max(_current_limit(limits))
    return None if bound is None else bound * (1 - _NOISE_MARGIN)


def dense_checks(L_open: dict, req: Requirements) -> list[float]:
    """Frequencies (Hz) of local minima below zero of the outer-open margin disk and the
    unconditional-stability test (``L_open``: per loop, (L, f) on a dense grid f)."""
    c, R = exclusion_disk(req)
    a = 10 ** (-req.margin_targets()[0] / 20)
    out = []
    for loop, (L, f) in L_open.items():
        checks = [np.maximum(np.maximum(a - np.abs(L), -L.imag), L.real)]
        if loop != "position":
            checks.append(np.abs(L + c) ** 2 - R**2)
        for m in checks:
            low = (m < 0) & (m <= np.r_[np.inf, m[:-1]]) & (m <= np.r_[m[1:], np.inf])
            out.extend(f[low].tolist())
    return out
