"""Event indicators of the right-hand side: one zero-crossing function per switch.

A solver that steps across a switch of ``f`` (a jump such as the contact damping that
engages when the screw's dead zone closes, or a kink such as a clip) loses its error
control there: at tight tolerances it shrinks its step until it gives up. A
model-exchange FMU therefore declares *event indicators*, functions that change sign
exactly where ``f`` switches, so that the importer's solver locates the switch, stops
there and restarts on the other side.

They are read off the symbolic right-hand side itself, so that no switch can be
forgotten and a new part needs nothing here. Every non-smooth operation in the
expression graph of ``xdot = f(x, u, p)`` contributes the quantity whose sign decides
it:

==========================  ========================
operation                   indicator
==========================  ========================
``fmax(a, b)``, ``fmin``    ``a - b``
``a < b``, ``a <= b``, ==   ``a - b``
``fabs(a)``, ``sign(a)``    ``a``
``floor(a)``, ``ceil(a)``   ``sin(pi a)`` (a zero at every integer)
==========================  ========================

(``fmod``, which no part uses, is left to decide itself.)

Only indicators that depend on the states or the inputs are kept (a switch on a
parameter alone cannot change during a run); duplicates (the same expression, or its
negative) are kept once. A switch reached only through a branch chosen by a parameter
(``if_else(P_blend > 0, tanh(..), sign(q))``) is an event only while that branch is
taken: its indicator is ``if_else(guard, z, 1)``, constant where the branch is off.
The outputs ``y`` are not searched: a switch there does not affect the integration.

Between events the switches are *held* (:func:`switches`), as FMI intends for
relations: each has a mode (the sign of its indicator, or the integer of a floor) and
the right-hand side the importer integrates takes the branch the mode selects instead
of deciding the switch itself, so it is smooth between events. The importer's solver
then cannot see a switch flip inside a step, a difference-quotient Jacobian or a
Newton iterate; this matters most where the solution rests on a switch (the rigid
screw's play, engaged while the nut pushes: the gap stays at B/2 to the last bit, and
a Jacobian column that steps across it reads an infinite slope). The modes are chosen
anew at every event from the state there; an indicator exactly 0 takes the side the
held model moves it to (and keeps its mode where it does not move).
"""

from __future__ import annotations

from typing import NamedTuple

import casadi as ca

from ...model.assembly import Model

__all__ = ["switches", "Switches"]

_DIFF = (ca.OP_FMAX, ca.OP_FMIN, ca.OP_LT, ca.OP_LE, ca.OP_EQ, ca.OP_NE)
_SELF = (ca.OP_FABS, ca.OP_SIGN)
_STEPS = (ca.OP_FLOOR, ca.OP_CEIL)
_NAMES = {ca.OP_FMAX: "fmax", ca.OP_FMIN: "fmin", ca.OP_LT: "<", ca.OP_LE: "<=", ca.OP_EQ: "==",
          ca.OP_NE: "!=", ca.OP_FABS: "fabs", ca.OP_SIGN: "sign", ca.OP_FLOOR: "floor", ca.OP_CEIL: "ceil"}


def _indicator(node: ca.SX):
    op = node.op()
    if op in _DIFF:
        return node.dep(0) - node.dep(1)
    if op in _SELF:
        return node.dep(0)
    if op in _STEPS:
        return ca.sin(ca.pi * node.dep(0))
    return None


def _switch_nodes(roots: list[ca.SX], free: ca.SX):
    """Every non-smooth node below ``roots`` with the parameter guards it is reached under.

    Returns ``[(node, guards)]`` in a fixed order; ``guards`` is a list of paths, each a
    tuple of parameter-only conditions that all hold on it (an empty tuple: unguarded).
    """
    seen, found, index, stack = set(), {}, [], [(r, ()) for r in reversed(roots)]
    while stack:
        node, guard = stack.pop()
        if node.is_leaf():
            continue
        key = (node.element_hash(), tuple(g.element_hash() for g in guard))
        if key in seen:
            continue
        seen.add(key)
        if node.op() in _NAMES:
            if node.element_hash() not in found:
                found[node.element_hash()] = (node, [])
                index.append(node.element_hash())
            found[node.element_hash()][1].append(guard)
        deps = [node.dep(i) for i in range(node.n_dep())]
        if node.op() == ca.OP_IF_ELSE_ZERO and not ca.depends_on(deps[0], free):
            stack.append((deps[1], guard + (deps[0],)))
            stack.append((deps[0], guard))
        else:
            stack.extend((d, guard) for d in reversed(deps))
    return [found[k] for k in index]


def _guarded(z: ca.SX, guards) -> ca.SX:
    if any(len(g) == 0 for g in guards):
        return z
    on = ca.SX(0)
    for path in guards:
        all_on = ca.SX(1)
        for g in path:
            all_on = ca.logic_and(all_on, g)
        on = ca.logic_or(on, all_on)
    return ca.if_else(on, z, 1)


def _branch(op, m, new):
    """The value of a switch node in the branch its mode ``m`` (+1 or -1) selects."""
    if op == ca.OP_FMAX:
        return ca.if_else(m > 0, new[0], new[1])
    if op == ca.OP_FMIN:
        return ca.if_else(m > 0, new[1], new[0])
    if op in (ca.OP_LT, ca.OP_LE):
        return ca.if_else(m > 0, 0, 1)
    if op in (ca.OP_EQ, ca.OP_NE):
        return ca.SX(float(op == ca.OP_NE))
    if op == ca.OP_FABS:
        return ca.if_else(m > 0, new[0], -new[0])
    return m  # sign


def _apply(op, new):
    return ca.SX.unary(op, new[0]) if len(new) == 1 else ca.SX.binary(op, new[0], new[1])


def _rebuild(roots: list[ca.SX], replace: dict) -> list[ca.SX]:
    """``roots`` rebuilt node by node, the nodes whose hash is in ``replace`` by
    ``replace[hash](node, new_deps)`` (post-order, each node once)."""
    memo, stack = {}, [(r, False) for r in roots]
    while stack:
        node, ready = stack.pop()
        key = node.element_hash()
        if key in memo:
            continue
        if node.is_leaf():
            memo[key] = node
            continue
        deps = [node.dep(i) for i in range(node.n_dep())]
        if not ready:
            stack.append((node, True))
            stack.extend((d, False) for d in deps if d.element_hash() not in memo)
            continue
        new = [memo[d.element_hash()] for d in deps]
        memo[key] = replace[key](node, new) if key in replace else _apply(node.op(), new)
    return [memo[r.element_hash()] for r in roots]


class Switches(NamedTuple):
    """The switches of a model's right-hand side (:func:`switches`)."""

    #: ``(x, u, p) -> z``: the event indicators, one per switch (and per distinct quantity).
    z: ca.Function
    #: the operation each indicator decides (``"fmax"``, ``"<="``, ``"floor"``, ...).
    what: list[str]
    #: ``(x, u, p, m) -> m``: the modes the switches take at a point, held in ``m`` so
    #: far: the sign of each indicator (for floor and ceil: the floor of the argument);
    #: where an indicator is exactly 0, the side the held model moves it to, and where
    #: it does not move it, the mode held so far (an exact 0 is where the solution
    #: rests on a switch, such as the rigid screw's play while the nut pushes).
    select: ca.Function
    #: ``(x, u, p, m) -> (xdot, y)``: the model with every switch held in the branch its
    #: mode selects (a mode 0 leaves its switch to decide itself).
    f: ca.Function


def _held(node, new, m):
    """A switch node held in the branch its mode ``m`` selects (``m`` = 0: the node itself)."""
    op = node.op()
    if op in _STEPS:  # the mode is floor(argument); ceil is one more between the integers
        return m + (1 if op == ca.OP_CEIL else 0)
    return ca.if_else(m == 0, _apply(op, new), _branch(op, m, new))


def _select(z, arg, held, x, xdot):
    """The mode of a switch at a point (:attr:`Switches.select`); ``arg``: the argument of
    a floor or ceil, None for the others; ``xdot``: the held model's rate."""
    if arg is not None:  # on an integer and moving down: the interval below
        n = ca.floor(arg)
        return ca.if_else(ca.logic_and(arg == n, ca.jtimes(arg, x, xdot) < 0), n - 1, n)
    zdot = ca.jtimes(z, x, xdot)
    return ca.if_else(z != 0, ca.sign(z), ca.if_else(zdot != 0, ca.sign(zdot), held))


def switches(model: Model) -> Switches:
    """The event indicators of ``model.f``'s right-hand side and the model with its switches held.

    Parameters
    ----------
    model : Model
        The assembled model.

    Returns
    -------
    Switches
        The indicators, their descriptions, the mode selection and the held model.
        Between events an importer integrates the held model (smooth: no switch can
        flip inside a step, in a difference-quotient Jacobian or a Newton iterate);
        at each event the modes are selected anew at the event's state.
    """
    x = ca.SX.sym("x", model.nx)
    u = ca.SX.sym("u", model.nu)
    p = ca.SX.sym("p", len(model.param_names))
    xdot, y = model.f(x, u, p)
    xu = ca.vertcat(x, u)
    z, what, sel, keys, held = [], [], [], {}, {}  # held: node hash -> (mode index, sign)
    for node, guards in _switch_nodes([xdot[i] for i in range(model.nx)], xu):
        e = _indicator(node)
        if e is None or not ca.depends_on(e, xu):
            continue
        e = _guarded(e, guards)
        key, neg = e.element_hash(), (-e).element_hash()
        if key in keys or neg in keys:
            held[node.element_hash()] = (keys[key], 1) if key in keys else (keys[neg], -1)
            continue
        keys[key] = len(z)
        held[node.element_hash()] = (len(z), 1)
        z.append(e)
        what.append(_NAMES[node.op()])
        sel.append(node.dep(0) if node.op() in _STEPS else None)
    m = ca.SX.sym("m", len(z))
    replace = {h: (lambda node, new, k=k, s=s: _held(node, new, -m[k] if s < 0 else m[k]))
               for h, (k, s) in held.items()}
    roots = [xdot[i] for i in range(model.nx)] + [y[i] for i in range(model.ny)]
    out = _rebuild(roots, replace)
    rate = ca.vertcat(*out[:model.nx])
    sel = [_select(zk, a, m[k], x, rate) for k, (zk, a) in enumerate(zip(z, sel, strict=True))]
    vec = ca.vertcat(*z) if z else ca.SX(0, 1)
    opts = {"cse": True}
    return Switches(
        ca.Function("ema_z", [x, u, p], [vec], ["x", "u", "p"], ["z"], opts), what,
        ca.Function("ema_modes", [x, u, p, m], [ca.vertcat(*sel) if sel else ca.SX(0, 1)], ["x", "u", "p", "m"],
                    ["m_now"], opts),
        ca.Function("ema_held", [x, u, p, m], [ca.vertcat(*out[:model.nx]), ca.vertcat(*out[model.nx:])],
                    ["x", "u", "p", "m"], ["xdot", "y"], opts))

