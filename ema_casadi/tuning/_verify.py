"""Verification of a gain set independently of the optimiser: a fresh trim and AD
linearisation per load case, the toolkit's loop margins, eigenvalues, bandwidth and a
linear step (exact zero-order-hold discretisation); a nonlinear step simulation on the
full model."""

from __future__ import annotations

import math
import warnings

import numpy as np

from ..frequency import LoopMargins, bandwidth, closed_loop, freqresp, margins
from ..linearisation import LinearizationError, linear_model, loop_model, operating_point
from ..model.assembly import Model
from ..model.params import Parameters
from ..signals import Signal
from ..simulation import simulate, step_response_metrics
from ._constraints import ecu_limits
from ._requirements import Requirements, _load_label

_F_MS = np.logspace(-2, 5, 701)  # Hz, 100 per decade for the sensitivity peak
_F_NOISE = np.logspace(-2, 4, 601)  # Hz, 100 per decade for the noise gain


def _loop_margins(L) -> dict:  # L: a loop transfer or its LoopMargins
    """Margins of a SISO loop transfer (:func:`ema_casadi.frequency.margins`, crossovers
    in 0.01 Hz - 100 kHz), every one >= 0: ``gm_db`` (the smallest gain rise that
    destabilises, inf if none) at ``f_pc_hz``, ``gm_down_db`` (the smallest gain fall,
    the gain-reduction margin, inf if none) at ``f_down_hz``, ``pm_deg`` (smallest
    angular distance of L to -1 at a gain crossover) at ``f_gc_hz``, and
    ``gain_crossovers`` (each ``f_hz`` with its ``pm_deg``)."""
    m = L if isinstance(L, LoopMargins) else margins(L)

    def hz(v):
        return None if v is None else float(v)

    return {"gm_db": float(m.gm_db), "f_pc_hz": hz(m.f_pc_hz), "gm_down_db": float(m.gm_down_db),
            "f_down_hz": hz(m.f_down_hz), "pm_deg": float(m.pm_deg), "f_gc_hz": hz(m.f_gc_hz),
            "gain_crossovers": [{"f_hz": float(c["f_hz"]), "pm_deg": float(c["pm_deg"])} for c in m.gain_crossovers]}


def _check_loops(model, op, label, req, worst, failures) -> dict:
    """Margins and sensitivity peak of every loop at ``op``; ``worst`` updated and the
    requirement's failures appended."""
    gm_up, pm_req = req.margin_targets()
    # a lower gain margin (crossing left of -1): GM itself, or 1 + 1/Ms under |1 + L| >= 1/Ms
    gm_down = gm_up if req.ms is None else 20 * math.log10(1 + 1 / req.ms)
    loops = {}
    for name in model.loops:
        L = loop_model(model, name, op)
        m = _loop_margins(L)
        m["ms"] = float(np.max(np.abs(1 / (1 + freqresp(L, _F_MS).ravel()))))
        loops[name] = m
        worst["gm_db"] = min(worst["gm_db"], m["gm_db"])
        worst["gm_down_db"] = min(worst["gm_down_db"], m["gm_down_db"])
        worst["pm_deg"] = min(worst["pm_deg"], m["pm_deg"])
        worst["ms"] = max(worst["ms"], m["ms"])
        where = f"{name} loop at {label}"
        if m["gm_db"] < gm_up - 1e-6:
            failures.append(f"{where}: GM {m['gm_db']:.2f} dB < {gm_up:.3g} dB required")
        if m["gm_down_db"] < gm_down - 1e-6:
            failures.append(f"{where}: gain-reduction margin {m['gm_down_db']:.2f} dB (gain may fall only that much) "
                            f"< {gm_down:.3g} dB required")
        if m["pm_deg"] < pm_req - 1e-6:
            failures.append(f"{where}: PM {m['pm_deg']:.2f} deg < {pm_req:.3g} deg required")
        if req.ms is not None and m["ms"] > req.ms * (1 + 1e-3):
            failures.append(f"{where}: sensitivity peak {m['ms']:.4g} > Ms = {req.ms:g}")
    return loops


def _check_cascade(model, op, label, req, failures) -> dict:
    """Every loop with its outer loops open (the cascade view): margins at every
    crossing, unconditional stability (no phase crossover where |L| > 10^(-GM/20)),
    the separation of neighbouring gain crossovers and the noise gain. Returns
    ``loops`` (per loop: as :func:`_loop_margins` plus ``gain_crossovers_hz``),
    ``separation`` (per inner loop: the ratio of its lowest gain crossover to the
    outer loop's highest) and ``noise_gain_A_per_m`` (peak |i_cmd / n_x|, 0.01 Hz -
    10 kHz, the tuner's grid ends there and the response is flat above)."""
    gm_up, pm_req = req.margin_targets()
    loops, fcs = {}, {}
    for name in model.loops:
        m = margins(loop_model(model, name, op, outer="open"))
        d = _loop_margins(m)
        d["gain_crossovers_hz"] = [c["f_hz"] for c in m.gain_crossovers]
        loops[name], fcs[name] = d, d["gain_crossovers_hz"]
        where = f"{name} loop (outer loops open) at {label}"
        if d["gm_down_db"] < math.inf:
            failures.append(f"{where}: conditionally stable (gain-reduction margin {d['gm_down_db']:.2f} dB); "
                            "unconditional stability required")
        if d["gm_db"] < gm_up - 1e-6:
            failures.append(f"{where}: GM {d['gm_db']:.2f} dB < {gm_up:.3g} dB required")
        if d["pm_deg"] < pm_req - 1e-6:
            failures.append(f"{where}: PM {d['pm_deg']:.2f} deg < {pm_req:.3g} deg required")
    names = list(model.loops)
    sep = {}
    for outer, inner in zip(names[:-1], names[1:], strict=True):
        ratio = min(fcs[inner]) / max(fcs[outer]) if fcs[inner] and fcs[outer] else math.nan
        sep[inner] = ratio
        if req.separation > 0 and not ratio >= req.separation * (1 - 1e-6):
            failures.append(f"{label}: {inner} loop crossover only {ratio:.3g} x the {outer} loop's "
                            f"(outer loops open); separation {req.separation:g} required")
    out = {"loops": loops, "separation": sep, "noise_gain_A_per_m": None}
    if model.outputs_with("current_command"):
        H = freqresp(linear_model(model, op, inputs=[model.loops[names[0]].injection],
                                  outputs=[model.output_with("current_command")]), _F_NOISE)
        gain = out["noise_gain_A_per_m"] = float(np.max(np.abs(H)))
        bound = req.noise_gain_max(ecu_limits(model, op.p)["current"])
        if bound is not None and gain > bound * (1 + 1e-4):
            n = req.sensor_noise
            failures.append(f"{label}: current command moves {gain * n:.3g} A on {n * 1e6:g} um of "
                            f"position-sensor noise > {bound * n:.3g} A")
    return out


def _linear_step(model, op, amp, t_end):
    """Closed-loop linear step of amp metres, exact at 20 us samples (zero-order-hold
    discretisation by the matrix exponential of [[A, B], [0, 0]] h): overshoot, 2 %
    settling time, peak |i_q| and |v_dq| including the operating values."""
    import scipy.linalg

    outs = [model.output_with(r) for r in ("rod_position", "motor_current", "d_voltage", "q_voltage")]
    lin = linear_model(model, op, inputs=[model.input_with("command")], outputs=outs)
    keep = [i for i in range(lin.A.shape[0]) if np.any(lin.A[:, i] != 0) or np.any(lin.C[:, i] != 0)]
    A, b, C, d = lin.A[np.ix_(keep, keep)], lin.B[keep, 0], lin.C[:, keep], lin.D[:, 0]
    h = 2e-5  # s: resolves the current peak
    n_steps = int(round(t_end / h))
    n = len(keep)
    M = np.zeros((n + 1, n + 1))
    M[:n, :n], M[:n, n] = A * h, b * h
    E = scipy.linalg.expm(M)
    Ad, bd = E[:n, :n], E[:n, n] * amp
    X = np.empty((n_steps + 1, n))
    x = np.zeros(n)
    X[0] = x
    for k in range(n_steps):
        x = Ad @ x + bd
        X[k + 1] = x
    t = h * np.arange(n_steps + 1)
    y = X @ C.T + amp * d  # the step holds from t = 0 on (its feedthrough at every sample)
    x_rel = y[:, 0] / amp
    i_q = op.output(outs[1]) + y[:, 1]
    v = np.hypot(op.output(outs[2]) + y[:, 2], op.output(outs[3]) + y[:, 3])
    m = step_response_metrics(t, x_rel)
    return {"overshoot": m["overshoot"], "settling_time_s": m["settling_time_s"],
            "i_q_peak_A": float(np.max(np.abs(i_q))), "v_dq_peak_V": float(np.max(v))}


def _check_load(model, op, F, req, limits, worst, failures) -> dict:
    """Every check at the operating point of load case F (N); ``limits`` = (current limit A,
    v_lim V)."""
    label = _load_label(F)
    loops = _check_loops(model, op, label, req, worst, failures)
    A = linear_model(model, op, inputs=[model.input_with("command")], outputs=[model.output_with("rod_position")]).A
    keep = [i for i in range(A.shape[0]) if np.any(A[:, i] != 0)]
    alpha = float(np.max(np.linalg.eigvals(A[np.ix_(keep, keep)]).real))
    stable = alpha < 0
    for v in loops.values():
        v["stable"] = stable
    if not alpha <= -req.sigma + 1e-9 * max(1.0, abs(alpha)):
        failures.append(f"{label}: closed-loop eigenvalue at Re = {alpha:.4g} 1/s, right of -sigma = {-req.sigma:g}")
    bw = bandwidth(closed_loop(model, op), f_min=0.01, f_max=1e4)
    worst["bandwidth_hz"] = min(worst["bandwidth_hz"], bw)
    if req.bandwidth_min_hz is not None and bw < req.bandwidth_min_hz * (1 - 1e-6):
        failures.append(f"{label}: bandwidth {bw:.3g} Hz < {req.bandwidth_min_hz:g} Hz required")
    cascade = _check_cascade(model, op, label, req, failures)
    worst["separation"] = min([worst["separation"], *cascade["separation"].values()])
    if cascade["noise_gain_A_per_m"] is not None:
        worst["noise_gain_A_per_m"] = max(worst["noise_gain_A_per_m"], cascade["noise_gain_A_per_m"])
    st = _linear_step(model, op, req.step, req.t_step)
    i_lim, v_lim = limits
    if st["overshoot"] > req.overshoot + 1e-4:
        failures.append(f"{label}: linear step overshoot {100 * st['overshoot']:.2f} % > {100 * req.overshoot:g} %")
    if st["i_q_peak_A"] > i_lim * (1 + 1e-4):
        failures.append(f"{label}: current peak {st['i_q_peak_A']:.3g} A > the current limit {i_lim:g} A on a "
                        f"{req.step * 1e3:g} mm step")
    if st["v_dq_peak_V"] > v_lim * (1 + 1e-4):
        failures.append(f"{label}: voltage peak {st['v_dq_peak_V']:.4g} V > {v_lim:.4g} V on a "
                        f"{req.step * 1e3:g} mm step")
    return {"f_ext_N": F, "loops": loops, "outer_open": cascade, "bandwidth_hz": bw, "spectral_abscissa": alpha,
            "stable": stable, "step": st}


def verify(model: Model, params: Parameters, loads=(0.0,), requirements: Requirements | None = None,
           nonlinear_step: float = 0.0) -> dict:
    """Check a gain set independently of the optimiser.

    For every load case a fresh trim and AD linearisation with these gains
    (:mod:`ema_casadi.linearisation`); per loop, the margins of the loop transfer
    (:func:`ema_casadi.frequency.margins`, crossovers in 0.01 Hz - 100 kHz; GM is the
    signed one of smallest magnitude, PM the smallest angular distance to -1), the
    sensitivity peak and the closed-loop stability; the closed-loop -3 dB bandwidth and
    the linear step (exact discretisation) with its peaks of current and voltage. Optionally
    a nonlinear step simulation (:func:`step_metrics`) at no load.

    Parameters
    ----------
    model : Model
        The assembled model.
    params : Parameters
        The parameter set with the gains to check.
    loads : sequence of float
        Load cases f_ext (N).
    requirements : Requirements, optional
        What every load case must meet (default :class:`Requirements`).
    nonlinear_step : float
        Amplitude (m) of a nonlinear step simulated at no load; 0 skips it.

    Returns
    -------
    dict
        ``loads`` (per load label: ``loops`` -> gm_db, f_pc_hz, gm_down_db, f_down_hz,
        pm_deg, f_gc_hz, ms, stable; ``outer_open`` -> the cascade view: ``loops`` with
        their outer loops open, ``separation`` per inner loop, ``noise_gain_A_per_m``;
        ``bandwidth_hz``, ``spectral_abscissa``, ``step``), ``worst`` (smallest |GM|, PM,
        bandwidth, separation, largest Ms and noise gain over all), ``meets`` (bool),
        ``failures`` (list of one-line texts) and ``nonlinear_step`` (or None).
    """
    req = requirements or Requirements()
    p = params.vector()
    lim = ecu_limits(model, p)
    limits = (lim["current"], lim["voltage"])
    out, failures = {}, []
    worst = {"gm_db": math.inf, "gm_down_db": math.inf, "pm_deg": math.inf, "ms": 0.0, "bandwidth_hz": math.inf,
             "separation": math.inf, "noise_gain_A_per_m": 0.0}
    for F in loads:
        label = _load_label(F)
        try:
            op = operating_point(model, f_ext=F, p=p)
        except LinearizationError as exc:
            failures.append(f"{label}: {exc}")
            continue
        out[label] = _check_load(model, op, F, req, limits, worst, failures)
    nl = step_metrics(model, params, nonlinear_step) if nonlinear_step else None
    return {"loads": out, "worst": worst, "meets": not failures, "failures": failures, "nonlinear_step": nl}


def step_metrics(model: Model, params: Parameters, amp: float = 1e-3, *, f_ext: float = 0.0,
                 t_end: float = 0.4, t0: float = 0.01, band: float = 0.02) -> dict:
    """Nonlinear step simulation (full model: friction, backlash, limits; CVODES) from
    rest under the load (trimmed, screw against the loaded flank of the backlash).

    Parameters
    ----------
    model : Model
        The assembled model.
    params : Parameters
        The parameter set (gains included).
    amp : float
        Step amplitude (m) at ``t0``.
    f_ext : float
        Constant external force (N).
    t_end : float
        End time (s).
    t0 : float
        Time of the step (s).
    band : float
        Settling band (fraction of amp).

    Returns
    -------
    dict
        ``overshoot`` (fraction), ``settling_time_s`` (from the step; inf if it has not
        settled by t_end), ``rise_time_s`` (10-90 %), ``i_q_peak_A``, ``v_dq_peak_V``,
        ``x_final_m``, ``amp_m``, ``f_ext_N``, and the series ``t`` (s), the rod position
        (``x_rod``, m) and the motor current (``i_q``, A), by the model's names, for plots.
    """
    pv = params.vector()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "inside the backlash gap" at no load: expected here
        # at rest under the load, the nut against the loaded flank of the gap
        x0 = operating_point(model, inputs={"load": f_ext}, backlash="keep", p=pv).x
    res = simulate(model, t_end, inputs={"command": Signal.step(amp, t0), "load": f_ext}, p=pv, x0=x0,
                   solver="cvodes", dt=1e-4, dt_out=1e-4, rtol=1e-7, atol=1e-10)
    rod, i_q, v_d, v_q = (model.output_with(r) for r in ("rod_position", "motor_current", "d_voltage", "q_voltage"))
    t, x = res.t, res[rod]
    # relative to the rest position before the step (a load compresses the screw)
    x0 = float(np.interp(t0, t, x))
    after = t >= t0
    m = step_response_metrics(t[after] - t0, (x[after] - x0) / amp, band)
    return {
        "amp_m": amp, "f_ext_N": f_ext,
        "overshoot": m["overshoot"],
        "settling_time_s": m["settling_time_s"],
        "rise_time_s": m["rise_time_s"],
        "i_q_peak_A": float(np.max(np.abs(res[i_q]))),
        "v_dq_peak_V": float(np.max(np.hypot(res[v_d], res[v_q]))),
        "x_final_m": float(x[-1]),
        "t": t, rod: x, i_q: res[i_q],
    }
