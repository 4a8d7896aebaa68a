"""Input ports: what a part reads from the others, declared beside what it provides.

A part's :attr:`~ema_casadi.model.components.Part.reads` lists the signals it reads that
another part provides (a :class:`Port`: name, SI unit, meaning), the way its ``outputs``
list what it provides and its ``inputs`` the model inputs it reads. The assembly connects
every port to the one provider of that name (same-name wiring: a model of one actuator
needs no table) or to the source a connection table names, and checks both ways when it
builds the model:

- a port that nothing provides is an :class:`~ema_casadi.model.components.AssemblyError`
  naming the part and the port (found when the model is built, not when a signal is
  first traced);
- a part that reads a signal of another part without declaring the port is an
  AssemblyError naming the part and the signal (the bus checks every read while the
  model's expressions are built).

:func:`wiring` returns the connection table (one :class:`Connection` per port and model
input): the model's wiring in one place, printed by ``Model.connections_text()``.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Port", "Connection", "allowed_reads", "wiring", "connections_text"]


@dataclass(frozen=True)
class Port:
    """A signal a part reads that another part provides (an input port).

    Attributes
    ----------
    name : str
        The signal's name on the bus (the provider's name; an instance prefix is added by
        the assembly).
    unit : str
        Its SI unit (the provider's; the assembly checks declared units agree).
    doc : str
        What the part reads it for (one line).
    optional : bool
        The part reads it only where some part provides it (it asks ``name in bus``
        first: the winding temperature a monitor compares only with the thermal network);
        unconnected, it is listed as such, not refused.
    """

    name: str
    unit: str
    doc: str = ""
    optional: bool = False


@dataclass(frozen=True)
class Connection:
    """One row of a model's connection table.

    Attributes
    ----------
    reader : str
        The part that reads (``friction = smooth``, with an instance prefix where there is one).
    port : str
        The port (the name the part reads).
    unit : str
        Its SI unit.
    source : str
        The bus signal it is connected to.
    provider : str
        Who provides it: a part (``screw = elastic``), ``model input`` or ``assembly``
        (a sum the assembly forms: the rod load, the heat into a node).
    """

    reader: str
    port: str
    unit: str
    source: str
    provider: str


def label(part) -> str:
    """``family = value``, with the part's instance name in front where it has one."""
    inst = getattr(part, "instance", "")
    return f"{inst + '.' if inst else ''}{part.family} = {part.value}"


def own_names(part) -> set:
    """The names a part may read without a port: its states and their rates, its model
    inputs and the signals it provides itself."""
    from ._part import der

    names = {s.name for s in part.states} | {der(s.name) for s in part.states} | {i.name for i in part.inputs}
    for key in part.signals():
        names.update(key if isinstance(key, tuple) else (key,))
    return names


def allowed_reads(parts, resolve: dict | None = None) -> dict:
    """``id(part) -> frozenset`` of the names each part may read: its own (:func:`own_names`)
    and its declared ports (each through ``resolve[id(part)]``, the model's name of a
    port: the instance's signal where the part belongs to one)."""
    resolve = resolve or {}
    return {id(p): frozenset(own_names(p) | {resolve.get(id(p), _same)(r.name) for r in p.reads}) for p in parts}


def _same(name: str) -> str:
    return name


def wiring(parts, owner: dict, states: dict, inputs: dict, units: dict, resolve: dict | None = None) -> tuple:
    """The connection table of a model, every port checked: each port a part reads, then
    each model input it declares (from outside, or provided by another part).

    Parameters
    ----------
    parts : sequence of Part
        The model's parts.
    owner : dict
        Bus signal name -> the part providing it (None: the assembly's sums).
    states, inputs : dict
        The model's states and inputs by name -> their declaration's part (states) or
        declaration (inputs).
    units : dict
        Signal name -> declared unit, where some declaration gives one.
    resolve : dict, optional
        ``id(part)`` -> ``fn(port name) -> model name`` (default: the same name).
    """
    from ._part import AssemblyError

    rows = []
    for part in parts:
        to = (resolve or {}).get(id(part), _same)
        for port in part.reads:
            name = to(port.name)
            if name in owner:
                who = owner[name]
                provider = "assembly" if who is None else label(who)
            elif name in states:
                provider = label(states[name])
            elif name in inputs:
                provider = "model input"
            elif port.optional:
                provider = "(unconnected, optional)"
            else:
                raise AssemblyError(f"port '{port.name}' of {label(part)} is connected to nothing: no part "
                                    "provides it (choose a variant that does, or connect it)")
            declared = units.get(name)
            if declared is not None and declared != port.unit:
                raise AssemblyError(f"port '{port.name}' of {label(part)} reads {port.unit}, its provider "
                                    f"{provider} gives {declared}")
            rows.append(Connection(label(part), port.name, port.unit, name, provider))
        for inp in part.inputs:  # its model inputs: from outside, or from a part that provides them
            plain = inp.name.split(".", 1)[1] if getattr(part, "instance", "") else inp.name
            who = owner.get(inp.name, False)
            provider = "model input" if who is False else ("assembly" if who is None else label(who))
            rows.append(Connection(label(part), plain, inp.unit, inp.name, provider))
    return tuple(rows)


def connections_text(rows) -> str:
    """The connection table as aligned text, one port a line (reader, port, unit, provider).

    Parameters
    ----------
    rows : sequence of Connection
        From :func:`wiring`.
    """
    head = ("reads", "port", "unit", "from")
    table = [head] + [(r.reader, r.port, r.unit, r.provider) for r in rows]
    widths = [max(len(row[k]) for row in table) for k in range(3)]
    return "\n".join(f"{a:<{widths[0]}}  {b:<{widths[1]}}  {c:<{widths[2]}}  {d}" for a, b, c, d in table)
