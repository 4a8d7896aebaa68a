"""The parameters a part ties to one law of an option (``Part.option_params``) are the
ones its equations read under that law and only there: for every anti-windup law, limit
shape and motor, each tied parameter is in ``Model.used_params`` exactly when the
model's equations (the continuous dynamics, the held ECU and its sampling) depend on it
symbolically. A parameter left out is refused as a free or structural parameter of a fit,
naming the option value that leaves it out."""

import itertools

import pytest

import ema_casadi as ema
from ema_casadi.identification import IdentificationError
from ema_casadi.identification._problem import free_parameters
from ema_casadi.model.components import PART_CLASSES

TIED = sorted({n for cls in PART_CLASSES for laws in cls.option_params.values() for names in laws.values()
               for n in names})


def _read(model) -> set:
    """The parameters the model's equations depend on (structurally)."""
    return set(model.param_names) - set(model.unread("p"))


def test_the_tied_parameters_are_the_controllers_switch_shapes():
    assert TIED == ["k_bc", "w_aw", "w_knee"]


@pytest.mark.parametrize("aw, shape, motor", list(itertools.product(("backcalc", "clamping"), ("clip", "smooth"),
                                                                  ("pmsm", "dc"))))
def test_a_tied_parameter_is_used_exactly_where_the_equations_read_it(params, aw, shape, motor):
    model = ema.build_model(params, {"anti_windup": aw, "limit_shape": shape, "motor": motor})
    read = _read(model)
    for n in TIED:
        assert (n in model.used_params) == (n in read), (n, aw, shape, motor)
    assert ("w_aw" in read) == (aw == "clamping") and ("k_bc" in read) == (aw == "backcalc")
    assert ("w_knee" in read) == (shape == "smooth")
    for n in TIED:
        if n not in read:
            with pytest.raises(IdentificationError, match=f"'{n}': .* = .* does not use it \\(only "):
                free_parameters(model, [n])


def test_each_instance_of_a_system_declares_its_laws_parameters():
    # the dual actuator: each channel's loop parts carry their option_params, prefixed
    from conftest import ROOT

    model = ema.build_model(ema.load_parameters(ROOT / "models" / "elevator_dual.toml"))
    read = _read(model)
    for ch in ("A", "B"):
        assert f"{ch}.k_bc" in model.used_params and f"{ch}.k_bc" in read
        assert f"{ch}.w_aw" not in model.used_params and f"{ch}.w_aw" not in read
        assert model.unused_reason(f"{ch}.w_aw") == "anti_windup = backcalc does not use it (only clamping)"
