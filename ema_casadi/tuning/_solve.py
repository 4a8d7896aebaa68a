"""The tuning driver: :func:`tune` solves the problem (refining its frequency grid),
verifies the result independently and returns a :class:`TuneResult`."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .._util._notebook import Summarised
from ..model.assembly import Model, build_model
from ..model.params import Parameters
from ._problem import TuningProblem
from ._report import _message
from ._requirements import Requirements, TuneError, _goal, _load_label, _request
from ._verify import step_metrics, verify

if TYPE_CHECKING:
    from collections.abc import Sequence

    from numpy.typing import ArrayLike

_FEAS_TOL = 1e-6         # a normalised constraint below -_FEAS_TOL is violated
#: At most this many solves: after each, frequencies where a dense (100 per decade)
#: check of the margin constraints fails are added to the grid (exchange method).
_ROUNDS = 3
_ACTIVE = 1e-2           # a group with its smallest normalised value below this is active
#: From a verified-feasible start, at most this many of the best feasible iterates are
#: verified when IPOPT's own answer cannot be used (the safety net of :func:`tune`).
_FALLBACK_CHECKS = 5


@dataclass(repr=False)
class TuneResult(Summarised):
    """Outcome of :func:`tune`.

    Attributes
    ----------
    success : bool
        IPOPT converged with no slack left and the independent verification meets every
        requirement; or, from a verified-feasible start where that fails, the safety
        net's gains (:attr:`fallback`) verify and are no worse than the start.
    status : str
        IPOPT's return status (e.g. ``Solve_Succeeded``).
    iterations : int
        IPOPT iterations, summed over the rounds.
    rounds : int
        Solves: after each, frequencies where a dense check finds a margin constraint
        violated between grid points are added to the grid (at most 3).
    solve_time, build_time : float
        Wall times (s) of IPOPT and of building the problems.
    n_freqs : int
        Frequencies in the final grid.
    objective : str
        ``bandwidth`` or ``tracking``.
    objective_value : float
        Worst-case -3 dB frequency f_b (Hz) for ``bandwidth``; the normalised ISE for
        ``tracking``.
    gains_before, gains_after : dict
        Free gains at the start and at the solution (SI).
    loads : list of float
        Load cases (N).
    requirements : Requirements
    violations : list of dict
        Constraint groups violated at the returned point (optimiser's model): ``kind``,
        ``loads``, ``loop``, ``min`` (smallest normalised value, >= 0 is met), ``slack``
        (elastic relaxation left), ``at_hz``.
    active : list of dict
        Constraint groups met with almost no slack (what limits the design), same keys.
    verification_before, verification_after : dict
        :func:`verify` at the start and at the result (fresh linearisation, independent of
        the optimiser).
    params : Parameters
        The parameter set with the tuned gains.
    message : str
        One line: what happened, naming a violated constraint if any.
    variants : dict
        The model's variants.
    fallback : str or None
        ``None`` when the gains are IPOPT's answer. From a verified-feasible start whose
        tune failed (IPOPT did not converge, its answer fails the check, or it is worse
        than the start), the safety net returns instead the best verified-feasible
        iterate (``"iterate"``) or the start itself (``"start"``).
    """

    success: bool
    status: str
    iterations: int
    rounds: int
    solve_time: float
    build_time: float
    n_freqs: int
    objective: str
    objective_value: float
    gains_before: dict
    gains_after: dict
    loads: list
    requirements: Requirements
    violations: list
    active: list
    verification_before: dict
    verification_after: dict
    params: Parameters
    message: str
    variants: dict = field(default_factory=dict)
    fallback: str | None = None

    def to_dict(self) -> dict:
        """JSON-ready summary (SI units; frequencies in Hz)."""
        return {
            "success": self.success, "status": self.status, "iterations": self.iterations,
            "rounds": self.rounds, "solve_time_s": self.solve_time, "build_time_s": self.build_time,
            "n_freqs": self.n_freqs,
            "objective": self.objective, "objective_value": self.objective_value,
            "gains_before": self.gains_before, "gains_after": self.gains_after,
            "loads_N": self.loads, "requirements": self.requirements.as_dict(),
            "violations": self.violations, "active": self.active, "message": self.message, "variants": self.variants,
            "fallback": self.fallback,
            "before": self.verification_before, "after": self.verification_after,
        }

    def plot(self, model: Model | None = None, reference: Parameters | None = None) -> list:
        """The Bode plots (closed loop and the loop transfers, first load case), the
        nonlinear step and the cascade view (each loop with its outer loops open) before
        and after tuning, as three matplotlib Figures.

        Parameters
        ----------
        model : Model, optional
            The model tuned (default: built from :attr:`params` and :attr:`variants`).
        reference : Parameters, optional
            A further gain set drawn dotted.
        """
        from ._figures import plot_tuning

        model = model if model is not None else build_model(self.params, self.variants or None)
        before = self.params.replace(**self.gains_before)
        return plot_tuning(self, model, before, None, reference)

    def _facts(self) -> dict:
        return {"success": self.success, "status": self.status,
                "objective": f"{self.objective} = {self.objective_value:.4g}",
                "gains": ", ".join(f"{k}={v:.4g}" for k, v in self.gains_after.items())}

    def write(self, path) -> Path:
        """Write the parameter file with the tuned gains (atomically); returns its path.

        Parameters
        ----------
        path : str or Path
            The ``.toml`` file; its header records the objective, IPOPT's status, the
            loads and the gains.
        """
        g = ", ".join(f"{k} = {v:.6g}" for k, v in self.gains_after.items())
        header = (f"Tuned by ema tune ({self.objective}; IPOPT {self.status}, {self.iterations} iterations)\n"
                  f"loads {', '.join(_load_label(f) for f in self.loads)}; {g}")
        return self.params.to_toml(path, header=header)


def tune(
    params: Parameters,
    variants: dict | None = None,
    *,
    free: Sequence[str] | None = None,
    loads: Sequence[float] = (0.0,),
    objective: str = "bandwidth",
    requirements: Requirements | None = None,
    start: dict | None = None,
    freqs: ArrayLike | None = None,
    max_iter: int = 200,
    hessian: str = "limited-memory",
    verify_step: float = 1e-3,
    model: Model | None = None,
) -> TuneResult:
    """Tune the cascade's gains by IPOPT (the formulation: :mod:`ema_casadi.tuning`).

    Parameters
    ----------
    params : Parameters
        Parameter set; its gains are the reference that scales the variables.
    variants : dict, optional
        Model variants (default the set's own).
    free : sequence of str, optional
        Gains to tune (default :func:`default_free`); the others keep their values.
    loads : sequence of float
        Load cases f_ext (N); the worst case must meet every requirement.
    objective : {"bandwidth", "tracking"}
        Maximise the worst-case -3 dB frequency (Hz), or minimise the worst-case
        integrated squared error of the step (normalised by the step and 10 ms).
    requirements : Requirements, optional
        What every load case must meet (default :class:`Requirements`).
    start : dict, optional
        Start values of free gains (SI; default the set's).
    freqs : array_like, optional
        Frequency grid (Hz) of the robustness constraints (default 0.5 Hz - 10 kHz,
        14 per decade), refined where a dense check finds a gap.
    max_iter : int
        IPOPT iteration limit (per solve).
    hessian : {"exact", "limited-memory"}
        Exact (AD) Hessian or IPOPT's L-BFGS approximation.
    verify_step : float
        Amplitude (m) of the nonlinear step simulated before and after (0 skips it).
    model : Model, optional
        An already built model for ``params``/``variants``.
    """
    req = _goal(requirements, objective)
    if hessian not in ("exact", "limited-memory"):
        raise TuneError(f"hessian '{hessian}' unknown; choose exact or limited-memory")
    if model is None:
        model = build_model(params, variants)
    free, loads, start, freqs = _request(model, params, free, loads, start, freqs)
    t0 = time.perf_counter()
    out, freqs, rounds, iterations, solve_time, prob, iterates = _solve_rounds(
        model, params, free, loads, req, objective, start, freqs, max_iter, hessian)
    build_time = time.perf_counter() - t0 - solve_time
    return _result(model, params, loads, req, objective, start, out, verify_step, prob, iterates,
                   rounds=rounds, iterations=iterations, solve_time=solve_time, build_time=build_time,
                   n_freqs=len(freqs))


def _solve_rounds(model, params, free, loads, req, objective, start, freqs, max_iter, hessian):
    """Solve, add the frequencies where the dense check fails, re-solve warm started (at
    most _ROUNDS solves). Returns the last solve's output, the final grid (Hz), the
    rounds, the summed iterations, the summed IPOPT time (s), the last problem and the
    iterates (theta, fb_log) of every solve."""
    iterations, solve_time, rounds, warm, iterates = 0, 0.0, 0, None, []
    for rounds in range(1, _ROUNDS + 1):  # noqa: B007 (the last value is returned)
        prob = TuningProblem(model, params, free, loads, req, objective, start, freqs)
        out = prob.solve(max_iter, hessian, warm)
        iterates.extend(prob.iterates)
        iterations += int(out["stats"].get("iter_count", 0))
        solve_time += out["wall"]
        relaxed = any(g["slack"] > _FEAS_TOL for g in out["groups"])
        gaps = prob.grid_gaps(out["gains"]) if out["stats"].get("success") and not relaxed else []
        if not len(gaps):
            break
        # semi-infinite constraints: add the frequencies where the dense check fails, re-solve
        freqs = np.sort(np.r_[freqs, gaps])
        warm = out["warm"]
    return out, freqs, rounds, iterations, solve_time, prob, iterates


def _result(model, params, loads, req, objective, start, out, verify_step, prob, iterates,
            **timing) -> TuneResult:
    """The :class:`TuneResult` of the last solve, verified before and after; from a
    verified-feasible start whose solve cannot be used, the safety net's gains."""
    stats = out["stats"]
    status = str(stats.get("return_status", "unknown"))
    converged = bool(stats.get("success", False)) and status in ("Solve_Succeeded", "Solved_To_Acceptable_Level")
    gains, groups, f_b, J = out["gains"], out["groups"], out["f_b"], out["objective"]
    violations = [g for g in groups if g["slack"] > _FEAS_TOL or g["min"] < -_FEAS_TOL]

    before_gains = dict(start)
    ver_before = verify(model, params.replace(**before_gains), loads, req, nonlinear_step=verify_step)
    ver_after = verify(model, params.replace(**gains), loads, req, nonlinear_step=verify_step)
    success = converged and not violations and ver_after["meets"]
    message = _message(converged, status, violations, ver_after, req)
    fallback = None
    if ver_before["meets"]:
        # A feasible start: never return worse than the start, nor "infeasible"
        start_value = _objective_value(objective, ver_before, prob.main_objective(before_gains))
        why = _unusable(converged, violations, ver_after, status, objective,
                        _objective_value(objective, ver_after, J), start_value)
        if why:
            picked = _best_seen(model, params, loads, req, objective, prob, iterates, start_value, before_gains)
            if picked is not None and all(math.isclose(picked["gains"][k], v, rel_tol=1e-9, abs_tol=1e-12)
                                          for k, v in before_gains.items()):
                picked = None  # IPOPT's first iterate: the start
            if picked is None:  # the start itself
                fallback, gains, ver_after = "start", dict(before_gains), ver_before
                f_b, J = prob.start_bandwidth, prob.main_objective(before_gains)
                text = "returning the start gains unchanged (no iterate verified better)"
            else:
                fallback, gains, ver_after = "iterate", picked["gains"], picked["verification"]
                f_b, J = picked["f_b"], picked["objective"]
                if verify_step:
                    ver_after["nonlinear_step"] = step_metrics(model, params.replace(**gains), verify_step)
                text = ("returning the best verified-feasible gains among its iterates ("
                        + _objective_text(objective, ver_after, J, ver_before, prob.main_objective(before_gains)) + ")")
            groups = prob.groups_at(gains, f_b, picked["zeta"] if picked is not None else None)
            violations = []
            success = ver_after["meets"]
            message = f"tuned (safety net): IPOPT {why}; from the verified-feasible start, {text}"
    active = [g for g in groups if g not in violations and g["min"] < _ACTIVE]
    value = f_b if objective == "bandwidth" else J
    return TuneResult(
        success=success, status=status, objective=objective, objective_value=value,
        gains_before=before_gains, gains_after=gains, loads=loads, requirements=req,
        violations=violations, active=active, verification_before=ver_before, verification_after=ver_after,
        params=params.replace(**gains), message=message, variants=dict(model.variants), fallback=fallback,
        **timing,
    )


def _objective_value(objective, ver, J) -> float:
    """What is compared with the start: the verified worst-case -3 dB frequency (Hz,
    higher is better) or the optimiser's worst-case ISE (lower is better)."""
    return ver["worst"]["bandwidth_hz"] if objective == "bandwidth" else J


def _no_worse(objective, value, start_value) -> bool:
    if not np.isfinite(value):
        return False
    if objective == "bandwidth":
        return value >= start_value * (1 - 1e-3)
    return value <= start_value * (1 + 1e-6) + 1e-12


def _unusable(converged, violations, ver_after, status, objective, value, start_value) -> str:
    """Why IPOPT's answer from a feasible start cannot be returned ('' if it can)."""
    if not converged:
        return f"{status}"
    if violations:
        return f"{status} with constraints relaxed"
    if not ver_after["meets"]:
        return f"{status}, but the independent check fails ({ver_after['failures'][0]})"
    if not _no_worse(objective, value, start_value):
        return f"{status} at gains worse than the start"
    return ""


def _objective_text(objective, ver, J, ver_start, J_start) -> str:
    if objective == "bandwidth":
        return (f"bandwidth {ver['worst']['bandwidth_hz']:.4g} Hz, "
                f"{ver_start['worst']['bandwidth_hz']:.4g} Hz at the start")
    return f"ISE {J:.4g}, {J_start:.4g} at the start"


def _best_seen(model, params, loads, req, objective, prob, iterates, start_value, start_gains):
    """The best of the iterates feasible in the optimiser's model that the independent
    check passes and that are no worse than the start (at most _FALLBACK_CHECKS
    verified, best first), or None."""
    checked = 0
    tried = []
    for cand in prob.feasible_iterates(iterates):
        if checked >= _FALLBACK_CHECKS:
            break
        if objective == "bandwidth" and not cand["f_b"] >= start_value * (1 - 1e-3):
            break  # sorted best first: the rest promise no better than the start
        if objective == "tracking" and not _no_worse(objective, cand["objective"], start_value):
            break
        g = np.array([cand["gains"][k] for k in start_gains])
        if any(np.allclose(g, t, rtol=1e-6, atol=0) for t in tried):
            continue
        tried.append(g)
        checked += 1
        ver = verify(model, params.replace(**cand["gains"]), loads, req)
        if ver["meets"] and _no_worse(objective, _objective_value(objective, ver, cand["objective"]), start_value):
            return dict(cand, verification=ver)
    return None
