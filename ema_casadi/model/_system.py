"""A model of several actuator instances on one surface, from a parameter file's
``[instances]``, ``[surface]`` and ``[equaliser]`` tables (docs: dual actuators)::

    [instances.A]
    mode = "active"              # active | standby | off
    [instances.A.channel]        # the attachment of channel A
    k_att = { value = 1.0e8, unit = "N/m" }
    [instances.B]
    mode = "standby"
    [instances.B.screw]          # an override: B's tables are the shared ones but for this
    C = { value = 1.4e8, unit = "N/m" }
    [instances.B.connect]        # optional: a port of B wired to another signal than its name
    eta = "A.eta"

    [surface]                    # the surface (components.surface.Hinge)
    torsion = "elastic"
    J_surf = { value = 15.0, unit = "kg*m^2" }
    ...
    [equaliser]
    law = "integral"
    K_eq = { value = 3e-8, unit = "m/(N*s)" }

Each instance is the actuator the ``[model]`` variants describe, its parts wrapped by
:class:`~ema_casadi.model._instances.Instanced` (names prefixed ``A.``), plus a
:class:`~ema_casadi.model.components.surface.Channel`; the surface and the equaliser are
shared. Parameters: the flat names of the shared tables, then each instance's copy of
every flat name and of its channel's (``A.K_x``, ``A.k_att``), then the surface's and the
equaliser's. A plain name given to :meth:`System.vector` sets the shared default and
every instance that does not override it; ``A.K_x`` sets instance ``A`` only.
Used by :mod:`ema_casadi.model.assembly` only.
"""

from __future__ import annotations

import dataclasses
import re
from dataclasses import dataclass, field

import numpy as np

from .._util._checks import nearest
from .components.surface import CHANNEL_PARAMS, EQUALISER_PARAMS, MODES, SURFACE_PARAMS, Channel, Equaliser, Hinge
from .params import GROUPS, SYSTEM_HOOKS, ParameterError, Parameters, UnknownParameterError, _check_value

__all__ = ["System", "read_system", "system_parts", "instances", "system_vector", "system_scalars", "replace_system"]

_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")
_OPTIONS = {"surface": ("torsion", ("rigid", "elastic")), "equaliser": ("law", ("integral", "off"))}


@dataclass
class System:
    """The instances of a model and its shared parts' parameters.

    Attributes
    ----------
    channels : tuple of str
        The instance names, in order.
    modes : dict
        Instance -> its mode (:data:`~ema_casadi.model.components.surface.MODES`).
    overrides : dict
        Instance -> flat name -> value (SI): its own tables (the shared ones elsewhere).
    channel : dict
        Instance -> its channel parameters (SI).
    shared : dict
        The surface's and the equaliser's parameters (SI).
    torsion, law : str
        The surface's torsion (``rigid``, ``elastic``) and the equaliser's law.
    connect : dict
        Instance -> port -> the model signal it is wired to (instead of same-name wiring).
    names : tuple of str
        The model's flat parameter names.
    """

    channels: tuple
    modes: dict
    overrides: dict
    channel: dict
    shared: dict
    torsion: str
    law: str
    connect: dict = field(default_factory=dict)
    names: tuple = ()

    def check_connections(self, parts, d) -> None:
        """Every ``[instances.X.connect]`` entry names a port of that instance and a
        signal of the model (one-line ParameterError naming the table and the port).

        Parameters
        ----------
        parts : sequence of Part
            The model's parts.
        d : Declarations
            Their merged declarations.
        """
        known = set(d.providers) | set(d.states) | set(d.inputs)
        for c, table in self.connect.items():
            ports = {r.name for p in parts if getattr(p, "instance", "") == c for r in (*p.reads, *p.inner.inputs)}
            for port, target in table.items():
                if port not in ports:
                    raise ParameterError(f"[instances.{c}.connect] {port}: no port of that name in instance {c}"
                                         f"{nearest(port, sorted(ports))}")
                if target not in known:
                    raise ParameterError(f"[instances.{c}.connect] {port} = {target!r}: no signal of that name in "
                                         f"the model{nearest(target, sorted(known))}")

    def units(self) -> dict:
        """SI unit of every parameter name of the model (:attr:`names`)."""
        base = {**Parameters.units(), **{n: u for n, (u, _, _) in CHANNEL_PARAMS.items()}}
        shared = {n: u for table in (SURFACE_PARAMS, EQUALISER_PARAMS) for n, (u, _, _) in table.items()}
        out = {**Parameters.units(), **shared}
        out.update({f"{c}.{n}": u for c in self.channels for n, u in base.items()})
        return {n: out[n] for n in self.names}

    def vector(self, params: Parameters, **overrides) -> np.ndarray:
        """The parameter vector (SI) in :attr:`names` order.

        Parameters
        ----------
        params : Parameters
            The shared tables.
        **overrides : float
            Values by flat name: a plain name sets the shared value and every instance
            that does not override it; ``A.name`` instance ``A`` only.
        """
        base = dataclasses.replace(params, system={}).as_dict()
        bad = [k for k in overrides if k not in self.names and k not in base]
        if bad:
            raise UnknownParameterError(f"Parameters.vector() got an unexpected keyword argument '{bad[0]}': no "
                                        f"parameter of that name{nearest(bad[0], self.names)}")
        plain = {k: float(v) for k, v in overrides.items() if k in base}
        base.update(plain)
        d = dict(base)
        for c in self.channels:
            own = {**base, **self.overrides[c], **{k: v for k, v in plain.items() if k not in self.overrides[c]},
                   **self.channel[c]}
            d.update({f"{c}.{n}": v for n, v in own.items()})
        d.update(self.shared)
        d.update({k: float(v) for k, v in overrides.items() if k not in base})
        return np.array([d[n] for n in self.names], dtype=float)


def _table(src: str, where: str, table, schema: dict, option: tuple | None = None) -> tuple[dict, str | None]:
    """Values (SI) of a table of ``schema`` (name -> (unit, check, doc)); every key given."""
    if not isinstance(table, dict):
        raise ParameterError(f"{src}: [{where}] must be a table")
    allowed = list(schema) + ([option[0]] if option else [])
    for key in table:
        if key not in allowed:
            raise ParameterError(f"{src}: [{where}] unknown key '{key}'{nearest(key, allowed)}")
    chosen = None
    if option:
        chosen = table.get(option[0], option[1][0])
        if chosen not in option[1]:
            raise ParameterError(f"{src}: [{where}] {option[0]} = {chosen!r}: expected one of {', '.join(option[1])}")
    out = {}
    for name, (unit, check, doc) in schema.items():
        if name not in table:
            raise ParameterError(f"{src}: [{where}] missing key '{name}' ({doc}, unit {unit})")
        out[name] = float(_check_value(src, where, name, {"unit": unit, "check": check, "doc": doc}, table[name],
                                       plain=False))
    return out, chosen


def _instance(src: str, name: str, table, read_groups: set) -> tuple:
    """(mode, flat overrides, channel values, connections) of one ``[instances.NAME]`` table."""
    where = f"instances.{name}"
    if not _NAME.match(name):
        raise ParameterError(f"{src}: [{where}] an instance name is a letter then letters, digits or _")
    if not isinstance(table, dict):
        raise ParameterError(f"{src}: [{where}] must be a table")
    mode = table.get("mode", "active")
    if mode not in MODES:
        raise ParameterError(f"{src}: [{where}] mode = {mode!r}: a channel has the modes {', '.join(MODES)}")
    overrides = {}
    for key, sub in table.items():
        if key in ("mode", "channel", "connect"):
            continue
        if key not in GROUPS:
            raise ParameterError(f"{src}: [{where}.{key}] unknown table{nearest(key, list(GROUPS))}; expected one "
                                 f"of {', '.join([*GROUPS, 'channel', 'connect'])}")
        if key not in read_groups:
            raise ParameterError(f"{src}: [{where}.{key}] no part of the model reads the table [{key}]")
        if not isinstance(sub, dict):
            raise ParameterError(f"{src}: [{where}.{key}] must be a table")
        fields_ = {f.name: f for f in GROUPS[key].__dataclass_fields__.values()}
        for k, raw in sub.items():
            if k not in fields_:
                raise ParameterError(f"{src}: [{where}.{key}] unknown key '{k}'{nearest(k, list(fields_))}")
            meta = dict(fields_[k].metadata)
            if meta.get("table"):
                raise ParameterError(f"{src}: [{where}.{key}] {k}: a table parameter cannot be overridden per "
                                     "instance")
            overrides[k] = float(_check_value(src, f"{where}.{key}", k, meta, raw, plain=False))
    chan_table = {k: v for k, v in table.get("channel", {}).items()}
    bridge, attached = MODES[mode]
    for key in ("bridge_on", "attached_on"):
        if key in chan_table:
            raise ParameterError(f"{src}: [{where}.channel] {key} is set by the instance's mode, not a table")
    chan_table.update({"bridge_on": {"value": bridge, "unit": "1"}, "attached_on": {"value": attached, "unit": "1"}})
    schema = {k: v for k, v in CHANNEL_PARAMS.items()}
    defaults = {k: {"value": 0.0, "unit": v[0]} for k, v in schema.items() if k in ("c_att", "x_rig", "R_damp")}
    channel, _ = _table(src, f"{where}.channel", {**defaults, **chan_table}, schema)
    connect = table.get("connect", {})
    if not isinstance(connect, dict) or not all(isinstance(v, str) for v in connect.values()):
        raise ParameterError(f"{src}: [{where}.connect] must map port names to signal names (strings)")
    return mode, overrides, channel, dict(connect)


def read_system(params: Parameters, parts) -> System:
    """The :class:`System` of a parameter set's ``[instances]``, ``[surface]`` and
    ``[equaliser]`` tables, checked (one-line :class:`ParameterError` naming the table).

    Parameters
    ----------
    params : Parameters
        With its ``system`` tables (from ``load_parameters``).
    parts : sequence of Part
        One actuator's parts (the tables an instance may override are the ones they read).
    """
    src, sysd = params.source, params.system
    inst = sysd.get("instances", {})
    if not isinstance(inst, dict) or len(inst) < 2:
        raise ParameterError(f"{src}: [instances] needs two or more instance tables ([instances.A], ...)")
    group_of = params.group_of()
    read_groups = {group_of[n] for p in parts for n in p.params if n in group_of}
    modes, overrides, channel, connect = {}, {}, {}, {}
    for name, table in inst.items():
        modes[name], overrides[name], channel[name], connect[name] = _instance(src, name, table, read_groups)
    surface, torsion = _table(src, "surface", sysd.get("surface", {}), SURFACE_PARAMS, _OPTIONS["surface"])
    eq_table = sysd.get("equaliser", {"law": "off"})
    law = eq_table.get("law", "integral") if isinstance(eq_table, dict) else None
    eq, law = _table(src, "equaliser", eq_table, EQUALISER_PARAMS if law == "integral" else {}, _OPTIONS["equaliser"])
    chans = tuple(inst)
    base = Parameters.names()
    names = (*base, *(f"{c}.{n}" for c in chans for n in (*base, *CHANNEL_PARAMS)), *SURFACE_PARAMS,
             *(EQUALISER_PARAMS if law == "integral" else ()))
    return System(chans, modes, overrides, channel, {**surface, **eq}, torsion, law, connect, tuple(names))


def system_parts(system: System, instance_parts: dict) -> list:
    """The model's parts: each instance's (wrapped) and its channel, then the surface
    and the equaliser.

    Parameters
    ----------
    system : System
        The instances.
    instance_parts : dict
        Instance -> its wrapped parts (:class:`~ema_casadi.model._instances.Instanced`).
    """
    from ._instances import Instanced

    out = []
    for c in system.channels:
        parts = instance_parts[c]
        integrators = tuple(s.name.split(".", 1)[1] for p in parts for s in p.states if s.loop is not None)
        out += parts + [Instanced(Channel(integrators), c)]
    return out + [Hinge(system.channels, system.torsion), Equaliser(system.channels, system.law)]


def instances(params: Parameters, parts) -> tuple[System, list]:
    """(System, the model's parts) for a parameter set with ``[instances]``: each instance
    the actuator of ``parts``, built again and wrapped with its name.

    Parameters
    ----------
    params : Parameters
        The set, with its system tables.
    parts : sequence of Part
        One actuator's parts (``parts_for`` of the variants).
    """
    from ._instances import Instanced
    from .components import parts_for

    system = read_system(params, parts)
    variants = {**params.variants}
    wrapped = {c: [Instanced(p, c, system.connect.get(c)) for p in parts_for(variants)[0]] for c in system.channels}
    return system, system_parts(system, wrapped)


def system_vector(params: Parameters, **overrides) -> np.ndarray:
    """The parameter vector of the model a parameter set with ``[instances]`` builds
    (:meth:`System.vector`; what ``Parameters.vector`` returns for such a set).

    Parameters
    ----------
    params : Parameters
        The set, with its system tables.
    **overrides : float
        Values by flat name (``K_x``: shared and every instance not overriding it; ``A.K_x``).
    """
    from .components import parts_for, validate_variants

    parts, _ = parts_for(validate_variants(params.variants))
    return read_system(params, parts).vector(params, **overrides)


def system_scalars(params: Parameters) -> dict:
    """Scalar parameter name -> (nominal (SI), unit, check) of the model a set with
    ``[instances]`` builds (what ``Parameters.scalars`` returns for it).

    Parameters
    ----------
    params : Parameters
        The set, with its system tables.
    """
    from .components import parts_for, validate_variants

    system = read_system(params, parts_for(validate_variants(params.variants))[0])
    base = dataclasses.replace(params, system={}).scalars()
    checks = {**{n: (u, c) for n, (_, u, c) in base.items()},
              **{n: (u, c) for table in (CHANNEL_PARAMS, SURFACE_PARAMS, EQUALISER_PARAMS) for n, (u, c, _) in
                 table.items()}}
    values = dict(zip(system.names, system.vector(params), strict=True))
    out = {}
    for name in system.names:
        plain = name.split(".", 1)[-1]
        if plain in checks:
            out[name] = (values[name], *checks[plain])
    return out


def replace_system(params: Parameters, values: dict) -> dict:
    """The system tables with ``values`` set (``A.C`` in ``[instances.A.screw]``, ``B.x_rig``
    in ``[instances.B.channel]``, ``K_theta`` in ``[surface]``), checked as a file is.

    Parameters
    ----------
    params : Parameters
        The set, with its system tables.
    values : dict
        Name -> value (SI).
    """
    import copy

    from .components import parts_for, validate_variants

    system = copy.deepcopy(params.system)
    group_of = params.group_of()
    units = {**Parameters.units(), **{n: t[0] for table in (CHANNEL_PARAMS, SURFACE_PARAMS, EQUALISER_PARAMS)
                                      for n, t in table.items()}}
    for name, v in values.items():
        inst, _, key = name.rpartition(".")
        entry = {"value": float(v), "unit": units.get(key, "1")}
        if inst and inst in system.get("instances", {}) and (key in CHANNEL_PARAMS or key in group_of) \
                and key not in ("bridge_on", "attached_on"):
            table = "channel" if key in CHANNEL_PARAMS else group_of[key]
            system["instances"][inst].setdefault(table, {})[key] = entry
        elif not inst and key in SURFACE_PARAMS:
            system.setdefault("surface", {})[key] = entry
        elif not inst and key in EQUALISER_PARAMS:
            system.setdefault("equaliser", {})[key] = entry
        else:
            raise UnknownParameterError(f"Parameters.replace() got an unexpected keyword argument '{name}': no "
                                        f"parameter of that name")
    read_system(dataclasses.replace(params, system=system), parts_for(validate_variants(params.variants))[0])
    return system


SYSTEM_HOOKS.update(vector=system_vector, scalars=system_scalars, replace=replace_system)
