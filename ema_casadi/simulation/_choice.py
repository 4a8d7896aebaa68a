"""The solver ``simulate(solver="auto")`` runs, the tolerances it runs at, and the
trimmed start of ``simulate(from_trim=True)``."""

from __future__ import annotations

import warnings

import numpy as np

from ..model.assembly import Model
from ._result import SimResult, SimulationError

__all__ = ["choose_solver", "tolerances", "trimmed_start", "AUTO_RTOL", "AUTO_ATOL", "RTOL", "ATOL"]

#: Tolerances of ``solver="auto"`` on a continuous model (compiled RODAS4). On the
#: reference scenario (1 mm step, 0.375 mm 1 Hz sine, 30 kN) the rod is then within
#: 0.0025 um of a CVODES run at rtol 1e-10 (0.022 um at rtol 1e-4, the loosest setting
#: meeting 0.1 um): a 40x margin on 0.1 um, at 1.1-1.4x the time of that loosest run
#: (benchmarks/bench_default.py).
AUTO_RTOL, AUTO_ATOL = 1e-5, 1e-8
#: Tolerances of an explicitly chosen variable-step solver (cvodes, rosenbrock).
RTOL, ATOL = 1e-8, 1e-11


def choose_solver(model: Model, solver: str = "auto", zoh: bool = False) -> tuple[str, str]:
    """(the solver that runs, why) for a requested ``solver``: ``auto`` picks the
    compiled RODAS4 for a continuous model and the compiled RK4 where the model
    switches or sticks; any other name is taken as given (checked later).

    Parameters
    ----------
    model : Model
        The model to run.
    solver : str
        The request (``"auto"``, ``"rk4"``, ``"cvodes"``, ``"rosenbrock"``).
    zoh : bool
        The sampled ECU is on.
    """
    if solver != "auto":
        return solver, "requested"
    if model.switched:
        return "rk4", f"the model switches ({', '.join(model.switched)}): RK4 steps to every switching instant"
    if model.hybrid:
        return "rk4", "hybrid (stick-slip) friction: RK4 with the mode logic inside each step"
    if zoh:
        return "rk4", "sampled ECU (zoh): RK4 updates each loop at its sampling instants"
    return "rosenbrock", "continuous model: variable-step RODAS4"


def tolerances(requested: str, rtol, atol) -> tuple[float, float]:
    """(rtol, atol) of a run: as given, else the defaults of ``auto`` or of an explicit solver."""
    auto = requested == "auto"
    return (float(rtol) if rtol is not None else (AUTO_RTOL if auto else RTOL),
            float(atol) if atol is not None else (AUTO_ATOL if auto else ATOL))


def _chosen(res: SimResult, requested: str, why: str, rtol: float, atol: float) -> SimResult:
    """Record the solver choice and its tolerance in the result's info."""
    used = res.info.get("solver")
    if used == "rk4":
        tol = {"dt": res.info.get("dt")}
    else:
        tol = {"rtol": rtol, "atol": atol}
    res.info.update(solver_requested=requested, solver_reason=why, tolerance=tol)
    return res


def trimmed_start(model: Model, sig: dict, pv: np.ndarray, x_base: np.ndarray | None = None) -> np.ndarray:
    """The initial state at the operating point of the inputs' values at t = 0
    (command, load, efficiency), the backlash kept: an equilibrium of the model that
    runs (friction at rest holds nothing, so its policy does not move the point).
    Temperatures are not trimmed (a thermal network settles over minutes, not at the
    start of a run): they keep their values in ``x_base`` (default ``model.x0()``), and
    the mechanics and electrics are trimmed on the same model without the network.

    Parameters
    ----------
    model : Model
        The model to run.
    sig : dict
        Its input signals by name (``x_cmd``, ``f_ext``, ``eta`` are read at t = 0).
    pv : ndarray
        Its parameter vector.
    x_base : ndarray, optional
        The state the temperatures come from.
    """
    from ..linearisation import LinearizationError, operating_point

    at0 = {name: float(np.asarray(s(np.array([0.0])))[0]) for name, s in sig.items()}
    x = np.array(model.x0() if x_base is None else x_base, float)
    plant, p_plant = model, pv
    if model.states_with("temperature"):
        plant = model.cache.get("trim_plant")
        if plant is None:
            from ..model.assembly import build_model

            plant = model.cache["trim_plant"] = build_model(model.params, {**model.variants, "thermal": "off"})
        given = dict(zip(model.param_names, pv, strict=True))
        p_plant = np.array([given.get(n, v) for n, v in zip(plant.param_names, plant.p(), strict=True)])
    try:
        with warnings.catch_warnings():  # "inside the backlash gap" concerns a linear model, not this start
            warnings.simplefilter("ignore")
            # a role the model lacks (no efficiency input: several actuators, each its own) is not given
            role = {r: at0.get(next(iter(model.inputs_with(r)), None)) for r in ("command", "load", "efficiency")}
            op = operating_point(plant, role["command"] or 0.0, role["load"] or 0.0, eta=role["efficiency"],
                                 p=p_plant, backlash="keep")
    except LinearizationError as exc:
        raise SimulationError(f"from_trim: no operating point for the inputs at t = 0: {exc}") from None
    for name, value in zip(plant.states, op.x, strict=True):
        x[model.index(name)] = value
    return x
