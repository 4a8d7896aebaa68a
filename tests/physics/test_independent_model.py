"""The benchmarks' NumPy right-hand side equals the CasADi model (independent transcription)."""

import sys

import numpy as np

from conftest import ROOT

sys.path.insert(0, str(ROOT / "benchmarks"))
import numpy_model  # noqa: E402


def test_numpy_rhs_matches_casadi_model(params, model_cache):
    model = model_cache()
    assert model.states == numpy_model.STATES
    P = params.as_dict()
    rng = np.random.default_rng(1)
    scale = np.array([10, 50, 50, 20, 20, 50, 100, 2e-3, 0.05])
    for _ in range(200):
        x = rng.normal(size=9) * scale
        x[7] = x[5] * params.screw.p / (2 * np.pi) + rng.normal() * 3e-5  # near contact
        u = dict(x_cmd=rng.normal() * 1e-3, f_ext=rng.normal() * 2e4, eta=0.9)
        ref = np.asarray(model.f(x, model.u(**u), model.p())[0]).ravel()
        got = numpy_model.rhs(0.0, x, u["x_cmd"], u["f_ext"], u["eta"], P)
        np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-9 * np.abs(ref).max())
