"""Samples left out of a fit (``identify(unsettled="leave-out")``, a record's
``left_out`` marks): they weigh nothing in the fit and its statistics, records without
chaotic bursts lose none, and the witness rig's chaotic bursts are the ones found."""

from __future__ import annotations

import dataclasses
import subprocess
import sys

import matplotlib.pyplot as plt
import numpy as np
import pytest

import ema_casadi as ema
from conftest import ROOT
from ema_casadi.identification import IdentificationError, example_records, read_record
from ema_casadi.identification._fitting import new_fit
from ema_casadi.identification._plot import fit_figure
from ema_casadi.identification._problem import free_parameters
from ema_casadi.identification._unsettled import MARGIN_S, unsettled
from ema_casadi.model.assembly import build_model

SIGMA = {"x_rod": 3e-7, "i_q": 0.05}


@pytest.fixture(scope="module")
def example(tmp_path_factory):
    p = ema.load_parameters()
    paths, truth = example_records(p, tmp_path_factory.mktemp("unsettled"))
    model = build_model(p)
    return p, [read_record(x, model) for x in paths], list(truth)


def test_a_window_left_out_weighs_nothing(example):
    """100 samples of one record's rod position corrupted by 50 noise levels and marked
    left out: the fit is the one of the clean records with the same marks, bit for bit
    (the residuals there are zero whatever was measured), and the chi-square counts
    the samples kept (the first sample fixes the start and is never counted); the
    marks are reported, shaded in the record's figure, and kept when the fit also
    searches for unsettled samples."""
    p, recs, free = example
    rec = recs[0]
    bad = np.zeros(rec.n, bool)
    bad[rec.n // 3 : rec.n // 3 + 100] = True
    shifted = {**rec.channels, "x_rod": rec.channels["x_rod"] + np.where(bad, 50 * SIGMA["x_rod"], 0.0)}
    clean = [dataclasses.replace(rec, left_out={"x_rod": bad}), *recs[1:]]
    dirty = [dataclasses.replace(rec, channels=shifted, left_out={"x_rod": bad}), *recs[1:]]
    a = ema.identify(p, clean, free, sigma=SIGMA, consistency=False)
    b = ema.identify(p, dirty, free, sigma=SIGMA, consistency=False)
    assert a.estimate == b.estimate and a.info["cost"] == b.info["cost"]
    (row,) = [c for c in b.channels if c["record"] == rec.path and c["channel"] == "x_rod"]
    assert row["samples"] == rec.n - 1 - 100
    assert b.adequacy["adequate"]
    (window,) = b.info["unsettled"]["channels"]  # the records' own marks, reported
    assert window["samples"] == 100 and window["windows"] == [[rec.t[rec.n // 3], rec.t[rec.n // 3 + 99]]]
    # searched for unsettled samples too (the example has none): the records' own marks stay
    c = ema.identify(p, clean, free, sigma=SIGMA, consistency=False, unsettled="leave-out")
    assert c.estimate == a.estimate and c.info["unsettled"]["samples"] == 100
    fig = fit_figure(b, 0)  # the window shaded on the rod position and its residuals
    assert len([ax for ax in fig.axes if ax.patches]) == 2
    plt.close(fig)


def test_records_without_chaotic_bursts_lose_nothing(example):
    """The example's records (no stick-slip burst): the predictions at rtol 1e-8 and
    1e-10 agree to the noise everywhere, nothing is left out, and the fit is the plain
    one bit for bit."""
    p, recs, free = example
    plain = ema.identify(p, recs, free, sigma=SIGMA, consistency=False)
    left = ema.identify(p, recs, free, sigma=SIGMA, consistency=False, unsettled="leave-out")
    assert left.info["unsettled"]["samples"] == 0 and left.info["unsettled"]["channels"] == []
    assert left.estimate == plain.estimate
    assert "unsettled" not in plain.info


def test_bad_unsettled_refused(example):
    """An unknown mode, and marks of a record that are not one boolean per sample of a
    channel it measures: one line, before any fit."""
    p, recs, free = example
    with pytest.raises(IdentificationError, match="unsettled: expected one of keep, leave-out"):
        ema.identify(p, recs, free, unsettled="drop")
    rec = recs[0]
    for marks, what in (({"F_in": np.zeros(rec.n, bool)}, "not a channel"),
                        ({"x_rod": np.zeros(rec.n - 1, bool)}, "booleans, one per sample")):
        with pytest.raises(IdentificationError, match=what):
            ema.identify(p, [dataclasses.replace(rec, left_out=marks), *recs[1:]], free)


def test_the_hump_rigs_chaotic_burst_is_found():
    """The exponential-hump witness rig's push record at its true parameters: the
    load-cell predictions at rtol 1e-8 and 1e-10 part by more than a third of the noise
    in the burst after the slew back (measured: 0.657-0.78 s with the +-20 ms margin),
    and nowhere before the first slew ends (0.3 s). The same record of
    the control rig (the model's own Gaussian hump) has no such burst."""
    sys.path.insert(0, str(ROOT / "studies"))
    import witness

    found = {}
    for rig in ("hump", "gauss"):
        variants, extra = witness.STRUCTURE[rig]
        p = ema.load_parameters().replace(**extra)
        model = build_model(p, variants)
        (push,) = [r for r in witness.realisation(witness.clean_records(rig, p), 0) if r.path == "push.csv"]
        fr = free_parameters(model, list(witness.TRUTH))
        fit = new_fit(model, [push], fr, (), witness.NOISE, 2, False)
        (marks,) = unsettled(fit, fr.z(np.array([witness.TRUTH[n] for n in fr.names])), witness.NOISE)
        found[rig] = marks["F_in"]
    t = push.t
    hump = found["hump"]
    inside = (t > 0.686) & (t < 0.734)
    assert hump[inside].mean() > 0.5
    assert not hump[t < 0.3].any()
    assert hump.mean() < 0.2  # measured 0.158: one window, 0.657 s to the record's end (0.78 s)
    edges = np.flatnonzero(np.diff(hump.astype(int)))
    assert np.all(np.diff(edges)[::2] >= 2 * MARGIN_S / (t[1] - t[0]))  # each window at least the margins wide
    assert not found["gauss"][(t > 0.6) & (t < 0.8)].any()


def test_leave_out_with_compare_is_refused(tmp_path):
    """``--unsettled leave-out`` with ``--compare`` is refused (each structure would
    leave out its own samples): exit 2, one line, nothing written."""
    cmd = ["identify", "r.csv", "--free", "F_seal", "--compare", "stribeck=off,on", "--unsettled", "leave-out",
           "--out", str(tmp_path / "f.toml")]
    out = subprocess.run([sys.executable, "-m", "ema_casadi.cli", *cmd], capture_output=True, text=True, cwd=tmp_path)
    assert out.returncode == 2
    assert "--unsettled" in out.stderr and len(out.stderr.strip().splitlines()) == 1
    assert not list(tmp_path.iterdir())
