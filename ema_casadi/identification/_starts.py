"""A multi-start fit's final state, handed from the worker process that ran it to the
caller's fit (the result does not depend on where a start ran)."""

from __future__ import annotations

__all__ = ["fit_state", "install_state"]


def fit_state(fit) -> dict:
    """What :func:`install_state` puts back: the fit's cache, grid and counts and its
    predictor's."""
    p = fit.pred
    return {"cache": fit._cache, "z_grid": fit.z_grid, "evaluations": fit.evaluations, "steps": p.steps,
            "rows": p.rows, "pred_evaluations": p.evaluations, "dx0": p.dx0}


def install_state(fit, state: dict) -> None:
    """A worker's final fit state in ``fit`` (the same model, records and free set)."""
    fit._cache, fit.z_grid, fit.evaluations = state["cache"], state["z_grid"], state["evaluations"]
    fit.pred.steps, fit.pred.rows = state["steps"], state["rows"]
    fit.pred.evaluations, fit.pred.dx0 = state["pred_evaluations"], state["dx0"]
