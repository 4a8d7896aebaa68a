"""Friction started from the records: the steady-state friction curve fitted first.

A single-shooting fit over long, lightly damped, friction-switching records has many
valleys; one that starts with the seal friction and the breakaway ratio wrong by 20 %
trades one against the other and stops there. Where the records hold *steady
segments* (the rod at a steady speed under a known load: slow ramps of the command,
slews at the rate limit), the friction force there is the steady-state friction curve
at that speed, read from the records without the dynamics:

- windows of :data:`WINDOW_S` per record where the load ``f_ext`` is constant; a
  quadratic fitted over the window to the rod position (``x_rod``, else the shaft
  angle ``phi`` times p/(2 pi), else ``omega``'s mean and slope) gives the speed v and
  acceleration a at its centre; the window is *steady* when the speed changes by at
  most :data:`STEADY` of itself across it, |a| W <= STEADY |v|, and v is at least
  :data:`MIN_Z` standard errors from 0 (the rod moves);
- the friction force there: F = mean(F_in) - f_ext - M a with the load cell ``F_in``
  measured; else from the q-current, T = 1.5 pp psi i_q less the inertia
  (J_m + J_s) a 2 pi/p and b_m omega, through the screw's efficiency
  (:func:`ema_casadi.model._steady.nut_force`) to the nut force
  (the start values of psi, J_m, ... : a current-based curve is as good as they are).
  Its standard error is the window's spread over sqrt(samples);
- the model's own steady-state law (:func:`ema_casadi.model._steady.steady_friction`:
  ``smooth`` with its shape and optional hump, the same curve for ``lugre_smooth``,
  the Stribeck curve with sign(v) for ``lugre``) is fitted to those forces by the
  Levenberg-Marquardt of :mod:`ema_casadi.optimisation` in log-parameters: the free
  ones of :data:`CURVE_PARAMS` (F_seal, C_bear, c_v, r_start, v_st). C_bear needs loads
  of two sizes (|f_ext| :data:`LOAD_SPAN` apart), r_start and v_st need :data:`MIN_SLOW`
  segments slower than :data:`SLOW` v_st; F_seal and c_v need speeds :data:`SPAN` apart.
  A parameter the segments cannot tell keeps its start value.

The curve's values are the dynamic fit's start. With ``starts`` > 1 the further starts
are a Latin hypercube (space-filling, seeded) over the free friction parameters: those
the curve told within twice its standard error, the others (typically the hump's,
which chattering slow windows hide) within +-:data:`DESIGN_SPAN` (log) of their start,
the rest of the parameters at the start; all are fitted (in parallel with ``jobs``),
the lowest cost wins and every start's cost is reported (``info["friction_start"]``).

Modes: ``auto`` uses the curve where the records' steady segments tell at least one
free friction parameter, and otherwise starts from the file's values, saying why
(``info["friction_start"]["why"]``); ``records`` requires it (an
:class:`IdentificationError` otherwise: records without steady segments under a known
load); ``off`` (the default) starts from the file's values. Why off by default: alone,
``auto`` narrows the valley a fit on the witness rigs (``studies/witness.py``) ends in
(median seal friction +3.4 % against +7.0 % from the file's values, viscous -33 %
against -91 %) but brings no fit to the truth; with ``coarse_to_fine`` and ``starts``
(:mod:`._coarse`: the starts compared on block means, where the cost is smooth) it
does on many (the identification guide's witness section), and on the benchmark
records the file's values already converge: ``auto`` would change the start, and so
the path, of every fit on records with steady segments.
"""

from __future__ import annotations

import dataclasses

import casadi as ca
import numpy as np

from ..model import AssemblyError, has_hump, nut_force, steady_friction
from ..optimisation import levenberg_marquardt
from ._records import IdentificationError

MODES = ("auto", "records", "off")
#: The curve's parameters (those of them free are fitted).
CURVE_PARAMS = ("F_seal", "C_bear", "c_v", "r_start", "v_st")
#: Window length (s).
WINDOW_S = 0.04
#: A steady window: the speed changes by at most this share of itself across it.
STEADY = 0.1
#: ... and is this many standard errors from rest.
MIN_Z = 10.0
#: A window whose force spreads more than CHATTER times the QUIET quantile of the windows'
#: spreads is not steady: the rod chatters on the screw's spring (a Stribeck slope steeper
#: than the contact damping makes that mode unstable), and a chattering window's mean
#: force is not the curve's at its mean speed.
CHATTER, QUIET = 3.0, 0.2
#: Slow: below this multiple of the start's Stribeck velocity v_st (the hump's range:
#: e^-9 of the Gaussian hump's height left there).
SLOW = 3.0
#: Slow segments needed for the hump (r_start, v_st) and for a ``records`` request.
MIN_SLOW = 3
#: Speeds (|v|, largest over smallest) needed to tell F_seal from c_v.
SPAN = 4.0
#: Loads (|f_ext|, N) needed apart to tell C_bear from F_seal.
LOAD_SPAN = 1000.0
#: Relative floor of a window's standard error (the loop's ripple is not white noise).
FLOOR = 0.002
#: A curve value whose standard error (log scale) exceeds this is not used (the start kept).
WIDE_REL = 0.5
#: Extra starts: the friction parameters the curve did not tell within +-DESIGN_SPAN of
#: their start (log scale: e^0.5 = 1.65), those it told within twice its standard error.
DESIGN_SPAN = 0.5


def check_mode(mode) -> str:
    """The friction-start mode, checked."""
    if mode not in MODES:
        raise IdentificationError(f"friction_start: expected one of {', '.join(MODES)}, got {mode!r}")
    return mode


def _values(model, fr) -> dict:
    """Every parameter's value (SI) at the fit's start."""
    pv = np.array(model.p(), float).ravel()
    pv[fr.index] = fr.theta0
    return dict(zip(model.param_names, pv.tolist(), strict=True))


def steady_segments(model, records, values: dict) -> list[dict]:
    """The steady windows of ``records`` (module docstring): per window the record,
    its time (s), speed ``v`` (m/s), load ``load`` (N), friction force ``F`` and its
    standard error ``sd`` (N). ``values``: parameter name -> value (SI)."""
    P = values
    r = P["p"] / (2 * np.pi)
    name = _names(model)
    eff = model.input_info.get(name["efficiency"])
    eta0 = P[eff.default] if eff is not None and eff.default else 1.0  # the input's default: its parameter
    out = []
    for rec in records:
        ch, n = rec.channels, max(3, int(round(WINDOW_S / np.median(np.diff(rec.t)))))
        got = {k: ch.get(v) for k, v in name.items() if v is not None and v in ch}
        if "force" not in got and not ("current" in got and "psi" in model.used_params):
            continue
        pos = got["position"] if "position" in got else got["angle"] * r if "angle" in got else None
        if pos is None and "speed" not in got:
            continue
        f_all = rec.inputs.get(name["load"], np.zeros(rec.n))
        eta_all = rec.inputs.get(name["efficiency"], np.full(rec.n, eta0))
        for k in range(0, rec.n - n + 1, n):
            sl = slice(k, k + n)
            f_ext = f_all[sl]
            if np.ptp(f_ext) > 1e-9 * max(1.0, abs(f_ext[0])):
                continue
            tau = rec.t[sl] - rec.t[sl].mean()
            if pos is not None:
                A = np.column_stack([np.ones(n), tau, tau**2])
                coef, res, *_ = np.linalg.lstsq(A, pos[sl], rcond=None)
                s2 = float(res[0]) / (n - 3) if len(res) else 0.0
                v, a = coef[1], 2 * coef[2]
                v_se = np.sqrt(s2 * np.linalg.inv(A.T @ A)[1, 1])
            else:
                w = got["speed"][sl] * r
                slope, mean = np.polyfit(tau, w, 1)
                v, a, v_se = mean, slope, np.std(w) / np.sqrt(n)
            if abs(a) * WINDOW_S > STEADY * abs(v) or abs(v) < MIN_Z * max(v_se, 1e-12):
                continue
            if "force" in got:
                push = got["force"][sl]
            else:
                T = 1.5 * P["pp"] * P["psi"] * got["current"][sl]
                omega = v / r
                T_net = T - (P["J_m"] + P["J_s"]) * a / r - P["b_m"] * omega
                push = np.array([nut_force(tn, omega, e, _Namespace(P)) for tn, e in
                                 zip(T_net, eta_all[sl], strict=True)])
            F = push - f_ext[0] - P["M"] * a
            out.append({"record": rec.path, "t": float(rec.t[sl].mean()), "v": float(v), "load": float(f_ext[0]),
                        "F": float(np.mean(F)), "sd": float(max(np.std(F) / np.sqrt(n), 1e-3))})
    if out:  # stick-slip: a window whose force spreads more than CHATTER x the quiet ones' is not steady
        quiet = np.quantile([s["sd"] for s in out], QUIET)
        out = [s for s in out if s["sd"] <= CHATTER * quiet]
    return out


def _names(model) -> dict:
    """The signals the segments are read from, by role (None where the model has none)."""
    def one(get, role):
        try:
            return get(role)
        except AssemblyError:
            return None

    return {"position": one(model.output_with, "rod_position"), "angle": one(model.state_with, "shaft_angle"),
            "speed": one(model.output_with, "motor_speed"), "current": one(model.output_with, "motor_current"),
            "force": one(model.output_with, "screw_force"), "load": one(model.input_with, "load"),
            "efficiency": one(model.input_with, "efficiency")}


class _Namespace:
    """Parameters by attribute: the dict's values, overridden by symbols."""

    def __init__(self, values: dict, symbols: dict | None = None):
        self._v, self._s = values, symbols or {}

    def __getattr__(self, name):
        return self._s[name] if name in self._s else self._v[name]


def _law(model, values: dict, names) -> ca.Function:
    """The model's steady-state friction law F(v, f_ext; log theta of ``names``) (N)."""
    v, f, z = ca.SX.sym("v"), ca.SX.sym("load"), ca.SX.sym("z", len(names))
    F = steady_friction(model.variants, v, f, _Namespace(values, {n: ca.exp(z[k]) for k, n in enumerate(names)}))
    return ca.Function("law", [v, f, z], [F, ca.jacobian(F, z)])


def curve_fit(model, segments: list[dict], names, values: dict) -> dict:
    """The steady-state law fitted to ``segments`` (:func:`steady_segments`) for the
    parameters ``names`` the segments can tell (module docstring); the others keep
    ``values``. Returns ``values`` (name -> SI), ``sd_rel`` (log-scale standard
    errors), ``fitted``, ``kept`` (name -> why), ``cost``, ``segments`` and ``speeds``."""
    speed = np.abs([s["v"] for s in segments])
    loads = np.abs([s["load"] for s in segments])
    slow = int(np.sum(speed < SLOW * values["v_st"]))
    law_params = ("F_seal", "C_bear", "c_v") + (("r_start", "v_st") if has_hump(model.variants) else ())
    kept = {}
    for n in names:
        if n not in law_params:
            continue
        if n == "C_bear" and np.ptp(loads) < LOAD_SPAN:
            kept[n] = f"the steady segments' loads span {np.ptp(loads):.0f} N (< {LOAD_SPAN:.0f} N)"
        elif n in ("r_start", "v_st") and slow < MIN_SLOW:
            kept[n] = f"{slow} steady segments slower than {SLOW:g} v_st (< {MIN_SLOW})"
        elif n in ("F_seal", "c_v") and speed.max() < SPAN * speed.min():
            kept[n] = f"the steady speeds span a factor {speed.max() / speed.min():.1f} (< {SPAN:g})"
        elif values[n] <= 0:
            kept[n] = "its start value is 0 (a log-scaled fit needs it positive)"
    fit = [n for n in names if n in law_params and n not in kept]
    doc = {"segments": len(segments), "slow_segments": slow, "speeds": [float(speed.min()), float(speed.max())],
           "fitted": fit, "kept": kept, "values": {n: values[n] for n in fit}, "sd_rel": {}, "cost": None}
    if not fit:
        return doc
    law = _law(model, values, fit)
    v, f = np.array([s["v"] for s in segments]), np.array([s["load"] for s in segments])
    F, sd = np.array([s["F"] for s in segments]), np.array([s["sd"] for s in segments])
    # the spread of a window is the noise's plus the loop's ripple; FLOOR of the force bounds what
    # a window's mean can tell (the ripple is not white), so no window outweighs the others
    sd = np.hypot(sd, FLOOR * np.abs(F))

    def evaluate(z):
        Fm, J = law.map(len(v))(v, f, z)
        return (np.asarray(Fm).ravel() - F) / sd, np.asarray(J).reshape(len(v), len(fit)) / sd[:, None]

    z0 = np.log([values[n] for n in fit])
    lo = np.where([n == "r_start" for n in fit], 0.0, z0 - 4.0)  # a hump, not a dip: r_start >= 1
    sol = levenberg_marquardt(evaluate, np.maximum(z0, lo), lo, z0 + 4.0, 200)
    J = sol["J"]
    # a column the segments do not see (a hump at speeds above it) gets a huge variance, not pinv's 0
    cov = np.linalg.inv(J.T @ J + 1e-9 * np.eye(len(fit))) * max(1.0, 2 * sol["cost"] / max(len(v) - len(fit), 1))
    sd_rel = dict(zip(fit, np.sqrt(np.diag(cov)).tolist(), strict=True))
    for n in fit:
        if sd_rel[n] > WIDE_REL:
            kept[n] = f"the curve tells it to +-{100 * sd_rel[n]:.0f} % only"
    use = [k for k, n in enumerate(fit) if n not in kept]
    doc.update(values={fit[k]: float(np.exp(sol["z"][k])) for k in use}, cost=float(sol["cost"]), sd_rel=sd_rel,
               fitted=[fit[k] for k in use])
    return doc


def friction_start(model, records, fr, mode: str):
    """(free set with the curve's start values, the report) for ``mode`` (module
    docstring); the free set unchanged where the curve is not used."""
    mode = check_mode(mode)
    if mode == "off":
        return fr, {"mode": mode, "used": False, "why": "off"}
    names = [n for n in fr.names if n in CURVE_PARAMS]
    values = _values(model, fr)
    segs = steady_segments(model, records, values) if names else []
    doc = curve_fit(model, segs, names, values) if segs else {}
    why = ("no free friction parameter (F_seal, C_bear, c_v, r_start, v_st)" if not names else
           "the records hold no steady-speed segments under a known load (record slow ramps of the command)"
           if not segs else "" if doc["fitted"] else
           "the steady segments tell none of them: " + "; ".join(f"{k}: {v}" for k, v in doc["kept"].items()))
    if why:
        if mode == "records":
            raise IdentificationError(f"friction_start records: {why}")
        return fr, {"mode": mode, "used": False, "why": why}
    theta0 = fr.theta0.copy()
    for n, val in doc["values"].items():
        k = fr.names.index(n)
        theta0[k] = min(max(val, fr.lo[k] * (1 + 1e-9)), fr.hi[k] * (1 - 1e-9))
    return dataclasses.replace(fr, theta0=theta0), {"mode": mode, "used": bool(doc["fitted"]), **doc}


def start_points(fr, starts: int, seed: int, design: dict | None = None) -> list:
    """The fit's starts in optimiser coordinates: the start values first; then, with a
    friction ``design`` (:func:`friction_start`'s report, used), a Latin hypercube over
    the free friction parameters (module docstring), else points drawn log-normally
    around the start (seeded)."""
    rng = np.random.default_rng(seed)
    lo, hi = fr.z_bounds()
    z0 = fr.z(fr.theta0)
    out = [z0]
    names = [n for n in fr.names if n in CURVE_PARAMS and fr.log[fr.names.index(n)]] if design else []
    if names and starts > 1:
        from scipy.stats import qmc

        over = [fr.names.index(n) for n in names]
        # what the curve told: within twice its standard error; the rest over +-DESIGN_SPAN
        span = np.array([min(DESIGN_SPAN, 2 * design["sd_rel"][n]) if n in design["fitted"] else DESIGN_SPAN
                         for n in names])
        for row in qmc.LatinHypercube(d=len(over), seed=rng).random(starts - 1):
            z = z0.copy()
            z[over] += span * (2 * row - 1)
            out.append(np.clip(z, lo + 1e-9, hi - 1e-9))
        return out
    for _ in range(1, starts):
        out.append(np.clip(z0 + np.where(fr.log, rng.normal(0, 0.4, len(z0)), rng.normal(0, 0.2, len(z0))),
                           lo + 1e-9, hi - 1e-9))
    return out
