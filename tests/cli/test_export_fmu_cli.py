"""ema export --format fmu-me/fmu-cs/c/casadi: results, and bad input ending with one
line (exit 2) and nothing written."""

import json
import os
from pathlib import Path

import pytest

from conftest import REFERENCE
from ema_casadi._util import _compiled as compiled
from ema_casadi.cli import main


def one_line_error(capsys, pattern):
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and pattern in err, err
    return err


def unwritable_folder(tmp_path) -> Path:
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    if os.access(ro, os.W_OK):  # root ignores the mode: take a folder nobody can write files into
        ro.chmod(0o755)
        return Path("/proc")
    return ro


@pytest.mark.parametrize("fmt, out", [("fmu-me", "x.fmu"), ("fmu-cs", "x.fmu"), ("c", "ema_c"),
                                      ("casadi", "ema_functions")])
def test_unwritable_output_refused_before_work(tmp_path, capsys, fmt, out):
    target = unwritable_folder(tmp_path) / out
    assert main(["export", str(REFERENCE), "--format", fmt, "--out", str(target)]) == 2
    one_line_error(capsys, "not writable")
    assert not target.exists()


def test_unknown_format_and_bad_suffix(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["export", str(REFERENCE), "--format", "fmu3", "--out", str(tmp_path / "x.fmu")])
    assert exc.value.code == 2
    one_line_error(capsys, "invalid choice: 'fmu3'")
    assert main(["export", str(REFERENCE), "--format", "fmu-cs", "--out", str(tmp_path / "x.zip")]) == 2
    one_line_error(capsys, "must end in .fmu")
    assert list(tmp_path.iterdir()) == []


def test_hybrid_model_exchange_refused(tmp_path, capsys):
    out = tmp_path / "ema_me.fmu"
    assert main(["export", str(REFERENCE), "--format", "fmu-me", "--variant", "friction=hybrid",
                 "--out", str(out)]) == 2
    one_line_error(capsys, "--format fmu-cs")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("argv, pattern", [
    (["--format", "fmu-cs", "--dt", "0", "--out", "x.fmu"], "dt must be a step"),
    (["--format", "fmu-me", "--dt", "1e-5", "--out", "x.fmu"], "nothing of it steps"),
    (["--format", "c", "--fmi-version", "3.0", "--out", "ema_c"], "only fmu-cs has a choice"),
    (["--format", "fmu-me", "--fmi-version", "2.0", "--out", "x.fmu"], "fmu-me is FMI 3.0"),
])
def test_flags_that_do_not_apply_refused(tmp_path, capsys, argv, pattern):
    argv = [str(tmp_path / a) if a in ("x.fmu", "ema_c") else a for a in argv]
    assert main(["export", str(REFERENCE), *argv]) == 2
    one_line_error(capsys, pattern)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.skipif(compiled.compiler() is None, reason="no C compiler on this machine")
def test_export_writes_fmu_and_reports(tmp_path, capsys):
    out = tmp_path / "ema_cs.fmu"
    assert main(["export", str(REFERENCE), "--format", "fmu-cs", "--variant", "friction=hybrid", "--dt", "1e-4",
                 "--out", str(out), "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    assert r["written"] == [str(out)] and out.is_file() and r["dt_internal"] == 1e-4
    assert "linux64" in r["platforms"] and r["build_cpu_time"] < 10
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ema_cs.fmu"]  # no temporary files
