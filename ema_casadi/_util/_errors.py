"""The one error family of the toolkit (docs: reliability, "One error family").

Every error the toolkit raises on purpose derives from :class:`EmaError`, through one of
three kinds that say what the user can do about it:

* :class:`InputError`: a mistake in what was asked (a value out of range, an unknown
  name, a file that cannot be read, a combination the model does not use). The
  command line reports it as one line naming the flag, key or file, exit status 2,
  nothing written.
* :class:`InfeasibleError`: a well-formed request with no answer inside the physical
  envelope or the limits (no move within the current limit, no test within the
  stroke). Exit status 3.
* :class:`RunError`: a run or an analysis that did not end in an answer (it left the
  envelope, an integrator gave up, a fit or a Newton iteration did not converge).
  Exit status 3.

The families' classes keep their older bases (``ValueError``, ``RuntimeError``) beside
these, so ``except ValueError`` in a script still catches a bad parameter. Every class of
the family pickles and unpickles whatever its ``__init__`` takes (a worker process's
error reaches the parent whole: the arguments and the attributes are restored without
calling ``__init__`` again).
"""

from __future__ import annotations

__all__ = ["EmaError", "InputError", "InfeasibleError", "RunError", "exit_status"]


def _rebuild(cls, args, state):
    """An instance of ``cls`` with ``args`` and the attributes ``state``, ``__init__`` not called."""
    obj = cls.__new__(cls, *args)
    obj.args = args
    obj.__dict__.update(state)
    return obj


class EmaError(Exception):
    """The base of every error the toolkit raises on purpose; ``str()`` is one line.

    Attributes
    ----------
    exit_status : int
        The command line's exit status for it (2 input, 3 infeasible or failed).
    """

    exit_status = 1

    def __reduce__(self):
        return _rebuild, (type(self), self.args, dict(self.__dict__))


class InputError(EmaError):
    """A mistake in the input (an argument, a flag, a file's key): exit status 2."""

    exit_status = 2


class InfeasibleError(EmaError):
    """A valid request with no answer inside the physical envelope or the limits: exit status 3."""

    exit_status = 3


class RunError(EmaError):
    """A run or an analysis that ended without an answer (it left the envelope, an
    integrator gave up, an iteration did not converge): exit status 3."""

    exit_status = 3


def exit_status(exc: BaseException) -> int | None:
    """The command line's exit status of an error of the family (None for any other)."""
    return exc.exit_status if isinstance(exc, EmaError) else None
