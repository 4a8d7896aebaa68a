"""One least-squares fit of ``identify``: residuals and Jacobian from one prediction,
the Levenberg-Marquardt solve (:func:`ema_casadi.optimisation.levenberg_marquardt`)
confirmed on step sequences chosen at its optimum, and the noise levels re-estimated
around it; the block means of coarse to fine (:mod:`._coarse`)."""

from __future__ import annotations

import numpy as np

from ..optimisation import COST_TOL, gauss_newton_decrease, levenberg_marquardt
from ..simulation import RunFailed, progress_bar
from ._failed import FitFailed
from ._problem import Predictor, marginal
from ._unsettled import kept

#: Relative change of the estimated noise levels below which their re-estimation stops.
SIGMA_TOL = 0.02
#: Re-estimation rounds of the noise levels at most.
SIGMA_ROUNDS = 6
#: Evaluations within this distance (in log-parameters) of the point where the step
#: sequences were chosen replay them (the cost is then a smooth function, so the small
#: steps near the optimum compare like with like); farther ones choose them anew.
REGRID = 0.05
#: Confirmations of an optimum on steps chosen there (:meth:`_Fit._confirmed`): an
#: adaptive run can accept a step whose error its estimate misses, and a grid chosen
#: there can hold a false optimum (one kernel's path: J_m 5 sd off, the cost 116 high).
CONFIRMS = 2
CONFIRM_EVALUATIONS = 8


class _Fit:
    """One fit: residuals and Jacobian from one prediction, the noise re-estimation
    around the least-squares solve."""

    def __init__(self, pred: Predictor, given: dict, max_evaluations: int, progress: bool):
        self.pred, self.given, self.max_eval, self.progress = pred, given, max_evaluations, progress
        self.channels = sorted({c for r in pred.records for c in r.channels})
        self.regrid = REGRID  # farther than this from where the steps were chosen: choose them anew
        self._cache = None
        self.z_grid = None
        self.failure = ""
        self.evaluations = 0
        self.history = []  # per evaluation: its cost (the round's weights), for the JSON of every exit
        self.round, self._logged = 0, None
        #: Coarse-to-fine: per record, the samples per block (None: every sample).
        self.blocks = None
        self.coarse_evaluations = 0

    # -- residuals -------------------------------------------------------------------
    def errors(self, theta):
        """(predictions, e per (record, channel), de/dz per (record, channel)); e =
        measured - model, from the second sample on (the first fixes the start); zero
        (both) on the samples a record leaves out (:mod:`._unsettled`)."""
        preds = self.pred.predict(theta)
        e, de = {}, {}
        m, n_rec = len(self.pred.x0_states), len(preds)
        first = 0 if m else 1  # an estimated start is fitted to the first sample too
        for i, (rec, pr) in enumerate(zip(self.pred.records, preds, strict=True)):
            for c, meas in rec.channels.items():
                e[i, c] = meas[first:] - pr["y"][c][first:]
                de[i, c] = -pr["dy"][c][first:]
                if m:  # the record's own initial-state columns; zero for the other records'
                    d0 = np.zeros((len(e[i, c]), m * n_rec))
                    d0[:, i * m : (i + 1) * m] = -pr["dy0"][c][first:]
                    de[i, c] = np.hstack([de[i, c], d0])
                keep = kept(rec, c, first)
                if keep is not None:
                    e[i, c] = np.where(keep, e[i, c], 0.0)
                    de[i, c] = np.where(keep[:, None], de[i, c], 0.0)
        return preds, e, de

    def samples(self, e) -> dict:
        """(record, channel) -> the samples of ``e`` that count (all but those left out)."""
        first = 0 if self.pred.x0_states else 1
        out = {}
        for (i, c), v in e.items():
            keep = kept(self.pred.records[i], c, first)
            out[i, c] = len(v) if keep is None else int(keep.sum())
        return out

    def weighted(self, e, de, sig):
        """Weighted residuals and Jacobian; at a coarse level (:attr:`blocks`) the
        means over blocks of N samples times sqrt(N) (white noise of unit variance stays
        so), a record's last partial block left out."""
        keys = sorted(e, key=lambda k: (k[0], k[1]))
        if self.blocks is None:
            r = np.concatenate([e[k] / sig[k[1]] for k in keys])
            J = np.concatenate([de[k] / sig[k[1]] for k in keys])
            return r, J
        rs, Js = [], []
        for k in keys:
            N = self.blocks[k[0]]
            n = len(e[k]) // N * N
            w = np.sqrt(N) / sig[k[1]]
            rs.append(e[k][:n].reshape(-1, N).mean(axis=1) * w)
            Js.append(de[k][:n].reshape(-1, N, de[k].shape[1]).mean(axis=1) * w)
        return np.concatenate(rs), np.concatenate(Js)

    def _raw(self, z):
        """(predictions, e, de) at ``z``, or None where the run failed; the last one kept."""
        z = np.asarray(z, float)
        key = z.tobytes()
        if self._cache is not None and self._cache[0] == key:
            return self._cache[1]
        if self.z_grid is None or np.max(np.abs(z - self.z_grid)) > self.regrid:
            self.pred.refresh()  # far from where the step sequences were chosen: choose them here
            self.z_grid = z.copy()
        self.evaluations += 1
        n = len(self.pred.free.names)
        self.pred.dx0 = list(z[n:].reshape(len(self.pred.records), -1)) if self.pred.x0_states else self.pred.dx0
        try:
            raw = self.errors(self.pred.free.theta(z[:n]))
            if not all(np.all(np.isfinite(v)) for d in raw[1:] for v in d.values()):
                raw, self.failure = None, "non-finite model values"
        except RunFailed as exc:
            raw, self.failure = None, exc.reason
        self._cache = (key, raw)
        progress_bar(min(1.0, self.evaluations / self.max_eval), self.progress, "identify",
                     f"evaluation {self.evaluations}")
        return raw

    def _eval(self, z, sig):
        """Weighted residuals and Jacobian at ``z`` (None, None where the run failed)."""
        raw = self._raw(z)
        if raw is None:
            return None, None
        r, J = self.weighted(raw[1], raw[2], sig)
        key = (np.asarray(z, float).tobytes(), self.round)
        if key != self._logged:  # each point once per round (a cached one is not a new evaluation)
            self._logged = key
            self.history.append({"evaluation": self.evaluations, "cost": 0.5 * float(r @ r), "round": self.round})
        return r, J

    def failed(self, what: str, z, cost=None, status: str = "not converged") -> FitFailed:
        """The :class:`FitFailed` of this fit at optimiser point ``z`` (its last iterate)."""
        fr = self.pred.free
        theta = fr.theta(np.asarray(z, float)[: len(fr.names)])
        return FitFailed(what, status=status, iterate=dict(zip(fr.names, theta.tolist(), strict=True)),
                         cost=None if cost is None or not np.isfinite(cost) else float(cost), history=self.history)

    # -- the fit ---------------------------------------------------------------------
    def _confirmed(self, sig, z, lo, hi, budget, tol) -> dict:
        """Levenberg-Marquardt from ``z``, its optimum confirmed on step sequences chosen
        there: where the Gauss-Newton step still predicts a decrease above 10 x the
        tolerance, the fit goes on from there (at most :data:`CONFIRMS` times, each
        within :data:`CONFIRM_EVALUATIONS`); where it is confirmed, or going on does not
        converge (a misfit far above the noise: the grids resolve its optimum no finer),
        the optimum on its own grid is kept."""
        sol = levenberg_marquardt(lambda zz: self._eval(np.asarray(zz), sig), z, lo, hi, budget, tol)
        if not sol["converged"]:
            raise self.failed(f"did not converge within {self.max_eval} model evaluations ({sol['message']})",
                              sol["z"], sol["cost"])
        for _ in range(CONFIRMS):
            z = sol["z"]
            if self.z_grid is not None and np.array_equal(z, self.z_grid):
                return sol
            kept = (self._cache, list(self.pred.steps), self.z_grid)
            self._cache, self.z_grid = None, z.copy()
            self.pred.refresh()
            r, J = self._eval(z, sig)
            room = min(CONFIRM_EVALUATIONS, self.max_eval - self.evaluations + 1)
            nxt = None
            if r is not None and gauss_newton_decrease(r, J, z, lo, hi) >= 10 * tol and room >= 2:
                nxt = levenberg_marquardt(lambda zz: self._eval(np.asarray(zz), sig), z, lo, hi, room, tol)
            if nxt is None or not nxt["converged"]:
                self._cache, self.pred.steps, self.z_grid = kept
                return sol
            sol = nxt
        return sol

    def full(self, z0) -> np.ndarray:
        """``z0`` with the estimated initial-state offsets (zero where not given)."""
        z0 = np.asarray(z0, float)
        n_x0 = len(self.pred.x0_states) * len(self.pred.records)
        return np.concatenate([z0, np.zeros(n_x0)]) if len(z0) == len(self.pred.free.names) else z0

    def box(self) -> tuple[np.ndarray, np.ndarray]:
        n_x0 = len(self.pred.x0_states) * len(self.pred.records)
        lo, hi = self.pred.free.z_bounds()
        return np.concatenate([lo, np.full(n_x0, -np.inf)]), np.concatenate([hi, np.full(n_x0, np.inf)])

    def start_sigma(self, z0) -> dict:
        """The first weights: channel -> its given noise level, else the residuals' RMS at
        ``z0``. Raises FitFailed (status failed) where the model fails there."""
        z0 = self.full(z0)
        self.z_grid = None
        raw = self._raw(z0)
        if raw is None:
            raise self.failed(f"the model run fails at the start values: {self.failure}", z0, status="failed")
        e0 = raw[1]
        n0 = self.samples(e0)
        sig = {c: self.given.get(c) or _rms([e0[k] for k in e0 if k[1] == c], [n0[k] for k in e0 if k[1] == c])
               for c in self.channels}
        return {c: (v if v > 0 else 1.0) for c, v in sig.items()}

    def run(self, z0) -> dict:

        fr = self.pred.free
        z0 = self.full(z0)
        sig = self.start_sigma(z0)
        lo, hi = self.box()
        z = np.clip(np.asarray(z0, float), lo, hi)
        estimate = [c for c in self.channels if c not in self.given]

        for _round in range(SIGMA_ROUNDS):
            self.round = _round
            if _round:  # the step sequences chosen anew at a later round's start, then frozen
                self._cache, self.z_grid = None, None
            budget = self.max_eval - self.evaluations + 1  # the round's start may be the cached point
            if budget < 2:
                raise self.failed(f"did not converge within {self.max_eval} model evaluations", z)
            tol = COST_TOL if _round or not estimate else 1e3 * COST_TOL  # the first weights are provisional
            sol = self._confirmed(sig, z, lo, hi, budget, tol)
            z = sol["z"]
            if not estimate:
                break
            _, e, _ = self._raw(z)
            counts = self.samples(e)
            dof = max(1e-3, 1.0 - len(z) / sum(counts.values()))
            new = {c: _rms([e[k] for k in e if k[1] == c], [counts[k] for k in e if k[1] == c]) / np.sqrt(dof)
                   for c in estimate}
            change = max(abs(new[c] / sig[c] - 1) for c in estimate)
            sig = {**sig, **new}
            if change < SIGMA_TOL:
                break
        r, J = self._eval(z, sig)
        progress_bar(1.0, self.progress, "identify", f"{self.evaluations} evaluations")
        n = len(fr.names)
        return {"z": z[:n], "z_full": z, "sigma": sig, "r": r, "J": marginal(J, n), "J_full": J,
                "cost": 0.5 * float(r @ r), "message": sol["message"], "estimated": estimate,
                "samples": sum(self.samples(self._raw(z)[1]).values())}


def _rms(arrays, counts) -> float:
    """The RMS of ``arrays`` over ``counts`` samples (their left-out samples are zeros)."""
    a = np.concatenate(arrays) if arrays else np.zeros(1)
    return float(np.sqrt(np.sum(a * a) / max(1, sum(counts))))


def new_fit(model, recs, fr, xs, given, max_evaluations, progress) -> _Fit:
    """A fresh fit of ``recs`` on ``model`` (its parameter vector the base) from a fresh
    predictor: free set ``fr``, estimated initial states ``xs``, given noise levels."""
    return _Fit(Predictor(model, recs, fr, model.p(), xs), given, max_evaluations, progress)
