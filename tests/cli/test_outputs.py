"""Outputs (the reliability contract, docs: reliability): checked for writability before any work, in every command, and
written whole or not at all — files through the one atomic writer, committed together
at the end of a command; folders assembled beside their place and moved in."""

import importlib

import pytest

from conftest import REFERENCE
from ema_casadi._util import _files
from ema_casadi.cli import main

M = str(REFERENCE)


@pytest.fixture
def place(tmp_path):
    """tmp_path with a regular file ``afile``, an existing folder ``adir`` and ``adir.toml``."""
    (tmp_path / "afile").write_text("x")
    (tmp_path / "adir").mkdir()
    (tmp_path / "adir.toml").mkdir()
    return tmp_path


def _bad_paths(p):
    return {"/proc": "/proc/x", "below a file": f"{p}/afile/x", "missing folder": f"{p}/nope/x",
            "a folder": f"{p}/adir"}


# (command, argv before the path, flag, suffix of the file it wants)
FILE_OUTPUTS = [
    ("simulate", ["--out"], ".csv"), ("simulate", ["--plot"], ".png"), ("linearize", ["--out"], ".mat"),
    ("margins", ["--plot"], ".png"), ("bode", ["--plot"], ".png"), ("freqresp", ["--out"], ".csv"),
    ("freqresp", ["--plot"], ".png"), ("tune", ["--out"], ".toml"), ("export", ["--format", "mat", "--out"], ".mat"),
    ("export", ["--format", "c", "--out"], ".c"),
]
DIR_OUTPUTS = [("demo", ["--out"]), ("tune", ["--plot-dir"])]


def _no_work(monkeypatch):
    """Any command that gets as far as loading the model fails the test."""
    def boom(args):
        raise AssertionError("work started before the outputs were checked")

    for name in ("simulate", "linearize", "margins", "bode", "freqresp", "tune", "export", "demo"):
        monkeypatch.setattr(importlib.import_module(f"ema_casadi.cli.{name}"), "load", boom)


def _assert_one_line(capsys, status=2):
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    return err


@pytest.mark.parametrize("case", ["/proc", "below a file", "missing folder", "a folder"])
@pytest.mark.parametrize("command, flag, suffix", FILE_OUTPUTS, ids=lambda v: str(v))
def test_an_unwritable_file_is_refused_before_any_work(place, monkeypatch, capsys, command, flag, suffix, case):
    _no_work(monkeypatch)
    path = _bad_paths(place)[case] + ("" if case == "a folder" else suffix)
    if case == "a folder":
        (place / f"adir{suffix}").mkdir(exist_ok=True)
        path += suffix
    before = sorted(p.name for p in place.iterdir())
    status = main([command, M, *flag, path])
    err = _assert_one_line(capsys)
    assert status == 2 and f"ema {command}: error: {flag[-1]} {path}" in err, err
    assert sorted(p.name for p in place.iterdir()) == before


@pytest.mark.parametrize("case", ["/proc", "below a file", "missing folder"])
@pytest.mark.parametrize("command, flag", DIR_OUTPUTS)
def test_an_unwritable_folder_is_refused_before_any_work(place, monkeypatch, capsys, command, flag, case):
    _no_work(monkeypatch)
    path = _bad_paths(place)[case]
    status = main([command, M, *flag, path])
    err = _assert_one_line(capsys)
    assert status == 2 and f"{flag[-1]} {path}" in err, err
    assert sorted(p.name for p in place.iterdir()) == ["adir", "adir.toml", "afile"]


@pytest.mark.parametrize("command, flag", DIR_OUTPUTS)
def test_a_folder_with_other_files_is_not_replaced(place, monkeypatch, capsys, command, flag):
    _no_work(monkeypatch)
    (place / "adir" / "mine.txt").write_text("keep me")
    assert main([command, M, *flag, str(place / "adir")]) == 2
    assert "holds other files (mine.txt)" in _assert_one_line(capsys)
    assert (place / "adir" / "mine.txt").read_text() == "keep me"
    assert main([command, M, *flag, str(place / "afile")]) == 2
    assert "exists and is not a folder" in _assert_one_line(capsys)


def test_a_good_output_is_not_written_when_another_is_bad(tmp_path, capsys):
    status = main(["simulate", M, "--t-end", "0.01", "--out", str(tmp_path / "good.csv"), "--plot", "/proc/x.png"])
    assert status == 2 and "--plot /proc/x.png" in _assert_one_line(capsys)
    assert not list(tmp_path.iterdir())


def test_tune_out_an_existing_folder_leaves_nothing(place, capsys):
    assert main(["tune", M, "--out", str(place / "adir.toml")]) == 2
    assert "is a folder" in _assert_one_line(capsys)
    assert sorted(p.name for p in place.iterdir()) == ["adir", "adir.toml", "afile"]


def test_the_outputs_of_a_command_appear_together(tmp_path, capsys):
    assert main(["simulate", M, "--t-end", "0.01", "--out", str(tmp_path / "r.csv"),
                 "--plot", str(tmp_path / "r.png")]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.csv", "r.png"]


def test_a_c_export_writes_its_three_files_or_none(tmp_path, capsys):
    (tmp_path / "f.h").mkdir()  # the header's place is taken: refused up front
    assert main(["export", M, "--format", "c", "--out", str(tmp_path / "f.c")]) == 2
    assert "f.h" in _assert_one_line(capsys)
    assert [p.name for p in tmp_path.iterdir()] == ["f.h"]
    assert main(["export", M, "--format", "c", "--out", str(tmp_path / "g.c")]) == 0
    assert sorted(p.name for p in tmp_path.glob("g*")) == ["g.c", "g.c.json", "g.h"]


# -- the writer itself -------------------------------------------------------------------
def test_transaction_commits_at_the_end_or_not_at_all(tmp_path):
    a, b = tmp_path / "a.txt", tmp_path / "b.txt"
    with _files.transaction():
        _files.write_text(a, "A")
        assert not a.exists() and len(list(tmp_path.iterdir())) == 1  # complete, not yet renamed
        _files.write_text(b, "B")
    assert a.read_text() == "A" and b.read_text() == "B" and len(list(tmp_path.iterdir())) == 2
    with pytest.raises(KeyboardInterrupt), _files.transaction():
        _files.write_text(a, "new A")
        _files.write_text(tmp_path / "c.txt", "C")
        raise KeyboardInterrupt
    assert a.read_text() == "A" and sorted(p.name for p in tmp_path.iterdir()) == ["a.txt", "b.txt"]


def test_atomic_dir_replaces_a_folder_whole_or_leaves_it(tmp_path):
    target = tmp_path / "out"
    with _files.atomic_dir(target) as tmp:
        (tmp / "one.txt").write_text("1")
        assert not target.exists()
    assert [p.name for p in target.iterdir()] == ["one.txt"]
    with pytest.raises(RuntimeError), _files.atomic_dir(target) as tmp:
        _files.write_text(tmp / "two.txt", "2")
        raise RuntimeError("a failure half-way")
    assert [p.name for p in target.iterdir()] == ["one.txt"] and [p.name for p in tmp_path.iterdir()] == ["out"]
    with _files.atomic_dir(target) as tmp:
        (tmp / "two.txt").write_text("2")
    assert [p.name for p in target.iterdir()] == ["two.txt"] and [p.name for p in tmp_path.iterdir()] == ["out"]


def test_remove_temporaries_finds_what_an_interrupt_left(tmp_path):
    cm = _files.atomic_path(tmp_path / "x.csv")
    tmp = cm.__enter__()
    tmp.write_text("half")
    d = _files.atomic_dir(tmp_path / "d")
    d.__enter__()
    assert len(list(tmp_path.iterdir())) == 2
    removed = _files.remove_temporaries()
    assert len(removed) >= 2 and not list(tmp_path.iterdir())
