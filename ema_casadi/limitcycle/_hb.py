"""Harmonic balance: a describing-function root refined with the higher harmonics (docs: aircraft).

The describing function balances the first harmonic only: the injection at the break is
A cos(w t) and the root is where the open loop returns it, L_N(A, w) = -1. In a
stick-slip cycle the signal at the break is far from a sine (the rod sticks most of the
cycle), and that single-harmonic balance misses the cycle by tens of percent. Here the
injection carries the higher harmonics too,

    u(t) = u_0 + Re[A exp(j w t) + sum_(k in H) c_k exp(j k w t)],

and the open loop (the same break, flag open, the same simulation and Fourier
coefficients as :func:`~ema_casadi.limitcycle.describing_function`) must return every
kept harmonic: Y_1 = A and Y_k = c_k for k in H (the loop closed, the injection is the
measurement). The unknowns are log A, log w and the complex c_k / A; Newton with
finite-difference slopes and a backtracking line search (each evaluation one
simulation). With no higher harmonic (``harmonics=()``) this is the describing
function's own root. A harmonic balance that does not converge is reported as such,
never as a cycle.
"""

from __future__ import annotations

import math

import numpy as np

from ..model.assembly import Model
from ..optimisation import newton_step
from ._df import _periodic_runner

__all__ = ["harmonic_balance", "harmonic_orders"]


def harmonic_orders(harmonics) -> tuple:
    """The higher harmonics to balance, checked: distinct whole orders from 2 to 31 (the
    64-sample period's Nyquist limit); ``ValueError`` naming what is wrong otherwise.

    Parameters
    ----------
    harmonics : iterable of int or float
        The orders (e.g. ``(3, 5, 7)``, or parsed from ``"3,5,7"``).
    """
    orders = tuple(harmonics)
    if any(k != int(k) or not 2 <= k <= 31 for k in orders) or len(set(orders)) != len(orders):
        raise ValueError(f"harmonics: distinct whole orders from 2 to 31, got {', '.join(f'{k:g}' for k in orders)}")
    return tuple(int(k) for k in orders)


def _unpack(z, H):
    A, f = math.exp(z[0]), math.exp(z[1])
    return A, f, {1: A, **{k: A * complex(z[2 + 2 * i], z[3 + 2 * i]) for i, k in enumerate(H)}}


def _residual(run, z, H):
    A, f, c = _unpack(z, H)
    Y, _, _ = run(f, c)
    r1 = np.log(complex(Y[1]) / A + 0j)  # 0 when the first harmonic comes back unchanged
    r = [r1.real, r1.imag]
    for k in H:
        e = (Y[k] - c[k]) / A
        r += [e.real, e.imag]
    return np.array(r), Y


def harmonic_balance(model: Model, loop: str, cycle: dict, *, p, x0, inputs=None, meas0: float = 0.0,
                     dt: float = 1e-4, periods: int = 16, settle: int = 8, harmonics=(3, 5, 7),
                     iterations: int = 10, tol: float = 2e-3, converged: float = 1e-2) -> dict:
    """A limit cycle by harmonic balance at a loop break, from a describing-function root.

    Parameters
    ----------
    model, loop, p, x0, inputs, meas0, dt, periods, settle
        As in :func:`~ema_casadi.limitcycle.break_response` (the operating point, the
        break, the RK4 step in s, the periods simulated and dropped).
    cycle : dict
        The starting root (``amplitude`` in the break signal's unit, ``freq_hz``), from
        :func:`~ema_casadi.limitcycle.predict` or :func:`~ema_casadi.limitcycle.refine`.
    harmonics : tuple of int
        The higher harmonics balanced besides the first (orders >= 2, below 32); odd
        ones for a cycle symmetric about the operating point.
    iterations : int
        Newton steps at most.
    tol : float
        Stop when the residual (relative to A) is below this.
    converged : float
        The residual up to which the result is a cycle (1e-2: 0.09 dB, 0.6 deg on the
        first harmonic and 1 % of A on each higher one).

    Returns
    -------
    dict
        ``cycle`` with ``harmonic_balance``: ``amplitude`` (first harmonic of the break
        signal), ``freq_hz``, ``harmonics`` (order -> amplitude relative to the first),
        ``residual`` and ``converged``; ``amplitude`` and ``freq_hz`` become the balanced
        values when it converged and stay the describing function's otherwise
        (``method`` says which), ``df_amplitude`` / ``df_freq_hz`` keep the starting root.
    """
    H = harmonic_orders(harmonics)
    run = _periodic_runner(model, loop, p, x0, dict(inputs or {}), meas0, dt, periods, settle)
    z = np.zeros(2 + 2 * len(H))
    z[:2] = math.log(cycle["amplitude"]), math.log(cycle["freq_hz"])
    _, Y = _residual(run, z, H)
    for i, k in enumerate(H):  # start the higher harmonics from the describing function's answer
        z[2 + 2 * i: 4 + 2 * i] = (Y[k] / cycle["amplitude"]).real, (Y[k] / cycle["amplitude"]).imag
    r, Y = _residual(run, z, H)
    for _ in range(iterations):
        if np.linalg.norm(r) < tol:
            break
        z, r, moved = _newton_step(run, z, r, H)
        if not moved:
            break
    res = float(np.linalg.norm(r))
    A, f, c = _unpack(z, H)
    hb = {"amplitude": A, "freq_hz": f, "harmonics": {k: float(abs(c[k]) / A) for k in H}, "residual": res,
          "converged": bool(res < converged)}
    best = {"amplitude": A, "freq_hz": f, "method": "harmonic balance"} if hb["converged"] else \
        {"method": "describing function"}
    return {**cycle, **best, "df_amplitude": cycle["amplitude"], "df_freq_hz": cycle["freq_hz"],
            "harmonic_balance": hb}


def _newton_step(run, z, r, H, h: float = 0.03):
    """One Newton step with forward-difference slopes (step h in each unknown), limited to
    0.3 in log A and log f, halved up to four times until the residual falls."""
    J = np.empty((len(r), len(z)))
    for j in range(len(z)):
        dz = np.zeros(len(z))
        dz[j] = h
        J[:, j] = (_residual(run, z + dz, H)[0] - r) / h
    step = newton_step(J, r, least_squares=True, max_step=0.3, capped=2)
    for _ in range(5):
        zn = z + step
        rn, _ = _residual(run, zn, H)
        if np.linalg.norm(rn) < np.linalg.norm(r):
            return zn, rn, True
        step = step / 2
    return z, r, False
