"""Functions the assembly derives from the parts' declarations besides ``f``: the
sampled-ECU split (``f_held`` and ``sample``), the switched split of a PWM bridge
(``f_switched`` and the carrier-period ``schedule``) and the hybrid parts' discrete map
(``project``); and :class:`Contract`, the parts' declarations for the analyses merged
(a base of the Model). Used by :mod:`ema_casadi.model.assembly` only."""

from __future__ import annotations

import casadi as ca

from .components import POLICIES, AssemblyError, Rating, der

__all__ = ["zoh_split", "switched_split", "projection", "Contract", "modify"]


def zoh_split(bus, evaluate, x, u, p, P, X, states, loops, holds, integrators):
    """The sampled-ECU split: ``f_held`` (plant with the controller outputs held and
    the controller integrators frozen) and ``sample`` (one ECU update: each flagged
    loop recomputes its held outputs and integrates its state by forward Euler over its
    own sample period; loops run outer to inner, each seeing the outer loop's new value)."""
    h = ca.SX.sym("h", len(holds))
    held = {hd.name: h[i] for i, hd in enumerate(holds)}
    frozen = {der(n): 0 for n in integrators}
    dots_h, y_h = evaluate(bus(overrides={**held, **frozen}))
    f_held = ca.Function("f_held", [x, u, p, h], [dots_h, y_h], ["x", "u", "p", "h"], ["xdot", "y"])

    flags = ca.SX.sym("flags", len(loops))
    flag = {name: flags[k] for k, name in enumerate(loops)}
    wrap = {hd.name: (lambda b, val, hd=hd: ca.if_else(flag[hd.loop], val, held[hd.name])) for hd in holds}
    bs = bus(wrap=wrap)
    x_new = {n: X[n] for n in states}
    for n in integrators:
        loop = loops[states[n].loop]
        x_new[n] = X[n] + flag[loop.name] * (1 / getattr(P, loop.rate)) * bs[der(n)]
    sample = ca.Function(
        "sample", [x, u, p, h, flags],
        [ca.vertcat(*x_new.values()), ca.vertcat(*[bs[hd.name] for hd in holds])],
        ["x", "u", "p", "h", "flags"], ["x_next", "h_next"],
    )
    return f_held, sample


def switched_split(parts, bus, evaluate, x, u, p, holds, integrators) -> dict:
    """The switched split of a model with a switched part (see :class:`Model`): the held
    plant with the switched signals as an input, and the carrier-period schedule."""
    switched = [n for part in parts for n in part.switched]
    owners = [part for part in parts if part.switched]
    if not owners:
        return {}
    if len(owners) > 1:
        raise AssemblyError(f"two switched parts: {', '.join(f'{o.family}={o.value}' for o in owners)}")
    h = ca.SX.sym("h", len(holds))
    held = {hd.name: h[i] for i, hd in enumerate(holds)}
    frozen = {der(n): 0 for n in integrators}
    sw = ca.SX.sym("s", len(switched))
    dots, y = evaluate(bus(overrides={**held, **frozen, **{n: sw[i] for i, n in enumerate(switched)}}))
    f_switched = ca.Function("f_switched", [x, u, p, h, sw], [dots, y], ["x", "u", "p", "h", "s"], ["xdot", "y"])
    halves = owners[0].schedule(bus(overrides=dict(held)))
    D = ca.horzcat(*[ca.vertcat(*dur) for dur, _ in halves]).T
    S = ca.horzcat(*[ca.vertcat(*vals) for _, states in halves for vals in states])
    schedule = ca.Function("schedule", [x, u, p, h], [D, S], ["x", "u", "p", "h"], ["D", "S"])
    return {"switched": tuple(switched), "carrier": owners[0].carrier, "f_switched": f_switched,
            "schedule": schedule}


def projection(parts, bus, x, u, p):
    """``project(x_prev, x, u, p) -> (x_next, stick)`` from the hybrid parts' maps; the
    stick test uses the continuous model's signals at ``x_prev`` and ``x``."""
    X_prev = {n: ca.SX.sym(n + "_prev") for n in bus().x}
    x_prev = ca.vertcat(*X_prev.values())
    now, prev = bus(), bus(X_prev)
    resets, sticks = {}, []
    for part in parts:
        mapped = part.project(prev, now)
        if mapped is not None:
            resets.update(mapped[0])
            sticks.append(mapped[1])
    stick = sticks[0] if len(sticks) == 1 else (ca.SX(0) if not sticks else ca.logic_or(*sticks))
    x_next = ca.vertcat(*[resets.get(n, sym) for n, sym in now.x.items()])
    return ca.Function("project", [x_prev, x, u, p], [x_next, stick], ["x_prev", "x", "u", "p"], ["x_next", "stick"])


class Contract:
    """What the model's parts declare for the analyses (the part contract), merged:
    a base of :class:`~ema_casadi.model.assembly.Model` (it reads ``parts``, ``state_info``,
    ``input_info``, ``output_info``, ``outputs`` and :meth:`pdict`)."""

    # -- signals by role -----------------------------------------------------------
    def inputs_with(self, role: str) -> tuple[str, ...]:
        """Names of the inputs that declare ``role``.

        Parameters
        ----------
        role : str
            An input role (:data:`~ema_casadi.model.components.INPUT_ROLES`), e.g. ``load``.
        """
        return tuple(n for n, i in self.input_info.items() if role in i.roles)

    def input_with(self, role: str) -> str:
        """The name of the one input with ``role`` (``command`` -> ``x_cmd``); AssemblyError
        if there is not exactly one (``command`` behind an airframe: its law drives the rod).

        Parameters
        ----------
        role : str
            An input role (:data:`~ema_casadi.model.components.INPUT_ROLES`).
        """
        return _one(self._lead(self.inputs_with, role), role, "inputs")

    def needs_input(self, role: str, what: str, error: type) -> str:
        """The name of the one input with ``role``, else ``error`` (one line): ``what``
        needs it, and the variant choice that took it away (``airframe=transport``: the
        pitch law commands the rod, the model takes ``theta_cmd``).

        Parameters
        ----------
        role : str
            An input role (``command``, ``load``).
        what : str
            What needs it, for the message (``"optimal_move"``).
        error : type
            The exception raised (the caller's, of the InputError family).
        """
        names = self._lead(self.inputs_with, role)
        if len(names) == 1:
            return names[0]
        from .components import DEFAULT_VARIANTS, SIGNAL_KEYS

        chosen = ", ".join(f"{k}={v}" for k, v in self.variants.items() if DEFAULT_VARIANTS.get(k) != v)
        others = [n for n in self.inputs if n.endswith("_cmd")] if role == "command" else []
        by = f" (it takes {', '.join(others)})" if others else ""
        raise error(f"variant {chosen or 'choice'}: {what} needs the {role} input {SIGNAL_KEYS.get(role, role)}; "
                    f"this model has {', '.join(names) or 'none'}{by}")

    def outputs_with(self, role: str) -> tuple[str, ...]:
        """Names of the outputs that declare ``role``.

        Parameters
        ----------
        role : str
            An output role (:data:`~ema_casadi.model.components.OUTPUT_ROLES`), e.g. ``rod_position``.
        """
        return tuple(n for n, o in self.output_info.items() if role in o.roles)

    def output_with(self, role: str) -> str:
        """The name of the one output with ``role``; AssemblyError if there is not exactly one.
        With several actuator instances, a role no shared part plays is the lead
        (first) instance's.

        Parameters
        ----------
        role : str
            An output role (:data:`~ema_casadi.model.components.OUTPUT_ROLES`).
        """
        return _one(self._lead(self.outputs_with, role), role, "outputs")

    def signals_with(self, role: str) -> tuple[str, ...]:
        """The outputs with ``role``, else the states, else the inputs (the columns of a
        result that play the role: ``pitch_attitude`` -> ``("theta",)``); () if none.

        Parameters
        ----------
        role : str
            An output, state or input role.
        """
        for names in (self.outputs_with(role), self.states_with(role), self.inputs_with(role)):
            if names:
                return names
        return ()

    def signal_with(self, role: str) -> str:
        """The one signal of :meth:`signals_with`; AssemblyError if there is not exactly one.

        Parameters
        ----------
        role : str
            An output, state or input role.
        """
        return _one(self._lead(self.signals_with, role), role, "signals")

    def _lead(self, lookup, role: str) -> tuple:
        """``lookup(role)``; in a model of several actuator instances, where no shared part
        plays the role, the first instance's (the lead channel, ``A.i_q`` for
        ``motor_current``): the analyses that measure one actuator measure it."""
        names = lookup(role)
        system = getattr(self, "system", None)
        if names or system is None:
            return names
        return lookup(f"{system.channels[0]}.{role}")

    def input_name(self, key: str) -> str:
        """The input a key names: an input's name as is, else the one input with that role.

        Parameters
        ----------
        key : str
            An input name (``f_ext``) or role (``load``).
        """
        if key in self.input_info:
            return key
        from .components import INPUT_ROLES

        if key in INPUT_ROLES:
            return self.input_with(key)
        from .._util._checks import nearest

        raise AssemblyError(f"'{key}' is neither an input of this model nor an input role"
                            f"{nearest(key, [*self.input_info, *INPUT_ROLES])}")

    def small_signal(self, **policies: str) -> dict[str, float]:
        """The parameter overrides of small-signal policies, merged from the parts.

        Raises :class:`~ema_casadi.model.components.AssemblyError` (a ValueError) with the
        one-line reason of a part that refuses a policy value, or for an unknown one.

        Parameters
        ----------
        **policies : str
            Policy -> value (:data:`~ema_casadi.model.components.POLICIES`), e.g.
            ``friction="off"``.
        """
        overrides: dict[str, float] = {}
        for policy, value in policies.items():
            allowed = POLICIES.get(policy)
            if allowed is None or value not in allowed:
                what = f"{policy} policy '{value}' unknown" if allowed else f"unknown policy '{policy}'"
                raise AssemblyError(f"{what}; choose one of {', '.join(allowed or POLICIES)}")
            for part in self.parts:
                declared = part.small_signal.get(policy, {}).get(value, {})
                if isinstance(declared, str):
                    raise AssemblyError(declared)
                overrides.update(declared)
        return overrides

    @property
    def freezes(self) -> tuple:
        """What the linearisation freezes (:class:`~ema_casadi.model.components.Freeze`), from the parts."""
        return tuple(fz for part in self.parts for fz in part.freeze)

    @property
    def trim_limits(self) -> tuple:
        """The saturations a trim keeps inactive (:class:`~ema_casadi.model.components.Limit`)."""
        return tuple(lim for part in self.parts for lim in part.trim_limits)

    def limit_values(self, p=None) -> dict[str, float]:
        """Each trim limit's value (SI) by name (``current``: A, ``rod_speed``: m/s, ...).

        Parameters
        ----------
        p : array_like, optional
            Parameter vector (SI); default the model's set.
        """
        P = self.pdict(p)
        return self._with_lead({lim.name: float(lim.limit(P)) for lim in self.trim_limits})

    def _with_lead(self, values: dict) -> dict:
        """``values``, and in a model of several actuator instances the lead instance's
        (``A.rod_speed``) under the plain name (``rod_speed``) as well."""
        system = getattr(self, "system", None)
        if system is None:
            return values
        lead = f"{system.channels[0]}."
        return {**{k[len(lead):]: v for k, v in values.items() if k.startswith(lead)}, **values}

    @property
    def ratings(self) -> tuple:
        """The operating limits (:class:`~ema_casadi.model.components.Rating`): the parts'
        ratings and, for every thermal node state, its rated temperature (``<node>_temperature``)."""
        nodes = tuple(Rating(f"{s.node.name}_temperature", f"rated {s.node.name} temperature", (n,), s.node.limit,
                             f"the {s.node.name} node's rating", s.unit, sense="max")
                      for n, s in self.state_info.items() if s.node is not None)
        return tuple(r for part in self.parts for r in part.ratings) + nodes

    def operating_limits(self, p=None) -> dict[str, float]:
        """Each operating limit's value (SI) by name (``current``: A, ``voltage``: V,
        ``stroke``: m, ``rod_speed``: m/s, ``winding_temperature``: degC, ...): what an
        optimal move is constrained by (:attr:`ratings`).

        Parameters
        ----------
        p : array_like, optional
            Parameter vector (SI); default the model's set.
        """
        P = self.pdict(p)
        return self._with_lead({r.name: float(r.limit(P)) for r in self.ratings})

    def heat_outputs(self, node: str) -> tuple[str, ...]:
        """The loss outputs the parts route to a thermal node (their ``heat`` tables).

        Parameters
        ----------
        node : str
            One of :data:`~ema_casadi.model.components.HEAT_NODES` (``winding``, ...).
        """
        routed = {n: v for part in self.parts for n, v in part.heat.items()}
        return tuple(n for n in self.outputs if routed.get(n) == node)

    @property
    def smooth_variants(self) -> dict:
        """Variant key -> value of the smooth counterparts the parts declare where they
        switch (hybrid friction -> smooth, the switched bridge -> averaged, the clip
        limits -> smooth): {} for a model that is smooth already."""
        return {k: v for part in self.parts for k, v in part.smooth.items() if self.variants.get(k) != v}

    @property
    def gains(self) -> tuple:
        """The tunable gains of the model's parts (:class:`~ema_casadi.model.components.Gain`), outer loop first."""
        return tuple(g for part in self.parts for g in part.gains)

    def rest_states(self, p=None) -> dict[str, str]:
        """Memory states the trim holds at a signal: state -> signal (their ``rest``
        rule, where it applies for the parameter vector).

        Parameters
        ----------
        p : array_like, optional
            Parameter vector (SI); default the model's set.
        """
        P = self.pdict(p)
        return {n: s.rest for n, s in self.state_info.items()
                if s.rest is not None and (s.rest_when is None or bool(s.rest_when(P)))}

    @property
    def memory_states(self) -> tuple[str, ...]:
        """States that may be neutral modes of a linearisation (:attr:`State.memory`)."""
        return tuple(n for n, s in self.state_info.items() if s.memory)


def _one(names: tuple, role: str, what: str) -> str:
    if len(names) != 1:
        raise AssemblyError(f"the model has {len(names)} {what} with role '{role}', expected one")
    return names[0]


def modify(parts, providers) -> None:
    """Apply every part's signal modifiers (:meth:`~ema_casadi.model.components.Part.modify`)
    to the providers, in assembly order."""
    for part in parts:
        for name, fn in part.modify().items():
            _modify(providers, name, fn, part)


def _modify(providers, name, fn, part):
    """Wrap the provider of ``name`` so that ``fn(bus, value)`` replaces its value
    (:meth:`~ema_casadi.model.components.Part.modify`)."""
    if name not in providers:
        raise AssemblyError(f"{part.family}={part.value} modifies '{name}', which no part provides")
    key, prov = providers[name]

    def wrapped(b):
        val = prov(b)
        if not isinstance(key, tuple):
            return b.acting(part, fn, val)
        vals = list(val)
        vals[key.index(name)] = b.acting(part, fn, vals[key.index(name)])
        return tuple(vals)

    for n in key if isinstance(key, tuple) else (key,):
        providers[n] = (key, wrapped)
