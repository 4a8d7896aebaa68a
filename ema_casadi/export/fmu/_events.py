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
``fmod(a, b)``              ``sin(pi a / b)``
==========================  ========================

Only indicators that depend on the states or the inputs are kept (a switch on a
parameter alone cannot change during a run); duplicates (the same expression, or its
negative) are kept once. A switch reached only through a branch chosen by a parameter
(``if_else(P_blend > 0, tanh(..), sign(q))``) is an event only while that branch is
taken: its indicator is ``if_else(guard, z, 1)``, constant where the branch is off.
The outputs ``y`` are not searched: a switch there does not affect the integration.
"""

from __future__ import annotations

import casadi as ca

from ...model.assembly import Model

__all__ = ["switch_indicators"]

_DIFF = (ca.OP_FMAX, ca.OP_FMIN, ca.OP_LT, ca.OP_LE, ca.OP_EQ, ca.OP_NE)
_SELF = (ca.OP_FABS, ca.OP_SIGN)
_STEPS = (ca.OP_FLOOR, ca.OP_CEIL)
_NAMES = {ca.OP_FMAX: "fmax", ca.OP_FMIN: "fmin", ca.OP_LT: "<", ca.OP_LE: "<=", ca.OP_EQ: "==",
          ca.OP_NE: "!=", ca.OP_FABS: "fabs", ca.OP_SIGN: "sign", ca.OP_FLOOR: "floor", ca.OP_CEIL: "ceil",
          ca.OP_FMOD: "fmod"}


def _indicator(node: ca.SX):
    op = node.op()
    if op in _DIFF:
        return node.dep(0) - node.dep(1)
    if op in _SELF:
        return node.dep(0)
    if op in _STEPS:
        return ca.sin(ca.pi * node.dep(0))
    if op == ca.OP_FMOD:
        return ca.sin(ca.pi * node.dep(0) / node.dep(1))
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


def switch_indicators(model: Model) -> tuple[ca.Function, list[str]]:
    """The event indicators of ``model.f``'s right-hand side.

    Parameters
    ----------
    model : Model
        The assembled model.

    Returns
    -------
    (Function, list of str)
        ``z(x, u, p) -> z`` (one entry per switch, in the order found) and a short
        description of each (the operation it decides, e.g. ``"fmax"``).
    """
    x = ca.SX.sym("x", model.nx)
    u = ca.SX.sym("u", model.nu)
    p = ca.SX.sym("p", len(model.param_names))
    xdot = model.f(x, u, p)[0]
    xu = ca.vertcat(x, u)
    z, what, keys = [], [], set()
    for node, guards in _switch_nodes([xdot[i] for i in range(model.nx)], xu):
        e = _indicator(node)
        if e is None or not ca.depends_on(e, xu):
            continue
        e = _guarded(e, guards)
        key, neg = e.element_hash(), (-e).element_hash()
        if key in keys or neg in keys:
            continue
        keys.add(key)
        z.append(e)
        what.append(_NAMES[node.op()])
    fn = ca.Function("ema_z", [x, u, p], [ca.vertcat(*z) if z else ca.SX(0, 1)], ["x", "u", "p"], ["z"],
                     {"cse": True})
    return fn, what
