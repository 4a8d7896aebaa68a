"""Nonlinear frequency response by sine stream (SPEC §4.5), like Simulink's ``frestimate``.

For every point of a grid (variant, load, amplitude, frequency) the nonlinear model is
driven by ``x_cmd = A sin(2 pi f t)`` under a constant external force ``f_ext`` until it
has settled; the first harmonic of ``x_rod`` over the last whole period, divided by the
command's, is the gain and phase. The first harmonic of the motor current ``i_q`` and
the harmonic distortion of both signals are reported too.

Method
------
*One simulator for the whole grid.* Time is normalised to periods, ``tau = f t``, so
``dx/dtau = f(x, u(tau), p) / f`` and every period is ``tau`` in [0, 1]. Amplitude,
frequency and load are appended to the model's parameter vector, so one CVODES (BDF)
integrator with one output grid (``samples`` points per period) serves every point;
smooth friction makes the rod stiff near v = 0 (eigenvalues ~ -5e5 1/s), which a
variable-step implicit method handles cheaply where a fixed-step explicit one cannot.

*Settling criterion.* Period after period, the first harmonic H_k of ``x_rod`` over
period k is compared with H_(k-1): the change is
``e_k = max(|20 log10|H_k/H_(k-1)|| / tol_db, |angle(H_k/H_(k-1))| / tol_deg)``.
A settling transient shrinks geometrically, so what is still to come is about
``e_k q / (1 - q)`` with ``q = e_k / e_(k-1)``; the point has settled when
``e_k / (1 - q) <= 1``, i.e. the last period is within ``tol_db`` and ``tol_deg`` of
the limit the sequence is heading for. q is capped at 0.9 and taken as 0.9 while only
one change is known, so a point settles after two periods only if they agree to a
tenth of the tolerances. Points that have not settled after ``max_periods`` are reported
(``converged`` = False) with their last period's values. The criterion watches x_rod;
the i_q harmonic and the distortions are taken from the same last period.

*Harmonics.* On the uniform grid of one whole period the rectangle rule is the
discrete Fourier transform: ``c_n = (2/K) sum_k y_k exp(-2 pi j n k/K)``. The command's
first harmonic is ``-j A``, so the gain is ``G = j c_1 / A``. The distortion is
``sqrt(sum_(n=2..K/2-1) |c_n|^2) / |c_1|`` (total harmonic distortion up to the
grid's Nyquist order).

*Initial state.* The state at rest under the load (found by a 1 s constant-load run)
plus the periodic response of the model linearised there with Coulomb friction,
backlash and the efficiency switch removed (scaled down where that response would
exceed the rate limit). It is only a starting guess: the settling criterion decides.

*Parallelism and memory.* Points run on a thread pool (CasADi releases the GIL), each
thread with its own call buffers on the one integrator; ``scheduler`` sends chunks of
points to a Dask distributed cluster instead (optional dependency). Only the harmonics
are kept per point unless ``keep=True`` (then the samples of ``x_rod`` and ``i_q`` over
all simulated periods).

Hybrid (stick-slip) friction needs the model's own stepping with its stick projection:
those points run :func:`ema_casadi.simulate.simulate` (compiled RK4) period by period,
on the same worker threads (the compiled rollouts keep one call buffer per thread).
"""

from __future__ import annotations

import csv
import itertools
import math
import os
import re
import threading
import time
from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path

import casadi as ca
import numpy as np

from .assembly import Model, build_model
from .compiled import BufferCall
from .components import validate_variants
from .params import Parameters, ParameterError
from .signals import Signal, SignalError, parse_quantity
from .simulation import STEPS_PER_CALL, SimulationError, progress_bar, simulate

__all__ = [
    "FreqResponse", "FreqRespError", "sine_stream", "plot_bode", "run_study",
    "paper_fig14a", "paper_fig14b", "parse_amplitudes", "parse_freqs", "parse_loads",
    "FIELDS", "PAPER_AMPLITUDES_PCT", "PAPER_LOADS",
]

#: Result fields per point, with units.
FIELDS = {
    "gain_db": "dB", "phase_deg": "deg", "distortion": "1",
    "i_q_amp": "A", "i_q_phase_deg": "deg", "i_q_distortion": "1",
    "x_offset": "m", "periods": "1", "converged": "1",
}
#: The paper's Fig. 14a amplitudes (% of the 75 mm stroke) and Fig. 14b loads (N).
PAPER_AMPLITUDES_PCT = (0.5, 1.0, 2.0, 5.0, 10.0)
PAPER_LOADS = (0.0, 10e3, 20e3, 30e3)
#: The paper's frequency band (Hz) and the default number of log-spaced points.
PAPER_BAND = (0.1, 30.0)
PAPER_NFREQ = 40


class FreqRespError(SimulationError):
    """Bad frequency-response request (one line, names the argument)."""


# ---------------------------------------------------------------------------------
@dataclass
class FreqResponse:
    """Sine-stream results on a grid with named axes.

    Attributes
    ----------
    axes : dict
        ``variant`` (labels), ``load`` (N), ``amplitude`` (m), ``frequency`` (Hz), in
        this order; every array in ``data`` has shape ``(n_variant, n_load,
        n_amplitude, n_frequency)``.
    data : dict of ndarray
        :data:`FIELDS`: ``gain_db`` (dB), ``phase_deg`` (deg, unwrapped along frequency,
        relative to x_cmd), ``distortion`` (-) of x_rod; ``i_q_amp`` (A), ``i_q_phase_deg``
        (deg, relative to x_cmd), ``i_q_distortion`` (-); ``x_offset`` (m, mean rod
        position over the last period); ``periods`` simulated; ``converged`` (bool).
    variants : dict
        Label -> complete variant dict.
    info : dict
        Options, wall time, counts.
    samples : dict, optional
        With ``keep=True``: (i_variant, i_load, i_amplitude, i_frequency) -> dict of
        ``t`` (s), ``x_cmd`` (m), ``x_rod`` (m), ``i_q`` (A) over all simulated periods.
    """

    axes: dict
    data: dict
    variants: dict
    info: dict = field(default_factory=dict)
    samples: dict | None = None

    @property
    def shape(self) -> tuple:
        return tuple(len(v) for v in self.axes.values())

    def rows(self) -> list[dict]:
        """One dict per point: variant, load_N, amplitude_m, freq_Hz, then the fields."""
        out = []
        for idx in itertools.product(*[range(n) for n in self.shape]):
            iv, il, ia, jf = idx
            row = {
                "variant": self.axes["variant"][iv],
                "load_N": float(self.axes["load"][il]),
                "amplitude_m": float(self.axes["amplitude"][ia]),
                "freq_Hz": float(self.axes["frequency"][jf]),
            }
            for k in FIELDS:
                v = self.data[k][idx]
                row[k] = bool(v) if k == "converged" else (int(v) if k == "periods" else float(v))
            out.append(row)
        return out

    def to_csv(self, path: str | Path) -> Path:
        """Write one row per point (columns as :meth:`rows`, SI units); atomic."""
        path = Path(path)
        rows = self.rows()
        cols = list(rows[0])
        tmp = path.with_name(path.name + ".tmp")
        try:
            with tmp.open("w", newline="") as fh:
                w = csv.writer(fh)
                w.writerow(cols)
                w.writerows([_fmt(r[c]) for c in cols] for r in rows)
            tmp.replace(path)
        finally:
            tmp.unlink(missing_ok=True)
        return path

    def curve(self, variant=None, load=None, amplitude=None) -> dict:
        """Arrays along frequency for one (variant, load, amplitude); an axis of length
        one needs no value, otherwise the nearest value (labels: exact) is taken."""
        iv = _pick(self.axes["variant"], variant, "variant")
        il = _pick(self.axes["load"], load, "load")
        ia = _pick(self.axes["amplitude"], amplitude, "amplitude")
        out = {"freq_Hz": np.asarray(self.axes["frequency"])}
        out.update({k: v[iv, il, ia] for k, v in self.data.items()})
        return out

    def not_converged(self) -> list[dict]:
        """Rows of the points that did not settle within ``max_periods``."""
        return [r for r in self.rows() if not r["converged"]]

    def to_dict(self) -> dict:
        """JSON-ready: axes (SI), variants, units, info and one entry per point."""
        return {
            "axes": {k: list(v) if k == "variant" else [float(a) for a in v] for k, v in self.axes.items()},
            "axis_units": {"variant": "", "load": "N", "amplitude": "m", "frequency": "Hz"},
            "units": dict(FIELDS),
            "variants": self.variants,
            "info": self.info,
            "points": self.rows(),
        }


def _fmt(v) -> str:
    if isinstance(v, bool):
        return "1" if v else "0"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, float):
        return f"{v:.10g}"
    return str(v)


def _pick(values, want, name) -> int:
    if want is None:
        if len(values) != 1:
            raise FreqRespError(f"{name}: several values {list(values)}, say which one")
        return 0
    if name == "variant":
        if want not in list(values):
            raise FreqRespError(f"variant '{want}' not in {list(values)}")
        return list(values).index(want)
    return int(np.argmin(np.abs(np.asarray(values, float) - float(want))))


# ---------------------------------------------------------------------------------
class _PeriodMap:
    """The one simulator of a model variant: ``(x0, [p; A; f; F_ext]) -> (x(1 period),
    x_rod and i_q at tau = k/K, k = 1..K)`` by CVODES in normalised time."""

    def __init__(self, model: Model, samples: int, rtol: float, atol: float):
        nx, npar = model.nx, len(model.param_names)
        self.nx, self.npar, self.K = nx, npar, samples
        x = ca.SX.sym("x", nx)
        pa = ca.SX.sym("pa", npar + 3)
        tau = ca.SX.sym("tau")
        p, A, freq, f_ext = pa[:npar], pa[npar], pa[npar + 1], pa[npar + 2]
        eta = p[model.param_names.index("eta")]
        u = ca.vertcat(A * ca.sin(2 * ca.pi * tau), f_ext, eta, ca.SX.zeros(3))
        dae = {"x": x, "p": pa, "t": tau, "ode": model.f(x, u, p)[0] / freq}
        grid = [k / samples for k in range(1, samples + 1)]
        opts = {"abstol": atol, "reltol": rtol, "max_num_steps": 10**6}
        integ = ca.integrator("sine_period_cvodes", "cvodes", dae, 0.0, grid, opts)
        X0 = ca.MX.sym("x0", nx)
        PA = ca.MX.sym("pa", npar + 3)
        Xk = integ(x0=X0, p=PA)["xf"]
        taus = np.array(grid)
        U = ca.vertcat(
            PA[npar] * ca.DM(np.sin(2 * np.pi * taus)).T,
            ca.repmat(PA[npar + 2], 1, samples),
            ca.repmat(PA[model.param_names.index("eta")], 1, samples),
            ca.MX.zeros(3, samples),
        )
        Y = model.f.map(samples)(Xk, U, PA[:npar])[1]
        sel = [model.outputs.index("x_rod"), model.outputs.index("i_q")]
        self.F = ca.Function("sine_period", [X0, PA], [Xk[:, -1], Y[sel, :]], ["x0", "pa"], ["x1", "y"])
        self.call = BufferCall(self.F)  # per-thread buffers, one shared Function

    def __call__(self, x0, pa):
        """One period from x0; returns (x at the period's end, (2, K) samples)."""
        x1, y = self.call(x0, pa)
        return x1.ravel(), y



class _HybridPeriods:
    """Period-by-period stepping of a hybrid-friction model through :func:`simulate`
    (compiled RK4 with the stick projection).

    Every frequency uses the same output decimation and at least one full rollout
    chunk of samples per period, so one compiled rollout serves the whole grid; the
    harmonics then come from that finer (still uniform, whole-period) grid."""

    DECIMATE = 16

    def __init__(self, model: Model, samples: int, dt_max: float):
        self.model, self.K, self.dt_max = model, samples, dt_max
        self.npar = len(model.param_names)
        self.k_min = max(samples, -(-STEPS_PER_CALL // self.DECIMATE))

    def __call__(self, x0, pa):
        p = pa[: self.npar]
        A, freq, f_ext = pa[self.npar :]
        n = max(self.k_min, math.ceil(1.0 / (freq * self.dt_max * self.DECIMATE) - 1e-9))
        n += n % 2
        res = simulate(self.model, 1.0 / freq, Signal.sine(A, freq), float(f_ext), p=p, x0=x0,
                       dt=1.0 / (freq * n * self.DECIMATE), decimate=self.DECIMATE, solver="rk4")
        x1 = np.array([res.states[name][-1] for name in self.model.states])
        y = np.vstack([res["x_rod"][1 : n + 1], res["i_q"][1 : n + 1]])
        return x1, y


def _harmonics(y: np.ndarray):
    """First harmonic c_1, distortion and mean of each row of y (samples at tau = k/K,
    k = 1..K, over one whole period)."""
    y = np.roll(y, 1, axis=-1)  # sample K (tau = 1) is tau = 0 of a periodic signal
    K = y.shape[-1]
    c = np.fft.rfft(y, axis=-1) * (2.0 / K)
    c1 = c[..., 1]
    higher = np.sqrt(np.sum(np.abs(c[..., 2 : K // 2]) ** 2, axis=-1))
    with np.errstate(divide="ignore", invalid="ignore"):
        thd = higher / np.abs(c1)
    return c1, thd, y.mean(axis=-1)


#: Largest contraction ratio assumed for a settling transient (also the value taken
#: while only one period-to-period change is known).
Q_MAX = 0.9


@dataclass(frozen=True)
class _Settle:
    tol_db: float = 0.01
    tol_deg: float = 0.1
    max_periods: int = 60


def _settle(step, x0, pa, A, freq, s: _Settle, keep: bool) -> dict:
    """Run periods until the x_rod harmonic settles (module docstring); return the point."""
    x = np.asarray(x0, float)
    H_prev, e_prev = None, None
    kept = []
    converged = False
    k = 0
    for k in range(1, s.max_periods + 1):
        try:
            x, y = step(x, pa)
        except RuntimeError:  # the integrator gave up
            return _failed(k)
        if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
            return _failed(k)
        if keep:
            kept.append(y)
        c1, thd, mean = _harmonics(y)
        H = 1j * c1[0] / A
        if H_prev is not None and H != 0 and H_prev != 0:
            ratio = H / H_prev
            e = max(abs(20 * math.log10(abs(ratio))) / s.tol_db, abs(math.degrees(np.angle(ratio))) / s.tol_deg)
            q = Q_MAX if not e_prev else min(e / e_prev, Q_MAX)
            if e / (1 - q) <= 1.0:
                converged = True
                break
            e_prev = e
        H_prev = H
    I = 1j * c1[1]  # i_q harmonic (A), phase relative to x_cmd (whose harmonic is -j A)
    out = {
        "H": H, "distortion": float(thd[0]), "I": I, "i_q_distortion": float(thd[1]),
        "x_offset": float(mean[0]), "periods": k, "converged": converged, "failed": False,
    }
    if keep:
        Y = np.hstack(kept)
        t = np.arange(1, Y.shape[1] + 1) / (freq * y.shape[1])
        out["samples"] = {"t": t, "x_cmd": A * np.sin(2 * np.pi * freq * t), "x_rod": Y[0], "i_q": Y[1]}
    return out


def _failed(k):
    return {"H": complex(np.nan, np.nan), "distortion": np.nan, "I": complex(np.nan, np.nan),
            "i_q_distortion": np.nan, "x_offset": np.nan, "periods": k, "converged": False, "failed": True}


# ---------------------------------------------------------------------------------
def _lin_params(model: Model, p: np.ndarray) -> np.ndarray:
    """p with Coulomb friction, backlash and the efficiency switch removed."""
    q = np.array(p, float)
    names = model.param_names
    for n, v in (("F_seal", 0.0), ("C_bear", 0.0), ("B", 0.0)):
        q[names.index(n)] = v
    q[names.index("eta_inv")] = 1.0 / q[names.index("eta")]
    return q


def _initial_states(model: Model, step, p, loads, amplitudes, freqs) -> dict:
    """(i_load, i_amplitude, i_frequency) -> starting state (module docstring)."""
    nx = model.nx
    x = ca.SX.sym("x", nx)
    u = ca.SX.sym("u", model.nu)
    pp = ca.SX.sym("p", len(model.param_names))
    xdot = model.f(x, u, pp)[0]
    ju = model.inputs.index("x_cmd")
    jac = ca.Function("lin_jacobians", [x, u, pp], [ca.jacobian(xdot, x), ca.jacobian(xdot, u)[:, ju]])
    p_lin = _lin_params(model, p)
    r = p[model.param_names.index("p")] / (2 * np.pi)
    v_max = p[model.param_names.index("v_max")]
    j_rod = model.states.index("x_rod") if "x_rod" in model.states else None
    out = {}
    for il, load in enumerate(loads):
        # at rest under the load: 1 s with the command held at zero
        x_rest, _ = step(np.zeros(nx), np.r_[p, 0.0, 1.0, load])
        if not np.all(np.isfinite(x_rest)):
            x_rest = np.zeros(nx)
        uu = model.u(f_ext=load, eta=p[model.param_names.index("eta")])
        Ja, Jb = (np.asarray(m, float) for m in jac(x_rest, uu, p_lin))
        Jb = Jb.ravel()
        for jf, f in enumerate(freqs):
            w = 2 * np.pi * f
            try:
                Xc = np.linalg.solve(1j * w * np.eye(nx) - Ja, Jb)
            except np.linalg.LinAlgError:
                Xc = np.zeros(nx, complex)
            # rod speed amplitude of the linear response per unit command amplitude
            g_rod = abs(Xc[j_rod]) if j_rod is not None else abs(Xc[model.states.index("phi")]) * r
            for ia, A in enumerate(amplitudes):
                scale = A * min(1.0, v_max / max(w * g_rod * A, 1e-300))
                out[il, ia, jf] = x_rest + scale * Xc.imag
    return out


# ---------------------------------------------------------------------------------
_STEPPERS: dict = {}
_STEPPERS_LOCK = threading.Lock()


def _stepper(variants: dict, params: Parameters, samples: int, rtol: float, atol: float, hybrid_dt: float):
    """The period map of a variant, built once per process (the model's structure
    depends on the variants only; parameter values are inputs)."""
    key = (tuple(sorted(variants.items())), samples, rtol, atol, hybrid_dt)
    with _STEPPERS_LOCK:
        if key not in _STEPPERS:
            model = build_model(params, variants)
            if _is_hybrid(model):
                _STEPPERS[key] = (model, _HybridPeriods(model, samples, hybrid_dt))
            else:
                _STEPPERS[key] = (model, _PeriodMap(model, samples, rtol, atol))
        return _STEPPERS[key]


def _is_hybrid(model: Model) -> bool:
    return model.hybrid


def hybrid_available(params: Parameters) -> tuple[bool, str]:
    """Whether the hybrid (stick-slip) friction variant can be simulated here, and why not."""
    try:
        model = build_model(params, {"friction": "hybrid"})
    except (ParameterError, ValueError) as exc:
        return False, f"friction variant 'hybrid' is not available: {exc}"
    if getattr(model, "project", None) is None:
        return False, "friction variant 'hybrid' is accepted but has no stick projection (model.project) yet"
    return True, ""


def _variant_set(params: Parameters, variants) -> dict:
    """Normalise ``variants`` to label -> complete variant dict."""
    if variants is None:
        return {"model": validate_variants(params.variants)}
    if isinstance(variants, dict) and all(isinstance(v, str) for v in variants.values()):
        full = dict(params.variants)
        full.update(variants)
        full = validate_variants(full)
        base = validate_variants(params.variants)
        diff = [f"{k}={v}" for k, v in full.items() if base[k] != v]
        return {";".join(diff) or "model": full}
    if isinstance(variants, dict):
        out = {}
        for label, v in variants.items():
            full = dict(params.variants)
            full.update(v or {})
            out[str(label)] = validate_variants(full)
        return out
    raise FreqRespError("variants: expected a dict of variant choices or a dict label -> dict")


def _as_axis(values, name, unit, positive=True) -> np.ndarray:
    a = np.atleast_1d(np.asarray(values, dtype=float))
    if a.ndim != 1 or a.size == 0:
        raise FreqRespError(f"{name}: expected one or more numbers ({unit})")
    if not np.all(np.isfinite(a)):
        raise FreqRespError(f"{name}: non-finite value")
    if positive and np.any(a <= 0):
        raise FreqRespError(f"{name}: values must be positive ({unit}), got {a[a <= 0][0]:g}")
    return a


def sine_stream(
    params: Parameters,
    amplitudes,
    freqs,
    loads=(0.0,),
    variants=None,
    *,
    p: np.ndarray | None = None,
    samples: int = 64,
    tol_db: float = 0.01,
    tol_deg: float = 0.1,
    max_periods: int = 60,
    rtol: float = 1e-6,
    atol: float = 1e-9,
    hybrid_dt: float = 5e-5,
    jobs: int | None = None,
    scheduler: str | None = None,
    progress: bool = False,
    keep: bool = False,
) -> FreqResponse:
    """Sine-stream frequency response of the nonlinear model x_rod / x_cmd.

    Parameters
    ----------
    params : Parameters
        Parameter set (its variants are the defaults).
    amplitudes : sequence of float
        Command amplitudes A (m).
    freqs : sequence of float
        Frequencies (Hz); sorted ascending in the result.
    loads : sequence of float
        Constant external forces F_ext (N, positive pushes the rod in).
    variants : dict, optional
        One variant choice (``{"screw": "rigid"}``) or several, label -> choice
        (``{"elastic": {"screw": "elastic"}, "rigid": {"screw": "rigid"}}``).
    p : ndarray, optional
        Raw parameter vector (default ``params.vector()``), e.g. with overrides.
    samples : int
        Output samples per period K (even, >= 8).
    tol_db, tol_deg : float
        Settling tolerances on the first harmonic (dB, deg); see the module docstring.
    max_periods : int
        Periods after which an unsettled point is reported as not converged.
    rtol, atol : float
        CVODES tolerances (atol in the states' SI units).
    hybrid_dt : float
        Largest RK4 step for hybrid-friction points (s); on the reference set 1e-4 s
        and 2e-5 s gave gains within 1e-3 dB of each other.
    jobs : int, optional
        Worker threads (default: the number of cores).
    scheduler : str, optional
        Address of a Dask distributed scheduler (``tcp://host:port``); needs the
        optional ``dask[distributed]`` and ema_casadi on the workers.
    progress : bool
        Progress bar on stderr.
    keep : bool
        Keep the x_rod and i_q samples of every simulated period.

    Returns
    -------
    FreqResponse
    """
    t_wall = time.perf_counter()
    amplitudes = _as_axis(amplitudes, "amplitudes", "m")
    freqs = np.unique(_as_axis(freqs, "freqs", "Hz"))
    loads = _as_axis(loads, "loads", "N", positive=False)
    if not (isinstance(samples, int) and samples >= 8 and samples % 2 == 0):
        raise FreqRespError(f"samples: expected an even integer >= 8, got {samples!r}")
    if not (isinstance(max_periods, int) and max_periods >= 3):
        raise FreqRespError(f"max_periods: expected an integer >= 3, got {max_periods!r}")
    for name, v in (("tol_db", tol_db), ("tol_deg", tol_deg), ("rtol", rtol), ("atol", atol), ("hybrid_dt", hybrid_dt)):
        if not (math.isfinite(v) and v > 0):
            raise FreqRespError(f"{name}: expected a positive number, got {v!r}")
    if jobs is not None and (not isinstance(jobs, int) or jobs < 1):
        raise FreqRespError(f"jobs: expected a positive integer, got {jobs!r}")
    vset = _variant_set(params, variants)
    for label, v in vset.items():
        if v["friction"] == "hybrid":
            ok, why = hybrid_available(params)
            if not ok:
                raise FreqRespError(why)
    pv = params.vector() if p is None else np.asarray(p, float)
    if pv.shape != (len(Parameters.names()),):
        raise FreqRespError(f"p must have {len(Parameters.names())} entries, got shape {pv.shape}")
    settle = _Settle(tol_db, tol_deg, max_periods)
    build = (samples, rtol, atol, hybrid_dt)

    # tasks: (variant index, load index, amplitude index, frequency index, x0, pa)
    tasks = []
    for iv, (label, v) in enumerate(vset.items()):
        model, step = _stepper(v, params, *build)
        x0s = _initial_states(model, step, pv, loads, amplitudes, freqs)
        for il, ia, jf in itertools.product(range(len(loads)), range(len(amplitudes)), range(len(freqs))):
            pa = np.r_[pv, amplitudes[ia], freqs[jf], loads[il]]
            tasks.append(((iv, il, ia, jf), v, x0s[il, ia, jf], pa))
    n_jobs = jobs or _cores()
    if scheduler:
        results = _run_dask(scheduler, tasks, params, build, settle, keep, progress)
    else:
        results = _run_local(tasks, params, build, settle, keep, progress, n_jobs)

    shape = (len(vset), len(loads), len(amplitudes), len(freqs))
    H = np.full(shape, np.nan, complex)
    I = np.full(shape, np.nan, complex)
    data = {k: np.full(shape, np.nan) for k in ("distortion", "i_q_distortion", "x_offset")}
    periods = np.zeros(shape, int)
    conv = np.zeros(shape, bool)
    samples_out = {} if keep else None
    failed = 0
    for idx, r in results.items():
        H[idx], I[idx] = r["H"], r["I"]
        for k in data:
            data[k][idx] = r[k]
        periods[idx], conv[idx] = r["periods"], r["converged"]
        failed += bool(r["failed"])
        if keep and "samples" in r:
            samples_out[idx] = r["samples"]
    data = {
        "gain_db": 20 * np.log10(np.abs(H)),
        "phase_deg": _unwrap_deg(np.degrees(np.angle(H))),
        "distortion": data["distortion"],
        "i_q_amp": np.abs(I),
        "i_q_phase_deg": _unwrap_deg(np.degrees(np.angle(I))),
        "i_q_distortion": data["i_q_distortion"],
        "x_offset": data["x_offset"],
        "periods": periods,
        "converged": conv,
    }
    info = {
        "samples_per_period": samples, "tol_db": tol_db, "tol_deg": tol_deg, "max_periods": max_periods,
        "rtol": rtol, "atol": atol, "jobs": None if scheduler else n_jobs, "scheduler": scheduler,
        "points": len(tasks), "not_converged": int((~conv).sum()), "failed": failed,
        "periods_total": int(periods.sum()),
        "simulated_time": float(np.sum(periods / freqs[None, None, None, :])),
        "wall_time": time.perf_counter() - t_wall,
    }
    axes = {"variant": list(vset), "load": loads, "amplitude": amplitudes, "frequency": freqs}
    return FreqResponse(axes=axes, data=data, variants=vset, info=info, samples=samples_out)


def _unwrap_deg(phase: np.ndarray) -> np.ndarray:
    """Unwrap along the last (frequency) axis, skipping failed (NaN) points."""
    out = np.array(phase, float)
    flat = out.reshape(-1, out.shape[-1])
    for row in flat:
        ok = np.isfinite(row)
        if ok.any():
            row[ok] = np.degrees(np.unwrap(np.radians(row[ok])))
    return out


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not on Linux
        return os.cpu_count() or 1


def _run_local(tasks, params, build, settle, keep, progress, jobs) -> dict:
    """Points on a thread pool (hybrid points serially); -> index -> point dict."""
    results = {}
    n = len(tasks)

    def work(task):
        idx, v, x0, pa = task
        _, step = _stepper(v, params, *build)
        return idx, _settle(step, x0, pa, pa[-3], pa[-2], settle, keep)

    parallel = [t for t in tasks if t[1]["friction"] != "hybrid"]
    serial = [t for t in tasks if t[1]["friction"] == "hybrid"]
    done = 0
    progress_bar(0.0, progress, "freqresp")
    if parallel:
        # highest frequencies first: they take the most periods, so the pool ends evenly
        parallel.sort(key=lambda t: -t[3][-2])
        with ThreadPoolExecutor(max_workers=jobs) as pool:
            for fut in as_completed([pool.submit(work, t) for t in parallel]):
                idx, r = fut.result()
                results[idx] = r
                done += 1
                progress_bar(done / n, progress, "freqresp")
    for t in serial:
        idx, r = work(t)
        results[idx] = r
        done += 1
        progress_bar(done / n, progress, "freqresp")
    return results


def _dask_chunk(params, build, settle, keep, chunk) -> list:
    """Worker side of :func:`_run_dask`: run a chunk of points in this process."""
    return list(_run_local(chunk, params, build, settle, keep, False, 1).items())


def _run_dask(address, tasks, params, build, settle, keep, progress) -> dict:
    try:
        from dask.distributed import Client, as_completed as dask_completed
    except ImportError:
        raise FreqRespError("--scheduler needs Dask: pip install 'ema_casadi[dask]' (dask[distributed])") from None
    try:
        client = Client(address, timeout="10s")
    except Exception as exc:  # noqa: BLE001 - any connection problem is the user's address
        raise FreqRespError(f"scheduler {address}: cannot connect ({type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''})") from None
    try:
        n_workers = max(1, sum(w.get("nthreads", 1) for w in client.scheduler_info().get("workers", {}).values()))
        # a few chunks per worker thread: balance without per-point scheduling overhead
        size = max(1, math.ceil(len(tasks) / (4 * n_workers)))
        order = sorted(tasks, key=lambda t: -t[3][-2])
        chunks = [order[i::math.ceil(len(tasks) / size)] for i in range(math.ceil(len(tasks) / size))]
        futures = [client.submit(_dask_chunk, params, build, settle, keep, c, pure=False) for c in chunks]
        results, done = {}, 0
        progress_bar(0.0, progress, "freqresp")
        for fut in dask_completed(futures):
            for idx, r in fut.result():
                results[tuple(idx)] = r
                done += 1
            progress_bar(done / len(tasks), progress, "freqresp")
        return results
    finally:
        client.close()


# ---------------------------------------------------------------------------------
_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"


def parse_amplitudes(text: str, stroke: float) -> np.ndarray:
    """'0.5%,1%,2mm' -> amplitudes (m); a bare number is mm, % is of the stroke."""
    try:
        vals = [parse_quantity(s, "length", "mm", stroke) for s in _items(text)]
    except SignalError as exc:
        raise FreqRespError(f"--amplitudes {exc}") from None
    return _as_axis(vals, "--amplitudes", "m")


def parse_loads(text: str) -> np.ndarray:
    """'0,10kN,30kN' -> loads (N); a bare number is N."""
    try:
        vals = [parse_quantity(s, "force", "N") for s in _items(text)]
    except SignalError as exc:
        raise FreqRespError(f"--loads {exc}") from None
    return _as_axis(vals, "--loads", "N", positive=False)


def parse_freqs(text: str) -> np.ndarray:
    """'0.1,1,5' (list) or '0.1-30:40' (40 log-spaced points from 0.1 to 30) -> Hz."""
    m = re.fullmatch(rf"\s*({_NUM}\s*(?:Hz)?)\s*-\s*({_NUM}\s*(?:Hz)?)\s*:\s*(\d+)\s*", text)
    try:
        if m:
            f0 = parse_quantity(m.group(1), "frequency", "Hz")
            f1 = parse_quantity(m.group(2), "frequency", "Hz")
            n = int(m.group(3))
            if not (0 < f0 < f1) or n < 2:
                raise FreqRespError(f"--freqs {text}: expected F0-F1:N with 0 < F0 < F1 and N >= 2")
            return np.geomspace(f0, f1, n)
        vals = [parse_quantity(s, "frequency", "Hz") for s in _items(text)]
    except SignalError as exc:
        raise FreqRespError(f"--freqs {exc}; expected a list '0.1,1,5' or a range '0.1-30:40'") from None
    return _as_axis(vals, "--freqs", "Hz")


def _items(text: str) -> list[str]:
    items = [s.strip() for s in str(text).split(",")]
    if not items or any(not s for s in items):
        raise SignalError(f"'{text}': expected a comma-separated list")
    return items


# ---------------------------------------------------------------------------------
def plot_bode(resp: FreqResponse, path: str | Path, title: str = "", stroke: float | None = None) -> Path:
    """Bode plot (gain dB, phase deg against Hz) with one line per (variant, load,
    amplitude); points that did not settle are marked with x. PNG, atomic."""
    from .plotting import plt, save

    fig, (ax_g, ax_p) = plt.subplots(2, 1, figsize=(8, 7), sharex=True)
    f = resp.axes["frequency"]
    multi = {k: len(v) > 1 for k, v in resp.axes.items()}
    for iv, il, ia in itertools.product(*[range(len(resp.axes[k])) for k in ("variant", "load", "amplitude")]):
        parts = []
        if multi["variant"] or not (multi["load"] or multi["amplitude"]):
            parts.append(str(resp.axes["variant"][iv]))
        if multi["load"]:
            parts.append(f"{resp.axes['load'][il] / 1e3:g} kN")
        if multi["amplitude"]:
            A = resp.axes["amplitude"][ia]
            parts.append(f"{100 * A / stroke:g} % ({A * 1e3:g} mm)" if stroke else f"{A * 1e3:g} mm")
        g = resp.data["gain_db"][iv, il, ia]
        ph = resp.data["phase_deg"][iv, il, ia]
        line, = ax_g.semilogx(f, g, lw=1.3, label=", ".join(parts))
        ax_p.semilogx(f, ph, lw=1.3, color=line.get_color())
        bad = ~resp.data["converged"][iv, il, ia]
        if bad.any():
            ax_g.semilogx(f[bad], g[bad], "x", color=line.get_color())
            ax_p.semilogx(f[bad], ph[bad], "x", color=line.get_color())
    ax_g.set_ylabel("x_rod / x_cmd gain (dB)")
    ax_p.set_ylabel("phase (deg)")
    ax_p.set_xlabel("frequency (Hz)")
    for a in (ax_g, ax_p):
        a.grid(True, which="both", alpha=0.3)
    ax_g.legend(loc="lower left", fontsize=8)
    if title:
        ax_g.set_title(title)
    fig.tight_layout()
    return save(fig, path)


def run_study(params: Parameters, out_dir: str | Path, name: str, title: str = "", **kwargs):
    """Run :func:`sine_stream` with ``kwargs`` and write ``<name>.csv`` and ``<name>.png``
    into ``out_dir`` (created). Returns (FreqResponse, PNG path)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    resp = sine_stream(params, **kwargs)
    csv = resp.to_csv(out / f"{name}.csv")
    png = plot_bode(resp, out / f"{name}.png", title=title, stroke=params.actuator.stroke)
    resp.info["written"] = [str(csv), str(png)]
    return resp, png


def _paper_freqs(freqs):
    return np.geomspace(*PAPER_BAND, PAPER_NFREQ) if freqs is None else freqs


def paper_fig14a(params: Parameters, out_dir: str | Path, *, freqs=None, **kwargs):
    """The paper's Fig. 14a: amplitudes 0.5, 1, 2, 5 and 10 % of the stroke, no load,
    0.1-30 Hz (40 log-spaced points unless ``freqs``). Writes ``fig14a.csv`` and
    ``fig14a.png`` into ``out_dir``; ``kwargs`` go to :func:`sine_stream`.
    Returns (FreqResponse, PNG path)."""
    amps = [a / 100 * params.actuator.stroke for a in PAPER_AMPLITUDES_PCT]
    return run_study(params, out_dir, "fig14a", "Fig. 14a: sine stream, no load, amplitudes in % of 75 mm",
                     amplitudes=amps, freqs=_paper_freqs(freqs), loads=[0.0], **kwargs)


def paper_fig14b(params: Parameters, out_dir: str | Path, *, freqs=None, **kwargs):
    """The paper's Fig. 14b: loads 0, 10, 20 and 30 kN at 0.5 % of the stroke,
    0.1-30 Hz. Writes ``fig14b.csv`` and ``fig14b.png``; returns (FreqResponse, PNG path)."""
    amp = PAPER_AMPLITUDES_PCT[0] / 100 * params.actuator.stroke
    return run_study(params, out_dir, "fig14b", "Fig. 14b: sine stream at 0.5 % of 75 mm, loads",
                     amplitudes=[amp], freqs=_paper_freqs(freqs), loads=list(PAPER_LOADS), **kwargs)
