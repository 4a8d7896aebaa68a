"""The cascade's constraint groups: each loop with its outer loops open (the classic
cascade view) unconditionally stable with the margins, the loop separation between
neighbouring loops, and the bound on the current command's response to position-sensor
noise. Each is a block of normalised constraints ``expr >= 0`` in the gains."""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from ._closed_loop import _LOOP_ORDER
from ._constraints import _disk_expr, _Group
from ._requirements import Requirements, exclusion_disk

#: Loops opened to see each loop of the cascade with its outer loops open.
OUTER_OPEN = {"position": (), "velocity": ("position",), "current": ("position", "velocity")}
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


def outer_open_groups(G_open: dict, G_sep: dict, freqs: np.ndarray, f_sep: np.ndarray, req: Requirements,
                      F: float, case: int) -> list[_Group]:
    """Margin disk and unconditional stability of every loop with its outer loops open
    (``G_open[loop]``: G = S - 1 of the configuration :data:`OUTER_OPEN` of that loop on
    ``freqs``, Hz), and the separation of each pair of neighbouring loops.

    Separation ``s``: wherever the outer loop's |L| >= 1 at a grid frequency f_k, the
    inner loop's |L| >= 1 at s f_(k+1) (``G_sep[inner]``, the inner loop's
    configuration on ``s freqs[1:]``). With one gain crossover each, the outer loop's
    lies below f_(k+1) for the last such k, the inner one's above s f_(k+1): their ratio
    is at least s (conservative by at most one grid step). ``G_sep[loop]`` = (G on the
    separation grid ``f_sep`` (Hz) as the outer loop of a pair, G on s f_sep[1:] as the
    inner one), each in the loop's outer-open configuration."""
    c, R = exclusion_disk(req)
    a = 10 ** (-req.margin_targets()[0] / 20)
    groups = []
    for loop in _LOOP_ORDER:
        j = _LOOP_ORDER.index(loop)
        G = G_open[loop]
        if loop != "position":  # the position loop has no outer loop: its disk is the margin group's
            groups.append(_Group("cascade_margin", [F], loop, _disk_expr(G, j, c, R).T, freqs, case))
        groups.append(_Group("unconditional", [F], loop, _unconditional(G, j, a).T, freqs, case))
    if req.separation > 0:
        for outer, inner in zip(_LOOP_ORDER[:-1], _LOOP_ORDER[1:], strict=True):
            u = _above_one(G_sep[outer][0], _LOOP_ORDER.index(outer))[:-1]
            v = _above_one(G_sep[inner][1], _LOOP_ORDER.index(inner))
            groups.append(_Group("separation", [F], inner, _smooth_max(v, -u).T, f_sep[:-1], case))
    return groups


def noise_group(S1: ca.Function, noise, freqs: np.ndarray, bound: float, F: float, case: int) -> _Group:
    """|i_cmd / n_x| <= bound (A/m) on the grid ``freqs`` (Hz): log(bound^2 / |H|^2) >= 0,
    H the closed-loop response of the current command to the position loop's injection
    (``noise`` = (A, b, c, d), reduced and balanced)."""
    H = S1.map(len(freqs))(*noise, (2 * np.pi * freqs).reshape(1, -1))
    h2 = H[0, :] ** 2 + H[1, :] ** 2
    return _Group("noise", [F], None, ca.log(bound**2 / (h2 + 1e-300)).T, freqs, case)


def noise_gain_bound(req: Requirements, ref: dict) -> float | None:
    """The bound (A/m) of :func:`noise_group` for the set's current limit I_max (A)."""
    return req.noise_gain_max(float(ref["I_max"]))


def dense_checks(f: np.ndarray, L_open: dict, req: Requirements) -> list[float]:
    """Frequencies (Hz) of local minima below zero of the outer-open margin disk and the
    unconditional-stability test (``L_open``: per loop, L on the dense grid f)."""
    c, R = exclusion_disk(req)
    a = 10 ** (-req.margin_targets()[0] / 20)
    out = []
    for loop, L in L_open.items():
        checks = [np.maximum(np.maximum(a - np.abs(L), -L.imag), L.real)]
        if loop != "position":
            checks.append(np.abs(L + c) ** 2 - R**2)
        for m in checks:
            low = (m < 0) & (m <= np.r_[np.inf, m[:-1]]) & (m <= np.r_[m[1:], np.inf])
            out.extend(f[low].tolist())
    return out


def separation_factor(freqs: np.ndarray) -> float:
    """Largest ratio of neighbouring grid frequencies: the most by which the separation
    groups can be conservative."""
    return float(np.max(freqs[1:] / freqs[:-1])) if len(freqs) > 1 else math.inf
