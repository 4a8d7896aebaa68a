"""The failure of a fit: a leaf module (the fit raises it; the comparison, the
frequency-response fit and the command line catch it)."""

from __future__ import annotations

from ..simulation import AnalysisFailed


class FitFailed(AnalysisFailed):
    """A fit that did not converge, or whose model run failed at the start values: not
    a result (the command line: exit status 3, one line on stderr, no fitted file; with
    ``--json`` the document of :meth:`to_dict` on stdout).

    Parameters
    ----------
    what : str
        The reason, one line.
    status : str
        ``not converged`` (the evaluations ran out) or ``failed`` (the model run fails
        at the start values, or no start converged).
    iterate : dict, optional
        Name -> the last accepted iterate (SI).
    cost : float, optional
        The cost there (1/2 the weighted sum of squares).
    history : sequence of dict, optional
        Per model evaluation: ``evaluation``, ``cost`` (with the weights of its round)
        and ``round`` (the noise levels' re-estimation round).
    """

    def __init__(self, what: str, *, status: str = "not converged", iterate: dict | None = None,
                 cost: float | None = None, history=()):
        super().__init__(what)
        self.status, self.iterate, self.cost, self.history = status, dict(iterate or {}), cost, list(history)
        self.hints = []  # the structure hints at the last iterate (identification._hints), where found

    def to_dict(self) -> dict:
        """Plain data: ``status``, ``reason``, ``last_iterate``, ``cost``, ``cost_history``,
        ``hints``."""
        return {"status": self.status, "converged": False, "reason": self.reason, "last_iterate": self.iterate,
                "cost": self.cost, "cost_history": self.history, "hints": self.hints}
