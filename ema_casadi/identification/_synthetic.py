"""Records made by the toolkit itself, for tests, benchmarks and the worked example:
the model with chosen "true" parameters, driven by commands sampled at the record's
rate (the table a rig logs, so that the fit, which interpolates the logged command,
sees the very input that made the record), solved by the compiled RODAS4 at tight
tolerances, with seeded Gaussian sensor noise added."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._files import write_text
from ..assembly import build_model
from ..signals import Signal, parse_signal
from ..simulation import simulate
from ..simulation._inputs import _as_signal

__all__ = ["SENSOR_NOISE", "synthetic_record"]

#: Sensor noise of a typical rig, 1 sigma (SI): rod position 0.3 um (LVDT), shaft angle
#: 2e-4 rad (resolver), speed 0.2 rad/s, currents 0.05 A, load cell 10 N.
SENSOR_NOISE = {"x_rod": 0.3e-6, "phi": 2e-4, "omega": 0.2, "i_q": 0.05, "i_d": 0.05, "F_in": 10.0}


def synthetic_record(params, path, *, t_end: float, x_cmd=0.0, f_ext=0.0, channels=("x_rod", "i_q"),
                     truth: dict | None = None, noise: dict | None = None, rate: float = 2000.0, seed: int = 0,
                     variants: dict | None = None, fields: dict | None = None) -> Path:
    """Simulate a test record and write it as CSV (``time``, ``Unit:`` row, the inputs,
    the noisy channels).

    Parameters
    ----------
    params : Parameters
        The parameter set; ``truth`` overrides values in it (the actuator "as built").
    path : str or Path
        The CSV file written.
    t_end : float
        Duration (s).
    x_cmd, f_ext : Signal, float or str
        Rod command (m) and external force (N), sampled at ``rate`` into the record.
    channels : sequence of str
        Model states or outputs recorded.
    truth : dict, optional
        Flat parameter name -> true value (SI).
    noise : dict, optional
        Channel -> noise standard deviation (SI); default :data:`SENSOR_NOISE`.
    rate : float
        Sample rate (Hz).
    seed : int
        Seed of the noise.
    variants : dict, optional
        Variant overrides of the model.
    fields : dict, optional
        File-level fields written as ``# NAME: VALUE`` lines (a time stamp).
    """
    model = build_model(params, variants)
    pv = params.vector(**(truth or {}))
    n = int(round(t_end * rate))
    t = np.arange(n + 1) / rate
    sampled = {}
    for name, value in (("x_cmd", x_cmd), ("f_ext", f_ext)):
        kind = model.input_info[name].kind
        s = parse_signal(value, kind, stroke=params.actuator.stroke, duration=t_end) if isinstance(value, str) \
            else _as_signal(value, name, kind)
        sampled[name] = s(t)
    tables = {k: Signal.table(t, v) for k, v in sampled.items()}
    res = simulate(model, t[-1], solver="rosenbrock", dt=1.0 / rate, p=pv, rtol=1e-10, atol=1e-13, **tables)
    rng = np.random.default_rng(seed)
    sig = {**SENSOR_NOISE, **(noise or {})}
    cols = {**sampled, **{c: res[c] + rng.normal(0.0, sig[c], len(res.t)) for c in channels}}
    units = model.units
    lines = [f"# {k}: {v}" for k, v in (fields or {}).items()]
    lines += ["time," + ",".join(cols), "Unit:," + ",".join(units[c] for c in cols)]
    data = np.column_stack([res.t, *cols.values()])
    lines += [",".join(repr(float(v)) for v in row) for row in data]
    return write_text(path, "\n".join(lines) + "\n")
