"""Assembly: composes the chosen parts into one model (docs: physics).

:func:`build_model` looks every variant key up in the registry
(:data:`~ema_casadi.model.components.REGISTRY`), collects what the parts declare (states,
inputs, outputs, loops, held controller outputs, stored energy, loads on the rod) and
wires them by signal name through a :class:`~ema_casadi.model.components.Bus`. There is no
branching on variant values here. The result is a :class:`Model` whose CasADi Function
``f(x, u, p) -> (xdot, y)`` has named states, inputs and outputs and takes the
parameters as an input vector, so one compiled model serves simulation, linearisation,
sweeps, tuning and export.

Summed signals the assembly provides: ``F_load_rod`` (N), the sum of every part's
``loads`` (the external force and, with end stops, the stop force); ``M_load_rod`` (kg),
the masses moving with the rod (every part's ``masses``: a surface referred through its
horn); ``E_stored`` (J),
the sum of every part's ``stored`` energies; ``P_heat_<node>`` (W) for each thermal
node of :data:`~ema_casadi.model.components.HEAT_NODES`, the sum of the losses the parts
route there (their ``heat`` tables). Reading a heat sum while some loss output is
routed nowhere is an AssemblyError (the heat would vanish from the thermal network).

For sampled (zero-order-hold) control the same wiring is also exposed split in two:
``f_held(x, u, p, h)`` (plant with the held controller outputs ``h``, see
:attr:`Model.holds`) and ``sample(x, u, p, h, flags)`` (one ECU update of the loops
whose flag is 1; flags in :attr:`Model.loops` order).

The physical envelope (the reliability contract, docs: reliability): parts declare a
:class:`~ema_casadi.model.components.Bound`
on the states and outputs they bring, and named envelope limits (the rod's
``overtravel``) that another part may widen (the end stop does);
:meth:`Model.envelope` evaluates them for a parameter vector, and every simulation
is checked against it (:mod:`ema_casadi.simulation`).

Hybrid parts (stick-slip friction) add the discrete map
``project(x_prev, x, u, p) -> (x_next, stick)`` that an integrator applies after each
step (or at each located switching instant); for a continuous model it is the identity.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from types import SimpleNamespace

import casadi as ca
import numpy as np

from .._util._kwargs import check_keywords
from .._util._notebook import Summarised, changed_variants
from ._derived import Contract, switched_split
from ._derived import projection as _projection
from ._derived import zoh_split as _zoh
from ._system import instances
from ._wiring import check_tables, declarations
from .components import AssemblyError, Bus, der, parts_for, validate_variants
from .components._ports import connections_text
from .params import ParameterError, Parameters

__all__ = ["Model", "build_model", "AssemblyError"]

@dataclass(repr=False)
class Model(Summarised, Contract):
    """An assembled EMA model.

    Attributes
    ----------
    variants : dict
        The complete variant choice.
    params : Parameters
        Default numeric parameters (the model itself is parametric).
    states, inputs, outputs, param_names : tuple of str
        Names of the entries of x, u, y and p.
    f : casadi.Function
        ``f(x, u, p) -> (xdot, y)``, continuous controller.
    f_held, sample : casadi.Function
        The ZOH split (see module docstring).
    project : casadi.Function
        ``project(x_prev, x, u, p) -> (x_next, stick)``: the discrete map of hybrid parts
        (identity and stick = 0 for a continuous model).
    parts : tuple
        The composed parts, in assembly order.
    state_info, input_info, output_info : dict
        Name -> the part's declaration (:class:`~ema_casadi.model.components.State`,
        ``Input``, ``Output``): unit, role, kind, meaning.
    loops : dict
        Loop name -> :class:`~ema_casadi.model.components.Loop`, outer to inner.
    holds : tuple
        The controller outputs held between ECU samples (``h`` of ``f_held``).
    switched, carrier : tuple of str, str or None
        A switched part's switched signals (PWM leg states, flag ``sw``) and its
        carrier-frequency parameter; () and None for a continuous model.
    f_switched, schedule : casadi.Function or None
        ``f_switched(x, u, p, h, s) -> (xdot, y)``, :attr:`f_held` with the switched
        signals ``s``; ``schedule(x, u, p, h) -> (D, S)``: sub-interval lengths of a
        carrier period's halves (2 x 4) and the switched values in each (n_sw x 8).
    ignored : tuple of str
        Option keys of the variant dict that no chosen part reads (e.g.
        ``friction_shape`` with hybrid friction): accepted and ignored.
    system : object or None
        With several actuator instances on one surface, their description (names,
        modes, per-instance tables); None for one actuator.
    connections : tuple
        The connection table: one :class:`~ema_casadi.model.components.Connection` per
        port a part reads (reader, port, unit, provider); :meth:`connections_text`.
    cache : dict
        Functions derived from the model (rollouts, integrators, Jacobians), kept with it.
    """

    variants: dict
    params: Parameters
    states: tuple
    inputs: tuple
    outputs: tuple
    param_names: tuple
    f: ca.Function
    f_held: ca.Function
    sample: ca.Function
    project: ca.Function
    parts: tuple = ()
    switched: tuple = ()
    carrier: str | None = None
    f_switched: ca.Function | None = None
    schedule: ca.Function | None = None
    state_info: dict = field(default_factory=dict)
    input_info: dict = field(default_factory=dict)
    output_info: dict = field(default_factory=dict)
    loops: dict = field(default_factory=dict)
    holds: tuple = ()
    ignored: tuple = ()
    connections: tuple = ()
    system: object = None
    _p0: np.ndarray | None = field(default=None, repr=False, compare=False)
    #: Functions derived from this model (rollouts, integrators, Jacobians), built once
    #: and kept with it: they live and die with the model (a cache keyed by ``id(f)``
    #: could hand a new model the functions of a freed one at the same address).
    cache: dict = field(default_factory=dict, repr=False, compare=False)

    def _facts(self) -> dict:
        from .components import DEFAULT_VARIANTS

        return {"variants": changed_variants(self.variants, DEFAULT_VARIANTS), "states": len(self.states),
                "inputs": len(self.inputs), "outputs": len(self.outputs), "parameters": len(self.param_names),
                "switched": ", ".join(self.switched) or None, "connections": len(self.connections)}

    def connections_text(self) -> str:
        """The model's wiring as text: each port a part reads, its unit and who provides it."""
        return connections_text(self.connections)

    def __getstate__(self):
        state = dict(self.__dict__)
        state["cache"] = {}
        return state

    # -- sizes and names -------------------------------------------------------------
    @property
    def hybrid(self) -> bool:
        """True when a part has a discrete map: integrate with :attr:`project`."""
        return any(part.hybrid for part in self.parts)

    @property
    def nx(self) -> int:
        return len(self.states)

    @property
    def nu(self) -> int:
        return len(self.inputs)

    @property
    def ny(self) -> int:
        return len(self.outputs)

    @property
    def units(self) -> dict:
        """The one table of SI units: time, states, inputs and outputs by name (a copy)."""
        table = self.cache.get("units")
        if table is None:
            table = {"t": "s", "time": "s"}
            for info in (self.state_info, self.input_info, self.output_info):
                table.update({n: d.unit for n, d in info.items()})
            self.cache["units"] = table
        return dict(table)

    def index(self, name: str) -> int:
        """Index of a state by name.

        Parameters
        ----------
        name : str
            State name (``model.states``).
        """
        return self.states.index(name)

    def yindex(self, name: str) -> int:
        """Index of an output by name.

        Parameters
        ----------
        name : str
            Output name (``model.outputs``).
        """
        return self.outputs.index(name)

    def states_with(self, role: str) -> tuple[str, ...]:
        """Names of the states that declare ``role``.

        Parameters
        ----------
        role : str
            A state role (see :class:`~ema_casadi.model.components.State`), e.g. ``rod_position``.
        """
        return tuple(n for n, s in self.state_info.items() if role in s.roles)

    def state_with(self, role: str) -> str:
        """The name of the one state with ``role``; AssemblyError if there is not exactly one.

        Parameters
        ----------
        role : str
            A state role (see :class:`~ema_casadi.model.components.State`).
        """
        names = self._lead(self.states_with, role)
        if len(names) != 1:
            raise AssemblyError(f"the model has {len(names)} states with role '{role}', expected one")
        return names[0]

    @property
    def used_params(self) -> frozenset:
        """Names of the parameters the model's parts use with their options' values (each
        part's ``params`` less those its ``option_params`` give to a law not chosen)."""
        return frozenset(n for part in self.parts for n in part.params if not _left_out(part, n))

    def unused_reason(self, name: str) -> str:
        """Why the model does not use the parameter ``name``: the option value whose law
        leaves it out (``"anti_windup = backcalc does not use it (only clamping)"``).

        Parameters
        ----------
        name : str
            A parameter's flat name.
        """
        for part in self.parts:
            why = _left_out(part, name)
            if why and name not in self.used_params:
                return why
        return f"the model's parts do not use it (variants {self.variants})"

    def unread(self, arg: str = "u") -> tuple[str, ...]:
        """The inputs (``arg="u"``) or parameters (``"p"``) no equation of the model reads
        (the dynamics, the held ECU, its sampling, the projection), structurally.

        Parameters
        ----------
        arg : {"u", "p"}
            Inputs or parameters.
        """
        names = self.inputs if arg == "u" else self.param_names
        sym, exprs = ca.SX.sym(arg, len(names)), []
        for f in (self.f, self.f_held, self.sample, self.project, self.f_switched):
            if f is not None:
                call = {n: sym if n == arg else ca.SX.sym(n, f.size_in(n)) for n in f.name_in()}
                exprs += [ca.vec(v) for v in f.call(call).values()]
        e = ca.vertcat(*exprs)
        return tuple(n for i, n in enumerate(names) if not ca.depends_on(e, sym[i]))

    def outputs_of(self, kind: str) -> tuple[str, ...]:
        """Names of the outputs of a kind.

        Parameters
        ----------
        kind : str
            One of :data:`~ema_casadi.model.components.OUTPUT_KINDS` (``signal``, ``loss``, ``power``, ...).
        """
        return tuple(n for n, o in self.output_info.items() if o.kind == kind)

    # -- numeric vectors -------------------------------------------------------------
    def p(self, params: Parameters | None = None, **overrides) -> np.ndarray:
        """Numeric parameter vector (defaults: the model's own set).

        Parameters
        ----------
        params : Parameters, optional
            Parameter set (default the model's).
        **overrides : float
            Flat parameter values by name (SI); an unknown name raises
            :class:`~ema_casadi.model.params.UnknownParameterError` (a TypeError).
        """
        if params is None and not overrides:  # the common case, cached (params are frozen)
            if self._p0 is None:
                self._p0 = self.params.vector() if self.system is None else self.system.vector(self.params)
            return self._p0.copy()
        if self.system is not None:
            return self.system.vector(params or self.params, **overrides)
        return (params or self.params).vector(**overrides)

    def param_units(self) -> dict[str, str]:
        """SI unit of every entry of the parameter vector (``param_names``), by name."""
        return Parameters.units() if self.system is None else self.system.units()

    def pdict(self, p=None) -> SimpleNamespace:
        """Parameter values by name (attribute access), from ``p`` or the model's set.

        Parameters
        ----------
        p : array_like, optional
            Parameter vector in ``param_names`` order (SI); default the model's set.
        """
        pv = self.p() if p is None else p
        return SimpleNamespace(**dict(zip(self.param_names, pv, strict=True)))

    def u(self, p=None, **values: float) -> np.ndarray:
        """Numeric input vector by name; missing inputs take their declared default
        (``eta``: the parameter set's efficiency; injections 0).

        Parameters
        ----------
        p : array_like, optional
            Parameter vector the defaults are read from (default the model's set).
        **values : float
            Input values by name (SI, the unit in ``model.input_info``); an unknown name
            raises TypeError.
        """
        check_keywords("Model.u", values, self.inputs)
        P = self.pdict(p)
        return np.array([float(values[n]) if n in values else _default(self.input_info[n], P) for n in self.inputs])

    def u_expr(self, p, **values) -> ca.SX:
        """Symbolic or numeric input column by name, defaults as :meth:`u`.

        Parameters
        ----------
        p : casadi.SX or array_like
            Parameter vector (may be a symbol: defaults that name a parameter are read
            from it).
        **values : casadi.SX or float
            Input values by name (SI); an unknown name raises TypeError.
        """
        check_keywords("Model.u_expr", values, self.inputs)
        P = SimpleNamespace(**{n: p[i] for i, n in enumerate(self.param_names)})
        return ca.vertcat(*[values[n] if n in values else _default(self.input_info[n], P) for n in self.inputs])

    def x0(self) -> np.ndarray:
        """Initial state as the parts declare it (at rest, the rod centred in the gap)."""
        return np.array([s.x0 for s in self.state_info.values()], dtype=float)

    def full_scale(self, p=None) -> np.ndarray:
        """Full-scale magnitude of every state (SI), as the parts declare it.

        Parameters
        ----------
        p : array_like, optional
            Parameter vector (SI); default the model's set.
        """
        P = self.pdict(p)
        return np.array([float(s.scale(P)) for s in self.state_info.values()])

    def envelope_limits(self, p=None) -> dict[str, float]:
        """The named envelope limits the parts declare (e.g. ``overtravel``, m), each at
        the widest value any part gives it.

        Parameters
        ----------
        p : array_like, optional
            Parameter vector (SI); default the model's set.
        """
        P = self.pdict(p)
        limits: dict[str, float] = {}
        for part in self.parts:
            for name, fn in part.limits.items():
                limits[name] = max(limits.get(name, -math.inf), float(fn(P)))
        return limits

    def envelope(self, p=None) -> dict[str, float]:
        """The physical envelope: signal name -> bound on its magnitude (SI), for the
        states, inputs and outputs whose parts declare one (``|x_rod| <= stroke +
        overtravel``, the currents within 3 x I_max, the load within 3 x the force the
        motor holds, ...). A run that leaves it is failed
        (:class:`~ema_casadi.simulation.RunFailed`).

        Parameters
        ----------
        p : array_like, optional
            Parameter vector (SI); default the model's set.
        """
        E = SimpleNamespace(**vars(self.pdict(p)), **self.envelope_limits(p))
        out: dict[str, float] = {}
        for table in (self.state_info, self.input_info, self.output_info):
            for name, d in table.items():
                if d.bound is not None:
                    out[name] = min(out.get(name, math.inf), float(d.bound.limit(E)))
        return out

    def smooth(self) -> Model:
        """The model with the smooth counterpart of every part that switches
        (:attr:`smooth_variants`), on the same parameters: what an optimiser's exact
        derivatives need. The model itself when it is smooth already."""
        over = self.smooth_variants
        if not over:
            return self
        key = ("smooth", tuple(sorted(over.items())))
        if key not in self.cache:
            self.cache[key] = build_model(self.params, {**self.variants, **over})
        return self.cache[key]

    def travel(self, p=None) -> dict[str, float]:
        """Position-like states -> rod travel (m) per unit of the state.

        Parameters
        ----------
        p : array_like, optional
            Parameter vector (SI); default the model's set.
        """
        P = self.pdict(p)
        return {n: float(s.travel(P)) for n, s in self.state_info.items() if s.travel is not None}


def _default(inp, P) -> float:
    return getattr(P, inp.default) if isinstance(inp.default, str) else inp.default


def _left_out(part, name: str) -> str:
    """Why ``part``'s options' values leave out its parameter ``name`` (else ``""``)."""
    for option, laws in part.option_params.items():
        chosen = part.opt.get(option, part.options[option][0])
        users = [v for v, names in laws.items() if name in names]
        if users and chosen not in users:
            return f"{option} = {chosen} does not use it (only {' or '.join(users)})"
    return ""


def build_model(params: Parameters, variants: dict | None = None) -> Model:
    """Assemble the EMA for a variant choice.

    Parameters
    ----------
    params : Parameters
        Parameter set; its ``variants`` are the defaults.
    variants : dict, optional
        Overrides, e.g. ``{"motor": "dc", "screw": "rigid"}`` (docs: cli). Unknown keys or
        values raise :class:`~ema_casadi.model.params.ParameterError` listing the allowed ones.
    """
    if not isinstance(params, Parameters):
        raise ParameterError(f"params: expected Parameters (from load_parameters), got {type(params).__name__}")
    given = set(params.overrides)  # load_parameters(variants=...): blamed on them, the rest on the file
    validate_variants({k: x for k, x in params.variants.items() if k not in given}, where=f"{params.source}: [model]")
    v = validate_variants(params.variants, where="variants")  # the file alone holds: what fails is theirs
    validate_variants(variants, where="variant")
    v.update(variants or {})
    params = dataclasses.replace(params, variants=v)
    parts, ignored = parts_for(v)
    check_tables(params, parts)
    if params.system:  # several actuator instances on one surface
        system, parts = instances(params, parts)
        return _assemble(params, v, parts, ignored, list(system.names), system)
    return _assemble(params, v, parts, ignored, Parameters.names(), None)


def _assemble(params, v, parts, ignored, names, system) -> Model:
    """The model of these parts on the parameter ``names`` (``system``: its instances)."""
    d = declarations(parts)
    states, inputs, outputs, providers, loops, holds = d.states, d.inputs, d.outputs, d.providers, d.loops, d.holds
    if system is not None:
        system.check_connections(parts, d)
    clash = sorted({n for part in parts for n in part.limits} & set(names))
    if clash:
        raise AssemblyError(f"envelope limits {clash} have the names of parameters")
    p = ca.SX.sym("p", len(names))
    P = SimpleNamespace(**{n: p[i] for i, n in enumerate(names)})
    u = ca.SX.sym("u", len(inputs))
    U = {n: u[i] for i, n in enumerate(inputs)}
    adjusted = {n: fn(P, U) for part in parts for n, fn in part.adjust().items()}
    if adjusted:  # parameters some part makes signals (Part.adjust)
        P = SimpleNamespace(**{**vars(P), **adjusted})
    for part in parts:
        if getattr(part, "instance", ""):  # its copies of the parameters (A.K_x as K_x)
            part.bind(P, [n.split(".", 1)[1] for n in names if n.startswith(f"{part.instance}.")])
    X = {n: ca.SX.sym(n) for n in states}
    x = ca.vertcat(*X.values())
    roles: dict = {}
    for s in states.values():
        for r in s.roles:
            roles.setdefault(r, []).append(s.name)

    def bus(xs=X, **kw):
        return Bus(providers, xs, U, P, roles, guard=d.guard, **kw)

    def evaluate(b):
        return ca.vertcat(*[b[der(n)] for n in states]), ca.vertcat(*[b[n] for n in outputs])

    xdot, y = evaluate(bus())
    f = ca.Function("f", [x, u, p], [xdot, y], ["x", "u", "p"], ["xdot", "y"])
    integrators = [n for n, s in states.items() if s.loop is not None]
    f_held, sample = _zoh(bus, evaluate, x, u, p, P, X, states, loops, holds, integrators)
    project = _projection(parts, bus, x, u, p)
    switching = switched_split(parts, bus, evaluate, x, u, p, holds, integrators)
    return Model(**switching,
        variants=v, params=params, states=tuple(states), inputs=tuple(inputs), outputs=tuple(outputs),
        param_names=tuple(names), f=f, f_held=f_held, sample=sample, project=project, parts=tuple(parts),
        state_info=states, input_info=inputs, output_info=outputs, loops=loops, holds=holds,
        ignored=tuple(ignored), connections=d.connections, system=system,
    )
