"""Native compilation: disk cache, and the VM fallback without a compiler."""

import casadi as ca
import numpy as np
import pytest

from ema_casadi._util import _compiled as compiled


def small_function(name="sq"):
    x = ca.SX.sym("x", 3)
    return ca.Function(name, [x], [ca.sin(x) * x])


def test_second_load_uses_the_disk_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("EMA_CASADI_CACHE", str(tmp_path))
    monkeypatch.setattr(compiled, "_loaded", {})
    f = small_function("cachetest")
    g, info = compiled.compile_function(f)
    assert info["compiled"] and not info["cached"]
    assert len(list(tmp_path.glob("cachetest_*.so"))) == 1
    monkeypatch.setattr(compiled, "_loaded", {})  # as in a new process
    g2, info2 = compiled.compile_function(f)
    assert info2["compiled"] and info2["cached"]
    x = np.array([0.1, 0.2, 0.3])
    np.testing.assert_allclose(np.asarray(g2(x)).ravel(), np.sin(x) * x, rtol=1e-15)


def test_without_a_compiler_the_vm_runs_with_a_warning(monkeypatch):
    monkeypatch.setattr(compiled, "compiler", lambda: None)
    monkeypatch.setattr(compiled, "_warned", False)
    f = small_function("nocc")
    with pytest.warns(UserWarning, match="no C compiler"):
        g, info = compiled.compile_function(f)
    assert g is f and not info["compiled"]


def test_buffer_call_equals_ordinary_call():
    x = ca.SX.sym("x", 2, 3)
    f = ca.Function("bf", [x], [x.T @ x, ca.sum1(x)])
    a = np.arange(6.0).reshape(2, 3)
    out = compiled.BufferCall(f)(a)
    np.testing.assert_array_equal(out[0], a.T @ a)
    np.testing.assert_array_equal(out[1], a.sum(axis=0, keepdims=True))


def test_simulate_is_thread_safe(model_cache):
    # compiled rollouts keep one call buffer per thread: concurrent runs with other
    # parameter values give exactly the sequential results
    from concurrent.futures import ThreadPoolExecutor

    import ema_casadi as ema

    model = model_cache()
    gains = [60.0, 75.0, 90.0, 105.0]

    def run(k):
        r = ema.simulate(model, 0.02, ema.Signal.step(1e-3, 0.001), p=model.p(K_x=k), dt=5e-6, dt_out=1e-4,
                         solver="rk4")
        return r["x_rod"]

    sequential = [run(k) for k in gains]
    with ThreadPoolExecutor(4) as pool:
        parallel = list(pool.map(run, gains))
    for a, b in zip(sequential, parallel, strict=True):
        np.testing.assert_array_equal(a, b)
    assert not np.array_equal(sequential[0], sequential[-1])


@pytest.mark.parametrize("variants, t_end, dt", [({}, 0.02, None),
                                                 ({"friction": "hybrid", "thermal": "lumped", "iron_loss": "on"},
                                                  0.2, 1e-4)], ids=["smooth", "hybrid-thermal"])
def test_the_c_rollout_loop_gives_the_mapaccum_rollouts_numbers_to_the_bit(params, monkeypatch, variants, t_end, dt):
    """The C driver loop calls CasADi's generated code of the same RK4 step: the same
    operations on the same numbers, so the same results exactly (tolerance 0), with
    the sampled ECU, the hybrid projection and the thermal network in the step (each
    model at a step inside its stability limit: the smooth law's default, about 1 us
    under the load)."""
    import ema_casadi as ema
    from ema_casadi.simulation import _rk4

    kw = dict(x_cmd="step:1mm@0.01", f_ext="sine:5kN@2", dt=dt, dt_out=1e-3, solver="rk4")
    native = ema.simulate(ema.build_model(params, variants), t_end, **kw)
    monkeypatch.setattr(_rk4, "native_rollout", lambda *a, **k: (None, {}))
    folded = ema.simulate(ema.build_model(params, variants), t_end, **kw)
    for name in native.states:
        np.testing.assert_array_equal(native.states[name], folded.states[name], err_msg=name)
    np.testing.assert_array_equal(native["P_dc"], folded["P_dc"])
