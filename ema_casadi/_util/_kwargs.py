"""The one check for keyword arguments a function takes as ``**kwargs`` and passes on
(python-control's rule: an unknown keyword is a TypeError naming it, never ignored)."""

from __future__ import annotations

import inspect

from ._checks import closest

__all__ = ["check_keywords", "keywords_of"]


def keywords_of(func, skip: int = 1) -> tuple[str, ...]:
    """Names ``func`` takes by keyword, after its first ``skip`` parameters."""
    params = list(inspect.signature(func).parameters.values())[skip:]
    return tuple(p.name for p in params if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY))


def check_keywords(func: str, kwargs, allowed, *, fixed=(), error: type = TypeError) -> None:
    """Raise ``error`` for the first keyword of ``kwargs`` that ``func`` cannot pass on.

    Parameters
    ----------
    func : str
        Name of the function that received the keywords, as the message shows it.
    kwargs : iterable of str
        The keywords received.
    allowed : iterable of str
        The names they are forwarded to.
    fixed : iterable of str
        Names among ``allowed`` that ``func`` sets itself.
    error : type
        The exception raised, TypeError or a subclass of it.
    """
    fixed = tuple(fixed)
    allowed = [k for k in allowed if k not in fixed]
    for key in kwargs:
        if key in allowed:
            continue
        if key in fixed:
            raise error(f"{func}() sets '{key}' itself; it passes on only {', '.join(allowed)}")
        close = closest(key, allowed, cutoff=0.6)
        hint = f"; did you mean '{close}'?" if close else f"; it takes {', '.join(allowed)}"
        raise error(f"{func}() got an unexpected keyword argument '{key}'{hint}")
