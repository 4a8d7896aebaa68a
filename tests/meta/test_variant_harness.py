"""One harness over every variant combination (PyBaMM's ``StandardModelTest``).

Every combination of the variant keys (the registry's, options at their defaults),
plus each non-default option value on the default model, is built and put through
the same steps: the right-hand side at the declared initial state is finite; the model
trims at rest and under 15 kN; the linearisation there is finite and, for the
continuous (non-hybrid) models, asymptotically stable.

Parameters: the reference set with the position loop's integral gain K_i_x = 400 1/s^2
(the file leaves it at 0, which makes the PI controller's integrator a frozen, neutral
state; unused by the P controller).
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest

import ema_casadi as ema
from ema_casadi.components import DEFAULT_VARIANTS, OPTIONS, REGISTRY

K_I_X = 400.0  # 1/s^2
LOADS = [pytest.param(0.0, id="rest"), pytest.param(15e3, id="15kN")]


def _label(variants: dict) -> str:
    changed = [f"{k}={v}" for k, v in variants.items() if v != DEFAULT_VARIANTS[k]]
    return "-".join(changed) or "default"


def _cases():
    combos = [dict(zip(REGISTRY, values, strict=True)) for values in itertools.product(*REGISTRY.values())]
    options = [{key: value} for key, allowed in OPTIONS.items() for value in allowed[1:]]
    return [pytest.param(v, id=_label(v)) for v in combos + options]


CASES = _cases()


def test_the_harness_covers_every_combination():
    n_combos = int(np.prod([len(values) for values in REGISTRY.values()]))
    n_options = sum(len(allowed) - 1 for allowed in OPTIONS.values())
    assert len(CASES) == n_combos + n_options
    assert len({c.id for c in CASES}) == len(CASES)


@pytest.mark.parametrize("variants", CASES)
def test_rhs_is_finite_at_the_initial_state(model_cache, variants):
    model = model_cache(**variants)
    xdot, y = (np.asarray(v, float).ravel() for v in model.f(model.x0(), model.u(), model.p(K_i_x=K_I_X)))
    assert xdot.shape == (model.nx,) and y.shape == (model.ny,)
    assert np.all(np.isfinite(xdot)), dict(zip(model.states, xdot, strict=True))
    assert np.all(np.isfinite(y)), dict(zip(model.outputs, y, strict=True))


def _asymptotic_modes(model, A):
    """Eigenvalues of A without the states nothing depends on (a zero column of A: the
    rigid screw's shaft angle, kept for its output, gives an exact eigenvalue 0 since
    det(sI - A) = s det(minor)); those states are returned too."""
    dropped = [j for j in range(model.nx) if not A[:, j].any()]
    keep = [j for j in range(model.nx) if j not in dropped]
    return np.linalg.eigvals(A[np.ix_(keep, keep)]), [model.states[j] for j in dropped]


@pytest.mark.parametrize("f_ext", LOADS)
@pytest.mark.parametrize("variants", CASES)
def test_trim_and_linearise(model_cache, variants, f_ext):
    model = model_cache(**variants)
    op = ema.operating_point(model, f_ext=f_ext, p=model.p(K_i_x=K_I_X))
    assert np.all(np.isfinite(op.x)) and op.residual < 1e-9
    lin = ema.linear_model(model, op)
    for name in "ABCD":
        assert np.all(np.isfinite(getattr(lin, name))), name
    if model.hybrid:
        return  # a stick-slip law has no meaningful small-signal stability
    eig, neutral = _asymptotic_modes(model, lin.A)
    assert set(neutral) <= set(model.states_with("shaft_angle")), neutral
    assert eig.real.max() < 0, f"unstable or neutral modes: {eig[eig.real >= 0]}"
