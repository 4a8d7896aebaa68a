"""Shared fixtures (the reference parameter set and its models, built once) and helpers."""

import os
from pathlib import Path

os.environ.setdefault("MPLBACKEND", "Agg")  # off screen, whatever display the machine has

import numpy as np  # noqa: E402
import pytest

from ema_casadi import build_model, load_parameters  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
REFERENCE = ROOT / "models" / "cesa_ema.toml"
#: A fault file of one disconnect, mid-run under a steady slew (the faults tests' case).
DISCONNECT = """
[scenario]
duration = 0.1
x_cmd = "ramp:40mm/s"

[[fault]]
kind = "disconnect"
onset = 0.05
"""
#: A two-run sweep file (two backlash values, 10 ms at RK4 0.1 ms on the hybrid friction, inside
#: its 0.44 ms stability limit; one metric): the smallest valid description, the base the
#: bad-input batteries alter one key at a time
SMALL_SWEEP = """[variants]
friction = "hybrid"
[parameters]
B = { values = [2e-5, 1e-4] }
[scenario]
duration = 0.01
x_cmd = "step:1mm@0.001"
solver = "rk4"
dt = 1e-4
[metrics]
peak = {}
"""


@pytest.fixture(autouse=True)
def _close_figures():
    """The figures a test's plot() calls leave with pyplot are released after it."""
    yield
    import sys

    if "matplotlib.pyplot" in sys.modules:
        sys.modules["matplotlib.pyplot"].close("all")


@pytest.fixture(scope="session")
def params():
    return load_parameters(REFERENCE)


@pytest.fixture(scope="session")
def model_cache(params):
    cache = {}

    def get(**variants):
        key = tuple(sorted(variants.items()))
        if key not in cache:
            cache[key] = build_model(params, variants)
        return cache[key]

    return get


#: A result's repr is a glance: at most this many lines and characters (the attributes
#: hold the rest; a notebook shows the same facts as a table, ``_repr_html_``).
GLANCE_LINES, GLANCE_CHARS = 5, 400


def assert_glance(obj) -> str:
    """``repr(obj)`` within :data:`GLANCE_LINES` lines and :data:`GLANCE_CHARS`
    characters, naming the class, and an HTML table for notebooks; returns the repr."""
    name = type(obj).__name__
    text = repr(obj)
    assert text.startswith(f"{name}(") and text.count("\n") < GLANCE_LINES and len(text) <= GLANCE_CHARS, text
    page = obj._repr_html_()
    assert page.startswith(f"<b>{name}</b><table>") and page.count("<tr>") >= 2 and len(page) < 4000, page
    return text


def on_grid(res, dt=1e-3):
    """The rows of an FMPy result at the multiples of dt (the last row where an event
    recorded a time twice)."""
    k = np.abs(res["time"] / dt - np.round(res["time"] / dt)) < 1e-6
    res = res[k]
    i = np.round(res["time"] / dt).astype(int)
    return res[np.r_[i[1:] != i[:-1], True]]
