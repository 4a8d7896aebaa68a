"""The constraint groups of the tuning problem, each a block of normalised constraints
``expr >= 0`` in the gains: margin disks and ECU-rate ceilings per loop, bandwidth,
eigenvalue bound, overshoot, current and voltage limits along the step."""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ._closed_loop import _LOOP_ORDER
from ._requirements import Requirements, exclusion_disk

#: constraint kinds that depend only on the linear dynamics (shared by equal load cases)
_SHARED = ("margin", "rate", "bandwidth", "bandwidth_min", "eigenvalue", "cascade_margin", "unconditional",
           "separation", "noise")


@dataclass
class _Group:
    """One named block of normalised constraints ``expr >= 0``."""

    kind: str        # "margin", "rate", "bandwidth", "bandwidth_min", "overshoot", "current", "voltage", "eigenvalue"
    loads: list      # load cases (N) it stands for
    loop: str | None
    expr: ca.MX
    freqs: np.ndarray | None = None
    case: int = -1   # index of the distinct linearisation it was built for


def _disk_expr(G, j: int, c: float, R: float):
    """(|L + c|^2 - R^2) / (|L|^2 + c^2 + R^2) of loop j (in [-1, 2] whatever the disk),
    from G = S - 1 (rows real and imaginary part, the loops interleaved): >= 0 outside
    the exclusion disk."""
    Sr, Si = 1 + G[0, j::3], G[1, j::3]
    s2 = Sr**2 + Si**2
    l2 = (1 - Sr) ** 2 + Si**2  # |1 - S|^2 = |L|^2 |S|^2
    u2 = (1 + (c - 1) * Sr) ** 2 + ((c - 1) * Si) ** 2  # |1 + (c-1) S|^2 = |L + c|^2 |S|^2
    return (u2 - R**2 * s2) / (l2 + (c**2 + R**2) * s2)


def ecu_limits(model, p=None) -> dict:
    """What the tuning keeps within, from the parts' declarations: the current limit
    (A) and the voltage limit (V) of the model's trim limits, and each loop's ECU
    sample rate (Hz, the parameter its :class:`~ema_casadi.model.components.Loop`
    names), at the parameter vector ``p`` (default the model's set)."""
    P, limit = vars(model.pdict(p)), model.limit_values(p)
    return {"current": limit["current"], "voltage": limit["voltage"],
            "rate": {name: float(P[loop.rate]) for name, loop in model.loops.items()}}


def _current_limit(limits: dict) -> float:
    """The current limit (A) of :func:`ecu_limits`."""
    return float(limits["current"])


def _rate_floor(limits: dict, loop: str, req: Requirements) -> float:
    """Frequency (Hz) above which the loop's gain must stay below 1."""
    return limits["rate"][loop] / req.rate_ratio


def _loop_groups(G, freqs: np.ndarray, req: Requirements, limits: dict, F: float, case: int) -> list[_Group]:
    """Margin disk and ECU-rate ceiling of each loop from G = S - 1 (2 x 3N: real and
    imaginary parts, the loops interleaved) on the grid ``freqs`` (Hz)."""
    c, R = exclusion_disk(req)
    groups = []
    for j, loop in enumerate(_LOOP_ORDER):
        Sr, Si = 1 + G[0, j::3], G[1, j::3]  # S_j = 1 + G_jj
        s2 = Sr**2 + Si**2
        l2 = (1 - Sr) ** 2 + Si**2  # |1 - S|^2 = |L|^2 |S|^2
        groups.append(_Group("margin", [F], loop, _disk_expr(G, j, c, R).T, freqs, case))
        if req.rate_ratio > 0:
            sel = np.nonzero(freqs >= _rate_floor(limits, loop, req))[0]
            if len(sel):  # -log|L|^2 >= 0
                groups.append(_Group("rate", [F], loop, ca.log(s2[sel] / l2[sel]).T, freqs[sel], case))
    return groups


def _bandwidth_groups(S: ca.Function, loop_matrices, fb, freqs: np.ndarray, req: Requirements,
                      F: float, case: int) -> list[_Group]:
    """|T| >= 1/sqrt(2) at the bandwidth variable ``fb`` (Hz, if any) and up to the
    required minimum bandwidth (on the grid from a decade below it)."""
    def t_half(w_rad):  # x_rod/x_cmd = T = 1 - S_x = -G_xx: log(2 |T|^2) >= 0
        g = S.map(w_rad.shape[1])(*loop_matrices, w_rad)
        return ca.log(2 * (g[0, 0::3] ** 2 + g[1, 0::3] ** 2)).T

    groups = []
    if fb is not None:
        groups.append(_Group("bandwidth", [F], "position", t_half(2 * np.pi * fb), None, case))
    if req.bandwidth_min_hz is not None:
        fm = req.bandwidth_min_hz
        fs = np.r_[freqs[(freqs >= fm / 10) & (freqs < fm)], fm]
        groups.append(_Group("bandwidth_min", [F], "position", t_half((2 * np.pi * fs).reshape(1, -1)), fs, case))
    return groups


def _eigenvalue_group(alpha, req: Requirements, F: float, case: int) -> _Group:
    """Spectral abscissa ``alpha`` (1/s) left of -sigma, as asinh of the scaled excess."""
    excess = -req.sigma - alpha  # >= 0 required (1/s)
    return _Group("eigenvalue", [F], None, ca.asinh(excess / max(1.0, req.sigma)), None, case)


def _overshoot_group(X, t: np.ndarray, c_rod, d_rod, req: Requirements, F: float, case: int):
    """Overshoot bound on the normalised x_rod of the step (states X at times t, s) and
    the step's integrated squared error (normalised by 10 ms)."""
    x_rod = (c_rod @ X) / req.step + d_rod
    group = _Group("overshoot", [F], None, (1 + req.overshoot - x_rod).T, None, case)
    e2 = (x_rod - 1) ** 2
    ise = ca.sum2((e2[:, :-1] + e2[:, 1:]) * ca.DM(np.diff(t)).T) / 2 / 0.01
    return group, ise


def _limit_groups(op, X, Cs, ds, req: Requirements, limits: dict, names: tuple) -> list[_Group]:
    """Current and voltage limits (:func:`ecu_limits`) along the step (rows of Cs/ds: the
    outputs ``names`` with the motor-current, d- and q-voltage roles, i_q, v_d, v_q;
    operating values added)."""
    F = op.f_ext
    Y = Cs @ X + ca.repmat(ds * req.step, 1, X.shape[1])
    i_q, v_d, v_q = (op.output(name) + Y[k, :] for k, name in enumerate(names))
    v_lim = limits["voltage"]
    r_i = (i_q / limits["current"]) ** 2
    r_v = (v_d**2 + v_q**2) / v_lim**2
    return [_Group("current", [F], None, ca.log((1 + 1e-3) / (r_i + 1e-3)).T),
            _Group("voltage", [F], None, ca.log((1 + 1e-3) / (r_v + 1e-3)).T)]


def _dense_minima(f: np.ndarray, L: np.ndarray, req: Requirements, limits: dict, loop: str) -> list[float]:
    """Frequencies (Hz) of the local minima below zero of the margin-disk and ECU-rate
    checks of the loop transfer L (complex, on the grid f)."""
    c, R = exclusion_disk(req)
    checks = [np.abs(L + c) ** 2 - R**2]
    if req.rate_ratio > 0:
        checks.append(np.where(f >= _rate_floor(limits, loop, req), 1 - np.abs(L) ** 2, 1.0))
    out = []
    for m in checks:
        low = (m < 0) & (m <= np.r_[np.inf, m[:-1]]) & (m <= np.r_[m[1:], np.inf])
        out.extend(f[low].tolist())
    return out
