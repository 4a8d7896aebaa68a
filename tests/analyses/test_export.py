"""Export of the linear model (.mat/.npz/.json round trips) and of the
nonlinear model (serialised CasADi Function, generated C code)."""

import json
import subprocess

import casadi as ca
import numpy as np
import pytest

from conftest import REFERENCE
from ema_casadi import export as ex
from ema_casadi import linearisation as lz
from ema_casadi._util import _compiled as compiled
from ema_casadi.cli import main
from ema_casadi.export._linear import FORMAT_ID


@pytest.fixture(scope="module")
def lin(model_cache):
    return lz.linear_model(model_cache(), x_cmd=1e-3, f_ext=12e3, open_loops=["velocity"])


@pytest.mark.parametrize("fmt", ex.LINEAR_FORMATS)
def test_linear_round_trip(lin, model_cache, tmp_path, fmt):
    """Matrices bit-identical, names, units and the operating point preserved."""
    model = model_cache()
    path = ex.save_linear(lin, tmp_path / f"lin.{fmt}", units=model.units)
    back, op = ex.load_linear(path)
    for k in "ABCD":
        np.testing.assert_array_equal(getattr(back, k), getattr(lin, k))
    assert back.states == lin.states and back.inputs == lin.inputs and back.outputs == lin.outputs
    assert back.open_loops == ("velocity",)
    np.testing.assert_array_equal(op["x"], lin.op.x)
    np.testing.assert_array_equal(op["u"], lin.op.u)
    np.testing.assert_array_equal(op["param_values"], lin.op.p)
    assert op["f_ext"] == 12e3 and op["x_cmd"] == 1e-3
    assert list(op["param_names"]) == list(model.param_names)
    assert op["policy"]["friction"] == "off" and op["policy"]["g_eff"] == pytest.approx(lin.op.policy["g_eff"])
    sys = back.to_statespace()
    assert list(sys.state_labels) == list(lin.states)


def test_mat_holds_matlab_cell_arrays_and_op_struct(lin, tmp_path):
    """As MATLAB sees it: names are cell arrays of char (column), op is a struct."""
    import scipy.io

    path = ex.save_linear(lin, tmp_path / "lin.mat")
    d = scipy.io.loadmat(path)
    names = d["state_names"]
    assert names.dtype == object and names.shape == (len(lin.states), 1)
    assert [str(n[0]) for n in names[:, 0]] == list(lin.states)
    assert d["A"].shape == lin.A.shape
    assert set(d["op"].dtype.names) >= {"x", "u", "y", "x_cmd", "f_ext", "v_rod", "param_names", "param_values"}


def test_json_is_plain_json(lin, tmp_path):
    d = json.loads(ex.save_linear(lin, tmp_path / "lin.json").read_text())
    assert d["format"] == FORMAT_ID
    assert len(d["A"]) == len(d["state_names"]) and d["operating_point"]["f_ext"] == 12e3


def test_bad_linear_files(tmp_path):
    with pytest.raises(ex.ExportError, match="format 'txt' unknown"):
        ex.load_linear(tmp_path / "a.txt")
    (tmp_path / "x.json").write_text('{"format": "other"}')
    with pytest.raises(ex.ExportError, match="not an ema_casadi.linear/1 file"):
        ex.load_linear(tmp_path / "x.json")


def _random_args(model, seed=1):
    rng = np.random.default_rng(seed)
    x = rng.normal(size=model.nx) * 1e-3
    u = model.u(x_cmd=2e-3, f_ext=3e3)
    p = model.p() * (1 + 0.05 * rng.uniform(-1, 1, len(model.param_names)))
    return x, u, p


def test_casadi_function_round_trip(model_cache, tmp_path):
    model = model_cache()
    written = ex.export_function(model, tmp_path / "ema_f.casadi")
    g = ca.Function.load(str(written[0]))
    sig = json.loads(written[1].read_text())
    assert sig["states"] == list(model.states) and len(sig["param_values"]) == len(model.param_names)
    args = _random_args(model)
    for a, b in zip(g(*args), model.f(*args), strict=True):
        np.testing.assert_array_equal(np.array(a), np.array(b))


@pytest.mark.skipif(compiled.compiler() is None, reason="no C compiler")
def test_generated_c_compiles_and_matches(model_cache, tmp_path):
    """The generated C, compiled and loaded back, reproduces f to round-off (1e-12 rel)."""
    model = model_cache()
    written = ex.export_function(model, tmp_path / "ema_f.c")
    assert {w.name for w in written} == {"ema_f.c", "ema_f.h", "ema_f.c.json"}
    so = tmp_path / "ema_f.so"
    subprocess.run([compiled.compiler(), "-O1", "-fPIC", "-shared", str(tmp_path / "ema_f.c"), "-o", str(so), "-lm"],
                   check=True, capture_output=True)
    g = ca.external("ema_f", str(so))
    args = _random_args(model, 2)
    for a, b in zip(g(*args), model.f(*args), strict=True):
        np.testing.assert_allclose(np.array(a), np.array(b), rtol=1e-12, atol=1e-300)


def test_cli_export_writes_and_refuses(tmp_path, capsys):
    out = tmp_path / "lin.npz"
    assert main(["export", str(REFERENCE), "--format", "npz", "--out", str(out), "--f-ext", "5kN", "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    assert r["written"] == [str(out)] and ex.load_linear(out)[1]["f_ext"] == 5e3
    assert main(["export", str(REFERENCE), "--format", "mat", "--out", str(tmp_path / "x.npz")]) == 2
    assert "--out" in capsys.readouterr().err
    assert main(["export", str(REFERENCE), "--format", "c", "--out", str(tmp_path / "9x.c")]) == 2
    err = capsys.readouterr().err
    assert "C identifier" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "9x.c").exists()
    assert main(["linearize", str(REFERENCE), "--out", str(tmp_path / "no" / "lin.mat")]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["lin.npz"]  # no partial or temporary files
