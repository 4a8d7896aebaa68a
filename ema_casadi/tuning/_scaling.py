"""The free gains as decision variables: gain = reference * exp(theta) within
reference * [1/100, 100]; K_i_x from a zero reference linearly, (K_x^2/4) * theta."""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from ._requirements import GAIN_INFO, TuneError

_BOUND = 100.0  # gains within reference * [1/_BOUND, _BOUND]


class _GainScaling:
    """Variables ``theta`` of one Opti problem and the gains as expressions of them.

    Attributes: ``theta`` (the variables), ``gains`` (MX, SI, in the order of ``free``),
    ``log_scaled`` (per gain: exp scaling, else linear), ``theta0`` (the start).
    """

    def __init__(self, opti: ca.Opti, free: tuple, ref: dict, start: dict):
        self.free, self.ref = free, ref
        self.theta = opti.variable(len(free))
        self.log_scaled, exprs, theta0 = [], [], []
        for i, g in enumerate(free):
            zero_scale = GAIN_INFO[g].zero_scale
            if zero_scale is not None and ref[g] == 0.0:
                s = self._linear_scale(g)
                self.log_scaled.append(False)
                exprs.append(s * self.theta[i])
                theta0.append(start[g] / s)
                opti.subject_to(opti.bounded(0, self.theta[i], _BOUND))
                continue
            for what, v in (("reference", ref[g]), ("start", start[g])):
                if v <= 0:
                    raise TuneError(f"{what} value of {g} must be positive, got {v}")
            self.log_scaled.append(True)
            exprs.append(ref[g] * ca.exp(self.theta[i]))
            theta0.append(math.log(start[g] / ref[g]))
            opti.subject_to(opti.bounded(-math.log(_BOUND), self.theta[i], math.log(_BOUND)))
        self.gains = ca.vertcat(*exprs)
        self.theta0 = np.array(theta0)
        opti.set_initial(self.theta, self.theta0)

    def _linear_scale(self, g: str) -> float:
        return GAIN_INFO[g].zero_scale(self.ref)  # the part's natural size of the gain

    def p(self, names: list, base: np.ndarray) -> ca.MX:
        """The parameter vector ``base`` with the free gains replaced by their expressions."""
        entries = [ca.MX(float(v)) for v in base]
        for i, g in enumerate(self.free):
            entries[names.index(g)] = self.gains[i]
        return ca.vertcat(*entries)

    def values(self, theta) -> np.ndarray:
        """Numeric gains (SI, in the order of ``free``) at ``theta``."""
        return np.array(ca.Function("gains", [self.theta], [self.gains])(theta), float).ravel()

    def theta_of(self, gains: dict) -> np.ndarray:
        """The variables that give these gains (SI, by name)."""
        return np.array([math.log(gains[g] / self.ref[g]) if ls else gains[g] / self._linear_scale(g)
                         for g, ls in zip(self.free, self.log_scaled, strict=False)])

    def random_theta(self, rng: np.random.Generator) -> np.ndarray:
        """Random variables near the start, no gain zero (a zero gain hides the states
        it drives)."""
        th = self.theta0 + rng.uniform(-1, 1, len(self.theta0))
        return np.where(self.log_scaled, th, np.abs(th) + 0.5)
