"""Native compilation: disk cache, and the VM fallback without a compiler."""

import casadi as ca
import numpy as np
import pytest

from ema_casadi import compiled


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
