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
    every part connected (:func:`~ema_casadi.model.components._ports.wiring`)."""
    states, inputs, outputs, providers, owner, state_owner = {}, {}, {}, {}, {}, {}
    loops, holds, stored, loads, heat, masses = {}, [], [], [], {}, []
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
        loads += part.loads
        masses += part.masses
        heat.update(part.heat)
    modify(parts, providers)
    providers["E_stored"] = ("E_stored", lambda b: _sum(b, stored))
    providers["F_load_rod"] = ("F_load_rod", lambda b: _sum(b, loads))
    providers["M_load_rod"] = ("M_load_rod", lambda b: _sum(b, masses))
    for node in HEAT_NODES:
        providers[heat_signal(node)] = (heat_signal(node), lambda b, node=node: _heat(b, node, heat, outputs))
    for n in ("E_stored", "F_load_rod", "M_load_rod", *map(heat_signal, HEAT_NODES)):
        owner[n] = None
    for o in SUMS:
        outputs[o.name] = o
    # an input that a part provides as a signal is internal (the airframe's flight-control
    # law provides the actuator's x_cmd); the model's inputs: signals first, injections last
    inputs = {n: i for n, i in inputs.items() if n not in providers}
    ordered = [i for i in inputs.values() if not i.injection] + [i for i in inputs.values() if i.injection]
    units = {n: d.unit for table in (states, inputs, outputs) for n, d in table.items()}
    table = wiring(parts, owner, state_owner, inputs, units)
    return Declarations(states, {i.name: i for i in ordered}, outputs, providers, loops, tuple(holds),
                        (owner, allowed_reads(parts)), table)


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
