"""Named instances of the actuator's parts: the same parts, their names prefixed.

A model of several actuators holds each actuator's parts once per instance
(``A``, ``B``): :class:`Instanced` wraps a part so that every name it declares carries the
instance's prefix (states ``A.x_rod``, inputs ``A.d_x``, outputs ``B.i_q``, parameters
``A.F_seal``, loops ``A.position``, roles ``A.rod_position``) while the part's own code
keeps reading its plain names: it sees the bus through a :class:`View` that resolves a
name ``n`` to ``A.n`` where the model has that signal and to the shared ``n`` otherwise
(the surface's hinge load, or a signal a shared part provides under the instance's
name: the surface gives ``A.f_ext``, the equaliser ``A.x_cmd``). Its parameters are the
instance's copies (``A.K_x``). Used by :mod:`ema_casadi.model.assembly` only.
"""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

from .components import AssemblyError, Freeze, Gain, Hold, Limit, Loop, Part, Rating, der

__all__ = ["Instanced", "View", "prefixed", "Local"]


def prefixed(inst: str, name: str) -> str:
    """``inst.name``; ``der(inst.x)`` for a state's rate ``der(x)``; ``name`` when ``inst`` is empty."""
    if not inst:
        return name
    if name.startswith("der(") and name.endswith(")"):
        return der(prefixed(inst, name[4:-1]))
    return f"{inst}.{name}"


class Local:
    """A mapping or namespace seen from an instance: ``n`` reads ``inst.n`` where it exists,
    else ``n`` (outputs by name for a trim limit, parameter values for a bound)."""

    def __init__(self, inner, inst: str):
        self._inner, self._inst = inner, inst

    def _get(self, name):
        local = f"{self._inst}.{name}"
        if isinstance(self._inner, dict):
            return self._inner[local] if local in self._inner else self._inner[name]
        return getattr(self._inner, local) if hasattr(self._inner, local) else getattr(self._inner, name)

    def __getitem__(self, name):
        return self._get(name)

    def __getattr__(self, name):
        if name.startswith("_"):
            raise AttributeError(name)
        return self._get(name)

    def __contains__(self, name):
        return f"{self._inst}.{name}" in self._inner or name in self._inner


class View:
    """The bus as one instance's part sees it (a :class:`~ema_casadi.model.components.Bus`
    with names resolved: ``n`` -> ``inst.n`` where the model has it, else the shared ``n``)."""

    def __init__(self, root, inst: str, P: SimpleNamespace, connect: dict | None = None):
        self._root, self._inst, self.P, self._connect = root, inst, P, connect or {}
        self.x, self.u = root.x, root.u

    def name(self, n: str) -> str:
        """The model's name of the signal the part calls ``n``."""
        if n in self._connect:
            return self._connect[n]
        if n.startswith(f"{self._inst}.") or n.startswith(f"der({self._inst}."):
            return n
        local = prefixed(self._inst, n)
        if n.startswith("der("):
            return local
        return local if local in self._root else n

    def __contains__(self, n: str) -> bool:
        return self.name(n) in self._root

    def __getitem__(self, n: str):
        return self._root[self.name(n)]

    def state_name(self, role: str) -> str:
        return self._root.state_name(f"{self._inst}.{role}")

    def state(self, role: str):
        return self._root[self.state_name(role)]

    def feedback(self, loop: Loop):
        return getattr(self.P, loop.flag) * self[loop.measured] + self[loop.injection]

    def acting(self, part, fn, *args):
        return self._root.acting(part, lambda b, *a: fn(self, *a), *args)


def _state(s, inst):
    """A state's declaration for instance ``inst``: names prefixed, its functions of the
    parameters and outputs reading the instance's."""
    def local(fn):
        return None if fn is None else (lambda *a: fn(*(Local(x, inst) for x in a)))

    seed = None if s.seed is None else dataclasses.replace(s.seed, offset=local(s.seed.offset),
                                                            warn=local(s.seed.warn))
    node = None if s.node is None else dataclasses.replace(s.node, capacity=local(s.node.capacity),
                                                            limit=local(s.node.limit))
    return dataclasses.replace(s, name=prefixed(inst, s.name), roles=_roles(inst, s.roles), loop=_opt(inst, s.loop),
                               rest=_opt(inst, s.rest), scale=local(s.scale), travel=local(s.travel),
                               rest_when=local(s.rest_when), seed=seed, node=node)


def _roles(inst, roles):
    return tuple(f"{inst}.{r}" for r in roles)


def _opt(inst, name):
    return None if name is None else f"{inst}.{name}"


class Instanced(Part):
    """One part of an instance: its declarations with the instance's prefix, its
    equations on a :class:`View`.

    Parameters
    ----------
    part : Part
        The part (as the registry assembles it).
    inst : str
        The instance's name (``A``).
    connect : dict, optional
        Port -> the model signal it reads instead of the same-name one.
    """

    def __init__(self, part: Part, inst: str, connect: dict | None = None):
        if part.trim_free or part.trim_fix or part.conditions:
            raise AssemblyError(f"{part.family} = {part.value} cannot be part of an instance (it trims the model)")
        super().__init__(part.opt)
        self.inner, self.instance, self.connect = part, inst, dict(connect or {})
        self.family, self.value, self.doc = part.family, part.value, part.doc
        pre = self._name
        self.states = tuple(_state(s, inst) for s in part.states)
        self.inputs = tuple(dataclasses.replace(
            i, name=pre(i.name), roles=_roles(inst, i.roles), noise=_opt(inst, i.noise), seed=_opt(inst, i.seed),
            default=pre(i.default) if isinstance(i.default, str) else i.default) for i in part.inputs)
        self.outputs = tuple(dataclasses.replace(
            o, name=pre(o.name), roles=_roles(inst, o.roles), threshold=_opt(inst, o.threshold),
            confirm=_opt(inst, o.confirm), alarm=_opt(inst, o.alarm)) for o in part.outputs)
        self.reads, self.limits, self.smooth, self.requires = part.reads, part.limits, part.smooth, part.requires
        self.params = tuple(map(pre, part.params))
        self.options = part.options  # and the parameters each law uses, prefixed
        self.option_params = {o: {v: tuple(map(pre, n)) for v, n in laws.items()}
                              for o, laws in part.option_params.items()}
        self.loops = tuple(Loop(pre(lp.name), pre(lp.flag), pre(lp.injection), pre(lp.measured), pre(lp.rate))
                           for lp in part.loops)
        self.holds = tuple(Hold(pre(h.name), h.unit, pre(h.loop)) for h in part.holds)
        self.stored, self.loads = tuple(map(pre, part.stored)), tuple(map(pre, part.loads))
        self.masses, self.switched = tuple(map(pre, part.masses)), tuple(map(pre, part.switched))
        self.carrier = _opt(inst, part.carrier)
        self.heat = {pre(k): v for k, v in part.heat.items()}
        self.small_signal = {pol: {val: d if isinstance(d, str) else {pre(k): x for k, x in d.items()}
                                   for val, d in vals.items()} for pol, vals in part.small_signal.items()}
        self.freeze = tuple(Freeze(pre(f.signal), {pre(k): fn for k, fn in f.inputs.items()},
                                   {pre(k): fn for k, fn in f.params.items()},
                                   None if f.nominal is None else (lambda P, f=f: f.nominal(Local(P, inst))))
                            for f in part.freeze)
        self.trim_limits = tuple(dataclasses.replace(
            lim, name=pre(lim.name), lift=tuple(map(pre, lim.lift)),
            value=lambda y, P, lim=lim: lim.value(Local(y, inst), Local(P, inst)),
            limit=lambda P, lim=lim: lim.limit(Local(P, inst))) for lim in part.trim_limits)
        self.ratings = tuple(dataclasses.replace(
            r, name=pre(r.name), signals=tuple(map(pre, r.signals)), limit=lambda P, r=r: r.limit(Local(P, inst)))
            for r in part.ratings if isinstance(r, Rating))
        self.gains = tuple(Gain(pre(g.name), pre(g.loop), g.kind, g.zero_scale) for g in part.gains)
        # a fault names its channel: ``jam`` of B is the kind jam with the target B, a
        # sensor fault on B's rod sensor the target B.x_s
        self.faults = tuple(dataclasses.replace(f, input=pre(f.input), target=inst if f.target is None else pre(
            f.target)) for f in part.faults)
        self._P = None
        assert all(isinstance(lim, Limit) for lim in self.trim_limits)

    def _name(self, name: str) -> str:
        return prefixed(self.instance, name)

    def bind(self, P: SimpleNamespace, names) -> None:
        """Give the instance its parameter namespace: each flat name its ``inst.`` copy.

        Parameters
        ----------
        P : SimpleNamespace
            The model's parameter symbols by name.
        names : iterable of str
            The flat names the instance has copies of.
        """
        self._P = SimpleNamespace(**{n: getattr(P, f"{self.instance}.{n}") for n in names})

    def view(self, b) -> View:
        """The bus ``b`` as this instance sees it."""
        return View(b, self.instance, self._P, self.connect)

    def signals(self) -> dict:
        out = {}
        for key, fn in self.inner.signals().items():
            new = tuple(map(self._name, key)) if isinstance(key, tuple) else self._name(key)
            out[new] = lambda b, fn=fn: fn(self.view(b))
        return out

    def modify(self) -> dict:
        return {self._name(n): (lambda b, v, fn=fn: fn(self.view(b), v)) for n, fn in self.inner.modify().items()}

    def adjust(self) -> dict:
        return {self._name(n): (lambda P, u, fn=fn: fn(Local(P, self.instance), Local(u, self.instance)))
                for n, fn in self.inner.adjust().items()}

    def project(self, prev, now):
        mapped = self.inner.project(self.view(prev), self.view(now))
        if mapped is None:
            return None
        resets, stick = mapped
        return {k if k.startswith(f"{self.instance}.") else self._name(k): v for k, v in resets.items()}, stick

    def schedule(self, bus):
        return self.inner.schedule(self.view(bus))

    @property
    def hybrid(self) -> bool:
        return self.inner.hybrid
