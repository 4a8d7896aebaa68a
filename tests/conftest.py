"""Shared fixtures: the reference parameter set and its models (built once)."""

from pathlib import Path

import pytest

from ema_casadi import build_model, load_parameters

ROOT = Path(__file__).resolve().parent.parent
REFERENCE = ROOT / "models" / "cesa_ema.toml"


@pytest.fixture(scope="session")
def params():
    return load_parameters(REFERENCE)


@pytest.fixture(scope="session")
def model_cache(params):
    cache = {}

    def get(**variants):
        key = tuple(sorted(variants.items()))
        if key not in cache:
            cache[key] = build_model(params, variants)
        return cache[key]

    return get
