"""The assembly's wiring: what the parts declare merged into one set of states, inputs,
outputs and signal providers, with who provides each signal (the owner the bus checks
reads against) and the connection table of the parts' ports
(:mod:`~ema_casadi.model.components._ports`). Used by :mod:`ema_casadi.model.assembly` only."""

from __future__ import annotations

from dataclasses import dataclass

from ._derived import modify
from .components import HEAT_NODES, AssemblyError, Output, heat_signal
from .components._ports import allowed_reads, wiring
from .params import ParameterError, Parameters

__all__ = ["Declarations", "declarations", "check_tables"]

#: Outputs the assembly adds to those of the parts.
SUMS = (Output("E_stored", "J", "stored energy: kinetic + spring + magnetic (+ end stop)", kind="energy",
               roles=("stored_energy",)),)


@dataclass
class Declarations:
    """The parts' declarations merged (name -> declaration, in assembly order)."""

    states: dict
    inputs: dict
    outputs: dict
    providers: dict
    loops: dict
    holds: tuple
    guard: tuple
    connections: tuple


def declarations(parts) -> Declarations:
    """Merge what the parts declare; a name declared twice must agree; every port of
    every part connected (:func:`~ema_casadi.model.components._ports.wiring`). Parts of
    an instance (``part.instance``, see :mod:`~ema_casadi.model._instances`) have their
    own sums (``A.F_load_rod``, ``A.P_heat_winding``); the stored energy is one sum."""
    states, inputs, outputs, providers, owner, state_owner = {}, {}, {}, {}, {}, {}
    loops, holds, stored, sums = {}, [], [], {}
    for part in parts:
        for s in part.states:
            if s.name in states:
                raise AssemblyError(f"state '{s.name}' declared by two parts")
            states[s.name] = s
            state_owner[s.name] = part
        for i in part.inputs:
            if inputs.setdefault(i.name, i) != i:
                raise AssemblyError(f"input '{i.name}' declared differently by two parts")
        for o in part.outputs:
            if outputs.setdefault(o.name, o) != o:
                raise AssemblyError(f"output '{o.name}' declared differently by two parts")
        for key, fn in part.signals().items():
            for n in key if isinstance(key, tuple) else (key,):
                if n in providers:
                    raise AssemblyError(f"signal '{n}' provided by two parts ({part.family}={part.value})")
                providers[n] = (key, fn)
                owner[n] = part
        loops.update({lp.name: lp for lp in part.loops})
        holds += part.holds
        stored += part.stored
        group = sums.setdefault(getattr(part, "instance", ""), {"loads": [], "masses": [], "heat": {}})
        group["loads"] += part.loads
        group["masses"] += part.masses
        group["heat"].update(part.heat)
    modify(parts, providers)
    providers["E_stored"] = ("E_stored", lambda b: _sum(b, stored))
    owner["E_stored"] = None
    for inst, group in sums.items():
        _add_sums(providers, owner, outputs, inst, group)
    for o in SUMS:
        outputs[o.name] = o
    # an input that a part provides as a signal is internal (the airframe's flight-control
    # law provides the actuator's x_cmd); the model's inputs: signals first, injections last
    known = set(providers) | set(states) | set(inputs)
    inputs = {n: i for n, i in inputs.items() if n not in providers}
    ordered = [i for i in inputs.values() if not i.injection] + [i for i in inputs.values() if i.injection]
    units = {n: d.unit for table in (states, inputs, outputs) for n, d in table.items()}
    resolve = {id(p): _resolver(p, known) for p in parts}
    table = wiring(parts, owner, state_owner, inputs, units, resolve)
    return Declarations(states, {i.name: i for i in ordered}, outputs, providers, loops, tuple(holds),
                        (owner, allowed_reads(parts, resolve)), table)


def _resolver(part, known):
    """How a part's port names map to the model's: ``inst.n`` where the model has it
    (a part of an instance), else ``n``."""
    inst, connect = getattr(part, "instance", ""), getattr(part, "connect", {})
    if not inst:
        return lambda n: n
    return lambda n: connect[n] if n in connect else (f"{inst}.{n}" if f"{inst}.{n}" in known else n)


def _add_sums(providers, owner, outputs, inst, group) -> None:
    """The sums the assembly forms for one instance (or the model, ``inst`` empty): the
    load and the masses on the rod, the heat into each thermal node."""
    pre = (lambda n: f"{inst}.{n}") if inst else (lambda n: n)
    loads, masses, heat = group["loads"], group["masses"], group["heat"]
    providers[pre("F_load_rod")] = (pre("F_load_rod"), lambda b: _sum(b, loads))
    providers[pre("M_load_rod")] = (pre("M_load_rod"), lambda b: _sum(b, masses))
    for node in HEAT_NODES:
        name = pre(heat_signal(node))
        providers[name] = (name, lambda b, node=node: _heat(b, node, heat, outputs))
    for n in ("F_load_rod", "M_load_rod", *map(heat_signal, HEAT_NODES)):
        owner[pre(n)] = None


def _heat(bus, node, heat, outputs):
    """The losses routed to ``node``, summed; every loss output must be routed."""
    unrouted = [n for n, o in outputs.items() if o.kind == "loss" and n not in heat]
    wrong = {n: v for n, v in heat.items() if v not in HEAT_NODES}
    if unrouted or wrong:
        raise AssemblyError(f"losses {unrouted} heat no thermal node; nodes {wrong} unknown (expected one of "
                            f"{', '.join(HEAT_NODES)}): declare each loss in its part's heat table")
    return _sum(bus, [n for n, v in heat.items() if v == node])


def _sum(bus, names):
    terms = [bus[n] for n in names]
    total = terms[0] if terms else 0
    for t in terms[1:]:
        total = total + t
    return total


def check_tables(params: Parameters, parts) -> None:
    """Refuse a model whose parts read a table the parameter file does not have."""
    if not params.missing:
        return
    group_of = params.group_of()
    for part in parts:
        for name in part.params:
            if group_of.get(name) in params.missing:
                raise ParameterError(f"{params.source}: missing table [{group_of[name]}] (its key '{name}' is read "
                                     f"by {part.family} = {part.value}); add the table or choose another variant")
