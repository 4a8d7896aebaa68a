"""The model is built once per command and passed down: identify and track take the
caller's model (checked to be the model of their parameters and variants)."""

import pytest

import ema_casadi as ema
from ema_casadi.identification._fit import given_model


def test_the_callers_model_is_used_as_given(params, model_cache):
    model = ema.build_model(params)
    assert given_model(model, params, None) is model
    assert given_model(None, params, {"motor": "dc"}).variants["motor"] == "dc"  # none given: built here


def test_a_model_of_other_variants_or_parameters_is_refused(params, model_cache):
    with pytest.raises(ema.IdentificationError, match="model: not the model of these parameters and variants"):
        given_model(ema.build_model(params, {"motor": "dc"}), params, None)
    with pytest.raises(ema.IdentificationError, match="model: not the model"):
        given_model(ema.build_model(params), params.replace(F_seal=100.0), None)
    with pytest.raises(ema.IdentificationError, match="model: expected"):
        given_model("cesa_ema.toml", params, None)
