"""Witness rigs with real friction (studies/witness.py: an exponential Stribeck hump,
written outside the model's friction code; steps, chirp and loaded speed staircases at
2 kHz with the benchmark's noise): the default structure is not adequate and says
which friction options to try, in the JSON on stdout of the command that fails; the
comparison it names ranks the hump first. Slow: three fits of 7-9 parameters on four
records (about 15 s of CPU each, a minute of wall time on a loaded machine)."""

from __future__ import annotations

import json
import sys

import pytest

from conftest import ROOT
from ema_casadi.cli import main

sys.path.insert(0, str(ROOT / "studies"))
import witness  # noqa: E402

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def hump_files(tmp_path_factory):
    return [str(p) for p in witness.write_records("hump", tmp_path_factory.mktemp("hump"), seed=0)]


def test_default_structure_names_the_friction_options(hump_files, capsys):
    """The default structure (smooth friction, no hump) on the hump rig: exit 3, one JSON
    document on stdout, its hint naming stribeck=on (with r_start, v_st) and
    lugre_smooth, and the comparison's command."""
    code = main(["identify", *hump_files, "--free", ",".join(witness.DEFAULT_FREE), "--json"])
    out, _ = capsys.readouterr()
    assert code == 3
    doc = json.loads(out)
    assert doc["verdict"] == "inadequate"
    (hint,) = doc["hints"]
    assert [c["option"] for c in hint["candidates"]] == ["stribeck=on", "friction=lugre_smooth"]
    assert hint["candidates"][0]["adds"] == ["r_start", "v_st"]
    assert "--compare stribeck=off,on" in hint["text"]


def test_compare_ranks_the_hump_first(params, hump_files):
    """--compare stribeck=off,on with r_start, v_st freed: the hump ranks first (lower BIC);
    whether it is adequate is the study's finding (the exponential hump is not the
    model's Gaussian one), asserted only as reported."""
    from ema_casadi import identification as idn

    cmp = idn.compare(params, hump_files, list(witness.TRUTH), {"stribeck": ["off", "on"]}, sigma=witness.NOISE)
    assert cmp.rows[0]["variants"]["stribeck"] == "on"
    assert cmp.rows[0]["bic"] < cmp.rows[1]["bic"]


def test_coarse_to_fine_reaches_the_truth_where_the_plain_fit_does_not(params):
    """The control rig (the model's own Gaussian hump, transcribed in the study),
    realisation 1, from the reference start with the friction start: fitted on every
    sample the fit stops in the valley (measured: r_start -9.7 %, v_st -19 %, c_v -99 %,
    cost 67 051); coarse to fine with six starts reaches the truth (measured: cost
    17 020, the noise's share; every estimate within 0.05 %, c_v -0.5 %), inside the
    study's tolerances (2 %, c_v and v_st 10 %)."""
    from ema_casadi import identification as idn

    clean = witness.clean_records("gauss")
    recs = witness.realisation(clean, 1)
    kw = {"sigma": witness.NOISE, "variants": {"stribeck": "on"}, "friction_start": "auto"}
    fit = idn.identify(params, recs, list(witness.TRUTH), starts=6, coarse_to_fine=True, **kw)
    err = {k: fit.estimate[k] / v - 1 for k, v in witness.TRUTH.items()}
    assert all(abs(err[k]) <= witness.TOLERANCE[k] for k in err), err
    assert fit.info["coarse_to_fine"]["starts"] == 6
    plain = idn.identify(params, recs, list(witness.TRUTH), **kw)
    assert plain.info["cost"] > 2 * fit.info["cost"]
    assert abs(plain.estimate["r_start"] / witness.TRUTH["r_start"] - 1) > witness.TOLERANCE["r_start"]


def test_leaving_out_the_chaotic_bursts_reaches_the_truth(params):
    """The exponential-hump rig, realisation 0, from the reference start with the
    friction start, six starts and coarse to fine: fitted on every sample it ended in a
    local minimum (one of the four misses of the guide's table, cost 40 800-47 500); with the chaotic
    bursts left out (``unsettled="leave-out"``, measured: 1 083 samples, cost 16 168, the
    kept samples' share of the noise; r_start -0.29 %, v_st +5.2 %, c_v -2.4 %, the rest
    within 0.11 %) every estimate is within the study's tolerances, and the JSON and
    text report name the windows left out."""
    from ema_casadi import identification as idn
    from ema_casadi.cli._identify_text import fit_text

    recs = witness.realisation(witness.clean_records("hump"), 0)
    res = idn.identify(params.replace(delta_st=1.0), recs, list(witness.TRUTH), sigma=witness.NOISE,
                       variants={"stribeck": "on"}, friction_start="auto", starts=6, coarse_to_fine=True,
                       unsettled="leave-out")
    err = {k: res.estimate[k] / v - 1 for k, v in witness.TRUTH.items()}
    assert all(abs(err[k]) <= witness.TOLERANCE[k] for k in err), err
    doc = res.to_dict()
    left = {(c["record"], c["channel"]): c["windows"] for c in doc["unsettled"]["channels"]}
    assert any(a <= 0.70 <= b for a, b in left[("push.csv", "F_in")])
    assert "unsettled samples left out:" in fit_text(doc)
