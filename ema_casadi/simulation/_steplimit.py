"""The fixed step RK4 can take on a model: the stability limit from the fastest
eigenvalues of the model's Jacobian at the states a run passes through.

Classical RK4 multiplies a mode ``exp(lambda t)`` by ``R(h lambda)`` per step, with
``R(z) = 1 + z + z^2/2 + z^3/6 + z^4/24``; the step is stable for a mode while
``|R(h lambda)| <= 1``: ``h |lambda| <= 2.785`` on the negative real axis, ``2.828`` on
the imaginary axis (:func:`rk4_reach` gives the reach along any direction). Above it
the mode grows by ``|R|`` per step until a nonlinearity bounds it: a chatter, not a
blow-up, when the fast mode is the slope of a smoothed Coulomb law.

The points (:func:`rk4_step_limit`):

``at rest, no load``
    ``model.x0()``: with backlash the rod sits in the middle of the gap, held by nothing
    but its friction, whose smoothed law has the slope ``F_r / v_s`` at rest: the mode
    ``-F_r / (v_s M)`` (-5.0e5 1/s on the reference set, limit 5.57 us).
``held under load``
    The operating point at rest under the run's largest load, backlash kept (the rod
    on a flank): the load-dependent bearing friction raises ``F_r`` (reference set:
    -1.13e6 1/s and 2.46 us at 5 kN, -4.27e6 1/s and 0.65 us at 30 kN). A run that
    holds its load (a jam, a hold, the reversals of a loaded sine) visits it.

With the sampled ECU the plant is the held-input flow ``f_held`` (the controller's
output held); otherwise ``f``. Hybrid (Karnopp) friction has no slope at rest, so its
limit is set by the electrical and contact modes (0.27 ms on the reference set).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..model.assembly import Model

__all__ = ["StepLimit", "StepLimitWarning", "rk4_step_limit", "rk4_reach", "rk4_growth", "RK4_REAL_REACH",
           "step_check", "peak_load", "sample_periods", "default_step", "inside_limit", "DT_DEFAULT", "DT_MARGIN",
           "mode_step_limit", "jacobian_step_limit"]

#: :func:`~ema_casadi.simulation.simulate`'s RK4 step without ``dt`` where it is inside
#: :data:`DT_MARGIN` x RK4's stability limit (s): hybrid friction (0.26 ms limit).
DT_DEFAULT = 1e-5
#: A default step's largest fraction of the stability limit.
DT_MARGIN = 0.8


def _R(z):
    return 1 + z + z**2 / 2 + z**3 / 6 + z**4 / 24


def rk4_growth(z) -> float:
    """``|R(z)|``, RK4's amplification of a mode per step.

    Parameters
    ----------
    z : complex
        ``h lambda``, the step times the mode's eigenvalue.
    """
    return float(abs(_R(complex(z))))


def rk4_reach(direction: complex) -> float:
    """The largest ``r`` with ``|R(r d)| <= 1`` along the unit direction ``d`` of the
    complex plane (``inf`` in the right half plane, where RK4 is unstable at any step
    and a step limit means nothing: a physically unstable mode).

    Parameters
    ----------
    direction : complex
        A direction; only its angle counts.
    """
    d = complex(direction)
    if d == 0 or d.real > 1e-12 * abs(d):
        return math.inf
    d /= abs(d)
    grid = np.linspace(0.0, 3.0, 3001)[1:]
    above = np.nonzero(np.abs(_R(grid * d)) > 1.0 + 1e-12)[0]
    if not above.size:
        return math.inf
    lo, hi = (grid[above[0] - 1] if above[0] else 0.0), grid[above[0]]
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if abs(_R(mid * d)) <= 1.0 + 1e-12 else (lo, mid)
    return lo


#: RK4's reach on the negative real axis, ``h |lambda| <= 2.7853``.
RK4_REAL_REACH = rk4_reach(-1.0)


def mode_step_limit(lam: complex) -> float:
    """RK4's largest stable step on the mode ``lam`` (s): ``rk4_reach(lam) / |lam|``
    (``inf`` for a zero or right-half-plane eigenvalue). The reach is not one number:
    2.785 on the negative real axis, 2.828 on the imaginary axis and 2.616 at 123 deg,
    so a complex mode can be limiting below ``2.785 / |lam|``.

    Parameters
    ----------
    lam : complex
        The eigenvalue (1/s).
    """
    lam = complex(lam)
    return math.inf if lam == 0 else rk4_reach(lam) / abs(lam)


def jacobian_step_limit(A) -> float:
    """RK4's largest stable step (s) on the linear flow ``dx/dt = A x``: the smallest
    :func:`mode_step_limit` over the eigenvalues of ``A``.

    Parameters
    ----------
    A : array_like
        The Jacobian (1/s), square.
    """
    return min((mode_step_limit(lam) for lam in np.linalg.eigvals(np.asarray(A, float))), default=math.inf)


class StepLimitWarning(UserWarning):
    """A fixed RK4 step above the stability limit of the model (the message names
    the limit, the mode and its growth per step)."""


@dataclass(frozen=True)
class StepLimit:
    """RK4's stability limit on a model, from the fastest eigenvalues of its Jacobian.

    Attributes
    ----------
    dt_max : float
        The largest stable step (s): the smallest over the points.
    eigenvalue : complex
        The mode that sets it (1/s).
    state : str
        The state that mode moves most (in units of each state's full scale).
    point : str
        Where (``at rest, no load``, ``held under 5 kN``, ...).
    points : tuple
        ``(point, dt_max, eigenvalue, state)`` for every point evaluated.
    """

    dt_max: float
    eigenvalue: complex
    state: str
    point: str
    points: tuple

    def growth(self, dt: float) -> float:
        """The largest ``|R(dt lambda)|`` over the points' limiting modes (> 1: the mode
        grows per step).

        Parameters
        ----------
        dt : float
            The step (s).
        """
        return max(rk4_growth(dt * lam) for _, _, lam, _ in self.points)

    def message(self, dt: float, label: str = "dt") -> str | None:
        """One line when ``dt`` is above the limit (None inside it).

        Parameters
        ----------
        dt : float
            The step (s).
        label : str
            The step's name in the line (``--dt``).
        """
        if dt <= self.dt_max * (1 + 1e-9):
            return None
        pt, lam, st = self.point, self.eigenvalue, self.state  # the limit's own point (ties: its first)
        return (f"{label} {dt:g} s is above RK4's stability limit {self.dt_max:.3g} s on this model (mode "
                f"{_complex(lam)} 1/s of {st}, {pt}: it grows x{rk4_growth(dt * lam):.3g} per step until a "
                f"nonlinearity bounds it, a chatter of {st}); use a step of at most {self.dt_max:.3g} s")

    def inside(self, periods=(), margin: float = DT_MARGIN, cap: float | None = None, lengths=()) -> float:
        """The largest step at most ``margin`` x :attr:`dt_max` (and ``cap``) that divides
        every period in ``periods`` (s; the ECU's sample periods): a round step (1,
        1.25, 2, 2.5 or 5 x 10^k s) or the fastest period over a whole number of steps;
        of those, one that also divides every length in ``lengths`` (s: a run's end and
        sample spacing) where one does.

        Parameters
        ----------
        periods : iterable of float
            Periods the step must divide (s).
        margin : float
            Fraction of the limit to stay under.
        cap : float, optional
            A largest step (s) on top of the limit.
        lengths : iterable of float
            Lengths the step should also divide where one of the steps does (s).
        """
        h = margin * self.dt_max if cap is None else min(cap, margin * self.dt_max)
        periods = sorted(float(T) for T in periods)
        fits = [dt for dt in _round_steps(h) if all(_whole(T / dt) for T in periods)]
        if periods:  # the fastest period over a whole number of steps
            dt = periods[0] / math.ceil(periods[0] / h - 1e-12)
            fits += [dt] if all(_whole(T / dt) for T in periods) else []
        whole = [dt for dt in fits if all(_whole(L / dt) for L in lengths)]
        return max(whole or fits) if fits else h


def _round_steps(h: float) -> list:
    """The round steps (1, 1.25, 2, 2.5, 5 x 10^k s) at most ``h``, six decades down."""
    e = math.floor(math.log10(h)) + 1
    return [float(f"{m}e{k}") for k in range(e, e - 6, -1) for m in (5, 2.5, 2, 1.25, 1)
            if float(f"{m}e{k}") <= h * (1 + 1e-12)]


def _whole(x: float) -> bool:
    return abs(x - round(x)) <= 1e-9 * max(1.0, abs(x))


def _complex(lam: complex) -> str:
    lam = complex(lam)
    if abs(lam.imag) <= 1e-9 * abs(lam):
        return f"{lam.real:.3g}"
    return f"{lam.real:.3g}{lam.imag:+.3g}j"


def _jacobian(model: Model, zoh: bool) -> ca.Function:
    """``(x, u, p) -> df/dx``: of ``f``, or with ``zoh`` of ``f_held`` at the hold an ECU
    update at that state gives."""
    key = ("step_limit_jacobian", zoh)
    if key not in model.cache:
        x = ca.SX.sym("x", model.nx)
        u = ca.SX.sym("u", model.nu)
        p = ca.SX.sym("p", len(model.param_names))
        if zoh and model.holds:
            # the hold an ECU update at x takes, fixed over the step: differentiate with it held
            h = ca.SX.sym("h", len(model.holds))
            hold = model.sample(x, u, p, ca.DM.zeros(len(model.holds)), ca.DM.ones(len(model.loops)))[1]
            A = ca.substitute(ca.jacobian(model.f_held(x, u, p, h)[0], x), h, hold)
        else:
            A = ca.jacobian(model.f(x, u, p)[0], x)
        model.cache[key] = ca.Function("step_limit_jacobian", [x, u, p], [A])
    return model.cache[key]


def _fastest(model: Model, A: np.ndarray, scale: np.ndarray, point: str) -> tuple:
    """``(point, dt_max, eigenvalue, state)`` of the mode with the smallest limit."""
    lam, V = np.linalg.eig(A)
    best = (point, math.inf, 0j, "")
    for j, lj in enumerate(lam):
        h = mode_step_limit(lj)
        if h < best[1]:
            w = np.abs(V[:, j]) / scale
            best = (point, float(h), complex(lj), model.states[int(np.argmax(w))])
    return best


def rk4_step_limit(model: Model, *, p=None, load: float = 0.0, zoh: bool = False) -> StepLimit:
    """RK4's stability limit on ``model`` (module docstring): the smallest step limit
    ``reach(angle(lambda)) / |lambda|`` over the eigenvalues of the model's Jacobian at
    rest without load and, for ``load`` > 0, held at rest under ``+-load`` (the rod on
    either flank). Cached on the model per parameter vector, load and ``zoh``.

    Parameters
    ----------
    model : Model
        The assembled model.
    p : array_like, optional
        Parameter vector (SI); default the model's set.
    load : float
        The run's largest load magnitude (N) on the model's load input.
    zoh : bool
        The sampled ECU (the held-input flow).
    """
    pv = np.asarray(model.p() if p is None else p, float)
    load = abs(float(load))
    key = ("step_limit", pv.tobytes(), load, bool(zoh))
    hit = model.cache.get(key)
    if hit is not None:
        return hit
    J = _jacobian(model, zoh)
    scale = np.maximum(np.abs(model.full_scale(pv)), 1e-300)
    x0, u0 = model.x0(), model.u(pv)
    points = [_fastest(model, np.array(J(x0, u0, pv)), scale, "at rest, no load")]
    if load > 0:
        points += _held(model, J, pv, load, scale)
    # the smallest limit; points within 1e-6 of it are ties (+-load are mirror images, and
    # which of the two comes out lower moves with the BLAS kernel in the last bits):
    # the first of them in the order above names the point
    h = min(q[1] for q in points)
    pt, _, lam, st = next(q for q in points if q[1] <= h * (1 + 1e-6))
    out = StepLimit(dt_max=h, eigenvalue=lam, state=st, point=pt, points=tuple(points))
    model.cache[key] = out
    return out


def _held(model: Model, J, pv, load: float, scale) -> list:
    """The points held at rest under +-load (the trims that exist)."""
    from ..linearisation import LinearizationError, operating_point

    out = []
    friction = "off" if model.hybrid else "smooth"
    for sign in (1.0, -1.0):
        try:
            with warnings.catch_warnings():  # the smooth-friction note concerns a linear model
                warnings.simplefilter("ignore")
                op = operating_point(model, f_ext=sign * load, backlash="keep", friction=friction, p=pv)
        except LinearizationError:
            continue
        out.append(_fastest(model, np.array(J(op.x, op.u, pv)), scale, f"held under {sign * load / 1e3:+.3g} kN"))
    return out


def peak_load(model: Model, sig: dict, t_end: float) -> float:
    """The largest magnitude of the model's load input over [0, t_end] (N; 0 without
    a load input), from 10001 samples of its signal.

    Parameters
    ----------
    model : Model
        The model (its ``load`` input).
    sig : dict
        Input name -> Signal of the run.
    t_end : float
        The run's end (s).
    """
    name = model.input_with("load")
    if name is None or name not in sig:
        return 0.0
    t = np.linspace(0.0, t_end, 10001)
    return float(np.max(np.abs(np.asarray(sig[name](t), float) * np.ones_like(t))))


def step_check(model: Model, dt: float, sig: dict, pv, zoh: bool, t_end: float, label: str = "dt",
               stacklevel: int = 3) -> StepLimit:
    """RK4's stability limit at a run's parameters and largest load; a
    :class:`StepLimitWarning` when ``dt`` is above it. Returns the limit.

    Parameters
    ----------
    model : Model
        The model.
    dt : float
        The run's step (s).
    sig : dict
        Its input signals by name.
    pv : ndarray
        Its parameter vector.
    zoh : bool
        The sampled ECU.
    t_end : float
        Its end (s).
    label : str
        The step's name in the warning.
    stacklevel : int
        The warning's stack level (the caller of the run).
    """
    limit = rk4_step_limit(model, p=pv, load=peak_load(model, sig, t_end), zoh=zoh)
    text = limit.message(dt, label)
    if text is not None:
        warnings.warn(text, StepLimitWarning, stacklevel=stacklevel)
    return limit


def fixed_step(model: Model, dt: float, sig: dict, pv, zoh: bool, t_end: float, check: bool = True):
    """A fixed-step run's (whether its steps split at the ECU's sampling instants,
    :func:`~ema_casadi.simulation.sampling_split`; RK4's stability limit or None,
    :func:`step_check`).

    Parameters
    ----------
    model, dt, sig, pv, zoh, t_end
        As in :func:`step_check`.
    check : bool
        Check the step against the stability limit.
    """
    from ._result import SimulationError
    from ._rk4 import sampling_split

    split = sampling_split(model, dt, pv, SimulationError) if zoh else False
    return split, step_check(model, dt, sig, pv, zoh, t_end, stacklevel=4) if check else None


def sample_periods(model: Model, pv=None) -> dict:
    """Loop name -> the ECU's sample period of that loop (s).

    Parameters
    ----------
    model : Model
        The model (its ``loops``).
    pv : ndarray, optional
        The parameter vector (default the model's).
    """
    pv = model.p() if pv is None else pv
    return {name: 1.0 / float(pv[model.param_names.index(loop.rate)]) for name, loop in model.loops.items()}


def default_step(model: Model, t_end, inputs, zoh: bool, dt_out=None, fixed: bool = True) -> float:
    """The RK4 step of a run without ``dt`` (:func:`~ema_casadi.simulation.simulate`,
    ``ema simulate``): :func:`inside_limit` at most :data:`DT_DEFAULT`, which is kept
    as it is where it is inside :data:`DT_MARGIN` x the limit (with ``zoh`` its steps
    split at the sample instants), ``t_end`` and ``dt_out`` the lengths it should
    divide. Not ``fixed`` (a variable-step solver runs), or a ``t_end`` that is not a
    positive number: DT_DEFAULT (the run's checks refuse it).

    Parameters
    ----------
    model : Model
        The model.
    t_end : float
        The run's end (s).
    inputs : callable
        ``() -> (given, pv)``: input name -> the value given (the undriven inputs take
        their defaults), and the parameter vector.
    zoh : bool
        The sampled ECU (a switched model's is always sampled).
    dt_out : float, optional
        The run's sample spacing (s).
    fixed : bool
        RK4 runs.
    """
    if not fixed or isinstance(t_end, bool) or not isinstance(t_end, (int, float)) or not 0 < t_end < math.inf:
        return DT_DEFAULT
    given, pv = inputs()
    lengths = (float(t_end),) + ((float(dt_out),) if isinstance(dt_out, (int, float)) and dt_out > 0 else ())
    return inside_limit(model, given, t_end, zoh, DT_DEFAULT, lengths, pv, keep_cap=True)


def inside_limit(model: Model, signals: dict, t_end: float | None, zoh: bool, cap: float = DT_DEFAULT, lengths=(),
                 pv=None, keep_cap: bool = False) -> float:
    """The one rule of every fixed-step default (a run's, a sweep's, a fault table's, a
    mission's, a limit cycle's, the exported simulators'): the largest step under
    :data:`DT_MARGIN` x RK4's stability limit on ``model`` at its parameters and the
    largest load of ``signals`` (:func:`rk4_step_limit`), at most ``cap`` (the use's
    own accuracy), dividing the ECU's sample periods with ``zoh`` (and ``lengths``
    where one does; :meth:`StepLimit.inside`).

    Parameters
    ----------
    model : Model
        The model.
    signals : dict
        Input name or role -> Signal or value of the run (a role the model lacks: left
        out; undriven inputs at their defaults).
    t_end : float or None
        The run's end (s); None: no load (the unloaded limit, the signals ignored).
    zoh : bool
        The sampled ECU.
    cap : float
        The largest step (s); default :data:`DT_DEFAULT`.
    lengths : iterable of float
        Lengths the step should divide (s: the run's end, its sample spacing).
    pv : ndarray, optional
        The parameter vector (default the model's).
    keep_cap : bool
        ``cap`` itself where it is inside the margin (it need not divide the sample
        periods: the steps are split at the instants).
    """
    pv = model.p() if pv is None else pv
    if t_end is None:
        limit = rk4_step_limit(model, p=pv, zoh=zoh)
    else:
        given = {model.input_name(k): v for k, v in signals.items() if k in model.inputs or model.inputs_with(k)}
        limit = _limit_at_peak(model, given, pv, t_end, zoh)
    if keep_cap and cap <= DT_MARGIN * limit.dt_max:
        return cap
    return limit.inside(sample_periods(model, pv).values() if zoh else (), DT_MARGIN, cap, tuple(lengths))


def _limit_at_peak(model: Model, given: dict, pv, t_end, zoh: bool) -> StepLimit:
    """RK4's stability limit at ``pv`` and the largest load of the run's inputs ``given``
    (input name -> value; the undriven ones at their defaults, without noise sequences)."""
    from ._inputs import input_signals

    sig = input_signals(model, given, pv)
    return rk4_step_limit(model, p=pv, load=peak_load(model, sig, float(t_end)), zoh=zoh)
