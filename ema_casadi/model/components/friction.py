"""Friction on the rod (docs: physics). Forces in N, velocities in m/s; positive friction
opposes positive velocity. With the rigid screw the same laws act on the shaft, with
the rod velocity v = omega p/(2 pi) and the force referred back through p/(2 pi).

Four variants:

``smooth`` (eq. 3)
    A continuous law, usable by any ODE solver and linearisable.
``hybrid`` (eqs. 4-8, Karnopp stick-slip)
    A discontinuous law with a dead band |v| < eps in which the rod is either held
    (the friction cancels the applied force) or breaks away against F_start. It is a
    hybrid system: the right-hand side alone lets a rod that enters the band with a
    small velocity keep it (creep); :func:`stick_entry` is the discrete part, applied
    by the integrator wrapper (:mod:`ema_casadi.simulation`), that zeroes the velocity
    when the rod enters the band and the stick condition holds.
``lugre`` (Canudas de Wit, Olsson, Astrom and Lischinsky 1995)
    A dynamic law with the bristle deflection z as a state:
    dz/dt = v - sigma_0 |v| z / g(v), F = sigma_0 z + sigma_1 dz/dt + sigma_2 v, with the
    Stribeck curve g(v) = F_c + (F_s - F_c) exp(-(v/v_s)^2). Mapped onto the parameters of
    the other laws: F_c = F_r (the sliding level of eq. 7, seal plus load-dependent
    bearing friction), F_s = r_start F_r (the breakaway force of eq. 8), v_s = v_st (the
    Stribeck velocity), sigma_2 = c_v (the viscous coefficient); sigma_0 (bristle
    stiffness) and sigma_1 (bristle damping) are its own. Continuous (no discrete map),
    so every ODE solver and the linearisation serve it; it sticks (pre-sliding: a force
    below breakaway deflects the bristles by F/sigma_0) and slips like the Karnopp law.
``lugre_smooth`` (LuGre on the smooth law's curve)
    The LuGre bristle state with g(v) = |F_c(v)|, the Coulomb part of ``smooth`` (its
    shape and optional Stribeck hump): steady sliding gives exactly the smooth law, and
    dz/dt = v - sigma_0 z (w/F_r) h(v/w) / hump(v) with h(x) = x/tanh(x) (even, 1 at rest,
    :func:`x_over_tanh`; w = v_s for tanh, 2 v_s for the Fermi shape, which is
    tanh(v/(2 v_s))). At rest z relaxes with the time constant F_r/(sigma_0 w): a spring
    sigma_0 in series with the smooth law's slope F_r/w at rest (a Maxwell element),
    which tends to the smooth law as sigma_0 grows.
"""

from __future__ import annotations

import casadi as ca

from ._part import Output, Part, State, der
from ._ports import Port
from .ballscrew import F_EXT

__all__ = ["sliding_level", "smooth", "hybrid", "stick_entry", "stribeck_curve", "lugre_rate", "x_over_tanh",
           "smooth_bristle_rate", "SHAPES", "Smooth", "Hybrid", "LuGre", "LuGreSmooth"]

SHAPES = ("tanh", "fermi")


def sliding_level(f_ext, P):
    """Resistive force level while sliding (eq. 7): F_r = F_seal + |F_ext| (2 pi/p) C_bear (N).

    Parameters
    ----------
    f_ext : SX
        External rod force (N).
    P : SimpleNamespace
        Parameter symbols by flat name (uses ``F_seal``, ``p``, ``C_bear``).
    """
    return P.F_seal + ca.fabs(f_ext) * (2 * ca.pi / P.p) * P.C_bear


def _s(v, v_s, shape):
    if shape == "tanh":
        return ca.tanh(v / v_s)
    if shape == "fermi":
        return 2 / (1 + ca.exp(-v / v_s)) - 1
    raise ValueError(f"friction shape '{shape}' not one of {SHAPES}")


def stribeck_hump(v, P):
    """The Stribeck hump's decay e^-(|v|/v_st)^delta_st (-): 1 at rest, falling with the
    speed; delta_st = 2 (the default) is the Gaussian hump, 1 the exponential one
    (Armstrong-Helouvry's generalised Stribeck curve). delta_st = 2 is written as
    e^-(v/v_st)^2; another exponent through max(|v|/v_st, 1e-300), so that its
    derivatives (also with respect to delta_st) stay finite at rest.

    Parameters
    ----------
    v : SX or float
        Velocity at the contact (m/s).
    P : SimpleNamespace
        Parameter symbols by flat name (uses ``v_st``, ``delta_st``).
    """
    x, delta = v / P.v_st, P.delta_st
    gauss = ca.exp(-(x**2))
    numeric = isinstance(delta, (int, float))
    if numeric and delta == 2:
        return gauss
    general = ca.exp(-ca.power(ca.fmax(ca.fabs(x), 1e-300), delta))
    return general if numeric else ca.if_else(delta == 2, gauss, general)


def smooth(v, F_r, P, shape="tanh", stribeck=False):
    """Simplified friction (eq. 3): F_r s(v) [+ (F_start - F_r) h(v) s(v)] + c_v v, with
    the hump h(v) = e^-(|v|/v_st)^delta_st (:func:`stribeck_hump`).

    Returns (F_friction (N), its Coulomb part without the viscous term (N)).

    Parameters
    ----------
    v : SX
        Velocity at the contact (m/s).
    F_r : SX
        Sliding level (eq. 7) (N).
    P : SimpleNamespace
        Parameter symbols by flat name (uses ``v_s``, ``c_v`` and, with ``stribeck``,
        ``r_start``, ``v_st``).
    shape : {"tanh", "fermi"}
        The smooth sign function s(v).
    stribeck : bool
        Add the Stribeck hump up to F_start = r_start F_r at rest.
    """
    s = _s(v, P.v_s, shape)
    F_c = F_r * s
    if stribeck:
        F_c = F_c + (P.r_start - 1) * F_r * stribeck_hump(v, P) * s
    return F_c + P.c_v * v, F_c


def hybrid(v, F_app, F_r, P, F_hold=None):
    """Enhanced friction (eqs. 4-8, Karnopp): Coulomb part F_c plus viscous c_v v.

    Parameters
    ----------
    v : SX
        Rod velocity (m/s).
    F_app : SX
        Net force on the rod from everything but friction (N): F_in - F_ext - c_v v
        for the elastic screw; the net motor torque referred to the rod minus F_ext
        and c_v v for the rigid screw.
    F_r : SX
        Sliding level (eq. 7) (N); F_start = r_start F_r (eq. 8).
    P : SimpleNamespace
        Parameter symbols by flat name (uses ``eps``, ``r_start``, ``c_v``).
    F_hold : SX, optional
        ``F_app`` with the contact at rest (v = 0) (N), used for the stick test so that
        it agrees with :func:`stick_entry` (velocity-dependent terms such as contact
        damping would otherwise let the test change when the velocity is reset).
        Default ``F_app``.

    Returns
    -------
    F_friction : SX
        F_c + c_v v (N).
    F_c : SX
        Sliding, |v| >= eps: F_r sign(v). In the dead band |v| < eps: F_app if
        |F_hold| <= F_start (held: the net force F_app - F_c is zero), else
        F_start sign(F_app) (breakaway).
    stick : SX
        1 while held (|v| < eps and |F_hold| <= F_start), else 0.
    """
    F_hold = F_app if F_hold is None else F_hold
    F_start = P.r_start * F_r
    band = ca.fabs(v) < P.eps
    stick = ca.logic_and(band, ca.fabs(F_hold) <= F_start)
    F_c = ca.if_else(band, ca.if_else(stick, F_app, F_start * ca.sign(F_app)), F_r * ca.sign(v))
    return F_c + P.c_v * v, F_c, stick


def stick_entry(v_prev, v, F_hold, F_r, P):
    """Discrete stick condition after a step from velocity ``v_prev`` to ``v`` (m/s).

    The rod is held (its velocity must be reset to 0) when it is in the dead band at
    the end of the step, or crossed it during the step (v changed sign), and the
    applied force with the rod at rest, ``F_hold`` (N), is within F_start (the same
    test as in :func:`hybrid`). Testing the crossing as well as the end point matters
    for the light rod of the elastic screw: sliding friction changes its velocity by
    F_r h / M ~ 5e-3 m/s per 1e-4 s step, fifty times the band width, so a step would
    rarely end inside the band. Returns 1 (stick) or 0.

    Parameters
    ----------
    v_prev, v : SX
        Contact velocity at the start and the end of the step (m/s).
    F_hold : SX
        Applied force with the contact at rest (N).
    F_r : SX
        Sliding level (eq. 7) (N).
    P : SimpleNamespace
        Parameter symbols by flat name (uses ``eps``, ``r_start``).
    """
    entered = ca.logic_or(ca.fabs(v) < P.eps, v_prev * v < 0)
    return ca.logic_and(entered, ca.fabs(F_hold) <= P.r_start * F_r)


# ---- parts: friction at the contact the screw part names (v_contact, F_drive) ---------
# Each provides F_friction, F_c (its Coulomb part), stick and F_net, the net force on the
# contact (F_drive minus friction), besides its outputs.
_OUT = (
    Output("F_friction", "N", "friction force at the contact, referred to the rod"),
    Output("stick", "1", "1 while stuck (hybrid friction)", kind="flag", roles=("stuck",)),
    Output("P_friction", "W", "seal/bearing (Coulomb) friction loss", kind="loss"),
    Output("P_viscous", "W", "viscous loss (rod and shaft)", kind="loss"),
)
_PARAMS = ("F_seal", "C_bear", "p", "c_v", "b_m")


def _common(_):
    return {
        "F_r": lambda b: sliding_level(b["f_ext"], b.P),
        "P_friction": lambda b: b["F_c"] * b["v_rod"],
        "P_viscous": lambda b: b.P.c_v * b["v_rod"] ** 2 + b.P.b_m * b["omega"] ** 2,
    }


class Smooth(Part):
    """Simplified friction (eq. 3), continuous: any ODE solver, linearisable."""

    family, value = "friction", "smooth"
    reads = (
        Port("v_contact", "m/s", "the velocity at the friction contact"),
        Port("F_drive", "N", "the force driving the friction contact"),
        Port("omega", "rad/s", "the motor speed"),
        Port("v_rod", "m/s", "the rod velocity"),
    )
    doc = "smooth Coulomb law F_r s(v) (+ Stribeck hump) + viscous"
    inputs = (F_EXT,)
    outputs = _OUT
    heat = {"P_friction": "screw", "P_viscous": "screw"}
    params = _PARAMS + ("v_s", "r_start", "v_st", "delta_st")
    small_signal = {"friction": {"off": {"F_seal": 0.0, "C_bear": 0.0}}}
    options = {"friction_shape": SHAPES, "stribeck": ("off", "on")}

    def signals(self):
        shape = self.opt.get("friction_shape", SHAPES[0])
        strib = self.opt.get("stribeck", "off") == "on"
        out = _common(None)
        out[("F_friction", "F_c")] = lambda b: smooth(b["v_contact"], b["F_r"], b.P, shape, strib)
        out["stick"] = lambda b: 0
        out["F_net"] = lambda b: b["F_drive"] - b["F_friction"]
        return out


class Hybrid(Part):
    """Enhanced (Karnopp stick-slip) friction (eqs. 4-8): a hybrid part, with the
    stick-entry map :meth:`project` applied by the integrators after each step."""

    family, value = "friction", "hybrid"
    reads = (
        Port("v_contact", "m/s", "the velocity at the friction contact"),
        Port("F_drive", "N", "the force driving the friction contact"),
        Port("omega", "rad/s", "the motor speed"),
        Port("v_rod", "m/s", "the rod velocity"),
    )
    doc = "Karnopp stick-slip: dead band eps, breakaway F_start = r_start F_r"
    inputs = (F_EXT,)
    outputs = _OUT
    heat = Smooth.heat
    params = _PARAMS + ("eps", "r_start")
    smooth = {"friction": "smooth"}
    # the stick band closed too: the hybrid model then linearises exactly like the smooth one
    small_signal = {"friction": {
        "off": {"F_seal": 0.0, "C_bear": 0.0, "eps": 0.0},
        "smooth": "friction policy 'smooth' linearises the smooth friction law; the hybrid (Karnopp) "
                  "variant has no meaningful slope: use friction policy 'off'",
    }}

    def signals(self):
        out = _common(None)
        out["F_app"] = lambda b: b["F_drive"] - b.P.c_v * b["v_contact"]
        out["F_net"] = lambda b: b["F_app"] - b["F_c"]
        # the stick test uses the applied force with the contact at rest
        out["F_hold"] = lambda b: ca.substitute(b["F_app"], b.state("contact_velocity"), 0)
        out[("F_friction", "F_c", "stick")] = lambda b: hybrid(b["v_contact"], b["F_app"], b["F_r"], b.P, b["F_hold"])
        return out

    def project(self, prev, now):
        stick = stick_entry(prev["v_contact"], now["v_contact"], now["F_hold"], now["F_r"], now.P)
        name = now.state_name("contact_velocity")
        return {name: ca.if_else(stick, 0, now.x[name])}, stick


# ---- LuGre ---------------------------------------------------------------------------
#: Floor of the Stribeck curve (N) in the bristle rate: only a parameter set without any
#: Coulomb friction (F_r = 0) reaches it, where the bristles then carry no force.
G_MIN = 1e-9
#: Contact velocity (m/s) below which the steady-state deflection z_ss is that at rest (0):
#: a trim at rest leaves a velocity of round-off (~1e-20 m/s), of either sign.
V_REST = 1e-12


def stribeck_curve(v, F_r, P):
    """The Stribeck curve g(v) = F_c + (F_s - F_c) h(v) with F_c = F_r, h the hump
    e^-(|v|/v_st)^delta_st (:func:`stribeck_hump`),
    F_s = r_start F_r, v_s = v_st (N): the steady-state LuGre friction without the
    viscous part.

    Parameters
    ----------
    v : SX
        Velocity at the contact (m/s).
    F_r : SX
        Sliding level (eq. 7) (N).
    P : SimpleNamespace
        Parameter symbols by flat name (uses ``r_start``, ``v_st``).
    """
    return F_r * (1 + (P.r_start - 1) * stribeck_hump(v, P))


def lugre_rate(v, z, g, P):
    """Bristle rate dz/dt = v - sigma_0 |v| z / g(v) (m/s).

    Parameters
    ----------
    v : SX
        Velocity at the contact (m/s).
    z : SX
        Bristle deflection (m).
    g : SX
        The Stribeck curve at v (N), :func:`stribeck_curve`.
    P : SimpleNamespace
        Parameter symbols by flat name (uses ``sigma_0``).
    """
    return v - P.sigma_0 * ca.fabs(v) * z / ca.fmax(g, G_MIN)


class LuGre(Part):
    """LuGre dynamic friction (Canudas de Wit et al. 1995): the bristle deflection z is a
    state; steady sliding gives the Stribeck curve, a force below breakaway a pre-sliding
    deflection F/sigma_0."""

    family, value = "friction", "lugre"
    reads = (
        Port("v_contact", "m/s", "the velocity at the friction contact"),
        Port("F_drive", "N", "the force driving the friction contact"),
        Port("omega", "rad/s", "the motor speed"),
        Port("v_rod", "m/s", "the rod velocity"),
    )
    doc = "LuGre: bristle state z, sigma_0 z + sigma_1 dz/dt + c_v v, Stribeck curve F_r..r_start F_r"
    # at rest nothing restores z (dz/dt = v): the trim holds it at its steady state z_ss(v)
    states = (State("z", "m", "LuGre bristle deflection", scale=lambda P: 1e-5, rest="z_ss"),)
    inputs = (F_EXT,)
    outputs = _OUT + (Output("z_ss", "m", "steady-state bristle deflection at the contact velocity", kind="aux"),)
    heat = Smooth.heat
    stored = ("E_bristle",)
    params = _PARAMS + ("r_start", "v_st", "delta_st", "sigma_0", "sigma_1")
    # off: no Coulomb friction and no bristles, viscous c_v only (as the other laws)
    small_signal = {"friction": {"off": {"F_seal": 0.0, "C_bear": 0.0, "sigma_0": 0.0, "sigma_1": 0.0}}}

    def signals(self):
        def bristle(b):
            P, z, zdot, v = b.P, b["z"], b[der("z")], b["v_contact"]
            # the bristle force's power less what its spring stores: the dissipated part
            return P.sigma_0 * z + P.sigma_1 * zdot, P.sigma_0 * z * (v - zdot) + P.sigma_1 * zdot * v

        out = _common(None)
        del out["P_friction"]  # provided with the bristle force
        out["g_stribeck"] = lambda b: stribeck_curve(b["v_contact"], b["F_r"], b.P)
        out[der("z")] = lambda b: lugre_rate(b["v_contact"], b["z"], b["g_stribeck"], b.P)
        out[("F_c", "P_friction")] = bristle
        out["F_friction"] = lambda b: b["F_c"] + b.P.c_v * b["v_contact"]
        out["stick"] = lambda b: 0
        out["F_net"] = lambda b: b["F_drive"] - b["F_friction"]
        out["E_bristle"] = lambda b: 0.5 * b.P.sigma_0 * b["z"] ** 2
        # steady-state deflection at the contact velocity, the trim's rest rule: g(v) sign(v)/sigma_0,
        # 0 at rest (below V_REST: a trim at rest has a velocity of round-off, of either sign)
        def z_ss(b):
            v = b["v_contact"]
            moving = ca.if_else(ca.fabs(v) > V_REST, ca.sign(v), 0)
            return ca.if_else(b.P.sigma_0 > 0, b["g_stribeck"] * moving / b.P.sigma_0, 0)

        out["z_ss"] = z_ss
        return out


# ---- LuGre on the smooth law's curve -----------------------------------------------------
#: |x| below which x/tanh(x) is its series 1 + x^2/3 - x^4/45: the next term, 2 x^6/945, is
#: 2e-21 there (below round-off of 1), so neither the value nor its derivative divides 0 by 0.
X_SERIES = 1e-3


def x_over_tanh(x):
    """h(x) = x / tanh(x): even, analytic, 1 at x = 0 (the series below |x| = X_SERIES,
    the quotient of a divisor kept away from 0 above; value and slope continuous to
    round-off at the switch).

    Parameters
    ----------
    x : SX
        Argument (1).
    """
    small = x**2 < X_SERIES**2
    xs = ca.if_else(small, 1, x)
    return ca.if_else(small, 1 + x**2 / 3 - x**4 / 45, xs / ca.tanh(xs))


def smooth_bristle_rate(v, z, F_r, P, shape="tanh", stribeck=False):
    """Bristle rate dz/dt = v - sigma_0 z |v|/g(v) on the smooth law's curve
    g(v) = |F_c(v)| (:func:`smooth`'s Coulomb part), written without 0/0 (m/s):
    |v|/g(v) = (w/F_r) h(v/w) / hump(v), h = :func:`x_over_tanh`, w = v_s (tanh) or
    2 v_s (Fermi: 2/(1 + e^-u) - 1 = tanh(u/2)), hump = 1 + (r_start - 1) h(v)
    (:func:`stribeck_hump`) with ``stribeck``, else 1. F_r is floored at G_MIN (only a set without Coulomb
    friction reaches it).

    Parameters
    ----------
    v : SX
        Velocity at the contact (m/s).
    z : SX
        Bristle deflection (m).
    F_r : SX
        Sliding level (eq. 7) (N).
    P : SimpleNamespace
        Parameter symbols by flat name (uses ``sigma_0``, ``v_s`` and, with ``stribeck``,
        ``r_start``, ``v_st``).
    shape : {"tanh", "fermi"}
        The smooth law's sign function.
    stribeck : bool
        The smooth law's Stribeck hump.
    """
    if shape not in SHAPES:
        raise ValueError(f"friction shape '{shape}' not one of {SHAPES}")
    w = P.v_s if shape == "tanh" else 2 * P.v_s
    hump = 1 + (P.r_start - 1) * stribeck_hump(v, P) if stribeck else 1
    return v - P.sigma_0 * z * w * x_over_tanh(v / w) / (ca.fmax(F_r, G_MIN) * hump)


class LuGreSmooth(Part):
    """LuGre on the smooth law's curve: the bristle state of :class:`LuGre` with
    g(v) = |F_c(v)| of :class:`Smooth` (same options), so steady sliding is the smooth
    law; at rest the bristles relax (time constant F_r/(sigma_0 v_s))."""

    family, value = "friction", "lugre_smooth"
    reads = (
        Port("v_contact", "m/s", "the velocity at the friction contact"),
        Port("F_drive", "N", "the force driving the friction contact"),
        Port("omega", "rad/s", "the motor speed"),
        Port("v_rod", "m/s", "the rod velocity"),
    )
    doc = "LuGre on the smooth law's curve: bristle state z, steady state F_r s(v) (+ hump) + viscous"
    # the trim holds z at its steady state (with sigma_0 = 0 nothing else determines it)
    states = (State("z", "m", "LuGre bristle deflection", scale=lambda P: 1e-5, rest="z_ss"),)
    inputs = (F_EXT,)
    outputs = LuGre.outputs
    heat = Smooth.heat
    stored = ("E_bristle",)
    params = _PARAMS + ("v_s", "r_start", "v_st", "delta_st", "sigma_0", "sigma_1")
    small_signal = LuGre.small_signal
    options = Smooth.options

    def signals(self):
        shape = self.opt.get("friction_shape", SHAPES[0])
        strib = self.opt.get("stribeck", "off") == "on"

        def bristle(b):
            P, z, zdot, v = b.P, b["z"], b[der("z")], b["v_contact"]
            return P.sigma_0 * z + P.sigma_1 * zdot, P.sigma_0 * z * (v - zdot) + P.sigma_1 * zdot * v

        out = _common(None)
        del out["P_friction"]  # provided with the bristle force
        out[der("z")] = lambda b: smooth_bristle_rate(b["v_contact"], b["z"], b["F_r"], b.P, shape, strib)
        out[("F_c", "P_friction")] = bristle
        out["F_friction"] = lambda b: b["F_c"] + b.P.c_v * b["v_contact"]
        out["stick"] = lambda b: 0
        out["F_net"] = lambda b: b["F_drive"] - b["F_friction"]
        out["E_bristle"] = lambda b: 0.5 * b.P.sigma_0 * b["z"] ** 2
        # steady deflection: the smooth law's Coulomb part over sigma_0 (smooth in v, 0 at rest)
        out["z_ss"] = lambda b: ca.if_else(b.P.sigma_0 > 0, smooth(b["v_contact"], b["F_r"], b.P, shape, strib)[1]
                                           / ca.fmax(b.P.sigma_0, 1e-300), 0)
        return out
