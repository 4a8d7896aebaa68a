"""``design_experiment()``: the rig test that makes the chosen parameters' intervals
smallest within the test's limits, and its comparison with the standard tests."""

from __future__ import annotations

import math
import re
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from .._util._checks import integer, nearest, number, read_text_file
from .._util._errors import InputError
from ..identification import SENSOR_NOISE, IdentificationError, free_parameters
from ..model.assembly import build_model
from ..model.params import Parameters
from ..simulation import AnalysisFailed, progress_bar
from ._excitation import realise, standard_test
from ._fisher import information, intervals
from ._library import admissible, at_limits, candidates, evaluate
from ._optimise import CRITERIA, WIDTH_RATIO, efficient_rounding, optimal_weights
from ._optimise import criterion as criterion_value

__all__ = ["DesignError", "DesignFailed", "design_experiment", "read_prior", "DEFAULT_FREE", "SPREAD"]

#: The seven parameters of the recovery case (friction, backlash, stiffness, the motor).
DEFAULT_FREE = ("F_seal", "C_bear", "c_v", "B", "C", "J_m", "psi")
#: DC: rounds of the realised test against the standard (each parameter whose realised
#: variance ratio exceeds the target has its additive bound tightened by the excess).
DC_ROUNDS = 4
#: Relative standard deviation of the prior's draws where no fitted file gives one.
SPREAD = 0.2
#: A test shorter than this many segments has no room for a design.
MIN_SEGMENTS = 2


class DesignError(InputError, ValueError):
    """A mistake in an experiment-design request (a parameter, a flag, limits no test can
    keep): one line naming it. The command line reports it with exit status 2."""


class DesignFailed(AnalysisFailed):
    """A design that could not be made (every candidate failed or left the limits, the
    optimiser did not converge): exit status 3.

    Parameters
    ----------
    what : str
        The reason, one line.
    """


_PRIOR = re.compile(r"^#\s+([A-Za-z_]\w*):\s*(\S+)\s*->\s*(\S+)\s*\(95 %:\s*(\S+)\s*\.\.\s*(\S+)\)")


def read_prior(path) -> dict:
    """The 95 % intervals of a fitted parameter file: name -> (estimate, lo, hi), SI.

    The file's header is the one ``ema identify`` writes, a line
    ``# NAME: start -> estimate (95 %: LO .. HI)`` per free parameter.

    Parameters
    ----------
    path : str or Path
        The fitted ``.toml`` file.
    """
    path = Path(path)
    if not path.is_file():
        raise DesignError(f"--prior {path}: no such file")
    try:
        text = read_text_file(path, "fitted parameter file", DesignError)
    except DesignError as exc:
        raise DesignError(f"--prior {exc}") from None
    out = {}
    for line in text.splitlines():
        if not line.startswith("#"):
            break
        m = _PRIOR.match(line)
        if m:
            try:
                out[m.group(1)] = tuple(float(m.group(k)) for k in (3, 4, 5))
            except ValueError:
                continue
    if not out:
        raise DesignError(f"--prior {path}: no fitted intervals in its header (a file written by ema identify --out)")
    return out


def _check_prior(prior: dict, fr, label: str) -> None:
    """A prior's entries for the free parameters: finite numbers, a non-empty interval
    around the estimate, a positive estimate where the parameter is fitted in logs."""
    for k, n in enumerate(fr.names):
        if n not in prior:
            continue
        try:
            est, lo, hi = (float(v) for v in prior[n])
        except (TypeError, ValueError):
            raise DesignError(f"{label}: {n}: expected (estimate, lo, hi), three numbers, got {prior[n]!r}") from None
        if not all(math.isfinite(v) for v in (est, lo, hi)):
            raise DesignError(f"{label}: {n} {est:g} (95 %: {lo:g} .. {hi:g}): not finite; the draws need a finite "
                              "interval (a parameter the records did not determine: leave it out of the prior)")
        if not lo < hi:
            raise DesignError(f"{label}: interval of {n} is empty ({lo:g} .. {hi:g})")
        if not lo <= est <= hi:
            raise DesignError(f"{label}: {n} estimate {est:g} outside its interval ({lo:g} .. {hi:g})")
        if fr.log[k] and not est > 0:
            raise DesignError(f"{label}: {n} estimate {est:g}: must be positive ({n} is a positive parameter, "
                              "drawn on a log scale)")


def _thetas(fr, prior: dict | None, draws: int, spread: float, seed: int) -> tuple[list, np.ndarray]:
    """The prior's draws (the first the centre: the prior's estimates where it gives
    them, else the file's values) and the standard deviations of the optimiser
    coordinates they were drawn with (a prior's parameter from its 95 % interval, one it
    does not give at 0, every parameter at ``spread`` without a prior)."""
    sd = np.full(len(fr.names), spread)
    centre = fr.theta0.copy()
    if prior is not None:
        for k, n in enumerate(fr.names):
            if n in prior:
                est, lo, hi = prior[n]
                centre[k] = est
                sd[k] = (math.log(hi / lo) if fr.log[k] and lo > 0 else (hi - lo) / abs(est or 1.0)) / (2 * 1.959964)
            else:
                sd[k] = 0.0
    rng = np.random.default_rng(seed)
    z_lo, z_hi = fr.z_bounds()
    zc = fr.z(centre)
    thetas = [centre]
    for _ in range(1, draws):
        z = np.clip(zc + rng.normal(0.0, sd), z_lo + 1e-9, z_hi - 1e-9)
        thetas.append(fr.theta(z))
    return thetas, sd


def _sigma(model, channels, sigma) -> dict:
    """Measured channel -> noise level (SI): given, else the typical rig's
    (``identification.SENSOR_NOISE``)."""
    given = dict(sigma or {})
    names = (*model.states, *model.outputs)
    for c in given:
        if c not in channels:
            raise DesignError(f"--sigma {c}: not a measured channel (--channels {','.join(channels)})")
    out = {}
    for c in channels:
        if c not in names:
            raise DesignError(f"--channels {c}: not a state or output of the model{nearest(c, names)}")
        v = given.get(c, SENSOR_NOISE.get(c))
        if v is None:
            raise DesignError(f"--sigma {c}=VALUE: give the noise of channel {c} (no typical value known)")
        out[c] = number(v, f"--sigma {c}", DesignError, positive=True)
    return out


def design_experiment(params: Parameters, free=DEFAULT_FREE, duration: float = 10.0, *, criterion: str = "DC",
                      weights: dict | None = None, stroke: float = 0.01, max_load: float = 15e3,
                      max_speed: float | None = None, sigma: dict | None = None, channels=None, prior=None,
                      draws: int | None = None, spread: float = SPREAD, segment: float = 1.0, rate: float = 2000.0,
                      library=None, variants: dict | None = None, seed: int = 0, progress: bool = False):
    """Design the rig test (command and load profile) whose 95 % intervals of the ``free``
    parameters are smallest by a criterion, within the test's stroke, the load capability
    and the limits the parts declare (the current and voltage ratings, the rated rod
    speed, temperatures), from the Fisher information of exact forward sensitivities
    (the ones ``identify`` fits with).

    Parameters
    ----------
    params : Parameters
        The parameter set (the values the test is designed at; the centre of the prior).
    free : sequence of str or str
        Flat names of the parameters to pin down.
    duration : float
        Test length (s), a whole number of segments.
    criterion : {"DC", "D", "A", "E"}
        DC (default): D with no named parameter's predicted interval wider than the
        standard test's of the same length (0.95 x it where the library allows, else the
        max-min optimum of the ratios; :mod:`._optimise`); D: the volume of the
        confidence ellipsoid; A: the sum of the (weighted) relative variances; E: the
        largest (weighted) variance.
    weights : dict, optional
        Name -> weight of a free parameter in the criterion (default 1 each; 0: not of
        interest, D then takes the others' ellipsoid).
    stroke : float
        The test's stroke (m): the rod stays within +-stroke (with a 5 % margin).
    max_load : float
        Load capability of the rig (N): load levels within +-max_load (0: no load).
    max_speed : float, optional
        The rod's speed bound (m/s) on the predicted trajectory, the speed loop's
        overshoot included; default the rated rod speed the model declares (its
        operating limit), at most that (a lower one: the rig's, or the ECU's rate limit
        to keep the rod below it).
    sigma : dict, optional
        Channel -> sensor noise (SI); default a typical rig's (0.3 um, 0.05 A, ...).
    channels : sequence of str, optional
        Measured channels (default the rod position and the motor current).
    prior : str, Path or dict, optional
        A fitted parameter file (its 95 % intervals) or name -> (estimate, lo, hi): the
        design averages the information over draws from it.
    draws : int, optional
        Parameter draws the information is averaged over (default 1 without a prior,
        4 with one; the first is the centre).
    spread : float
        Relative standard deviation of the draws of a parameter the prior does not give.
    segment : float
        Segment length (s): the period of the lowest multisine frequency.
    rate : float
        Sample rate of the test's tables (Hz).
    library : sequence of Segment, optional
        The candidate segments to choose from (default :func:`~ema_casadi.design.candidates`:
        multisines, slews and stop-and-go steps at five load levels and three
        amplitudes, each counted after a lead-in of itself).
    variants : dict, optional
        Variant overrides of the model.
    seed : int
        Seed of the prior's draws.
    progress : bool
        One line of progress on stderr.

    Returns
    -------
    DesignResult
        The designed test, its predicted intervals and correlation, the standard test's,
        the limits used.
    """
    t_wall = time.perf_counter()
    req = _request(params, free, duration, criterion, weights, stroke, max_load, max_speed, sigma, channels, prior,
                   draws, spread, segment, rate, library, variants, seed)
    return _run(req, progress, t_wall)


def _request(params, free, duration, criterion, weights, stroke, max_load, max_speed, sigma, channels, prior, draws,
             spread, segment, rate, library, variants, seed) -> SimpleNamespace:
    """Every argument checked (DesignError naming the first mistake), before any run."""
    if not isinstance(params, Parameters):
        raise DesignError("params: a Parameters object (from load_parameters)")
    model = build_model(params, variants)
    for role in ("command", "load"):  # the test commands the rod against its load
        model.needs_input(role, "a designed test of the rod", DesignError)
    if isinstance(free, str):
        free = [s.strip() for s in free.split(",") if s.strip()]
    try:
        fr = free_parameters(model, free)
    except IdentificationError as exc:
        raise DesignError(str(exc).replace("free parameter", "--free")) from None
    if criterion not in CRITERIA:
        raise DesignError(f"--criterion {criterion}: unknown (use {', '.join(CRITERIA)})")
    segment = number(segment, "--segment", DesignError, positive=True)
    duration = number(duration, "--duration", DesignError, positive=True)
    n_seg = duration / segment
    if n_seg < MIN_SEGMENTS - 1e-9 or abs(n_seg - round(n_seg)) > 1e-6:
        raise DesignError(f"--duration {duration:g} s: too short for the lowest frequency {1 / segment:g} Hz or not a "
                          f"whole number of {segment:g} s segments (at least {MIN_SEGMENTS})")
    n_seg = int(round(n_seg))
    rate = number(rate, "--rate", DesignError, positive=True)
    if abs(segment * rate - round(segment * rate)) > 1e-6:
        raise DesignError(f"--rate {rate:g} Hz: a {segment:g} s segment must hold a whole number of samples")
    stroke = number(stroke, "--stroke", DesignError, positive=True)
    pos = model.output_with("rod_position")
    reach = model.envelope().get(pos, math.inf)
    if stroke >= reach:
        raise DesignError(f"--stroke {stroke * 1e3:g} mm: at or beyond the actuator's travel ({reach * 1e3:g} mm)")
    max_load = number(max_load, "--max-load", DesignError, nonneg=True)
    held = model.envelope_limits().get("held_load", math.inf)
    if max_load >= 0.95 * held:
        raise DesignError(f"--max-load {max_load / 1e3:g} kN: the current limit holds at most {held / 1e3:.3g} kN; "
                          f"no excitation keeps the motor current within it at that load")
    rated = model.operating_limits().get("rod_speed", model.limit_values().get("rod_speed", math.inf))
    if max_speed is None:
        max_speed = rated
    max_speed = number(max_speed, "--max-speed", DesignError, positive=True)
    if max_speed > rated:
        raise DesignError(f"--max-speed {max_speed * 1e3:g} mm/s: above the rated rod speed ({rated * 1e3:g} mm/s)")
    pw = np.ones(len(fr.names))
    for n, w in dict(weights or {}).items():
        if n not in fr.names:
            raise DesignError(f"--weights {n}: not a free parameter{nearest(n, fr.names)}")
        pw[fr.names.index(n)] = number(w, f"--weights {n}", DesignError, nonneg=True)
    if not pw.any():
        raise DesignError("--weights: give at least one parameter a weight above 0")
    if channels is None:
        channels = (model.output_with("rod_position"), model.output_with("motor_current"))
    elif isinstance(channels, str):
        channels = [c.strip() for c in channels.split(",") if c.strip()]
    if isinstance(channels, str) or not channels:
        raise DesignError("--channels: none given; give at least one measured "
                          "channel (a state or output, e.g. x_rod,i_q)")
    sig = _sigma(model, list(channels), sigma)
    label = f"--prior {prior}" if isinstance(prior, (str, Path)) else "--prior"
    if isinstance(prior, (str, Path)):
        prior = read_prior(prior)
    if prior is not None and not isinstance(prior, dict):
        raise DesignError(f"prior: expected a fitted file's path or a dict name -> (estimate, lo, hi), got "
                          f"{type(prior).__name__}")
    if prior is not None:
        _check_prior(prior, fr, label)
    draws = integer(draws if draws is not None else (4 if prior is not None else 1), "--draws", DesignError,
                    minimum=1)
    spread = number(spread, "--spread", DesignError, nonneg=True)
    seed = integer(seed, "--seed", DesignError, minimum=0)  # numpy's generators take whole numbers >= 0
    if library is not None:
        from ._excitation import Segment

        library = list(library)
        if not library or not all(isinstance(s, Segment) for s in library):
            raise DesignError("library: a non-empty sequence of Segment")
    names = (model.input_with("command"), model.input_with("load"))
    return SimpleNamespace(**{k: v for k, v in locals().items() if k != 'exc'})


def _realise(req, segs, counts, thetas, lim):
    """The test of ``counts`` whole segments realised, its information per draw:
    (counts, test, infos)."""
    order = sorted([k for k in range(len(segs)) for _ in range(counts[k])],
                   key=lambda k: (segs[k].load, segs[k].kind, segs[k].band, segs[k].amplitude))
    test = realise([segs[k] for k in order], req.segment, req.rate, *req.names)
    return counts, test, [information(req.model, test, req.fr, req.sig, th, **lim) for th in thetas]


def _rounds(req, segs, Ms, M_std, thetas, lim):
    """The weights, the realised test and its information; for DC the rounds against the
    standard test (:data:`DC_ROUNDS`), the one nearest it kept: (chosen round, rounds,
    opt, counts, test, infos, M)."""
    fr, criterion, pw, n_seg = req.fr, req.criterion, req.pw, req.n_seg
    factor, rounds, tried = np.ones(len(fr.names)), [], []
    for _ in range(DC_ROUNDS if criterion == "DC" else 1):
        opt = optimal_weights(Ms, criterion, pw, n_seg, reference=M_std, factor=factor)
        if not opt["success"]:
            raise DesignFailed(f"IPOPT did not converge on the design weights ({opt['status']})")
        counts = efficient_rounding(opt["w"], req.n_seg)
        if any(np.array_equal(counts, r[3]) for r in tried):
            break  # the same test as an earlier round: nothing more to learn
        counts, test, infos = _realise(req, segs, counts, thetas, lim)
        M = np.mean([i.M for i in infos], axis=0)
        ratio = np.diag(np.linalg.inv(M)) / np.diag(np.linalg.inv(M_std))  # realised variances / the standard's
        worst = float(np.max(ratio[pw > 0]))
        rounds.append({"variance_ratio": ratio.tolist(), "factor": factor.tolist(), "worst_width_ratio":
                       float(np.sqrt(worst))})
        tried.append((worst, len(tried), opt, counts, test, infos, M))
        over = (pw > 0) & (ratio > WIDTH_RATIO**2)
        if criterion != "DC" or not over.any():
            break
        factor = np.where(over, factor * WIDTH_RATIO**2 / ratio, factor)  # the additive sum was optimistic there
    _, best, opt, counts, test, infos, M = min(tried, key=lambda r: r[:2])  # DC: the round nearest the standard
    return best, rounds, opt, counts, test, infos, M


def _run(req, progress: bool, t_wall: float):
    """The design: candidates, weights, the realised test, the standard test."""
    from ._result import DesignResult

    params, model, fr, sig, names = req.params, req.model, req.fr, req.sig, req.names
    segment, rate, stroke, max_load = req.segment, req.rate, req.stroke, req.max_load
    lim = {"stroke": stroke, "max_load": max_load, "max_speed": req.max_speed}
    criterion, pw, duration, variants, library = req.criterion, req.pw, req.duration, req.variants, req.library
    prior, draws, spread, seed = req.prior, req.draws, req.spread, req.seed
    thetas, prior_sd = _thetas(fr, prior, draws, spread, seed)

    def bar(f, what):
        progress_bar(f, progress, "design-experiment", what)

    # the candidates: information per segment, limits along their predictions
    cands = candidates(segment, stroke, max_load) if library is None else list(library)
    t0 = time.perf_counter()
    ev = evaluate(model, cands, segment, rate, fr, sig, thetas, lim, names,
                  lambda f: bar(0.6 * f, "candidates"))
    extra = at_limits(cands, ev)  # the shapes whose largest amplitude leaves a limit, at the limits
    if extra:
        ev += evaluate(model, extra, segment, rate, fr, sig, thetas, lim, names,
                       lambda f: bar(0.6 + 0.2 * f, "candidates at the limits"))
        cands += extra
    t_cand = time.perf_counter() - t0
    ok = [k for k, e in enumerate(ev) if e is not None and admissible(e[1])]
    if not ok:
        raise DesignFailed("no candidate segment keeps the limits (stroke, current, rod speed, voltage) on its "
                           "prediction")
    segs = [cands[k] for k in ok]
    Ms = np.array([ev[k][0] for k in ok])
    standard = standard_test(duration, stroke, max_load, rate, *names, max_speed=req.max_speed)
    bar(0.65, "the standard test")
    std_infos = [information(model, standard, fr, sig, th, **lim) for th in thetas]
    M_std = np.mean([i.M for i in std_infos], axis=0)  # the reference of the DC criterion
    t0 = time.perf_counter()
    best, rounds, opt, counts, test, infos, M = _rounds(req, segs, Ms, M_std, thetas, lim)
    t_opt = time.perf_counter() - t0
    bar(0.85, "the designed test")
    usage = {n: max(i.usage[n] for i in infos) for n in infos[0].usage}
    if not admissible(usage):
        worst = max(usage, key=lambda n: usage[n] / (0.95 if n == "stroke" else 1.0))
        raise DesignFailed(f"the designed test's prediction leaves the {worst} limit ({usage[worst]:.3g} x it)")
    bar(1.0, "done")
    table = [{"segment": s.label(), "kind": s.kind, "band": list(s.band), "load": s.load, "amplitude": s.amplitude,
              "share": float(opt["w"][ok_k]), "count": int(counts[ok_k])}
             for ok_k, s in enumerate(segs) if counts[ok_k] > 0 or opt["w"][ok_k] > 1e-3]
    info = {"criterion": criterion, "weights": dict(zip(fr.names, pw.tolist(), strict=True)),
            "criterion_value": criterion_value(M, criterion, pw),
            "criterion_standard": criterion_value(M_std, criterion, pw),
            "ipopt": {"status": opt["status"], "iterations": opt["iterations"]},
            **({"reference": {"maxmin_variance_ratio": opt["maxmin"], "variance_bound": opt["bound"],
                              "width_ratio_target": WIDTH_RATIO, "reachable": opt["maxmin"] <= WIDTH_RATIO**2,
                              "rounds": rounds, "chosen_round": best,
                              "width_ratio_realised": rounds[best]["worst_width_ratio"]}}
               if criterion == "DC" else {}),
            "candidates": len(cands), "admissible": len(ok), "draws": len(thetas),
            "prior_sd": dict(zip(fr.names, prior_sd.tolist(), strict=True)),
            "additive_criterion": opt["value"], "segment": segment, "rate": rate, "duration": duration,
            "stroke": stroke, "max_load": max_load, "max_speed": req.max_speed, "sigma": sig,
            "variant_overrides": dict(variants or {}),
            "time_candidates": t_cand, "time_optimiser": t_opt, "wall_time": time.perf_counter() - t_wall,
            "standard_usage": {n: max(i.usage[n] for i in std_infos) for n in std_infos[0].usage}}
    res = DesignResult(params=params, model=model, free=fr, test=test, standard=standard, M=M, M_standard=M_std,
                       predicted=intervals(M, fr, thetas[0]), standard_predicted=intervals(M_std, fr, thetas[0]),
                       usage=usage, segments=table, thetas=thetas, info=info, runs=infos[0].runs)
    res.candidates = list(zip(segs, Ms, strict=True))
    return res
