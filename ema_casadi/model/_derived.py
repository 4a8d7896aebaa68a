"""Functions the assembly derives from the parts' declarations besides ``f``: the
sampled-ECU split (``f_held`` and ``sample``) and the hybrid parts' discrete map
(``project``). Used by :func:`ema_casadi.model.assembly.build_model` only."""

from __future__ import annotations

import casadi as ca

from .components import der

__all__ = ["zoh_split", "projection"]


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
