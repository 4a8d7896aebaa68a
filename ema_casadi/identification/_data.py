"""Plain data for JSON (the result documents)."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def plain(obj):
    """``obj`` with NumPy arrays and numbers as lists and floats, tuples as lists, paths
    as text, non-finite floats as None / "inf" / "-inf" (JSON has no NaN or infinity).

    Parameters
    ----------
    obj : object
        Nested dicts, lists, tuples, arrays and numbers.
    """
    if isinstance(obj, dict):
        return {str(k): plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple, np.ndarray)):
        return [plain(v) for v in obj]
    if isinstance(obj, (float, np.floating)):
        v = float(obj)
        return v if np.isfinite(v) else (None if np.isnan(v) else ("inf" if v > 0 else "-inf"))
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, Path):
        return str(obj)
    return obj
