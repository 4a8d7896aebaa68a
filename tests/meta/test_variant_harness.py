"""One harness over every variant combination (PyBaMM's ``StandardModelTest``).

Every combination of the actuator's core variant keys (``CORE``, options at their
defaults); for every other key (added families such as the supply or the airframe),
every pair of its non-default values with every value of any other key (all-pairs
coverage: the full product would multiply the suite); plus each non-default option
value on the default model and with the other values of the families whose parts read
it. Combinations the registry refuses (``validate_variants``
raises) are checked for their one-line error instead. Every case is built and put through
the same steps: the right-hand side at the declared initial state is finite; the model
trims at rest and under 15 kN (with an airframe: the whole loop at its flight condition,
the 15 kN on top of the hinge load); the linearisation there is finite and, for the
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
from ema_casadi.linearisation import flight_point
from ema_casadi.model.components import DEFAULT_VARIANTS, OPTIONS, REGISTRY, VariantError, served_by, validate_variants

K_I_X = 400.0  # 1/s^2
LOADS = [pytest.param(0.0, id="rest"), pytest.param(15e3, id="15kN")]


def _label(variants: dict) -> str:
    changed = [f"{k}={v}" for k, v in variants.items() if v != DEFAULT_VARIANTS[k]]
    return "-".join(changed) or "default"


#: The keys crossed in full; every other key is covered pairwise.
CORE = ("controller", "motor", "inverter", "screw", "friction", "endstop", "thermal")


def _accepted(variants: dict) -> bool:
    try:
        validate_variants(variants)
    except VariantError:
        return False
    return True


def _all_combinations():
    core = [k for k in REGISTRY if k in CORE]
    base = {k: DEFAULT_VARIANTS[k] for k in REGISTRY}
    combos = [base | dict(zip(core, values, strict=True)) for values in itertools.product(*(REGISTRY[k] for k in core))]
    others = [k for k in REGISTRY if k not in CORE]
    for k in others:
        for v in list(REGISTRY[k])[1:]:
            combos.append(base | {k: v})
            for k2 in REGISTRY:
                if k2 == k:
                    continue
                for v2 in list(REGISTRY[k2])[1:]:
                    combos.append(base | {k: v, k2: v2})
    unique = {tuple(sorted(c.items())): c for c in combos}
    return list(unique.values())


def _option_cases():
    """Each non-default option value on the default model, and with every other value
    of each family whose part for that value reads the option (``anti_windup`` with the
    dc motor's current PI and the PI position loop)."""
    cases = []
    for key, allowed in OPTIONS.items():
        for value in allowed[1:]:
            cases.append({key: value})
            cases += [{family: v, key: value} for family, values in REGISTRY.items()
                      for v in list(values)[1:] if any(key in c.options for c in served_by(values[v]))]
    return [c for c in cases if _accepted(c)]


def _cases():
    combos = [v for v in _all_combinations() if _accepted(v)]
    return [pytest.param(v, id=_label(v)) for v in combos + _option_cases()]


REFUSED = [pytest.param(v, id=_label(v)) for v in _all_combinations() if not _accepted(v)]
CASES = _cases()


def test_the_harness_covers_every_combination():
    core = [k for k in REGISTRY if k in CORE]
    n_core = int(np.prod([len(REGISTRY[k]) for k in core]))
    n_options = sum(len(allowed) - 1 for allowed in OPTIONS.values())
    assert len(CASES) + len(REFUSED) >= n_core + n_options
    assert len({c.id for c in CASES}) == len(CASES)
    # every pair of values of two keys, one of them outside the core, appears in a case
    for k in (k for k in REGISTRY if k not in CORE):
        for v in REGISTRY[k]:
            for k2 in (x for x in REGISTRY if x != k):
                for v2 in REGISTRY[k2]:
                    # an option case names only its option: the other keys at their defaults
                    hit = [c for c in CASES + REFUSED if {**DEFAULT_VARIANTS, **c.values[0]}[k] == v
                           and {**DEFAULT_VARIANTS, **c.values[0]}[k2] == v2]
                    assert hit, (k, v, k2, v2)


@pytest.mark.parametrize("variants", REFUSED or [pytest.param(None, marks=pytest.mark.skip("none refused"))])
def test_refused_combinations_say_why_in_one_line(variants):
    with pytest.raises(VariantError) as err:
        validate_variants(variants)
    assert "\n" not in str(err.value) and len(str(err.value)) < 300


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
    det(sI - A) = s det(minor)); those states are returned too. A column at round-off
    (below 1e-14 of the largest entry of A) counts as zero: the PWM bridge's averaged
    voltage is Park(inverse Park(v_dq, theta), theta), independent of the shaft angle
    but for rounding (measured 4.7e-12 against max |A| = 1.6e8, rigid screw at 15 kN)."""
    floor = 1e-14 * np.abs(A).max()
    dropped = [j for j in range(model.nx) if np.abs(A[:, j]).max() <= floor]
    keep = [j for j in range(model.nx) if j not in dropped]
    return np.linalg.eigvals(A[np.ix_(keep, keep)]), [model.states[j] for j in dropped]


@pytest.mark.parametrize("f_ext", LOADS)
@pytest.mark.parametrize("variants", CASES)
def test_trim_and_linearise(model_cache, variants, f_ext):
    model = model_cache(**variants)
    if any(part.trim_free for part in model.parts):
        # an airframe: x_cmd is its flight-control law's, so the whole loop is trimmed at
        # its flight condition (airspeed, altitude). The 15 kN acts against the hinge load
        # (8.1 kN pushing in at the transport's cruise trim): on top of it, 23 kN held for
        # ever has no thermal steady state with thermal = lumped (measured: T_w 134 degC at
        # 16 kN, no trim at 20 kN: R(T_w) and psi(T_h) run away)
        op = flight_point(model, f_ext=-f_ext, p=model.p(K_i_x=K_I_X))
    else:
        op = ema.operating_point(model, f_ext=f_ext, p=model.p(K_i_x=K_I_X))
    assert np.all(np.isfinite(op.x)) and op.residual < 1e-9
    lin = ema.linear_model(model, op)
    for name in "ABCD":
        assert np.all(np.isfinite(getattr(lin, name))), name
    if model.hybrid:
        return  # a stick-slip law has no meaningful small-signal stability
    eig, neutral = _asymptotic_modes(model, lin.A)
    # only the states the parts declare as memory (State.memory: a play, a friction
    # bristle, a position only a memory element reads) may be neutral modes
    memory = set(model.memory_states)
    assert set(neutral) <= memory, neutral
    # those that something reads keep their exact neutral mode (a play without backlash
    # whose shaft angle the surface reads: its offset from the nut, d(x_play - x_in)/dt = 0):
    # at most one each, at round-off (below 1e-9 of the largest |eigenvalue|)
    for _ in range(len(memory - set(neutral))):
        k = np.argmin(np.abs(eig))
        if abs(eig[k]) <= 1e-9 * np.abs(eig).max():
            eig = np.delete(eig, k)
    assert eig.real.max() < 0, f"unstable or neutral modes: {eig[eig.real >= 0]}"
