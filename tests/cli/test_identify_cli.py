"""``ema identify``: a mistake -> exit 2 and one line naming it, nothing
written; a fit that does not converge -> exit 3, one line, no fitted file; plain
``ema identify`` (the built-in example) succeeds and writes what it is asked to."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

import ema_casadi as ema
from conftest import REFERENCE
from ema_casadi import identification as idn
from ema_casadi.cli import main

REF = str(REFERENCE)
GOOD = "time,x_cmd,x_rod\nUnit:,m,m\n0,0,0\n0.0005,0,1e-7\n0.001,0,-1e-7\n"


@pytest.fixture(scope="module")
def record(params, tmp_path_factory):
    """A short record (0.3 s) of a 1 mm step, seal friction +40 %."""
    d = tmp_path_factory.mktemp("rec")
    return idn.synthetic_record(params, d / "step.csv", t_end=0.3, x_cmd="step:1mm@0.02", truth={"F_seal": 210.0})


def _run(argv, capsys):
    code = main(argv)
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize("content, flags, words", [
    ("x,x_rod\n0,0\n1,0\n", [], ["first column must be the time"]),
    ("time,x_rod\n0,0\n0.001,0\n0.0005,0\n", [], ["increase strictly"]),
    ("time,x_cmd,x_rod [kN]\n0,0,0\n0.001,0,0\n", [], ["x_rod", "kN"]),
    ("time,x_cmd,x_rood\n0,0,0\n0.001,0,0\n", [], ["did you mean 'x_rod'"]),
    ("", [], ["empty"]),
    (GOOD, ["--free", "F_sael"], ["did you mean 'F_seal'"]),
    (GOOD, ["--bounds", "F_seal=300:100"], ["--bounds F_seal", "LO"]),
    (GOOD, ["--bounds", "F_seal=0:100"], ["--bounds F_seal", "log scale"]),
    (GOOD, ["--bounds", "F_seal=1"], ["--bounds", "LO:HI"]),
    (GOOD, ["--sigma", "x_rd=0.3um"], ["--sigma x_rd", "did you mean 'x_rod'"]),
    (GOOD, ["--out", "{tmp}/fit.txt"], ["--out", ".toml"]),
    (GOOD, ["--profile", "c_v"], ["--profile c_v", "not a free parameter"]),
    (GOOD, ["--method", "shooting"], ["method", "'shooting'", "auto, single, multiple, collocation"]),
    (GOOD, ["--method", "collocation", "--nodes", "0"], ["nodes", "at least one per record"]),
])
def test_mistakes_exit_2_with_one_line_and_nothing_written(tmp_path, capsys, content, flags, words):
    rec = tmp_path / "r.csv"
    rec.write_text(content)
    flags = [f.format(tmp=tmp_path) for f in flags]
    free = [] if "--free" in flags else ["--free", "F_seal"]
    code, out, err = _run(["identify", REF, str(rec), *free, *flags, "--out", str(tmp_path / "fit.toml"),
                           "--no-progress"] if "--out" not in flags else
                          ["identify", REF, str(rec), *free, *flags, "--no-progress"], capsys)
    assert code == 2, err
    assert err.count("\n") == 1 and err.startswith("ema identify: error:"), err
    assert all(w in err for w in words), err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.csv"]


def test_a_record_too_large_is_refused_up_front(tmp_path, capsys, monkeypatch, record):
    """The working set (samples x states x directions) against the machine's allowance:
    with the allowance lowered to 10 kB the 0.3 s record is refused before any fit."""
    monkeypatch.setattr(idn._records, "MAX_BYTES", 1e4)
    code, _, err = _run(["identify", REF, str(record), "--free", "F_seal", "--out", str(tmp_path / "f.toml")], capsys)
    assert code == 2 and "GB" in err and err.count("\n") == 1, err
    assert not (tmp_path / "f.toml").exists()


def test_no_free_parameters_named(capsys, record):
    code, _, err = _run(["identify", REF, str(record)], capsys)
    assert code == 2 and "--free" in err


def test_a_fit_that_does_not_converge_exits_3_and_writes_nothing(tmp_path, capsys, record):
    code, out, err = _run(["identify", REF, str(record), "--free", "F_seal,c_v", "--max-evaluations", "2",
                           "--out", str(tmp_path / "fit.toml"), "--report", str(tmp_path / "rep")], capsys)
    assert code == 3, err
    assert err.count("\n") == 1 and "did not converge" in err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("case", ["converged", "inadequate", "not converged", "failed"])
def test_every_exit_prints_one_json_document(tmp_path, capsys, monkeypatch, record, misfit_record, case):
    """--json: whatever the fit's end, one JSON document on stdout with the status, the
    last iterate, the cost history and the reason; exit 0 for a converged adequate
    fit, 3 otherwise with the reason on stderr in one line. "failed": the model run
    fails at the start values (made to fail here). Without --json the text names the
    status and the last iterate."""
    if case == "failed":
        from ema_casadi.simulation import RunFailed

        def fail(self, theta):
            raise RunFailed("x_rod = 0.08 m beyond its envelope", 0.01)

        monkeypatch.setattr(idn._fit._Fit, "errors", fail)
    rec = misfit_record if case == "inadequate" else record
    limit = ["--max-evaluations", "2"] if case == "not converged" else []
    sigma = ["--sigma", "x_rod=0.3um", "--sigma", "i_q=0.05A"]  # given: one weighting, the costs comparable
    argv = ["identify", REF, str(rec), "--free", "F_seal,c_v" if limit else "F_seal", *limit, *sigma,
            "--no-progress"]
    code, out, err = _run([*argv, "--json"], capsys)
    doc = json.loads(out)
    assert code == (0 if case == "converged" else 3), err
    assert doc["status"] == ("converged" if case in ("converged", "inadequate") else case)
    assert doc.get("verdict", case) == {"converged": "adequate"}.get(case, case) and doc["reason"], doc
    assert set(doc["last_iterate"]) == ({"F_seal", "c_v"} if limit else {"F_seal"})
    costs = [h["cost"] for h in doc["cost_history"]]
    assert all(c >= 0 for c in costs) and (costs or case == "failed")
    if case == "converged":
        assert doc["last_iterate"]["F_seal"] == doc["parameters"]["F_seal"]["estimate"] and not err
        assert min(costs) == pytest.approx(doc["cost"], rel=1e-12) and costs[0] > doc["cost"]
    else:
        assert err.count("\n") == 1 and doc["reason"].split(";")[0] in err, err
    if case == "not converged":  # the start and the one step the budget allowed
        assert len(costs) == 2 and "did not converge within 2" in doc["reason"]
    if case == "failed":
        assert "fails at the start values" in doc["reason"] and doc["last_iterate"]["F_seal"] == 150.0
    code, out, err = _run(argv, capsys)
    if case in ("not converged", "failed"):
        assert out.startswith(f"status: {case}\nlast iterate: F_seal = ") and err.count("\n") == 1, out


def test_the_json_names_the_method_that_ran(capsys, record):
    """--method auto on a record single shooting fits: single shooting ran, said so in
    the document (``method`` and what each method tried did)."""
    code, out, err = _run(["identify", REF, str(record), "--free", "F_seal", "--method", "auto", "--json",
                           "--no-progress"], capsys)
    assert code == 0, err
    doc = json.loads(out)
    assert doc["method"] == "single"
    assert doc["methods"] == [{"method": "single", "outcome": "converged"}]


def test_coarse_to_fine_is_in_the_document_and_the_text(capsys, record):
    """--coarse-to-fine: the JSON carries each level's block length, cost and evaluations
    (a 0.3 s record: its 0.2 s level averages one block per channel); the text says it;
    the estimate is the plain fit's within 0.5 of its standard deviation (measured 0.35: with
    the noise levels estimated the stopping rule resolves this cost to about 0.1)."""
    code, out, err = _run(["identify", REF, str(record), "--free", "F_seal", "--coarse-to-fine", "--json",
                           "--no-progress"], capsys)
    assert code == 0, err
    doc = json.loads(out)
    assert [lv["block_s"] for lv in doc["coarse_to_fine"]["levels"]] == [0.2, 0.1, 0.05, 0.025]
    code, plain, err = _run(["identify", REF, str(record), "--free", "F_seal", "--json", "--no-progress"], capsys)
    plain = json.loads(plain)
    a, b = doc["parameters"]["F_seal"], plain["parameters"]["F_seal"]
    assert abs(a["estimate"] - b["estimate"]) < 0.5 * b["std"]
    code, text, err = _run(["identify", REF, str(record), "--free", "F_seal", "--coarse-to-fine", "--no-progress"],
                           capsys)
    assert code == 0 and "coarse to fine: residuals averaged over blocks of 200 ms" in text


def test_a_fit_writes_the_file_and_the_report(tmp_path, capsys, record):
    code, out, err = _run(["identify", str(record), "--free", "F_seal", "--sigma", "x_rod=0.3um",
                           "--sigma", "i_q=0.05A", "--out", str(tmp_path / "fit.toml"),
                           "--report", str(tmp_path / "rep"), "--json", "--no-progress"], capsys)
    assert code == 0, err
    doc = json.loads(out)
    est = doc["parameters"]["F_seal"]
    assert abs(est["estimate"] - 210.0) <= 3 * est["std"] and est["identifiable"]
    assert doc["sigma"] == {"x_rod": 3e-7, "i_q": 0.05} and doc["sigma_estimated"] == []
    assert sorted(p.name for p in (tmp_path / "rep").iterdir()) == ["fit_0.png", "intervals.png", "misfit.png",
                                                                   "summary.json", "summary.md"]
    assert "F_seal = { value = " + repr(est["estimate"]) in (tmp_path / "fit.toml").read_text()


def test_plain_identify_runs_the_example(capsys):
    code, out, err = _run(["identify", "--json", "--no-progress"], capsys)
    assert code == 0, err
    doc = json.loads(out)
    for n, v in doc["example"]["truth"].items():
        d = doc["parameters"][n]
        assert abs(d["estimate"] - v) <= 3 * d["std"], n


@pytest.fixture(scope="module")
def misfit_record(params, tmp_path_factory):
    """A record whose rotor inertia is +25 % while the fit may move only F_seal: the
    model cannot explain it."""
    d = tmp_path_factory.mktemp("misfit")
    return idn.synthetic_record(params, d / "m.csv", t_end=0.3, x_cmd="step:1mm@0.02",
                                truth={"F_seal": 210.0, "J_m": 1.5e-3})


def test_an_inadequate_fit_exits_3_and_says_so_in_the_file_name(tmp_path, capsys, misfit_record):
    code, out, err = _run(["identify", str(misfit_record), "--free", "F_seal", "--out", str(tmp_path / "fit.toml"),
                           "--json", "--no-progress"], capsys)
    # the effect size first: x_rod's running-mean misfit is 11.8 noise levels (the inertia error)
    assert code == 3 and err.count("\n") == 1 and "inadequate fit" in err and "systematic misfit" in err, err
    assert "x_rod" in err and "sigma" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fit.inadequate.toml"]
    doc = json.loads(out)
    assert doc["adequate"] is False and doc["verdict"] == "inadequate"
    assert any("not white" in m for m in doc["misfit"])  # the statistical tests stay listed
    assert doc["model_error"]["largest_sigma"] > 5
    assert "INADEQUATE FIT" in (tmp_path / "fit.inadequate.toml").read_text()


def test_a_tolerated_model_error_exits_0_and_names_it(tmp_path, capsys, misfit_record):
    """--model-error above the misfit's 11.8 noise levels (above the ceiling of 10, so
    confirmed by --allow-misfit): adequate within model error, status 0, the fitted file
    under its own name, the misfit named in the JSON."""
    code, out, err = _run(["identify", str(misfit_record), "--free", "F_seal", "--out", str(tmp_path / "fit.toml"),
                           "--json", "--no-progress", "--model-error", "20", "--allow-misfit"], capsys)
    doc = json.loads(out)
    assert code == 0 and doc["verdict"] == "adequate within model error" and doc["adequate"] is True, err
    assert doc["model_error"]["threshold_sigma"] == 20 and doc["model_error"]["misfits"][0]["channel"] == "x_rod"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fit.toml"]
    assert "ADEQUATE WITHIN MODEL ERROR" in (tmp_path / "fit.toml").read_text()
    for bad in ("0", "-1", "nan"):
        code, _, err = _run(["identify", str(misfit_record), "--free", "F_seal", "--model-error", bad], capsys)
        assert code == 2 and err.count("\n") == 1 and "--model-error" in err, err


def test_allow_misfit_warns_and_succeeds(tmp_path, capsys, misfit_record):
    code, out, err = _run(["identify", str(misfit_record), "--free", "F_seal", "--out", str(tmp_path / "fit.toml"),
                           "--allow-misfit", "--no-progress"], capsys)
    assert code == 0 and err.startswith("ema identify: warning: inadequate fit") and err.count("\n") == 1, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fit.toml"]


@pytest.mark.parametrize("argv", [["--help"], ["identify", "--help"]])
def test_help(argv, capsys):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 0 and "identify" in capsys.readouterr().out


def test_track_writes_the_trend(params, tmp_path, capsys):
    """Three records stamped 0, 1000, 2000 h (seal friction 150, 200, 250 N): the trend
    report, with the crossing of 300 N predicted."""
    recs = [str(idn.synthetic_record(params, tmp_path / f"r{h}.csv", t_end=0.3, x_cmd="step:1mm@0.02",
                                     truth={"F_seal": 150.0 + 0.05 * h}, seed=h, fields={"flight_hours": h}))
            for h in (0, 1000, 2000)]
    code, out, err = _run(["identify", "--track", *recs, "--free", "F_seal", "--limit", "F_seal=300N",
                           "--report", str(tmp_path / "trend"), "--json", "--no-progress"], capsys)
    assert code == 0, err
    doc = json.loads(out)
    assert [r["stamp"] for r in doc["records"]] == [0.0, 1000.0, 2000.0]
    a, b = doc["trend"]["F_seal"]["crossing_interval"]
    assert a <= 3000.0 <= b
    assert sorted(p.name for p in (tmp_path / "trend").iterdir()) == ["trend.json", "trend.png"]


@pytest.mark.parametrize("flags, words", [
    (["--compare", "anti_windop=clamping"], ["did you mean 'anti_windup'"]),
    (["--compare", "anti_windup=clamp"], ["did you mean 'clamping'"]),
    (["--compare", "anti_windup=backcalc,clamping", "--compare", "limit_shape=clip,smooth", "--max-fits", "3"],
     ["--max-fits"]),
    (["--compare", "anti_windup"], ["KEY=V1,V2"]),
    (["--compare", "anti_windup=backcalc,clamping", "--compare", "limit_shape=clip,smooth", "--compare",
      "friction_shape=tanh,fermi", "--compare", "stribeck=off,on"], ["16 combinations", "--max-fits 8"]),
    (["--estimate-x0", "omgea"], ["--estimate-x0 omgea", "did you mean 'omega'"]),
    (["--starts", "2", "--jobs", "0"], ["--jobs"]),
])
def test_compare_mistakes_exit_2(tmp_path, capsys, record, flags, words):
    code, _, err = _run(["identify", str(record), "--free", "F_seal", *flags, "--out", str(tmp_path / "f.toml")],
                        capsys)
    assert code == 2 and err.count("\n") == 1 and all(w in err for w in words), err
    assert list(tmp_path.iterdir()) == []


def test_compare_report_has_the_residuals_side_by_side(tmp_path, capsys, record):
    code, out, err = _run(["identify", str(record), "--free", "F_seal", "--compare", "anti_windup=backcalc,clamping",
                           "--report", str(tmp_path / "rep"), "--json", "--no-progress"], capsys)
    assert code in (0, 3), err
    names = sorted(p.name for p in (tmp_path / "rep").iterdir())
    assert "comparison.png" in names and "summary.json" in names
    assert len(json.loads(out)["comparison"]) == 2


def test_a_clamping_ecu_is_inadequate_by_default_and_found_by_compare(params, tmp_path, capsys):
    """Records of an ECU with clamping anti-windup and a 0.02 W efficiency switch (5 mm
    and 10 mm steps, the loops saturating), fitted with the default structure: exit 3,
    chi-square and whiteness both fail, the file written as inadequate. Compared over
    anti_windup: clamping first and adequate (the switch width left at the file's
    0.1 W), its estimates within 3 sigma of the truth (measured: F_seal 209.0 +- 0.67
    for 210), exit 0, the file written under its own name."""
    truth = {"F_seal": 210.0, "J_m": 1.44e-3}
    rec = idn.synthetic_record(params, tmp_path / "sat.csv", t_end=0.6, x_cmd="step:5mm@0.05+step:-10mm@0.3",
                               truth={**truth, "P_blend": 0.02}, seed=1, variants={"anti_windup": "clamping"})
    base = ["identify", str(rec), "--free", "F_seal,J_m", "--sigma", "x_rod=0.3um", "--sigma", "i_q=0.05A",
            "--json", "--no-progress"]
    code, out, err = _run([*base, "--out", str(tmp_path / "f.toml")], capsys)
    reasons = json.loads(out)["misfit"]
    assert code == 3 and err.count("\n") == 1 and (tmp_path / "f.inadequate.toml").exists()
    assert any("chi-square" in r for r in reasons) and any("not white" in r for r in reasons)
    code, out, err = _run([*base, "--compare", "anti_windup=backcalc,clamping", "--out", str(tmp_path / "g.toml")],
                          capsys)
    doc = json.loads(out)
    assert code == 0, err
    assert doc["chosen"] == {"anti_windup": "clamping"} and doc["adequate"] is True
    for n, v in truth.items():
        assert abs(doc["parameters"][n]["estimate"] - v) <= 3 * doc["parameters"][n]["std"], n
    assert (tmp_path / "g.toml").exists()


def test_example_records_refused_where_they_cannot_go(tmp_path, capsys):
    """--example-records names a new folder, and writes records, never fits them."""
    (tmp_path / "rec").mkdir()
    code, _, err = _run(["identify", "--example-records", str(tmp_path / "rec")], capsys)
    assert code == 2 and "--example-records" in err and "exists" in err and err.count("\n") == 1, err
    code, _, err = _run(["identify", "a.csv", "--example-records", str(tmp_path / "new")], capsys)
    assert code == 2 and "a.csv given too" in err and not (tmp_path / "new").exists(), err


@pytest.mark.slow
def test_example_records_are_what_the_guide_fits(tmp_path, capsys):
    """The guide's records: the four of the seven-parameter case and the four of the
    health trend, whose fit crosses the 300 N limit where the truth does (150 N +
    0.05 N/h: 3000 h) within its 95 % interval."""
    rec = tmp_path / "rec"
    code, out, err = _run(["identify", "--example-records", str(rec), "--json"], capsys)
    assert code == 0, err
    assert sorted(p.name for p in rec.iterdir()) == sorted(idn.GUIDE_FILES)
    code, out, err = _run(["identify", "--track", *[str(rec / f"rig_{h:04d}h.csv") for h in (0, 500, 1000, 1500)],
                           "--free", "F_seal", "--limit", "F_seal=300N", "--json", "--no-progress"], capsys)
    assert code == 0, err
    lo, hi = json.loads(out)["trend"]["F_seal"]["crossing_interval"]
    assert lo <= 3000.0 <= hi


def test_a_structural_range_widens_the_intervals(tmp_path, capsys, record):
    """--structural P_blend=0.05:0.2: the JSON names the range and each parameter's
    type-B sd, and F_seal's interval is wider than without it (the estimate the same);
    a malformed or impossible range is refused in one line (exit 2) before any fit."""
    base = ["identify", REF, str(record), "--free", "F_seal", "--json", "--no-progress"]
    code, out, err = _run(base, capsys)
    plain = json.loads(out)
    code2, out2, err2 = _run([*base, "--structural", "P_blend=0.05:0.2"], capsys)
    doc = json.loads(out2)
    assert code == 0 and code2 == 0, (err, err2)
    assert doc["robust"]["structural"]["P_blend"]["range"] == [0.05, 0.2]
    assert doc["robust"]["structural_relative_sd"]["F_seal"] > 0
    a, b = plain["parameters"]["F_seal"]["interval"], doc["parameters"]["F_seal"]["interval"]
    est = plain["parameters"]["F_seal"]["estimate"]
    assert doc["parameters"]["F_seal"]["estimate"] == pytest.approx(est, rel=1e-12)
    assert b[1] - b[0] > a[1] - a[0]
    for bad, words in (("P_blend=0.2:0.3", "strictly inside"), ("P_blend=x", "expected LO:HI"),
                       ("F_seal=1:500", "is free"), ("P_blend=0.3:0.05", "LO must be below HI")):
        code, _, err = _run([*base, "--structural", bad], capsys)
        assert code == 2 and err.count("\n") == 1 and "structural" in err, (bad, err)
        assert words in err, (bad, err)


@pytest.mark.parametrize("value", ["1e6", "10.5"])
def test_a_model_error_above_the_ceiling_needs_its_confirmation(tmp_path, capsys, misfit_record, value):
    # 1e6 called a 61-sigma misfit adequate; the ceiling stops it before the fit, naming the confirmation
    from ema_casadi.identification import MAX_MODEL_ERROR, IdentificationError, check_model_error, identify

    out = tmp_path / "fit.toml"
    code, _, err = _run(["identify", str(misfit_record), "--free", "F_seal", "--out", str(out),
                         "--model-error", value], capsys)
    assert code == 2 and err.count("\n") == 1, err
    assert f"above the ceiling of {MAX_MODEL_ERROR:g}" in err and "--allow-misfit" in err
    assert not out.exists() and not list(tmp_path.iterdir())
    with pytest.raises(IdentificationError, match="model error .* above the ceiling"):
        identify(ema.load_parameters(REFERENCE), [misfit_record], ["F_seal"], model_error=float(value))
    assert check_model_error(float(value), True) == float(value) and check_model_error(MAX_MODEL_ERROR) == 10
    assert f"above {MAX_MODEL_ERROR:g} only with --allow-misfit" in " ".join(
        subprocess.run([sys.executable, "-m", "ema_casadi.cli", "identify", "--help"], capture_output=True,
                       text=True).stdout.split())


@pytest.mark.parametrize("args, words", [
    (("--free", "w_aw"), "free parameter 'w_aw': anti_windup = backcalc does not use it (only clamping)"),
    (("--free", "k_bc", "--variant", "anti_windup=clamping"),
     "free parameter 'k_bc': anti_windup = clamping does not use it (only backcalc)"),
    (("--free", "w_knee"), "free parameter 'w_knee': limit_shape = clip does not use it (only smooth)"),
    (("--free", "F_seal", "--structural", "w_aw=0.005:0.02"),
     "structural 'w_aw': anti_windup = backcalc does not use it (only clamping)"),
])
def test_a_parameter_the_chosen_law_does_not_use_is_refused(tmp_path, capsys, record, args, words):
    # the fit printed "w_aw 0.01 -inf..inf" for a parameter no equation of back-calculation reads
    out = tmp_path / "fit.toml"
    code, _, err = _run(["identify", str(record), *args, "--out", str(out)], capsys)
    assert code == 2 and err.count("\n") == 1 and words in err, err
    assert not list(tmp_path.iterdir())
