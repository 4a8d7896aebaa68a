"""Frequency response and stability margins of the linearised model (docs: linearise-margins).

Everything here works on NumPy ``A, B, C, D`` (a :class:`~ema_casadi.linearisation.LinearModel`
or a ``control.StateSpace`` - both carry those attributes), so margins come without
importing python-control.

Margins of a loop transfer L(s) (negative feedback, closed loop L/(1+L)) are taken
from its response on a dense log grid (default 0.01 Hz - 100 kHz, 200 points per
decade), every crossover bracketed on the grid and refined by SciPy's Brent method:

``pm_deg``
    The smallest phase rotation (lead or lag) that puts L on -1 at a gain crossover
    |L| = 1: min over crossovers of |wrap(angle L + 180 deg)|, >= 0. With several
    crossovers (the velocity and current loops with the outer loops closed have two)
    the smallest counts; every crossover is listed in ``gain_crossovers``.
``gm_db`` and ``gm_down_db``
    At each phase crossover (angle L = -180 deg mod 360) the gain change that puts L on
    -1 is 20 log10|L| dB away (listed as ``gain_db`` in ``phase_crossovers``). The gain
    margin ``gm_db`` is the smallest gain *rise* that does it (a crossover with
    |L| < 1), the gain-reduction margin ``gm_down_db`` the smallest gain *fall* (a
    crossover with |L| > 1: a conditionally stable loop). Both are >= 0, each with its
    frequency (``f_pc_hz``, ``f_down_hz``), +inf when there is no such crossover. No
    margin is reported as a negative number.
``disk_margin``
    Balanced (skew sigma = 0) disk margin alpha = 1/max_w |S - 1/2| = min_w 2|1+L|/|1-L|
    (Seiler, Packard & Gahinet, "An introduction to disk margins", IEEE Control
    Systems Magazine 40(5), 2020; python-control's ``disk_margins`` with skew 0): the
    loop tolerates any simultaneous gain and phase change f in the disk
    {(2 + alpha d)/(2 - alpha d) : |d| <= 1}, i.e. gains within +-``disk_gm_db`` or
    phases within +-``disk_pm_deg`` = 2 atan(alpha/2).
All margins assume the nominal closed loop is stable; ``stable`` says whether it is
(closed-loop eigenvalues; modes on the imaginary axis within round-off, like the rigid
screw's redundant shaft angle, count as neutral).

Arguments are checked first: a wrong type or value raises
:class:`~ema_casadi.linearisation.LinearizationError` naming it, and a frequency grid
above :data:`MAX_FREQ_POINTS` is refused with its memory estimate (the batched solve
holds n_f x n x (n + inputs) complex numbers: 26 GB for 2e7 frequencies of the 9-state
reference model).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from .._util._checks import describe, instance, number
from .._util._kwargs import check_keywords, keywords_of
from .._util._notebook import Summarised
from ..linearisation import (
    LOOPS,
    OUTER,
    LinearizationError,
    LinearModel,
    OperatingPoint,
    linear_model,
    loop_model,
    operating_point,
)
from ..model.assembly import Model
from ._grid import MAX_FREQ_POINTS, _frequencies, check_points, frequency_grid
from ._margins import _closed_loop_stable, _disk_margin, _gain_crossovers, _phase_crossovers, _root, _unwrap_deg

if TYPE_CHECKING:
    from collections.abc import Sequence

    import control
    from numpy.typing import ArrayLike

    from ..linearisation import LinearModel


__all__ = [
    "LoopMargins", "frequency_grid", "freqresp", "bode", "margins", "loop_margins",
    "closed_loop", "compliance", "dynamic_stiffness", "bandwidth", "modes", "check_points", "MAX_FREQ_POINTS",
]

REQUIREMENT = {"gm_db": 6.0, "pm_deg": 45.0}  # the usual requirement template

#: What ``**op_kwargs`` may name: the keywords of :func:`~ema_casadi.linearisation.operating_point`.
_OP_KEYWORDS = keywords_of(operating_point)


def _abcd(sys, name: str = "sys"):
    if isinstance(sys, tuple) and len(sys) == 4:
        sys = LinearModel(*sys, (), (), ())
    if not all(hasattr(sys, k) for k in "ABCD"):
        raise LinearizationError(f"{name}: expected a LinearModel or control.StateSpace (with A, B, C, D), "
                                 f"got {describe(sys)}")
    try:
        A, B, C, D = (np.atleast_2d(np.asarray(getattr(sys, k), float)) for k in "ABCD")
    except (TypeError, ValueError):
        raise LinearizationError(f"{name}: A, B, C, D must be numeric matrices") from None
    n = A.shape[0] if A.size else 0
    fits = D.shape == (C.shape[0], B.shape[1])
    if n:
        fits = fits and A.shape == (n, n) and B.shape[0] == n and C.shape[1] == n
    if not fits:
        raise LinearizationError(f"{name}: A, B, C, D do not fit together (shapes {A.shape}, {B.shape}, {C.shape}, "
                                 f"{D.shape})")
    return A, B, C, D


def freqresp(sys, f_hz) -> np.ndarray:
    """Complex response C (jwI - A)^-1 B + D, shape (n_outputs, n_inputs, n_freqs).

    Parameters
    ----------
    sys : LinearModel or control.StateSpace
        The system (its A, B, C, D are used).
    f_hz : array_like
        Frequencies (Hz).
    """
    A, B, C, D = _abcd(sys)
    f = _frequencies(f_hz, "f_hz", A.shape[0])
    n = A.shape[0] if A.size else 0
    if n == 0:
        return np.repeat(D[:, :, None].astype(complex), len(f), axis=2)
    M = (2j * np.pi * f)[:, None, None] * np.eye(n) - A
    X = np.linalg.solve(M, np.broadcast_to(B, (len(f),) + B.shape))
    H = C @ X + D
    return np.moveaxis(H, 0, 2)


def _siso(sys, what="the system", name="sys"):
    A, B, C, D = _abcd(sys, name)
    if B.shape[1] != 1 or C.shape[0] != 1:
        raise LinearizationError(f"{what} must be SISO (1 input, 1 output), has {B.shape[1]} inputs and "
                                 f"{C.shape[0]} outputs; pick a pair with input=/output=")
    return A, B, C, D


def bode(sys: LinearModel | control.StateSpace, f_hz: ArrayLike | None = None, *, input: str | None = None,
         output: str | None = None) -> dict:
    """Bode data of a SISO system or of one input/output pair (by name).

    Returns a dict with ``freq_hz``, ``mag_db`` (20 log10 |H|, in dB re the system's
    SI unit ratio), ``phase_deg`` (unwrapped, starting in (-180, 180] at the lowest
    frequency) and ``response`` (complex).

    Parameters
    ----------
    sys : LinearModel or control.StateSpace
        The system; SISO unless ``input`` or ``output`` picks a pair.
    f_hz : array_like, optional
        Frequencies (Hz); default 0.1 Hz - 2 kHz, 100 points per decade.
    input, output : str, optional
        Input and output names of the pair (default the first of each).
    """
    if input is not None or output is not None:
        sys = _select(sys, input, output)
    A = _siso(sys)[0]
    f = frequency_grid(0.1, 2e3, 100) if f_hz is None else _frequencies(f_hz, "f_hz", A.shape[0])
    H = freqresp(sys, f)[0, 0]
    return {"freq_hz": f, "mag_db": 20 * np.log10(np.abs(H)), "phase_deg": _unwrap_deg(H), "response": H}


def _select(sys, input, output):
    A, B, C, D = _abcd(sys)
    for label, name, names in (("input", input, getattr(sys, "inputs", getattr(sys, "input_labels", ()))),
                               ("output", output, getattr(sys, "outputs", getattr(sys, "output_labels", ())))):
        if name is not None and name not in list(names):
            raise LinearizationError(f"{label}: '{name}' is not an {label} of the system; it has "
                                     f"{', '.join(map(str, names)) or 'no names'}")
    if isinstance(sys, LinearModel):
        return sys.select([input] if input else None, [output] if output else None)
    ii = list(sys.input_labels).index(input) if input else 0
    oo = list(sys.output_labels).index(output) if output else 0
    return LinearModel(A, B[:, [ii]], C[[oo], :], D[[oo]][:, [ii]], (), (input,), (output,))


# ---------------------------------------------------------------------------------
@dataclass(repr=False)
class LoopMargins(Summarised):
    """Stability margins of one loop (see the module docstring for definitions).

    Frequencies in Hz, gains in dB, phases in degrees, delays in s.

    Attributes
    ----------
    loop : str
        Loop name.
    gm_db, f_pc_hz : float
        The (upper) gain margin: the smallest gain rise (dB, >= 0) that puts L on -1, at
        the phase crossover ``f_pc_hz`` (Hz); inf and None when the gain may rise without
        bound. Never negative: a loop that a gain *fall* destabilises has a
        gain-reduction margin instead.
    gm_down_db, f_down_hz : float
        The gain-reduction margin (lower gain margin): the smallest gain fall (dB, >= 0)
        that puts L on -1, at the phase crossover ``f_down_hz`` (Hz); inf and None for a
        loop that is not conditionally stable (no phase crossover where |L| > 1).
    pm_deg, f_gc_hz : float
        Phase margin (deg, >= 0): the smallest over every gain crossover of the phase
        rotation (either way) that puts L on -1, and that crossover (Hz, None without
        one).
    disk_margin : float
        Balanced disk margin alpha (-).
    disk_gm_db, disk_pm_deg : float
        The gain (dB) and phase (deg) variations the disk margin allows.
    f_disk_hz : float
        Frequency of the disk margin (Hz).
    delay_margin_s : float
        Smallest loop delay that destabilises (s).
    stable : bool
        Whether the nominal closed loop is stable.
    gain_crossovers : list of dict
        Every gain crossover (|L| = 1): ``f_hz``, ``phase_deg`` (angle of L, deg),
        ``pm_deg`` (>= 0, its phase margin) and ``lag_deg`` (the added phase lag that
        puts L on -1 there).
    phase_crossovers : list of dict
        Every phase crossover (L real negative): ``f_hz`` and ``gain_db`` (20 log10 |L|
        there: below 0 an upper gain margin of -gain_db, above 0 a gain-reduction
        margin of gain_db).
    outer : str
        ``closed`` or ``open``: how the other loops were taken (:func:`loop_margins`).
    """

    loop: str
    gm_db: float
    f_pc_hz: float | None
    pm_deg: float
    f_gc_hz: float | None
    disk_margin: float
    disk_gm_db: float
    disk_pm_deg: float
    f_disk_hz: float
    delay_margin_s: float
    stable: bool
    gain_crossovers: list = field(default_factory=list)   # [{"f_hz", "phase_deg", "pm_deg", "lag_deg"}]
    phase_crossovers: list = field(default_factory=list)  # [{"f_hz", "gain_db"}]
    outer: str = "closed"
    gm_down_db: float = math.inf
    f_down_hz: float | None = None

    def _facts(self) -> dict:
        return {"loop": self.loop, "gm": f"{self.gm_db:.3g} dB", "pm": f"{self.pm_deg:.3g} deg",
                "disk": f"{self.disk_margin:.3g}", "stable": self.stable, "outer": self.outer}

    @property
    def conditionally_stable(self) -> bool:
        """A phase crossover where |L| > 1: a gain reduction would destabilise the loop."""
        return math.isfinite(self.gm_down_db)

    def meets(self, gm_db: float = REQUIREMENT["gm_db"], pm_deg: float = REQUIREMENT["pm_deg"]) -> bool:
        """Stable, with the gain margin and the gain-reduction margin both >= gm_db (every
        phase crossover) and PM >= pm_deg at every gain crossover.

        Parameters
        ----------
        gm_db : float
            Required gain margin (dB).
        pm_deg : float
            Required phase margin (deg).
        """
        return bool(self.stable and self.gm_db >= gm_db and self.gm_down_db >= gm_db and self.pm_deg >= pm_deg)

    def as_dict(self) -> dict:
        d = asdict(self)
        d["meets_requirement"] = self.meets()
        d["conditionally_stable"] = self.conditionally_stable
        return d


def margins(L: LinearModel | control.StateSpace, *, f_min: float = 1e-2, f_max: float = 1e5, per_decade: int = 200,
            loop: str = "") -> LoopMargins:
    """Gain, phase, delay and disk margins of a SISO loop transfer L (negative feedback).

    Parameters
    ----------
    L : LinearModel or control.StateSpace
        Loop transfer at the break (e.g. :func:`~ema_casadi.linearisation.loop_model`).
    f_min, f_max : float
        Frequency window searched for crossovers (Hz); crossovers outside it (the
        spurious ones python-control finds near 0 Hz and ~1e9 Hz) are not considered.
    per_decade : int
        Grid density for bracketing.
    loop : str
        Label stored in the result.
    """
    A, B, C, D = _siso(L, "the loop transfer", "L")
    if not isinstance(loop, str):
        raise LinearizationError(f"loop: expected a label (str), got {describe(loop)}")
    d = float(D[0, 0])
    eye = np.eye(A.shape[0])

    def H(f):
        return complex((C @ np.linalg.solve(2j * np.pi * f * eye - A, B))[0, 0] + d)

    f = frequency_grid(f_min, f_max, per_decade)
    Hg = freqresp((A, B, C, D), f)[0, 0]
    gcs, pcs = _gain_crossovers(H, f, Hg), _phase_crossovers(H, f, Hg)
    stable = _closed_loop_stable(A, B, C, d)
    if gcs:
        best = min(gcs, key=lambda c: c["pm_deg"])
        pm, f_gc = best["pm_deg"], best["f_hz"]
        delay = min(math.radians(c["lag_deg"]) / (2 * math.pi * c["f_hz"]) for c in gcs)
    else:
        pm, f_gc, delay = math.inf, None, math.inf
    up = min((c for c in pcs if c["gain_db"] < 0), key=lambda c: -c["gain_db"], default=None)
    down = min((c for c in pcs if c["gain_db"] >= 0), key=lambda c: c["gain_db"], default=None)
    alpha, f_dm = _disk_margin(H, f, Hg) if stable else (0.0, _disk_margin(H, f, Hg)[1])
    dgm = 20 * math.log10((2 + alpha) / (2 - alpha)) if alpha < 2 else math.inf
    dpm = math.degrees(2 * math.atan(alpha / 2))
    return LoopMargins(
        loop=loop, gm_db=-up["gain_db"] if up else math.inf, f_pc_hz=up["f_hz"] if up else None, pm_deg=pm,
        f_gc_hz=f_gc, disk_margin=alpha,
        disk_gm_db=dgm, disk_pm_deg=dpm, f_disk_hz=f_dm, delay_margin_s=delay, stable=stable,
        gain_crossovers=gcs, phase_crossovers=pcs,
        gm_down_db=down["gain_db"] if down else math.inf, f_down_hz=down["f_hz"] if down else None,
    )


def loop_margins(
    model: Model,
    op: OperatingPoint | None = None,
    loops: str | Sequence[str] = "all",
    *,
    outer: str = "closed",
    f_min: float = 1e-2,
    f_max: float = 1e5,
    per_decade: int = 200,
    **op_kwargs,
) -> dict[str, LoopMargins]:
    """Margins at the position, velocity and current loop breaks.

    Parameters
    ----------
    model : Model
        The assembled model.
    op : OperatingPoint, optional
        Default :func:`~ema_casadi.linearisation.operating_point` ``(model, **op_kwargs)``.
    loops : "all", a loop name or a sequence of them
        The loop breaks.
    outer : {"closed", "open"}
        Other loops closed (loop-at-a-time, default) or the outer ones opened.
    f_min, f_max, per_decade
        Crossover search window (Hz) and grid (points per decade), see :func:`margins`.
    **op_kwargs
        Arguments of :func:`~ema_casadi.linearisation.operating_point` when ``op`` is not
        given (``x_cmd`` in m, ``f_ext`` in N, ``v_rod`` in m/s, ``friction``, ...); an
        unknown keyword raises TypeError.
    """
    check_keywords("loop_margins", op_kwargs, _OP_KEYWORDS)
    _model_op(model, op)
    if outer not in OUTER:
        raise LinearizationError(f"outer: expected one of {', '.join(OUTER)}, got {describe(outer)}")
    frequency_grid(f_min, f_max, per_decade)  # checks the window before the trim
    if not (loops == "all" or isinstance(loops, str) or (isinstance(loops, (list, tuple))
                                                          and all(isinstance(n, str) for n in loops))):
        raise LinearizationError(f"loops: expected 'all', a loop name or a list of them ({', '.join(LOOPS)}), "
                                 f"got {describe(loops)}")
    if op is None:
        op, op_kwargs = operating_point(model, **op_kwargs), {}
    names = list(model.loops) if loops == "all" else ([loops] if isinstance(loops, str) else list(loops))
    out = {}
    for name in names:
        L = loop_model(model, name, op, outer=outer, **op_kwargs)  # op and op_kwargs both: refused there
        m = margins(L, f_min=f_min, f_max=f_max, per_decade=per_decade, loop=name)
        m.outer = outer
        out[name] = m
    return out


# ---------------------------------------------------------------------------------
def closed_loop(model: Model, op: OperatingPoint | None = None, **op_kwargs) -> LinearModel:
    """Closed-loop x_rod/x_cmd (m/m) as a SISO :class:`LinearModel`.

    Parameters
    ----------
    model : Model
        The assembled model.
    op : OperatingPoint, optional
        Default :func:`~ema_casadi.linearisation.operating_point` ``(model, **op_kwargs)``.
    **op_kwargs
        Arguments of :func:`~ema_casadi.linearisation.operating_point` when ``op`` is not
        given (``x_cmd`` in m, ``f_ext`` in N, ``v_rod`` in m/s, ``friction``, ...); an
        unknown keyword raises TypeError.
    """
    check_keywords("closed_loop", op_kwargs, _OP_KEYWORDS)
    _model_op(model, op)
    lin = linear_model(model, op, inputs=[model.input_with("command")], outputs=[model.output_with("rod_position")],
                       **op_kwargs)
    lin.name = "T_x"
    return lin


def compliance(model: Model, op: OperatingPoint | None = None, **op_kwargs) -> LinearModel:
    """Closed-loop x_rod/f_ext (m/N) as a SISO :class:`LinearModel` (negative at low
    frequency: a positive force pushes the rod in).

    Parameters
    ----------
    model : Model
        The assembled model.
    op : OperatingPoint, optional
        Default :func:`~ema_casadi.linearisation.operating_point` ``(model, **op_kwargs)``.
    **op_kwargs
        Arguments of :func:`~ema_casadi.linearisation.operating_point` when ``op`` is not
        given (``x_cmd`` in m, ``f_ext`` in N, ``v_rod`` in m/s, ``friction``, ...); an
        unknown keyword raises TypeError.
    """
    check_keywords("compliance", op_kwargs, _OP_KEYWORDS)
    _model_op(model, op)
    lin = linear_model(model, op, inputs=[model.input_with("load")], outputs=[model.output_with("rod_position")],
                       **op_kwargs)
    lin.name = "compliance"
    return lin


def dynamic_stiffness(model: Model, op: OperatingPoint | None = None, f_hz: ArrayLike | None = None,
                      **op_kwargs) -> dict:
    """Dynamic stiffness K = -f_ext/x_rod (N/m) of the closed loop.

    Returns a dict with ``freq_hz``, ``stiffness`` (complex, N/m), ``magnitude`` (N/m),
    ``mag_db`` (dB re 1 N/m) and ``phase_deg``.

    Parameters
    ----------
    model : Model
        The assembled model.
    op : OperatingPoint, optional
        Default :func:`~ema_casadi.linearisation.operating_point` ``(model, **op_kwargs)``.
    f_hz : array_like, optional
        Frequencies (Hz); default 0.1 Hz - 2 kHz, 100 points per decade.
    **op_kwargs
        Arguments of :func:`~ema_casadi.linearisation.operating_point` when ``op`` is not
        given (``x_cmd`` in m, ``f_ext`` in N, ``v_rod`` in m/s, ``friction``, ...); an
        unknown keyword raises TypeError.
    """
    check_keywords("dynamic_stiffness", op_kwargs, _OP_KEYWORDS)
    _model_op(model, op)
    f = frequency_grid(0.1, 2e3, 100) if f_hz is None else _frequencies(f_hz, "f_hz", model.nx)
    G = compliance(model, op, **op_kwargs)
    K = -1.0 / freqresp(G, f)[0, 0]
    return {"freq_hz": f, "stiffness": K, "magnitude": np.abs(K), "mag_db": 20 * np.log10(np.abs(K)),
            "phase_deg": _unwrap_deg(K)}


def bandwidth(sys, level_db: float = -3.0, f_min: float = 1e-2, f_max: float = 1e5) -> float:
    """Lowest frequency (Hz) at which |H| falls to ``level_db`` below its value at f_min
    (refined between grid points); inf if it never does.

    Parameters
    ----------
    sys : LinearModel or control.StateSpace
        A SISO system.
    level_db : float
        The level relative to the low-frequency gain (dB).
    f_min, f_max : float
        Search window (Hz).
    """
    _siso(sys)
    # a level above the low-frequency gain is never "fallen to": no bandwidth, not a NaN
    level_db = number(level_db, "level_db", LinearizationError, unit="dB below the low-frequency gain",
                      negative=True)
    f = frequency_grid(f_min, f_max, 200)
    db = 20 * np.log10(np.abs(freqresp(sys, f)[0, 0]))
    m = db - db[0] - level_db
    idx = np.nonzero(m[:-1] * m[1:] <= 0)[0]
    if not len(idx):
        return math.inf
    i = idx[0]
    lf = np.log10(f)
    x = _root(lambda t: 20 * math.log10(abs(freqresp(sys, [10**t])[0, 0, 0])) - db[0] - level_db,
                      lf[i], lf[i + 1], m[i], m[i + 1])
    return 10**x


def _model_op(model, op) -> None:
    """LinearizationError unless ``model`` is a Model and ``op`` None or an OperatingPoint."""
    instance(model, Model, "model", LinearizationError, " (from build_model)")
    if op is not None:
        instance(op, OperatingPoint, "op", LinearizationError, " (from operating_point)")


def modes(sys) -> list[dict]:
    """Oscillatory modes of A: natural frequency (Hz) and damping ratio, one per pair,
    sorted by frequency.

    Parameters
    ----------
    sys : LinearModel or control.StateSpace
        The system (its A is used).
    """
    lam = np.linalg.eigvals(_abcd(sys)[0])
    out = []
    for z in lam[lam.imag > 0]:
        wn = abs(z)
        out.append({"f_n_hz": wn / (2 * np.pi), "zeta": -z.real / wn, "f_d_hz": z.imag / (2 * np.pi)})
    return sorted(out, key=lambda m: m["f_n_hz"])
