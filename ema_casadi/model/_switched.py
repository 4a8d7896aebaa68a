"""The switched split of an assembled model (the switched PWM bridge uses it): for a part with ``switched``
signals (the PWM bridge's leg states), the held plant with those signals as an input,
``f_switched(x, u, p, h, s)``, and the part's carrier-period ``schedule(x, u, p, h)``
(see :class:`~ema_casadi.model.assembly.Model`). Private to :mod:`ema_casadi.model.assembly`."""

from __future__ import annotations

import casadi as ca

from .components import AssemblyError, der

__all__ = ["switched_split"]


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
