"""What makes a result pleasant in a notebook: a short ``repr``, a small HTML table
(``_repr_html_``) and DataFrames (``to_pandas()``; pandas is optional)."""

from __future__ import annotations

import html

__all__ = ["data_frame", "short_repr", "html_summary"]


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


def short_repr(name: str, facts: dict) -> str:
    """``Name(key=value, ...)`` with the facts that are not None."""
    return f"{name}(" + ", ".join(f"{k}={v}" for k, v in facts.items() if v is not None) + ")"


def html_summary(name: str, facts: dict) -> str:
    """A two-column HTML table of the facts under the result's name."""
    rows = "".join(f"<tr><th style='text-align:left'>{html.escape(str(k))}</th><td style='text-align:left'>"
                   f"{html.escape(str(v))}</td></tr>" for k, v in facts.items() if v is not None)
    return f"<b>{html.escape(name)}</b><table>{rows}</table>"
