"""The numerics of :func:`ema_casadi.frequency.margins`: crossovers bracketed on the
grid and refined by SciPy's Brent method, closed-loop stability, the balanced disk
margin refined by a bounded scalar minimisation."""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import brentq, minimize_scalar


def _wrap180(deg):
    return (deg + 180.0) % 360.0 - 180.0


def _unwrap_deg(H: np.ndarray) -> np.ndarray:
    return np.degrees(np.unwrap(np.angle(H)))


def _gain_crossovers(H, f, Hg) -> list[dict]:
    """|L| = 1: log|L| changes sign between grid points; each root refined by Brent (a
    loop of no gain, a channel in standby, has none)."""
    with np.errstate(divide="ignore"):
        lf, lm = np.log10(f), np.log10(np.abs(Hg))
    out = []
    for i in np.nonzero(lm[:-1] * lm[1:] <= 0)[0]:
        if lm[i] == 0 and i > 0 and lm[i - 1] * lm[i + 1] > 0:
            continue  # touches 1 without crossing
        x = _root(lambda t: math.log10(abs(H(10**t))), lf[i], lf[i + 1], lm[i], lm[i + 1])
        fc = 10**x
        phase = math.degrees(np.angle(H(fc)))  # (-180, 180]
        # pm_deg >= 0: the smallest phase rotation (either way) that puts L on -1;
        # lag_deg: the extra phase lag that does (what a loop delay adds)
        out.append({"f_hz": fc, "phase_deg": phase, "pm_deg": abs(_wrap180(phase + 180.0)),
                    "lag_deg": (phase + 180.0) % 360.0})
    return _dedupe(out)


def _phase_crossovers(H, f, Hg) -> list[dict]:
    """The unwrapped phase passes -180 + 360 k; each root refined by Brent."""
    lf, ph = np.log10(f), _unwrap_deg(Hg)
    k = np.floor((ph + 180.0) / 360.0)
    out = []
    for i in np.nonzero(np.diff(k))[0]:
        level = -180.0 + 360.0 * max(k[i], k[i + 1])
        H0, p0 = Hg[i], ph[i]

        def g(t, H0=H0, p0=p0, level=level):
            return p0 + math.degrees(np.angle(H(10**t) / H0)) - level

        x = _root(g, lf[i], lf[i + 1], ph[i] - level, ph[i + 1] - level)
        fc = 10**x
        # gain_db = 20 log10 |L| there: < 0 the gain may rise by -gain_db (an upper gain
        # margin), > 0 it may fall by gain_db (a gain-reduction margin)
        out.append({"f_hz": fc, "gain_db": 20 * math.log10(abs(H(fc)))})
    return _dedupe(out)


def _root(g, a, b, ga, gb):
    """Root of g in the bracket [a, b] (g(a) g(b) <= 0), SciPy's Brent method."""
    if ga == 0:
        return a
    if gb == 0:
        return b
    return brentq(g, a, b, xtol=1e-13, rtol=4 * np.finfo(float).eps)


def _closed_loop_stable(A, B, C, d) -> bool:
    """Stability of L/(1+L): x' = (A - B C/(1+D)) x."""
    if abs(1 + d) < 1e-12:
        return False
    n = A.shape[0]
    lam = np.linalg.eigvals(A - B @ C / (1 + d)) if n else np.zeros(0)
    tol = 1e-9 * max(1.0, float(np.max(np.abs(lam)))) if n else 0.0
    return bool(np.all(lam.real < tol))


def _disk_margin(H, f, Hg) -> tuple[float, float]:
    """Balanced disk margin alpha = min 2|1 + L|/|1 - L| and its frequency (Hz): the
    grid minimum refined by a bounded scalar minimisation between its neighbours."""
    lf = np.log10(f)
    alpha_g = 2 * np.abs(1 + Hg) / np.abs(1 - Hg)
    j = int(np.argmin(alpha_g))
    lo, hi = lf[max(j - 1, 0)], lf[min(j + 1, len(lf) - 1)]
    res = minimize_scalar(lambda t: _alpha(H(10**t)), bounds=(lo, hi), method="bounded",
                          options={"xatol": 1e-10})
    alpha = min(_alpha(H(10**res.x)), float(alpha_g[j]))
    return alpha, (10**res.x if alpha < alpha_g[j] else f[j])


def _alpha(h: complex) -> float:
    return 2 * abs(1 + h) / abs(1 - h) if h != 1 else math.inf


def _dedupe(items):
    out = []
    for it in sorted(items, key=lambda c: c["f_hz"]):
        if not out or abs(it["f_hz"] - out[-1]["f_hz"]) > 1e-9 * it["f_hz"]:
            out.append(it)
    return out


def margin_text(m, digits: int = 1) -> str:
    """One line naming each margin for what it is: ``GM`` (the gain may rise by it),
    ``gain-reduction margin`` (it may fall by it; only a conditionally stable loop has
    one), ``PM`` (the smallest over every gain crossover), each with its frequency, and
    every gain crossover where there are several. No margin is printed negative.

    Parameters
    ----------
    m : LoopMargins or dict
        Margins, or their ``as_dict`` / JSON form (``gm_db``, ``f_pc_hz``,
        ``gm_down_db``, ``f_down_hz``, ``pm_deg``, ``f_gc_hz``, optionally
        ``gain_crossovers``); JSON may carry inf as the text "inf".
    digits : int
        Decimals of the dB and degree values.
    """
    d = m.as_dict() if hasattr(m, "as_dict") else m

    def val(key):
        v = d.get(key)
        return math.inf if v is None else float(v)

    def at(key):
        v = d.get(key)
        return f" at {float(v):.3g} Hz" if v is not None else ""

    gm, down, pm = val("gm_db"), val("gm_down_db"), val("pm_deg")
    text = f"GM {gm:.{digits}f} dB{at('f_pc_hz')}" if math.isfinite(gm) else "GM inf"
    if math.isfinite(down):
        text += f", gain-reduction margin {down:.{digits}f} dB{at('f_down_hz')}"
    text += f", PM {pm:.{digits}f} deg{at('f_gc_hz')}" if math.isfinite(pm) else ", PM inf"
    gcs = d.get("gain_crossovers") or []
    if len(gcs) > 1:
        text += " (gain crossovers " + ", ".join(f"{float(c['f_hz']):.3g} Hz PM {float(c['pm_deg']):.{digits}f} deg"
                                                 for c in gcs) + ")"
    return text
