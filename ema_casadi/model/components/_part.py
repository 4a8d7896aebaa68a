"""What a component variant declares, and the signal bus the assembly wires parts with.

A *part* is one variant of one component family (``screw = "elastic"``). It declares
what it brings, next to its equations (motulator's ``States/Inputs/Outputs``, PyBaMM's
submodels):

- :class:`State` entries (name, unit, roles, initial value, full scale),
- the model :class:`Input` entries it reads,
- its :class:`Output` entries (name, unit, kind, one-line meaning),
- the parameters it uses (flat names of :class:`~ema_casadi.model.params.Parameters`),
- control :class:`Loop` entries it closes and the controller outputs it :class:`Hold`\\ s
  between ECU samples,
- contributions to summed signals (stored energy, the load on the rod),
- what the analyses need to know about it (the part contract):
  its small-signal policies (:attr:`Part.small_signal`), what the linearisation freezes
  (:class:`Freeze`), the saturations a trim must keep inactive (:class:`Limit`), how a
  memory state is trimmed (:attr:`State.rest`, :class:`Seed`), the gains a tuner may
  move (:class:`Gain`),
- the physical envelope of what it brings: a :class:`Bound` on a state, input or output
  (``|value| <= bound(P)``), and named envelope ``limits`` that other parts may widen
  (the end stop widens the rod's ``overtravel``); every simulation is checked
  against it (:meth:`~ema_casadi.model.assembly.Model.envelope`),

and a :meth:`Part.signals` table of *providers*: functions of the :class:`Bus` that
return one signal (or several at once). The bus resolves a signal on demand, by name,
so parts never call each other and the assembly never needs to know in which order to
evaluate them; a circular dependency is reported as an algebraic loop.

A state's derivative is the signal ``der(NAME)`` (see :func:`der`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from types import SimpleNamespace
from typing import ClassVar

from ..._util._errors import InputError
from ._contract import POLICIES, RATING_SENSES, Fault, Freeze, Gain, Limit, Node, Rating, Seed, node_outflow

__all__ = [
    "State", "Input", "Output", "Loop", "Hold", "Bound", "Limit", "Rating", "RATING_SENSES", "Freeze",
    "Gain", "Seed", "Fault", "Part", "Bus",
    "AssemblyError", "der", "POLICIES", "Node", "node_outflow",
    "OUTPUT_KINDS", "INPUT_KINDS", "INPUT_ROLES", "OUTPUT_ROLES", "SIGNAL_KEYS", "MARGIN", "HEAT_NODES", "heat_signal",
]

#: Output kinds: ``signal`` (a physical signal, linearised by default), ``loss``
#: (power dissipated, W), ``power`` (power through a port, W), ``energy`` (J), ``flag``
#: (a mode indicator), ``aux`` (an internal quantity exposed for analyses) and ``alarm``
#: (an ECU monitor's latch: 0 healthy, rising to 1 when it latches; detected at 1/2),
#: ``statistic`` (what a monitor compares with its threshold: the condition holds at
#: statistic >= threshold, the parameter ``Output.threshold`` names).
OUTPUT_KINDS = ("signal", "loss", "power", "energy", "flag", "aux", "alarm", "statistic")

#: Roles of model inputs, what analyses ask the model for: the rod command, the external load
#: on the rod, the screw efficiency, the ambient temperature, the pitch-attitude command, the gust.
INPUT_ROLES = ("command", "load", "efficiency", "ambient_temperature", "attitude_command", "gust")
#: Roles of model outputs: rod position and velocity, motor speed and current, the screw force;
#: the nut position, the speed loop's current command, the winding voltages (d and q axes),
#: the hybrid friction's stuck flag; powers (to the load, drawn from the supply, heat to the
#: ambient) and energies (stored mechanically and magnetically, stored as heat); the
#: temperature-dependent winding resistance, magnet flux and screw efficiency; behind an
#: airframe the rod command it gives, its law's rod and elevator commands, the elevator, the
#: surface load on the rod and the normal load factor; a surface driven by several
#: actuators: its angle, each attachment's force and the force fight between two channels.
OUTPUT_ROLES = ("rod_position", "rod_velocity", "motor_speed", "motor_current", "screw_force",
                "nut_position", "current_command", "d_voltage", "q_voltage", "stuck",
                "load_power", "electrical_power", "ambient_heat", "stored_energy", "thermal_energy",
                "winding_resistance", "magnet_flux", "screw_efficiency",
                "rod_command", "law_command", "elevator_command", "elevator", "surface_load", "load_factor",
                "surface_angle", "attachment_force", "force_fight")

#: The key under which a role's signal is written in files, flags and reports (the CLI
#: contract: a mission segment's ``x_cmd``, a sweep scenario's ``f_ext``, a trim's JSON
#: ``v_rod``, a record's ``x_rod`` column): the reference model's names, written here once.
#: Analyses read a key from this table and ask the model for the signal by role
#: (:meth:`~ema_casadi.model.Model.input_with`), so a model whose load is another input
#: still reads the file's ``f_ext``.
SIGNAL_KEYS = {
    "command": "x_cmd", "load": "f_ext", "efficiency": "eta", "ambient_temperature": "T_amb",
    "attitude_command": "theta_cmd", "gust": "w_g",
    "rod_position": "x_rod", "rod_velocity": "v_rod", "motor_current": "i_q",
}

#: Quantity kinds of model inputs, as understood by the signal parser.
INPUT_KINDS = ("length", "force", "dimensionless", "angular_velocity", "current", "temperature", "angle", "rate")

#: Thermal nodes a loss can heat (docs: physics): every ``loss`` output names one in its
#: part's :attr:`Part.heat`, and the assembly sums them into :func:`heat_signal` per node.
HEAT_NODES = ("winding", "housing", "screw", "inverter")


def heat_signal(node: str) -> str:
    """Bus name of the summed heat flow (W) into a thermal node (:data:`HEAT_NODES`).

    Parameters
    ----------
    node : str
        The node (``winding``, ``housing``, ``screw``, ``inverter``).
    """
    return f"P_heat_{node}"


#: Factor between what the actuator can do and its physical envelope (:class:`Bound`):
#: generous enough for any manoeuvre within its ratings, tight enough that a run
#: beyond it (a current no winding survives, a back-EMF far above the DC link) is
#: garbage, not a result.
MARGIN = 3.0


class AssemblyError(InputError, ValueError):
    """Parts that do not fit together (a signal nobody provides, an algebraic loop,
    two parts declaring one name differently)."""


def der(name: str) -> str:
    """Bus name of the time derivative of state ``name``.

    Parameters
    ----------
    name : str
        State name.
    """
    return f"der({name})"


@dataclass(frozen=True)
class Bound:
    """The physical envelope of one signal: ``|value| <= limit(E)``.

    A run whose signal leaves it is reported as failed, never as a result (the reliability contract, docs: reliability).
    Bounds are generous (a few times what the actuator can do), so they catch
    garbage — a rod running away, a current no winding survives — not a demanding
    but physical manoeuvre.

    Attributes
    ----------
    limit : callable
        ``limit(E) -> float`` (SI, the signal's unit), from the numeric parameters and
        the model's envelope limits (``E.stroke``, ``E.overtravel``, ...; see
        :attr:`Part.limits`).
    why : str
        What the bound is, for the failure message ("3 x I_max").
    """

    limit: Callable
    why: str


@dataclass(frozen=True)
class State:
    """A state a part brings.

    Attributes
    ----------
    name, unit, doc : str
        Name (the physics reference's symbol), SI unit, one-line meaning.
    roles : tuple of str
        What analyses may ask the model for: ``rod_position``, ``rod_velocity``,
        ``shaft_angle``, ``shaft_speed``, ``contact_velocity`` (the velocity at the
        friction contact), ``current``, ``controller_integral``, ``play`` (a memory
        element without dynamics of its own), ``temperature`` (a thermal node, degC),
        ``hysteresis`` (a rate-independent memory whose rate switches with the sign of a
        speed and saturates at its band's edges: the screw's self-locking memory).
    x0 : float
        Initial value (SI; temperatures in degC).
    scale : callable
        ``scale(P) -> float``: full-scale magnitude (SI) from the numeric parameters,
        used to judge residuals and steps.
    travel : callable, optional
        ``travel(P) -> float``: rod travel (m) per unit of this state, for position-like
        states (rod position 1, shaft angle p/2pi); trims start from the command and
        move at the commanded rod speed through it.
    loop : str, optional
        For controller integrators: the loop whose ECU sample period integrates it.
    bound : Bound, optional
        Its physical envelope (None: only checked to be finite).
    rest : str, optional
        A memory element without restoring dynamics of its own (a play, a friction
        bristle): the trim holds it at the value of this signal (one more trim equation,
        the state equal to the signal, and the state set exactly to it after); the
        signal is an output of the model.
    rest_when : callable, optional
        ``rest_when(P) -> bool``: when the ``rest`` rule applies (default always; the
        play only without backlash, where its edges meet).
    neutral : bool
        The state may be a neutral mode of a linearisation (nothing restores it: a
        memory state, or a position only a memory element reads). Default: a state
        with a ``rest`` rule.
    seed : Seed, optional
        Where the trim starts this state (:class:`Seed`).
    node : Node, optional
        For a temperature: the thermal node it is (:class:`Node`: name, heat capacity,
        rated temperature); its part provides :func:`node_outflow` of it.
    """

    name: str
    unit: str
    doc: str
    roles: tuple = ()
    x0: float = 0.0
    scale: Callable = lambda P: 1.0
    travel: Callable | None = None
    loop: str | None = None
    bound: Bound | None = None
    rest: str | None = None
    rest_when: Callable | None = None
    neutral: bool = False
    seed: Seed | None = None
    node: Node | None = None

    @property
    def memory(self) -> bool:
        """True when the state may be a neutral mode (``neutral`` or a ``rest`` rule)."""
        return self.neutral or self.rest is not None


@dataclass(frozen=True)
class Input:
    """A model input a part reads.

    Attributes
    ----------
    name, unit, doc : str
        Name (the physics reference's symbol), SI unit, one-line meaning.
    kind : str
        Its quantity for the signal parser, one of :data:`INPUT_KINDS`.
    default : float or str
        Value when not driven (SI), or the name of the parameter giving it.
    injection : bool
        A loop-break injection (zero unless driven; listed after the other inputs).
    bound : Bound, optional
        Its physical envelope (None: only checked to be finite).
    noise : str, optional
        A unit white-noise input: the name of the loop (:class:`Loop`) at whose sample
        rate it is held. A time simulation that does not drive it fills it with a seeded
        sample-and-hold sequence of standard normal values (the parameter named by
        ``seed``; one stream per input name), so a run is reproducible bit for bit; the
        linear analyses see its default, 0.
    seed : str, optional
        For a noise input: the parameter giving the seed of its sequence.
    roles : tuple of str
        What analyses may ask the model for (:data:`INPUT_ROLES`: ``command``, ``load``, ...).
    """

    name: str
    unit: str
    kind: str
    doc: str
    default: float | str = 0.0
    injection: bool = False
    bound: Bound | None = None
    noise: str | None = None
    seed: str | None = None
    roles: tuple = ()


@dataclass(frozen=True)
class Output:
    """An output a part provides.

    Attributes
    ----------
    name, unit, doc : str
        Name (the physics reference's symbol), SI unit, one-line meaning.
    kind : str
        One of :data:`OUTPUT_KINDS`.
    bound : Bound, optional
        Its physical envelope (None: only checked to be finite).
    roles : tuple of str
        What analyses may ask the model for (:data:`OUTPUT_ROLES`: ``rod_position``, ...).
    threshold, confirm, alarm : str, optional
        A ``statistic`` output: the parameter of its threshold (same unit), of its
        confirmation time (s), and the ``alarm`` output of its latch.
    """

    name: str
    unit: str
    doc: str
    kind: str = "signal"
    bound: Bound | None = None
    roles: tuple = ()
    threshold: str | None = None
    confirm: str | None = None
    alarm: str | None = None


@dataclass(frozen=True)
class Loop:
    """A feedback loop a part closes, with its break (the paper's "Gain = 1" block):
    the feedback is ``flag * measured + injection``.

    Attributes
    ----------
    name : str
        Loop name (``position``, ``velocity``, ``current``).
    flag : str
        The loop-closure flag parameter (1 closed, 0 open).
    injection : str
        The input added at the break.
    measured : str
        The fed-back signal.
    rate : str
        The parameter giving the loop's ECU sample rate (Hz).
    """

    name: str
    flag: str
    injection: str
    measured: str
    rate: str


@dataclass(frozen=True)
class Hold:
    """A controller output held between the samples of ``loop`` (zero-order hold).

    Attributes
    ----------
    name : str
        The held signal.
    unit : str
        Its SI unit.
    loop : str
        The loop whose samples update it.
    """

    name: str
    unit: str
    loop: str


class Part:
    """Base class of a component variant; subclasses fill in the declarations.

    ``family`` and ``value`` are the variant key and value it serves (``screw``,
    ``elastic``). ``options`` lists the sub-choices it reads, with their allowed values
    (first the default), e.g. the smooth friction's ``friction_shape``.

    Parameters
    ----------
    options : dict, optional
        The values of the options this part reads (default: each option's default).
    """

    family: ClassVar[str] = ""
    value: ClassVar[str] = ""
    doc: ClassVar[str] = ""
    states: ClassVar[tuple] = ()
    inputs: ClassVar[tuple] = ()
    #: Signals it reads that other parts provide (:class:`~ema_casadi.model.components._ports.Port`)
    reads: ClassVar[tuple] = ()
    outputs: ClassVar[tuple] = ()
    params: ClassVar[tuple] = ()
    #: option -> value -> the parameters only that value's law uses (a part's used
    #: parameters: ``Model.used_params``; ``{"anti_windup": {"clamping": ("w_aw",)}}``)
    option_params: ClassVar[dict] = {}
    loops: ClassVar[tuple] = ()
    holds: ClassVar[tuple] = ()
    options: ClassVar[dict] = {}
    #: internal signals that are stored energy (J); summed into the output E_stored
    stored: ClassVar[tuple] = ()
    #: signals that load the rod (N, positive pushes the rod in); summed into F_load_rod
    loads: ClassVar[tuple] = ()
    #: signals that are masses moving with the rod (kg, e.g. a surface's inertia referred
    #: through its horn); summed into M_load_rod, which the screw adds to its rod mass
    masses: ClassVar[tuple] = ()
    #: trim of an outer loop (the airframe): the inputs the trim solves for and the states
    #: it fixes (state -> the parameter giving its value, or a number)
    trim_free: ClassVar[tuple] = ()
    trim_fix: ClassVar[dict] = {}
    #: named envelope limits, ``name -> fn(P)`` (SI), read by the :class:`Bound` of any
    #: part; where several parts declare one, the widest holds (a part can only widen)
    limits: ClassVar[dict] = {}
    #: loss signal -> the thermal node its heat reaches (HEAT_NODES); summed per node
    heat: ClassVar[dict] = {}
    #: Variant key -> values this part works with (e.g. the PWM bridge needs the
    #: three-phase motor); :func:`validate_variants` refuses other combinations.
    requires: ClassVar[dict] = {}
    #: Switched signals (the PWM bridge's leg states): in the continuous model they take
    #: their providers' (averaged) values; a carrier-synchronous integrator sets them per
    #: sub-interval of :meth:`schedule` (``Model.f_switched``, ``Model.schedule``).
    switched: ClassVar[tuple] = ()
    #: The parameter giving the carrier frequency (Hz) of :meth:`schedule`.
    carrier: ClassVar[str | None] = None
    #: Small-signal policies (:data:`POLICIES`): policy -> value -> the parameter
    #: overrides it applies (``{"friction": {"off": {"F_seal": 0.0}}}``), or a one-line
    #: reason (str) when this part refuses that value.
    small_signal: ClassVar[dict] = {}
    #: What the linearisation freezes (:class:`Freeze`).
    freeze: ClassVar[tuple] = ()
    #: Saturations a trim must keep inactive (:class:`Limit`).
    trim_limits: ClassVar[tuple] = ()
    #: Operating limits (:class:`Rating`): the constraints of an optimal move.
    ratings: ClassVar[tuple] = ()
    #: Variant key -> value of the smooth counterpart an optimiser uses in this part's
    #: place (hybrid friction -> smooth, the switched bridge -> averaged): see
    #: :meth:`~ema_casadi.model.assembly.Model.smooth`.
    smooth: ClassVar[dict] = {}
    #: Gains a tuner may move (:class:`Gain`), outer loop first.
    gains: ClassVar[tuple] = ()
    #: Named operating conditions (the airframe's flight conditions): name -> flat
    #: parameter values (SI) that set it up.
    conditions: ClassVar[dict] = {}
    #: The faults this part can inject (:class:`Fault`), each through one of its inputs.
    faults: ClassVar[tuple] = ()
    #: Parts this part brings into the model, assembled just before it with their own
    #: declarations and options (the motor's current controller, a controller-family part).
    brings: ClassVar[tuple] = ()

    @classmethod
    def form(cls, options: dict) -> type:
        """The class that serves these option values: the part itself, or a subclass whose
        class-level declarations the option extends (the PMSM with a shorted winding).

        Parameters
        ----------
        options : dict
            The values of the options the part reads.
        """
        return cls

    def __init__(self, options: dict | None = None):
        self.opt = dict(options or {})

    def signals(self) -> dict:
        """Providers: ``{name or tuple of names: fn(bus) -> expr or tuple}``."""
        return {}

    def modify(self) -> dict:
        """Modifiers of signals other parts provide: ``{name: fn(bus, value) -> new}``.

        The assembly applies each to the provider's value of ``name`` (in assembly order
        when several parts modify one signal), so a fault or a reaction acts on a signal
        without the part that provides it knowing. A model without modifiers is the
        model of the providers alone, expression for expression.
        """
        return {}

    def adjust(self) -> dict:
        """Parameters that become signals: ``{name: fn(P, u) -> expr}`` of the parameter
        symbols ``P`` and the model inputs ``u`` (by name). Every part then reads the
        adjusted value as ``bus.P.name`` (wear growing the friction with time). A model
        without adjustments reads the parameters themselves.
        """
        return {}

    def project(self, prev: Bus, now: Bus):
        """Discrete map applied after each step (hybrid parts): returns
        ``({state name: new value}, stick flag)`` or None for a continuous part.

        Parameters
        ----------
        prev : Bus
            The signals at the start of the step.
        now : Bus
            The signals at its end.
        """
        return None

    def schedule(self, bus: Bus):
        """Switched parts: one carrier period from the signals at its start (the held
        references in ``bus``), as a list of halves ``(durations, values)``: the
        sub-interval lengths (s) of each half and, per sub-interval, the values of
        :attr:`switched` in it. None for other parts.

        Parameters
        ----------
        bus : Bus
            The signals at the sample instant (controller outputs held).
        """
        return None

    @property
    def hybrid(self) -> bool:
        """True when the part has a discrete map (:meth:`project` is overridden)."""
        return type(self).project is not Part.project


class Bus:
    """Signals by name over one set of state, input and parameter symbols.

    ``bus["x_rod"]`` returns a state, an input or the value of the provider of that
    name (evaluated once and cached). ``bus.P.K_x`` is a parameter symbol. Overrides
    replace a signal (the held controller outputs of the sampled ECU).

    Parameters
    ----------
    providers : dict
        Signal name -> (key, provider) from the parts' :meth:`Part.signals`.
    x, u : dict
        State and input symbols by name.
    P : SimpleNamespace
        Parameter symbols by flat name.
    roles : dict
        State role -> the names of the states declaring it.
    overrides : dict, optional
        Signals replaced by the given expressions.
    wrap : dict, optional
        Signal name -> ``fn(bus, value)`` applied to the provider's value.
    guard : tuple, optional
        ``(owner, allowed)``: signal name -> the part providing it, and ``id(part)`` -> the
        names it may read (:func:`~ema_casadi.model.components._ports.allowed_reads`);
        a provider reading a name outside its set is an AssemblyError (an undeclared port).
    """

    def __init__(self, providers: dict, x: dict, u: dict, P: SimpleNamespace,
                 roles: dict, overrides: dict | None = None, wrap: dict | None = None, guard: tuple | None = None):
        self._providers = providers
        self.x, self.u, self.P = x, u, P
        self._roles = roles
        self._cache = dict(overrides or {})
        self._wrap = wrap or {}
        self._busy: list = []
        self._owner, self._allowed = guard or ({}, None)
        self._who: list = []

    def _check(self, name: str) -> None:
        part = self._who[-1] if self._who else None
        if part is not None and self._allowed is not None and name not in self._allowed[id(part)]:
            inst = getattr(part, "instance", "")
            raise AssemblyError(f"{inst + '.' if inst else ''}{part.family} = {part.value} reads '{name}' without "
                                f"declaring it: add Port('{name}', ...) to its reads")

    def acting(self, part, fn, *args):
        """``fn(self, *args)`` with the reads checked against ``part``'s ports (a modifier).

        Parameters
        ----------
        part : Part
            The part whose ports the reads are checked against.
        fn : callable
            ``fn(bus, *args)``.
        *args
            Passed on to ``fn``.
        """
        self._who.append(part)
        try:
            return fn(self, *args)
        finally:
            self._who.pop()

    def __contains__(self, name: str) -> bool:
        return name in self._cache or name in self.x or name in self.u or name in self._providers

    def __getitem__(self, name: str):
        if self._who:
            self._check(name)
        if name in self._cache:
            return self._cache[name]
        if name in self.x:
            return self.x[name]
        if name in self.u:
            return self.u[name]
        key = self._providers.get(name)
        if key is None:
            raise AssemblyError(f"no part provides the signal '{name}'")
        if name in self._busy:
            raise AssemblyError("algebraic loop: " + " -> ".join([*self._busy, name]))
        self._busy.append(name)
        self._who.append(self._owner.get(name))
        try:
            key, fn = key
            val = fn(self)
        finally:
            self._busy.pop()
            self._who.pop()
        names = key if isinstance(key, tuple) else (key,)
        vals = val if isinstance(key, tuple) else (val,)
        for n, v in zip(names, vals, strict=True):
            self._cache[n] = self._wrap[n](self, v) if n in self._wrap else v
        return self._cache[name]

    def state_name(self, role: str) -> str:
        """The name of the one state with ``role``.

        Parameters
        ----------
        role : str
            A state role (see :class:`State`).
        """
        names = self._roles.get(role, ())
        if len(names) != 1:
            raise AssemblyError(f"expected one state with role '{role}', the parts declare {len(names)}")
        return names[0]

    def state(self, role: str):
        """The symbol of the one state with ``role``.

        Parameters
        ----------
        role : str
            A state role (see :class:`State`).
        """
        name = self.state_name(role)
        if self._who:
            self._check(name)
        return self.x[name]

    def feedback(self, loop: Loop):
        """``flag * measured + injection`` of a loop.

        Parameters
        ----------
        loop : Loop
            The loop.
        """
        return getattr(self.P, loop.flag) * self[loop.measured] + self[loop.injection]
