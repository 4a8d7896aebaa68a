"""Inspection of a :class:`~ema_casadi.tuning.TuningProblem`: the optimiser's loop
sensitivities and step response at given gains, and the sharing of load cases."""

from __future__ import annotations

import casadi as ca
import numpy as np

from ._cascade import OUTER_OPEN
from ._closed_loop import _LOOP_ORDER


class _Inspection:
    """Methods of :class:`~ema_casadi.tuning.TuningProblem` that read its model back."""

    def loop_sensitivities(self, case: int = 0, gains: dict | None = None, freqs=None, outer: str = "closed") -> dict:
        """The optimiser's loop sensitivities S = 1/(1 + L), each loop broken with the
        others closed (or, ``outer="open"``, its outer loops open), from its reduced,
        balanced closed loop.

        Parameters
        ----------
        case : int
            Index of the load case (into :attr:`cases`).
        gains : dict, optional
            Values of the free gains (SI, by name; default the start).
        freqs : array_like, optional
            Frequencies (Hz; default the problem's grid).

        Returns
        -------
        dict
            Per loop (position, velocity, current): S at ``freqs`` (complex, dimensionless).
        """
        theta = self._scaling.theta0 if gains is None else self._scaling.theta_of(gains)
        f = self.freqs if freqs is None else np.asarray(freqs, float)
        if outer == "open":
            return {loop: self._sensitivities(case, f, theta, OUTER_OPEN[loop])[loop] for loop in _LOOP_ORDER}
        return self._sensitivities(case, f, theta)

    def step_response(self, case: int = 0, gains: dict | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The optimiser's closed-loop response to the step of ``requirements.step``
        (exact at the samples: matrix exponential on the doubling time grid).

        Parameters
        ----------
        case : int
            Index of the load case (into :attr:`cases`).
        gains : dict, optional
            Values of the free gains (SI, by name; default the start).

        Returns
        -------
        t : ndarray
            Sample times (s) from the step.
        Y : ndarray
            Rows x_rod (m), i_q (A), v_d (V), v_q (V): deviations from the operating point.
        """
        theta = self._scaling.theta0 if gains is None else self._scaling.theta_of(gains)
        X, t = self._trajectories[self._case_step[case]]
        _, _, (_, Cs, ds) = self._loop.matrices(self.cases[case])
        Y = Cs @ X + ca.repmat(ds * self.requirements.step, 1, X.shape[1])
        return t, np.array(ca.Function("Y", [self._scaling.theta], [Y])(theta))

    @property
    def n_linearisations(self) -> int:
        """Distinct linear dynamics among the load cases (each with its own frequency,
        bandwidth and eigenvalue constraints)."""
        return len(self._signatures["frequency"])

    @property
    def n_step_responses(self) -> int:
        """Distinct closed-loop state responses to the step among the load cases."""
        return len(self._trajectories)
