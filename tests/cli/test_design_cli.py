"""``ema design-experiment``: a mistake -> exit 2 and one line naming it before any
work, nothing written; a small design runs, writes its folder and its --json."""

from __future__ import annotations

import json

import pytest

from conftest import REFERENCE
from ema_casadi.cli import main
from ema_casadi.design import output_names

REF = str(REFERENCE)


def _run(argv, capsys):
    code = main(argv)
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize("flags, words", [
    (["--free", "F_seel"], ["--free", "did you mean 'F_seal'"]),
    (["--duration", "0.5s"], ["--duration", "too short for the lowest frequency"]),
    (["--duration", "2.5s"], ["--duration", "whole number"]),
    (["--criterion", "G"], ["--criterion G", "unknown"]),
    (["--max-load", "60kN"], ["--max-load", "current limit holds"]),
    (["--stroke", "200mm"], ["--stroke", "travel"]),
    (["--weights", "psi_x=1"], ["--weights psi_x", "did you mean 'psi'"]),
    (["--weights", "psi"], ["--weights 'psi'", "NAME=W"]),
    (["--sigma", "omega=0.1"], ["--sigma omega", "not a measured channel"]),
    (["--sigma", "x_rd=1um"], ["--sigma x_rd", "did you mean 'x_rod'"]),
    (["--sigma", "v_d=abc"], ["--sigma v_d=abc", "expected a number in V (SI)"]),
    (["--max-speed", "500mm/s"], ["--max-speed 500 mm/s", "above the rated rod speed"]),
    (["--max-speed", "fast"], ["--max-speed fast", "expected a rate"]),
    (["--channels", "x_rood"], ["--channels x_rood", "did you mean 'x_rod'"]),
    (["--verify", "-1"], ["--verify"]),
    (["--draws", "0"], ["--draws"]),
    (["--prior", "{tmp}/none.toml"], ["--prior", "no such file"]),
    (["--prior", "{ref}"], ["--prior", "no fitted intervals"]),
])
def test_mistakes_exit_2_with_one_line_and_nothing_written(tmp_path, capsys, flags, words):
    flags = [f.format(tmp=tmp_path, ref=REF) for f in flags]
    code, out, err = _run(["design-experiment", REF, *flags, "--out", str(tmp_path / "out"), "--no-progress"], capsys)
    assert code == 2, err
    assert err.count("\n") == 1 and err.startswith("ema design-experiment: error:"), err
    assert all(w in err for w in words), err
    assert "None" not in err, err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow  # 18 candidate runs and the standard test: ~15 s (tests/analyses/test_design.py is the fast one)
def test_a_small_design_writes_its_folder_and_json(tmp_path, capsys):
    """Two parameters, 2 s, no load (18 candidates): the folder holds what the docs name,
    the JSON the comparison and the limits."""
    code, out, err = _run(["design-experiment", REF, "--free", "F_seal,psi", "--duration", "2s", "--max-load", "0",
                           "--out", str(tmp_path / "out"), "--json", "--no-progress"], capsys)
    assert code == 0, err
    doc = json.loads(out)
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == sorted(output_names())
    assert set(doc["comparison"]["parameters"]) == {"F_seal", "psi"}
    assert doc["limits_used"]["stroke"] <= 0.95 and doc["limits_used"]["current"] <= 1.005
    assert sum(s["count"] for s in doc["segments"]) == 2


def test_verify_2_end_to_end_reports_realised_against_predicted(tmp_path, capsys, monkeypatch):
    """``--verify 2`` on a one-parameter 2 s design: both simulated records are written,
    read back and fitted inside the command's transaction (the records live in a private
    folder, not staged to the command's end), and the text reports realised against
    predicted widths. The textbook interval of a fit is the design's own Fisher interval
    evaluated at the estimate instead of the truth, with the same noise and the same test:
    measured 0.16 % from the predicted width (the estimates lie 0.01 % and 0.14 % from the
    truth), asserted within 2 %. The scratch folder is gone afterwards."""
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", None)  # re-read TMPDIR
    out_dir = tmp_path / "out"
    code, out, err = _run(["design-experiment", REF, "--free", "F_seal", "--duration", "2s", "--verify", "2",
                           "--out", str(out_dir), "--json", "--no-progress"], capsys)
    assert code == 0, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]  # no scratch folder left
    doc = json.loads(out)
    v = doc["verification"]
    assert v["n"] == 2 and v["converged"] == 2 and not v["failed"]
    predicted, textbook = v["predicted_width"]["F_seal"], v["realised_width_textbook"]["F_seal"]
    assert abs(textbook / predicted - 1.0) < 0.02, (textbook, predicted)
    assert v["realised_width"]["F_seal"] > 0 and all(abs(f["estimate"]["F_seal"] / 150.0 - 1) < 0.01 for f in v["fits"])
    from ema_casadi.cli.design_experiment import report

    report(doc)  # the text the command prints without --json
    text = capsys.readouterr().out
    assert "verify: 2 of 2 fits converged" in text, text
    assert any(s.strip().startswith("F_seal: realised width") and "/ predicted" in s for s in text.splitlines()), text
