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
    (["--weights", "psi"], ["--weights psi", "NAME=W"]),
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
