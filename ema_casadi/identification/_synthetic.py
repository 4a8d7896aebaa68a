"""Records made by the toolkit itself, for tests, benchmarks and the worked example:
the model with chosen "true" parameters, driven by commands sampled at the record's
rate (the table a rig logs, so that the fit, which interpolates the logged command,
sees the very input that made the record), solved by the compiled RODAS4 at tight
tolerances, with seeded Gaussian sensor noise added."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._util._files import write_text
from ..model.assembly import build_model
from ..signals import Signal, parse_signal
from ..simulation import as_signal, simulate
from ._records import IdentificationError

__all__ = ["SENSOR_NOISE", "synthetic_record", "example_records", "EXAMPLE_TRUTH", "recovery_records",
           "RECOVERY_TRUTH", "guide_records", "TREND_TRUTH", "GUIDE_FILES"]

#: The worked example's actuator "as built": seal friction +40 %, viscous friction +50 %,
#: rotor inertia +25 %, flux linkage -20 % against the reference set.
EXAMPLE_TRUTH = {"F_seal": 210.0, "c_v": 300.0, "J_m": 1.5e-3, "psi": 0.24}

#: The seven-parameter recovery case: 20-100 % from the reference set (seal friction
#: +50 %, bearing friction +40 %, viscous friction +100 %, backlash +30 %, stiffness -20 %,
#: rotor inertia +20 %, flux linkage -20 %).
RECOVERY_TRUTH = {"F_seal": 225.0, "C_bear": 4.2e-5, "c_v": 400.0, "B": 2.6e-5, "C": 1.92e8, "J_m": 1.44e-3,
                  "psi": 0.24}

#: The recovery case's four records: name -> (duration s, rod command, load).
RECOVERY_RECORDS = {
    "steps": (3.0, "step:2mm@0.1+step:-4mm@1.0+step:2mm@2.0", 0.0),
    "chirp": (4.0, "chirp:0.5mm@0.5-25", 0.0),
    "slews_push": (3.0, "step:5mm@0.3+step:-10mm@1.3+step:5mm@2.3", "step:8kN@0.1"),
    "slews_pull": (2.5, "step:-5mm@0.3+step:10mm@1.2+step:-5mm@2.0", "step:-15kN@0.1"),
}

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
    for role in ("command", "load"):  # a record holds the rod's command and load
        model.needs_input(role, "a record of the rod (synthetic_record)", IdentificationError)
    pv = params.vector(**(truth or {}))
    n = int(round(t_end * rate))
    t = np.arange(n + 1) / rate
    sampled = {}
    for name, value in (("x_cmd", x_cmd), ("f_ext", f_ext)):
        kind = model.input_info[name].kind
        s = parse_signal(value, kind, stroke=params.actuator.stroke, duration=t_end) if isinstance(value, str) \
            else as_signal(value, name, kind)
        sampled[name] = s(t)
    tables = {k: Signal.table(t, v) for k, v in sampled.items()}
    res = simulate(model, t[-1], solver="rosenbrock", dt_out=1.0 / rate, p=pv, rtol=1e-10, atol=1e-13, **tables)
    rng = np.random.default_rng(seed)
    sig = {**SENSOR_NOISE, **(noise or {})}
    cols = {**sampled, **{c: res[c] + rng.normal(0.0, sig[c], len(res.t)) for c in channels}}
    units = model.units
    lines = [f"# {k}: {v}" for k, v in (fields or {}).items()]
    lines += ["time," + ",".join(cols), "Unit:," + ",".join(units[c] for c in cols)]
    data = np.column_stack([res.t, *cols.values()])
    lines += [",".join(repr(float(v)) for v in row) for row in data]
    return write_text(path, "\n".join(lines) + "\n")


def example_records(params, folder, truth: dict | None = None, seed: int = 0) -> tuple[list, dict]:
    """The worked example's two records (1 s each at 2 kHz, rod position and q-current
    with :data:`SENSOR_NOISE`): steps of +1 mm and -2 mm, and a 0.5 mm chirp 1-20 Hz
    with a 5 kN load step; written into ``folder``.

    Parameters
    ----------
    params : Parameters
        The reference set.
    folder : str or Path
        Where the CSV files go.
    truth : dict, optional
        The true values (default :data:`EXAMPLE_TRUTH`).
    seed : int
        Seed of the noise.

    Returns
    -------
    paths, truth : list of Path, dict
    """
    truth = dict(EXAMPLE_TRUTH if truth is None else truth)
    folder = Path(folder)
    steps = synthetic_record(params, folder / "steps.csv", t_end=1.0, x_cmd="step:1mm@0.05+step:-2mm@0.5",
                             truth=truth, seed=seed)
    chirp = synthetic_record(params, folder / "chirp_loaded.csv", t_end=1.0, x_cmd="chirp:0.5mm@1-20",
                             f_ext="step:5kN@0.1", truth=truth, seed=seed + 1)
    return [steps, chirp], truth


def recovery_records(params, folder, truth: dict | None = None, seed: int = 0,
                     channels=("x_rod", "i_q")) -> tuple[list, dict]:
    """The seven-parameter recovery case (benchmark and slow tests): four records at
    2 kHz of 2.5-4 s (steps, a 0.5 mm chirp 0.5-25 Hz, slews of +-5 mm under +8 kN and
    -15 kN), rod position and q-current with :data:`SENSOR_NOISE`.

    Parameters
    ----------
    params : Parameters
        The reference set.
    folder : str or Path
        Where the CSV files go.
    truth : dict, optional
        The true values (default :data:`RECOVERY_TRUTH`).
    seed : int
        Seed of the noise (record k uses seed + k).
    channels : sequence of str
        The channels recorded.

    Returns
    -------
    paths, truth : list of Path, dict
    """
    truth = dict(RECOVERY_TRUTH if truth is None else truth)
    paths = []
    for k, (name, (t_end, x_cmd, f_ext)) in enumerate(RECOVERY_RECORDS.items()):
        paths.append(synthetic_record(params, Path(folder) / f"{name}.csv", t_end=t_end, x_cmd=x_cmd, f_ext=f_ext,
                                      truth=truth, seed=seed + k, channels=channels))
    return paths, truth


#: The health-trend records of :func:`guide_records`: flight hours -> seal friction F_seal
#: (N), 150 N new, +0.05 N per flight hour (the 300 N limit crossed at 3000 h).
TREND_TRUTH = {0: 150.0, 500: 175.0, 1000: 200.0, 1500: 225.0}
#: The files :func:`guide_records` writes (``ema identify --example-records DIR``).
GUIDE_FILES = (*(f"{name}.csv" for name in RECOVERY_RECORDS), *(f"rig_{h:04d}h.csv" for h in TREND_TRUTH))


def guide_records(params, folder) -> tuple[list, dict]:
    """The records the identification guide fits (``ema identify --example-records``):
    the seven-parameter case of :func:`recovery_records` and four 0.5 s records of a
    health trend, ``rig_<hours>h.csv`` with a ``# flight_hours`` field and the seal
    friction of :data:`TREND_TRUTH`, each with sensor noise of its own seed.

    Parameters
    ----------
    params : Parameters
        The reference set.
    folder : str or Path
        Where the CSV files go (:data:`GUIDE_FILES`).

    Returns
    -------
    paths, truth : list of Path, dict
        The files and the truth of the seven-parameter case (the trend's: :data:`TREND_TRUTH`).
    """
    paths, truth = recovery_records(params, folder)
    for h, f_seal in TREND_TRUTH.items():
        paths.append(synthetic_record(params, Path(folder) / f"rig_{h:04d}h.csv", t_end=0.5, x_cmd="step:1mm@0.02",
                                      truth={"F_seal": f_seal}, seed=h, fields={"flight_hours": h}))
    return paths, truth
