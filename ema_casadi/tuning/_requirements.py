"""What a tuning request asks for: the tunable gains, the requirements, their
exclusion disk, and the validation of a request (one-line :class:`TuneError`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .._util._checks import nearest
from .._util._errors import InputError
from ..model.assembly import Model
from ..model.components import PART_CLASSES, REGISTRY, served_by
from ..model.params import Parameters


def _declared_gains() -> dict:
    """Every gain a registered part declares (name -> Gain), in each part's order: a gain
    new to the list goes right after the one before it in its part (outer loop first)."""
    order: list = []
    info: dict = {}
    for cls in PART_CLASSES:  # the registry's parts, those they bring (the current controllers), their forms
        prev = None
        for g in cls.gains:
            if g.name not in info:
                info[g.name] = g
                order.insert(order.index(prev) + 1 if prev else len(order), g.name)
            prev = g.name
    return {n: info[n] for n in order}


#: Tunable gains (flat parameter names), as the parts declare them: name -> Gain.
GAIN_INFO = _declared_gains()
#: Tunable gains (flat parameter names, the physics reference's symbols).
GAINS = tuple(GAIN_INFO)


def _where(gain: str) -> str:
    """The variants whose parts declare a gain ("controller=PI")."""
    return " or ".join(f"{k}={v}" for k, values in REGISTRY.items() for v, cls in values.items()
                       if any(g.name == gain for c in served_by(cls) for g in c.gains))
OBJECTIVES = ("bandwidth", "tracking")


class TuneError(InputError, ValueError):
    """A tuning request cannot be served (unknown gain, bad requirement, a load the
    actuator cannot hold). The one-line message names the option."""


@dataclass(frozen=True)
class Requirements:
    """What the tuned loops must satisfy, in every load case.

    Attributes
    ----------
    gm_db : float
        Gain margin of every loop (dB), either direction.
    pm_deg : float
        Phase margin of every loop (deg).
    ms : float or None
        If given, the sensitivity-peak bound |1 + L| >= 1/ms replaces the GM/PM disk;
        the verification then checks the peak and the margins it implies
        (:meth:`margin_targets`).
    overshoot : float
        Largest overshoot of x_rod in the step response (fraction, 0.05 = 5 %).
    bandwidth_min_hz : float or None
        Closed-loop x_rod/x_cmd at least -3 dB up to this frequency (Hz).
    sigma : float
        Closed-loop eigenvalues left of -sigma (1/s).
    step : float
        Step amplitude (m) of the response that must stay inside the current and
        voltage limits.
    t_step : float
        Horizon of the step response (s).
    rate_ratio : float
        Loop gain below 1 above (ECU sample rate)/rate_ratio; 0 switches it off.
    separation : float
        Loop separation of the cascade: each inner loop's gain crossover, with its outer
        loops open, at least ``separation`` times the next outer loop's (default 3; 0
        switches it off). With its outer loops open every loop must also be
        unconditionally stable with the margins: every gain crossover at least PM away
        from -1 and, at every phase crossover, |L| <= 10^(-GM/20) (no lower gain margin).
    sensor_noise : float
        Amplitude (m) of the position-sensor noise the current command must not amplify
        beyond ``command_noise`` (default 1 um, the resolution of a linear position
        sensor on this stroke).
    command_noise : float
        Largest current-command amplitude that ``sensor_noise`` may cause at any
        frequency, as a fraction of I_max (default 0.005: 0.12 A for 24 A): the peak of
        |i_cmd / n_x| (closed loop, A/m) is bounded by command_noise I_max / sensor_noise.
        0 switches the bound off.
    """

    gm_db: float = 6.0
    pm_deg: float = 45.0
    ms: float | None = None
    overshoot: float = 0.05
    bandwidth_min_hz: float | None = None
    sigma: float = 0.0
    step: float = 1e-4
    t_step: float = 0.2
    rate_ratio: float = 10.0
    separation: float = 3.0
    sensor_noise: float = 1e-6
    command_noise: float = 0.005

    def check(self) -> None:
        """Raise :class:`TuneError` naming the first invalid field."""
        def bad(name, what):
            raise TuneError(f"{name} must be {what}, got {getattr(self, name)!r}")

        for name in ("gm_db", "pm_deg", "overshoot", "sigma", "rate_ratio", "separation", "command_noise"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                bad(name, "a non-negative number")
        if self.gm_db <= 0:
            bad("gm_db", "positive (dB)")
        if not 0 < self.pm_deg < 90:
            bad("pm_deg", "between 0 and 90 deg")
        if self.ms is not None and not (math.isfinite(self.ms) and self.ms > 1):
            bad("ms", "a number above 1")
        bw = self.bandwidth_min_hz
        if bw is not None and not (math.isfinite(bw) and bw > 0):
            bad("bandwidth_min_hz", "a positive frequency (Hz)")
        for name in ("step", "t_step"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                bad(name, "positive")
        if 0 < self.rate_ratio < 1:
            bad("rate_ratio", "0 (off) or at least 1")
        if 0 < self.separation < 1:
            bad("separation", "0 (off) or at least 1")
        if not (isinstance(self.sensor_noise, (int, float)) and math.isfinite(self.sensor_noise)
                and self.sensor_noise > 0):
            bad("sensor_noise", "a positive length (m)")

    def noise_gain_max(self, i_limit: float) -> float | None:
        """Bound (A/m) on the peak gain from position-sensor noise to the current command,
        command_noise I_max / sensor_noise, or None when switched off.

        Parameters
        ----------
        i_limit : float
            Current limit I_max (A) of the model.
        """
        return self.command_noise * i_limit / self.sensor_noise if self.command_noise > 0 else None

    def margin_targets(self) -> tuple[float, float]:
        """(GM dB, PM deg) every loop must reach: the requested ones, or with ``ms`` the
        ones the sensitivity bound implies, 20 log10(Ms/(Ms-1)) and 2 asin(1/(2 Ms))."""
        if self.ms is None:
            return self.gm_db, self.pm_deg
        return 20 * math.log10(self.ms / (self.ms - 1)), math.degrees(2 * math.asin(1 / (2 * self.ms)))

    def as_dict(self) -> dict:
        """The fields as a plain dict (SI units, as the attributes)."""
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


def exclusion_disk(req: Requirements) -> tuple[float, float]:
    """Centre -c and radius R of the disk the loop transfer must stay out of.

    See :mod:`ema_casadi.tuning`: the disk through -10^(-GM/20) and -e^(+-j PM), or the
    sensitivity disk (c = 1, R = 1/Ms) when ``req.ms`` is given.

    Parameters
    ----------
    req : Requirements
        The margins (``gm_db`` in dB, ``pm_deg`` in deg) or the sensitivity peak ``ms``.

    Returns
    -------
    c, R : float
        Centre -c and radius R of the disk in the complex plane (dimensionless, as L).
    """
    if req.ms is not None:
        return 1.0, 1.0 / req.ms
    a = 10 ** (-req.gm_db / 20)
    cphi = math.cos(math.radians(req.pm_deg))
    if cphi > a:
        c = (1 - a * a) / (2 * (cphi - a))
    else:
        c = 1 / cphi
    return c, math.sqrt(c * c - 2 * c * cphi + 1)


def default_free(model: Model) -> tuple[str, ...]:
    """All gains that act in this variant: those a part of the model uses (``K_i_x`` only
    with the PI position loop).

    Parameters
    ----------
    model : Model
        The assembled model; its parts declare the parameters they use.
    """
    return tuple(g.name for g in model.gains)


def scaled_gains(params: Parameters, factor: float, free=None) -> dict[str, float]:
    """Gains ``factor`` times the set's: K_x, K_i_x, K_p_w, K_p_i, K_i_i scale, the speed
    loop's integral time T_i_w stays (so its integral gain K_p_w/T_i_w scales too).

    Parameters
    ----------
    params : Parameters
        The set whose gains are scaled (SI: K_x 1/s, K_i_x 1/s^2, K_p_w A s/rad,
        T_i_w s, K_p_i V/A, K_i_i V/(A s)).
    factor : float
        Scale factor (dimensionless).
    free : sequence of str, optional
        Gains to return (default all of :data:`GAINS`).
    """
    d = params.as_dict()
    names = [g for g in GAINS if free is None or g in free]
    return {g: d[g] if GAIN_INFO[g].kind == "time" else factor * d[g] for g in names}


def _load_label(f: float) -> str:
    return f"{f / 1e3:g} kN"


def _goal(requirements: Requirements | None, objective: str) -> Requirements:
    """The checked requirements (default :class:`Requirements`); the objective checked."""
    req = requirements or Requirements()
    req.check()
    if objective not in OBJECTIVES:
        raise TuneError(f"objective '{objective}' unknown; choose one of {', '.join(OBJECTIVES)}")
    return req


def _request(model: Model, params: Parameters, free, loads, start, freqs):
    """Checked and completed (free, loads, start, freqs) of a request: the free gains
    (default :func:`default_free`), the load cases (N) as floats, the start value of
    every free gain (default the set's) and the frequency grid (Hz, default 0.5 Hz -
    10 kHz, 14 per decade)."""
    free = tuple(default_free(model) if free is None else free)
    if not free:
        raise TuneError("no free gain: name at least one of " + ", ".join(GAINS))
    for g in free:
        if g not in GAINS:
            raise TuneError(f"'{g}' is not a tunable gain{nearest(g, GAINS)}; choose from {', '.join(GAINS)}")
        if g not in {x.name for x in model.gains}:
            raise TuneError(f"{g} acts in no part of this model (it acts only with {_where(g)})")
    if len(set(free)) != len(free):
        raise TuneError("a gain is named twice in free")
    loads = [float(f) for f in loads]
    if not loads or not all(math.isfinite(f) for f in loads):
        raise TuneError("loads must be one or more finite forces (N)")
    d = params.as_dict()
    start = {g: float(d[g]) for g in free} | {k: float(v) for k, v in (start or {}).items() if k in free}
    for k in start:
        if not math.isfinite(start[k]) or start[k] < 0:
            raise TuneError(f"start value of {k} must be a non-negative number, got {start[k]}")
    freqs = np.logspace(math.log10(0.5), 4, 61) if freqs is None else np.asarray(freqs, float)
    return free, loads, start, freqs
