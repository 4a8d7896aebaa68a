"""The registry: every variant key and value mapped to the part that serves it.

Adding a variant is one part class (in its family's module) plus one entry here. The
first value of each key is its default. Options (sub-choices a part reads, such as the
smooth friction's ``friction_shape``) are declared by the parts themselves.
"""

from __future__ import annotations

import itertools

from ..._util._checks import nearest as _nearest
from ..params import ParameterError
from . import (
    airframe,
    ballscrew,
    controller,
    endstop,
    faults,
    friction,
    inverter,
    load,
    monitors,
    motor,
    sensor,
    supply,
    thermal,
)
from ._part import AssemblyError, Part

__all__ = ["REGISTRY", "VARIANTS", "DEFAULT_VARIANTS", "OPTIONS", "VariantError", "validate_variants", "parts_for",
           "PART_CLASSES", "served_by"]


class VariantError(ParameterError):
    """An unknown variant key or value; the one-line message lists the allowed ones."""


def _off(key: str, value: str = "off") -> type:
    """The part of a family that is switched off: it brings nothing."""
    return type(f"{key.title()}Off", (Part,), {"family": key, "value": value, "doc": f"no {key}"})


#: Variant key -> value -> part class, in assembly order (outer controller to rod).
REGISTRY: dict[str, dict[str, type]] = {
    # the airframe first: its loop is the outermost
    "airframe": {"none": _off("airframe", "none"), "transport": airframe.Transport, "b747": airframe.B747},
    "controller": {"P": controller.PositionP, "PI": controller.PositionPI},
    "motor": {"pmsm": motor.Pmsm, "dc": motor.Dc},
    "inverter": {"ideal": inverter.Ideal, "pwm": inverter.Pwm},
    "supply": {"ideal": supply.Ideal, "line": supply.Line},
    "screw": {"elastic": ballscrew.Elastic, "rigid": ballscrew.Rigid},
    "friction": {"smooth": friction.Smooth, "hybrid": friction.Hybrid, "lugre": friction.LuGre,
                 "lugre_smooth": friction.LuGreSmooth},
    "endstop": {"off": _off("endstop"), "elastic": endstop.Elastic},
    "load": {"constant": load.Constant, "aero_spring": load.AeroSpring},
    "thermal": {"off": thermal.Off, "lumped": thermal.Lumped},
    "sensor": {"ideal": sensor.Ideal, "real": sensor.Real},
    "faults": {"off": _off("faults"), "on": faults.On},
    "monitors": {"off": _off("monitors"), "on": monitors.On},
}


def served_by(cls: type) -> tuple[type, ...]:
    """The part classes a registry entry stands for, in assembly order: the parts it
    brings (:attr:`~ema_casadi.model.components.Part.brings`), then itself.

    Parameters
    ----------
    cls : type
        A part class of :data:`REGISTRY`.
    """
    return (*cls.brings, cls)


def merge_options(registry: dict) -> dict[str, tuple]:
    """Option key -> allowed values (first the default), from the parts that read them.
    Two parts may read one option only with the same values (one declaration shared,
    such as the anti-windup of the current and the outer loops); an option declared
    again with other values, or with the name of a variant key, is refused.

    Parameters
    ----------
    registry : dict
        Variant key -> value -> part class (:data:`REGISTRY`).
    """
    out, where = {}, {}
    for values in registry.values():
        for cls in (c for entry in values.values() for c in served_by(entry)):
            for name, allowed in cls.options.items():
                here = f"{cls.family} = {getattr(cls, 'value', '?')}"
                if name in registry:
                    raise AssemblyError(f"option '{name}' of {here} has the name of a variant key")
                if name in out and out[name] != tuple(allowed):
                    raise AssemblyError(f"option '{name}' declared twice: {where[name]} {out[name]}, "
                                        f"{here} {tuple(allowed)}")
                out.setdefault(name, tuple(allowed))
                where.setdefault(name, here)
    return out


#: Option key -> allowed values (first the default), from the parts that read them.
OPTIONS: dict[str, tuple] = merge_options(REGISTRY)

#: Allowed values per key (variant keys, then options), first the default.
VARIANTS: dict[str, tuple[str, ...]] = {k: tuple(v) for k, v in REGISTRY.items()} | OPTIONS
DEFAULT_VARIANTS = {k: v[0] for k, v in VARIANTS.items()}


def _part_classes() -> dict[type, dict]:
    out = {}
    for key, values in REGISTRY.items():
        for value, entry in values.items():
            for cls in served_by(entry):
                for combo in itertools.product(*cls.options.values()):
                    opts = dict(zip(cls.options, combo, strict=True))
                    out.setdefault(cls.form(opts), {key: value, **opts})
    return out


#: Every part class a model can be assembled from (the registry's, the parts they bring,
#: the forms their options select: :meth:`~ema_casadi.model.components.Part.form`) -> the
#: variant choices (key and options) that assemble it.
PART_CLASSES: dict[type, dict] = _part_classes()


def validate_variants(variants: dict | None, where: str = "variant") -> dict[str, str]:
    """Complete a variant dict with defaults and check every key and value.

    Raises :class:`VariantError` naming ``where`` and the key, listing the allowed values.

    Parameters
    ----------
    variants : dict or None
        Variant key -> value, partial (missing keys take their defaults).
    where : str
        Named in the error message (the file or argument the dict came from).
    """
    if variants is not None and not isinstance(variants, dict):
        raise VariantError(f"{where}: expected a dict of variant names, got {type(variants).__name__}")
    out = dict(DEFAULT_VARIANTS)
    for key, value in (variants or {}).items():
        if key not in VARIANTS:
            raise VariantError(
                f"{where}: unknown variant key '{key}'{_nearest(key, VARIANTS)}; allowed keys: {', '.join(VARIANTS)}"
            )
        if value not in VARIANTS[key]:
            raise VariantError(f"{where}: unknown {key} variant '{value}'; allowed: {', '.join(VARIANTS[key])}")
        out[key] = value
    for key, values in REGISTRY.items():
        for other, allowed in values[out[key]].requires.items():
            if out[other] not in allowed:
                raise VariantError(
                    f"{where}: {key}={out[key]} needs {other}={' or '.join(allowed)}, got {other}={out[other]}"
                )
    return out


def parts_for(variants: dict) -> tuple[list[Part], list[str]]:
    """The parts of a complete variant dict, in assembly order, and the option keys
    that none of them reads (ignored: e.g. ``friction_shape`` with hybrid friction).

    Parameters
    ----------
    variants : dict
        A complete variant dict (:func:`validate_variants`).
    """
    parts, read = [], set()
    for key, values in REGISTRY.items():
        for cls in served_by(values[variants[key]]):
            opts = {k: variants[k] for k in cls.options}
            parts.append(cls.form(opts)(opts))
            read.update(cls.options)
    return parts, sorted(k for k in OPTIONS if k not in read)
