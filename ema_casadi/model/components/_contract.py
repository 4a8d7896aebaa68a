"""What a part declares for the analyses beyond its equations (the part contract):
small-signal policies, what the linearisation freezes, trim limits, trim seeds,
tunable gains and the faults a part can inject. The analyses read these through the model
(:class:`~ema_casadi.model.assembly.Model`), never a part's parameter names.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

__all__ = ["POLICIES", "Limit", "Rating", "RATING_SENSES", "Freeze", "Seed", "Gain", "Node", "node_outflow", "Fault"]


#: Small-signal policies of the linearisation: policy -> allowed values, first the
#: default. A part states what each value sets (:attr:`Part.small_signal`). Policies
#: the caller does not choose take their default (``quantisation = "off"``: a real
#: sensor's quantisation steps 0, so its reading has slope 1). ``switch_width``: a smooth
#: switch's width (``keep``, or the ``wide`` and ``wider`` widths a continuation of an
#: optimal move starts from: :mod:`ema_casadi.optimal._collocation`).
POLICIES = {"friction": ("off", "smooth"), "backlash": ("off", "keep"), "quantisation": ("off", "keep"),
            "screw_lock": ("off", "keep"), "switch_width": ("keep", "wide", "wider")}


@dataclass(frozen=True)
class Limit:
    """A saturation an operating point must keep inactive: ``value(y, P) < limit(P)``.

    The trim lifts it (multiplies the ``lift`` parameters by a large factor), trims,
    and refuses the point when the value reaches the limit (a load the current limit
    cannot hold, a speed above the rate limit): evaluated like a :class:`Bound`.

    Attributes
    ----------
    name : str
        Short name (``current``, ``rod_speed``, ``voltage``): :meth:`Model.limit_values`.
    what : str
        For the message ("current limit").
    symbol : str
        The limited quantity in the message (``i_q``, ``|v_dq|``).
    value : callable
        ``value(y, P) -> float``: the quantity (SI, >= 0) from the outputs by name and
        the numeric parameters.
    limit : callable
        ``limit(P) -> float``: its limit (SI).
    why : str
        The limit in the message ("I_max").
    lift : tuple of str
        Parameters whose product with a large factor lifts the saturation.
    unit : str
        Display unit of the message; ``scale`` converts SI to it.
    scale : float
        Display factor (1e3 for mm/s).
    holds_load : bool
        The message estimates the largest load held (value proportional to the load).
    digits : int
        Significant digits of the message's numbers.
    """

    name: str
    what: str
    symbol: str
    value: Callable
    limit: Callable
    why: str
    lift: tuple
    unit: str
    scale: float = 1.0
    holds_load: bool = False
    digits: int = 4


#: How a :class:`Rating` limits its signals: ``norm`` (the 2-norm of the signals, a
#: current or voltage vector), ``max`` (the one signal at most the limit), ``min`` (at least).
RATING_SENSES = ("norm", "max", "min")


@dataclass(frozen=True)
class Rating:
    """An operating limit a part declares: what the actuator may do in operation (the
    current limit, the voltage circle, the stroke, the rated rod speed), as opposed to a
    :class:`Bound` (beyond which a run is garbage). Optimal control takes the ratings as
    its constraints and checks its replay against them
    (:meth:`~ema_casadi.model.assembly.Model.operating_limits`).

    Attributes
    ----------
    name : str
        Short name (``current``, ``voltage``, ``stroke``, ``rod_speed``, ...).
    what : str
        For messages ("current limit").
    signals : tuple of str
        The limited states or outputs of the model (SI).
    limit : callable
        ``limit(P) -> float``: the limit (SI) from the numeric parameters.
    why : str
        The limit in messages ("I_max").
    unit : str
        SI unit of the signals and the limit.
    sense : str
        One of :data:`RATING_SENSES`: ``norm`` (``sqrt(sum s^2) <= limit``, written
        ``sum s^2 <= limit^2``, smooth at 0), ``max`` (``s <= limit``) or ``min`` (``s >= limit``).
    role : str
        What the limit is for an optimiser: ``rating`` (the actuator's own limit) or
        ``strategy`` (how its drive is run, e.g. no field weakening; an optimiser may be
        told to lift it).
    """

    name: str
    what: str
    signals: tuple
    limit: Callable
    why: str
    unit: str
    sense: str = "norm"
    role: str = "rating"


@dataclass(frozen=True)
class Freeze:
    """What the linearisation freezes to make a blend constant: inputs and parameters set
    from the value ``v`` of one output at the operating point (the screw-nut factor
    ``g_screw``: ``eta = 1/v``, ``eta_inv = v``, the thermal efficiency feedback off).

    Attributes
    ----------
    signal : str
        The output whose value at the point fixes the freeze.
    inputs, params : dict
        Input / parameter name -> ``fn(v) -> value`` (SI).
    nominal : callable, optional
        ``nominal(P) -> v``: the value to freeze at without an operating point (a guess
        of the small-signal model: the screw-nut factor driving the load, 1/eta), the
        value the inputs give at their defaults: only ``params`` are then set.
    """

    signal: str
    inputs: dict = field(default_factory=dict)
    params: dict = field(default_factory=dict)
    nominal: Callable | None = None


@dataclass(frozen=True)
class Seed:
    """Where a trim starts a state that the equations cannot find by Newton (a position
    inside a backlash gap, where the spring has no slope): trim first with the small-signal
    ``policy`` at ``"off"``, then move the state by ``offset(P, y)`` from that point.

    Attributes
    ----------
    policy : str
        The policy (of :data:`POLICIES`) whose ``"off"`` overrides the first trim takes.
    offset : callable
        ``offset(P, y) -> float``: the shift (state units) from the numeric parameters
        and the outputs of the first trim by name; 0 means no seed is needed.
    warn : callable, optional
        ``warn(P, y) -> str or None``: a warning about the trimmed point when the policy
        is not ``off`` (the nut inside the gap: the rod decoupled from the screw).
    """

    policy: str
    offset: Callable
    warn: Callable | None = None


@dataclass(frozen=True)
class Gain:
    """A controller gain a tuner may move (a flat parameter name).

    Attributes
    ----------
    name : str
        The parameter.
    loop : str
        The loop it acts in.
    kind : str
        ``gain`` (scales with a gain factor) or ``time`` (an integral time, kept).
    zero_scale : callable, optional
        For a gain that may start at zero: ``zero_scale(ref) -> float``, its natural
        size from the reference gains by name (then it is scaled linearly).
    """

    name: str
    loop: str
    kind: str = "gain"
    zero_scale: Callable | None = None


@dataclass(frozen=True)
class Node:
    """The thermal node a temperature state is (:attr:`State.node`).

    Attributes
    ----------
    name : str
        The node (one of ``HEAT_NODES``: ``winding``, ``housing``, ...).
    capacity : callable
        ``capacity(P) -> float``: its heat capacity (J/K).
    limit : callable
        ``limit(P) -> float``: the temperature it is rated for (degC), what a mission is
        judged against when its file names none.
    """

    name: str
    capacity: Callable
    limit: Callable


def node_outflow(node: str) -> str:
    """Bus name of the heat a thermal node passes on to its neighbours and the ambient (W):
    its heat input less C dT/dt. A part with temperature states provides it per node.

    Parameters
    ----------
    node : str
        The node (``winding``, ``housing``, ``screw``, ``inverter``).
    """
    return f"P_out_{node}"


@dataclass(frozen=True)
class Fault:
    """A fault a part can inject: the model input that activates it.

    The input is 0 (healthy) unless driven; a fault schedule drives it from the onset
    on with the severity (a step, or a ramp to it), so one model serves every case.

    Attributes
    ----------
    kind : str
        The fault kind (``jam``, ``free_run``, ``bias`` ...).
    input : str
        The model input that carries the fault's severity (0 when healthy).
    unit : str
        The severity's SI unit (what the input's value means).
    lo, hi : float
        The severity's allowed range (SI), inclusive.
    doc : str
        One line: what the fault does and what its severity is.
    target : str, optional
        The signal the fault acts on (sensor faults: the sensed signal), or None.
    rate : bool
        The severity is a rate (``unit`` per second): the input ramps from the onset
        (a drift) instead of stepping to the severity.
    requires : tuple
        ``(variant key, allowed values)`` pairs the fault means something with (the
        disconnect needs a screw with a coupling to shear: ``(("screw", ("elastic",)),)``);
        a fault file's case under other variants is refused.
    """

    kind: str
    input: str
    unit: str
    lo: float
    hi: float
    doc: str
    target: str | None = None
    rate: bool = False
    requires: tuple = ()

    def check_requires(self, variants: dict, where: str, error: type) -> None:
        """``error`` naming ``where`` unless the model's ``variants`` are what this fault
        needs (:attr:`requires`: a case that would run and mean nothing otherwise).

        Parameters
        ----------
        variants : dict
            The model's variant key -> value.
        where : str
            How to name the fault in the message (``"--input a_shear"``).
        error : type
            The exception raised.
        """
        for key, allowed in self.requires:
            if variants.get(key) not in allowed:
                raise error(f"{where}: a {self.kind} fault needs {key} = {' or '.join(allowed)}, the model has "
                            f"{key} = {variants.get(key)} ({self.doc})")

    def check(self, value: float, where: str, error: type, healthy: bool = False) -> float:
        """``value`` as a severity of this fault: within [lo, hi] (``healthy``: or 0, the
        input undriven), else ``error`` naming ``where``; the one range check of a
        severity, for a fault file's and a driven input's.

        Parameters
        ----------
        value : float
            The severity (SI, :attr:`unit`).
        where : str
            How to name it in the message (``"[[fault]] 1 severity"``, ``"a_jam"``).
        error : type
            The exception raised.
        healthy : bool
            Also accept 0 (the input's healthy value).
        """
        if not (self.lo <= value <= self.hi or (healthy and value == 0)):
            unit = "" if self.unit == "1" else f" {self.unit}"
            raise error(f"{where}: {value:g}{unit} is outside the range of a {self.kind} fault "
                        f"[{self.lo:g}, {self.hi:g}]{unit}")
        return value
