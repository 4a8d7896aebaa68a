"""LuGre dynamic friction (Canudas de Wit, Olsson, Astrom, Lischinsky 1995).

dz/dt = v - sigma_0 |v| z / g(v), F = sigma_0 z + sigma_1 dz/dt + sigma_2 v, with the
Stribeck curve g(v) = F_c + (F_s - F_c) exp(-(v/v_s)^2); here F_c = F_r (eq. 7),
F_s = r_start F_r, v_s = v_st, sigma_2 = c_v. The expected values below are the paper's
formulas evaluated in NumPy from the parameter file, independently of the part.
"""

import math

import numpy as np
import pytest
from scipy.optimize import brentq

import ema_casadi as ema


@pytest.fixture(scope="module")
def lugre(model_cache):
    return lambda screw="elastic": model_cache(friction="lugre", screw=screw)


def stribeck(params, v, f_ext=0.0):
    fr = params.friction
    F_c = fr.F_seal + abs(f_ext) * 2 * math.pi / params.screw.p * fr.C_bear
    F_s = fr.r_start * F_c
    return F_c + (F_s - F_c) * math.exp(-((v / fr.v_st) ** 2))


@pytest.mark.parametrize("f_ext", [0.0, 15e3])
@pytest.mark.parametrize("v", [float(v) for v in np.geomspace(1e-5, 0.1, 9)] + [-1e-3, -0.05])
def test_steady_state_friction_is_the_stribeck_curve(params, lugre, v, f_ext):
    """At constant contact velocity v the bristle state settles where dz/dt = 0 (found by
    Brent on the model's own right-hand side); the friction force there, less the viscous
    c_v v, is the Stribeck curve within 1e-6 relative (measured ~1e-15: the root is
    found to rtol 1e-14)."""
    model = lugre()
    x = model.x0()
    x[model.index("v_rod")] = v
    u, p = model.u(f_ext=f_ext), model.p()
    iz = model.index("z")

    def rate(z):
        x[iz] = z
        return float(model.f(x, u, p)[0][iz])

    z_max = 2 * params.friction.r_start * stribeck(params, 0.0, f_ext) / params.friction.sigma_0
    z = brentq(rate, -z_max, z_max, xtol=1e-20, rtol=1e-14)
    x[iz] = z
    y = np.asarray(model.f(x, u, p)[1], float).ravel()
    F = y[model.yindex("F_friction")] - params.friction.c_v * v
    expected = math.copysign(stribeck(params, abs(v), f_ext), v)
    assert F == pytest.approx(expected, rel=1e-6)


def test_presliding_displacement_is_force_over_sigma0(params, lugre):
    """A constant motor current (position and speed loops open, the speed integrator
    holding the current command) drives the rigid screw's shaft contact with
    F0 = K_t I0 / ((p/2pi) g) = 1 % of the breakaway force F_s; the bristles deflect and
    the nut comes to rest F0/sigma_0 from where it started, within 1 %. While the
    bristles load they also slip: with v >= 0 throughout, dx = dz / (1 - sigma_0 z/g), so
    x = -(g/sigma_0) ln(1 - a), a = F0/g: 0.50 % above F0/sigma_0 at a = 0.01 (measured
    0.50 %), which is why the force is small. The bristle mode is critically damped
    here (sigma_1 = 2 sqrt(sigma_0 M_eq), M_eq the inertia referred to the rod), so the
    nut does not overshoot and slip back."""
    model = lugre("rigid")
    fr = params.friction
    F0 = 0.01 * fr.r_start * fr.F_seal
    r = params.screw.p / (2 * math.pi)
    g_rest = 0.5 / params.screw.eta + 0.5 * params.screw.eta_inv  # the blend at standstill
    I0 = F0 * r * g_rest / params.K_t
    M_eq = (params.motor.J_m + params.screw.J_s) / r**2 + params.screw.M
    x0 = model.x0()
    x0[model.index("z_w")] = I0
    x0[model.index("i_q")] = I0
    x0[model.index("z_q")] = params.motor.R * I0  # the current PI's steady output
    p = model.p(loop_x=0, loop_w=0, sigma_1=2 * math.sqrt(fr.sigma_0 * M_eq))
    res = ema.simulate(model, 0.3, 0.0, x0=x0, p=p, solver="cvodes", rtol=1e-10, atol=1e-16)
    dx = res["x_in"][-1] - res["x_in"][0]
    assert abs(res["v_rod"][-1]) < 1e-7  # at rest again
    assert dx == pytest.approx(F0 / fr.sigma_0, rel=1e-2)
