"""Frequency-domain records: a rig's measured frequency response (``freq_hz``,
``gain_db``, ``phase_deg``) of a named input/output pair, fitted through the linear
model at the record's operating point.

Why the linear model and not the sine stream: a rig's frequency response is taken at
small amplitude around an operating point, which is what the exact AD linearisation
describes, in milliseconds per evaluation; the nonlinear sine stream would need a
settled simulation per frequency and a first-harmonic extraction for every evaluation
and every parameter difference. What the linearisation excludes by its small-signal
policy (Coulomb friction, backlash) the fit cannot see: those parameters come out not
identifiable, as they should. The Jacobian is by forward differences of the
linearisation (a handful of parameters, each evaluation a trim and a linearisation).

Record layout (CSV): header ``freq_hz,gain_db,phase_deg``; file-level fields name the
pair and the operating point: ``# input: x_cmd``, ``# output: x_rod`` (the defaults),
``# f_ext: 10000`` (N) and ``# x_cmd: 0``; ``# sigma_gain_db`` and
``# sigma_phase_deg`` give the noise levels (else estimated from the residuals).
"""

from __future__ import annotations

import math
import time

import numpy as np

from .._util._checks import nearest
from ..model.assembly import build_model
from ..model.components import SIGNAL_KEYS
from ..optimisation import levenberg_marquardt
from ..signals import SignalError, table_rows
from ._problem import free_parameters
from ._records import IdentificationError, Record, _fields
from ._result import IdentResult, uncertainty

COLUMNS = ("freq_hz", "gain_db", "phase_deg")
#: Forward-difference step of the Jacobian (in optimiser coordinates: log-parameters).
DIFF_STEP = 1e-6


def is_frequency_record(path) -> bool:
    """True when a CSV file's header starts with ``freq_hz``.

    Parameters
    ----------
    path : str or Path
        The file.
    """
    try:
        rows = table_rows(path)
    except SignalError:
        return False
    return bool(rows) and rows[0][1][0].strip().lower().startswith("freq_hz")


def read_frequency_record(path, model) -> Record:
    """A frequency-response record as a :class:`Record` whose ``t`` is the frequency
    (Hz) and whose channels are ``gain_db`` and ``phase_deg``; the pair and operating
    point in ``fields``.

    Parameters
    ----------
    path : str or Path
        The CSV file (module docstring).
    model : Model
        The model (the pair's names are checked against it).
    """
    from pathlib import Path

    path = Path(path)
    rows = table_rows(path)
    if not rows:
        raise IdentificationError(f"{path}: empty frequency record")
    first = [c.strip() for c in rows[0][1]]
    if first[:3] != list(COLUMNS):
        raise IdentificationError(f"{path}: expected the columns {', '.join(COLUMNS)}, got {', '.join(first)}")
    data = np.array([_row(path, line, r) for line, r in rows[1:]], float).reshape(-1, 3)
    if len(data) < 2:
        raise IdentificationError(f"{path}: expected at least two rows ({', '.join(COLUMNS)}), got {len(data)}")
    lines = [line for line, _ in rows[1:]]
    for k, f in enumerate(data[:, 0]):
        if f <= 0 or (k and f <= data[k - 1, 0]):
            raise IdentificationError(f"{path}: line {lines[k]}: freq_hz {f:g}: frequencies must be positive and "
                                      "increasing" + (f" (the row before has {data[k - 1, 0]:g})" if k else ""))
    fields = _fields(path.read_text(encoding="utf-8-sig"))
    fields.setdefault("input", model.input_with("command"))
    fields.setdefault("output", model.output_with("rod_position"))
    if fields["input"] not in model.inputs:
        raise IdentificationError(f"{path}: input '{fields['input']}' is not a model input"
                                  f"{nearest(str(fields['input']), model.inputs)}")
    if fields["output"] not in model.outputs:
        raise IdentificationError(f"{path}: output '{fields['output']}' is not a model output"
                                  f"{nearest(str(fields['output']), model.outputs)}")
    return Record(str(path), data[:, 0], {}, {"gain_db": data[:, 1], "phase_deg": data[:, 2]}, fields)


def _row(path, line, cells) -> list[float]:
    """One row's three numbers; a cell that is not a finite number is named with its
    line, column and value."""
    if len(cells) < 3:
        raise IdentificationError(f"{path}: line {line}: expected three numbers ({', '.join(COLUMNS)}), got "
                                  f"{len(cells)} cells")
    out = []
    for name, c in zip(COLUMNS, cells[:3], strict=True):
        try:
            v = float(c)
        except ValueError:
            v = math.nan
        if not math.isfinite(v):
            raise IdentificationError(f"{path}: line {line}: {name} '{c.strip()}' is not a finite number")
        out.append(v)
    return out


def _response(model, rec: Record, pv) -> dict:
    from ..frequency import bode
    from ..linearisation import linear_model, operating_point

    # the record's operating point: its '# x_cmd:' and '# f_ext:' fields (the keys of the roles)
    op = operating_point(model, inputs={r: float(rec.fields.get(SIGNAL_KEYS[r], 0.0)) for r in ("command", "load")},
                         p=pv)
    lin = linear_model(model, op, inputs=[rec.fields["input"]], outputs=[rec.fields["output"]])
    b = bode(lin, rec.t)
    return {"gain_db": b["mag_db"], "phase_deg": b["phase_deg"]}


def _errors(model, recs, pv) -> dict:
    e = {}
    for i, rec in enumerate(recs):
        y = _response(model, rec, pv)
        e[i, "gain_db"] = rec.channels["gain_db"] - y["gain_db"]
        e[i, "phase_deg"] = (rec.channels["phase_deg"] - y["phase_deg"] + 180.0) % 360.0 - 180.0
    return e


def _given(recs, sigma) -> dict:
    """Noise levels given: the argument's, else the records' fields if all give them."""
    given = dict(sigma or {})
    for c in ("gain_db", "phase_deg"):
        vals = [r.fields.get(f"sigma_{c}") for r in recs]
        if c not in given and all(isinstance(v, float) for v in vals):
            given[c] = float(np.mean(vals))
    return given


def identify_frequency(params, records, free, *, sigma: dict | None = None, variants: dict | None = None,
                       max_evaluations: int = 40) -> IdentResult:
    """Fit named parameters to measured frequency responses through the linear model.

    Parameters
    ----------
    params : Parameters
        The parameter set (the start, and everything not free).
    records : sequence of str or Path
        Frequency-response CSV files (module docstring).
    free : sequence of str
        Parameters to fit.
    sigma : dict, optional
        ``gain_db`` / ``phase_deg`` -> noise level (dB, deg); else the records' fields,
        else estimated from the residuals.
    variants : dict, optional
        Variant overrides of the model.
    max_evaluations : int
        Jacobian evaluations at most (each n + 1 linearisations per record).
    """
    t_wall = time.perf_counter()
    model = build_model(params, variants)
    recs = [read_frequency_record(r, model) for r in records]
    fr = free_parameters(model, free)
    base = model.p()
    given = _given(recs, sigma)

    def pv_of(z):
        pv = base.copy()
        pv[fr.index] = fr.theta(z)
        return pv

    def weighted(e, sig):
        keys = sorted(e)
        return np.concatenate([e[k] / sig[k[1]] for k in keys]), keys

    sig = {c: given.get(c, 1.0) for c in ("gain_db", "phase_deg")}
    n_eval = [0]

    def evaluate(z):
        try:
            e0 = _errors(model, recs, pv_of(z))
            r0, keys = weighted(e0, sig)
            J = np.empty((len(r0), len(z)))
            for j in range(len(z)):
                dz = np.zeros(len(z))
                dz[j] = DIFF_STEP
                J[:, j] = (weighted(_errors(model, recs, pv_of(z + dz)), sig)[0] - r0) / DIFF_STEP
        except Exception:  # noqa: BLE001 - a trim or linearisation that fails: a point the optimiser avoids
            return None, None
        n_eval[0] += 1
        return r0, J

    z = np.zeros(len(fr.names))
    lo, hi = fr.z_bounds()
    estimate = [c for c in sig if c not in given]
    for _round in range(4):
        sol = levenberg_marquardt(evaluate, z, lo, hi, max_evaluations)
        if not sol["converged"]:
            from ._fit import FitFailed

            raise FitFailed(f"frequency fit did not converge ({sol['message']})")
        z = sol["z"]
        if not estimate:
            break
        e = _errors(model, recs, pv_of(z))
        new = {c: float(np.sqrt(np.mean(np.concatenate([e[k] for k in e if k[1] == c]) ** 2))) for c in estimate}
        change = max(abs(new[c] / sig[c] - 1) for c in estimate)
        sig.update(new)
        if change < 0.02:
            break
    r, J = evaluate(z)
    e = _errors(model, recs, pv_of(z))
    unc = uncertainty(fr, z, J, r, bool(estimate))
    preds = [{"y": {c: rec.channels[c] - e[i, c] for c in rec.channels}} for i, rec in enumerate(recs)]
    out = {"sigma": sig, "estimated": estimate, "cost": 0.5 * float(r @ r), "message": sol["message"]}
    return IdentResult._build(model=model, params=params, free=fr, theta=fr.theta(z), unc=unc, out=out,
                              records=recs, preds=preds, errors=e, held={},
                              wall_time=time.perf_counter() - t_wall, evaluations=n_eval[0],
                              start=dict(zip(fr.names, fr.theta0.tolist(), strict=True)))
