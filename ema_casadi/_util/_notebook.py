"""What makes a result pleasant in a notebook: a short ``repr``, a small HTML table
(``_repr_html_``) and DataFrames (``to_pandas()``; pandas is optional)."""

from __future__ import annotations

import html

__all__ = ["data_frame", "short_repr", "html_summary", "Summarised", "changed_variants"]

#: The longest text of one fact in a repr (the rest is elided: a repr is a glance, the
#: attributes hold everything).
FACT_CHARS = 80


def data_frame(columns: dict, index: str | None = None, units: dict | None = None):
    """A :class:`pandas.DataFrame` of equal-length columns, optionally indexed by the
    column ``index``; ``units`` (column -> unit) go to ``DataFrame.attrs["units"]``.

    Raises
    ------
    ImportError
        pandas is not installed (the message says how to install it).
    """
    try:
        import pandas as pd
    except ImportError:
        raise ImportError("to_pandas() needs pandas: pip install pandas (or 'ema_casadi[pandas]')") from None
    frame = pd.DataFrame(columns)
    if index is not None:
        frame = frame.set_index(index)
    if units:
        frame.attrs["units"] = {k: v for k, v in units.items() if k in columns}
    return frame


def _fact(v) -> str:
    text = str(v)
    return text if len(text) <= FACT_CHARS else text[: FACT_CHARS - 3] + "..."


def short_repr(name: str, facts: dict) -> str:
    """``Name(key=value, ...)`` with the facts that are not None, each at most
    :data:`FACT_CHARS` characters."""
    return f"{name}(" + ", ".join(f"{k}={_fact(v)}" for k, v in facts.items() if v is not None) + ")"


class Summarised:
    """What a result is at a glance: ``repr`` one line ``Name(fact=..., ...)`` and, in a
    notebook, ``_repr_html_`` the same facts as a table; the class gives ``_facts()``
    (name -> short value; None left out). A dataclass using it says ``repr=False``."""

    def _facts(self) -> dict:
        raise NotImplementedError

    def __repr__(self) -> str:
        return short_repr(type(self).__name__, self._facts())

    def _repr_html_(self) -> str:
        return html_summary(type(self).__name__, self._facts())


def changed_variants(variants: dict, defaults: dict) -> str:
    """The variant choices that differ from ``defaults``, ``key=value, ...``, or
    ``defaults``."""
    diff = [f"{k}={v}" for k, v in variants.items() if defaults.get(k) != v]
    return ", ".join(diff) or "defaults"


def html_summary(name: str, facts: dict) -> str:
    """A two-column HTML table of the facts under the result's name."""
    rows = "".join(f"<tr><th style='text-align:left'>{html.escape(str(k))}</th><td style='text-align:left'>"
                   f"{html.escape(_fact(v))}</td></tr>" for k, v in facts.items() if v is not None)
    return f"<b>{html.escape(name)}</b><table>{rows}</table>"
