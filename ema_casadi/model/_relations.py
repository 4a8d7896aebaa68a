"""Checks of parameter values beyond a file's own: values valid one by one
that mean nothing together, checked when a parameter set is built; a single flat
value set from elsewhere (a flag, an override), checked as a file's value is."""

from __future__ import annotations

import math

#: Largest dead time as a share of the carrier period 1/f_sw: beyond it the dead time,
#: not the duty, sets the bridge's voltage (the reference: 1.5 us of 62.5 us, 2.4 %).
DEAD_TIME_SHARE = 0.1


def check_relations(src: str, groups: dict, error: type, missing=()) -> None:
    """``error`` for a dead time that eats the carrier period, or an actuator pin
    inside the horn radius (the crank cannot close).

    Parameters
    ----------
    src : str
        The file, named in the message.
    groups : dict
        Group name -> its checked dataclass (``power``, ``airframe``, ``actuator``).
    error : type
        The exception raised (ParameterError).
    missing : iterable of str
        Groups the file does not have (checked when a variant reads them).
    """
    pw = groups["power"]
    if "power" not in missing and pw.t_dead >= DEAD_TIME_SHARE / pw.f_sw:
        raise error(f"{src}: [power] t_dead: {pw.t_dead:g} s is {100 * pw.t_dead * pw.f_sw:.3g} % of the "
                    f"carrier period 1/f_sw = {1 / pw.f_sw:g} s; it must stay below "
                    f"{100 * DEAD_TIME_SHARE:g} % (DEAD_TIME_SHARE)")
    af, stroke = groups["airframe"], groups["actuator"].stroke
    a, r = af.a_pin, af.r_horn
    if {"airframe", "actuator"} & set(missing):
        return
    if not a > r or not a - r < math.sqrt(a * a - r * r) - stroke:
        raise error(f"{src}: [airframe] a_pin: {a:g} m with r_horn {r:g} m and a stroke of +-{stroke:g} m: "
                    "the crank cannot reach the stroke's ends (need a_pin > r_horn and "
                    "sqrt(a_pin^2 - r_horn^2) - stroke > a_pin - r_horn)")
