"""The compile cache checks what it loads: a damaged library (garbage,
truncated, empty) is rebuilt with one line on stderr and never loaded; a file the
cache's index does not record is rebuilt silently; a cache folder that cannot be used
(a file, read-only) is replaced by a temporary folder with one line on stderr. Every
case gives the same numbers as a sound cache (bit-identical: one process, one build).
"""

from __future__ import annotations

import ctypes
import json
import os
import subprocess
import sys
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from conftest import REFERENCE
from ema_casadi._util import _compiled as compiled

pytestmark = pytest.mark.skipif(compiled.compiler() is None, reason="no C compiler on this machine")

C_SOURCE = "double ema_cache_probe(double x) { return 3.0 * x * x + 1.0; }\n"
X = np.array([0.1, -0.2, 0.3])


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """A fresh cache folder, as seen by a new process."""
    d = tmp_path / "cache"
    monkeypatch.setenv("EMA_CASADI_CACHE", str(d))
    fresh(monkeypatch)
    return d


def fresh(monkeypatch):
    monkeypatch.setattr(compiled, "_loaded", {})
    monkeypatch.setattr(compiled, "_usable", {})
    monkeypatch.setattr(compiled, "_noted", set())


def function(name):
    x = ca.SX.sym("x", 3)
    return ca.Function(name, [x], [ca.sin(x) * x + x**3])


def evaluate(api: str, name: str):
    """(numbers, info, library path) of one cached build through ``api``."""
    if api == "function":
        g, info = compiled.compile_function(function(name))
        return np.asarray(g(X)).ravel(), info, Path(compiled._loaded_path(g))
    if api == "keyed":
        g, info = compiled.compile_keyed(name, ["cache-test", name], lambda: function(name))
        so = next(Path(os.environ["EMA_CASADI_CACHE"]).glob(f"{name}_k*.so"), None)
        return np.asarray(g(X)).ravel(), info, so
    path, info = compiled.compile_source(name, ["cache-test", name], lambda: C_SOURCE)
    fn = ctypes.CDLL(str(path)).ema_cache_probe
    fn.restype, fn.argtypes = ctypes.c_double, [ctypes.c_double]
    return np.array([fn(float(v)) for v in X]), info, path


def damage(path: Path, how: str) -> None:
    """Replace the library by a damaged file (a new file: the copy this process has
    loaded stays intact)."""
    data = path.read_bytes()
    bad = {"garbage": os.urandom(len(data)),  # the same size: only the hash tells
           "truncated": data[: len(data) // 3],  # loading it would crash the process with SIGBUS
           "empty": b""}[how]
    tmp = path.with_name(path.name + ".damaged")
    tmp.write_bytes(bad)
    os.replace(tmp, path)


@pytest.mark.parametrize("how", ["garbage", "truncated", "empty"])
@pytest.mark.parametrize("api", ["function", "keyed", "source"])
def test_a_damaged_entry_is_rebuilt_with_one_line(api, how, cache, capsys, monkeypatch):
    name = f"ct_{api}_{how}"
    good, info, so = evaluate(api, name)
    assert info["compiled"] and not info["cached"]
    index = json.loads((cache / compiled.INDEX).read_text())
    assert index[so.name]["size"] == so.stat().st_size
    damage(so, how)
    fresh(monkeypatch)
    capsys.readouterr()
    again, info, so2 = evaluate(api, name)
    err = capsys.readouterr().err
    np.testing.assert_array_equal(again, good)  # one build, one process: the same bits
    assert so2 == so and (api == "keyed" or not info["cached"])  # keyed: built from compile_function's entry
    assert err.count("\n") == 1 and "is damaged" in err and so.name in err, err
    fresh(monkeypatch)
    _, info, _ = evaluate(api, name)  # rebuilt and recorded: a sound entry again
    assert info["cached"] and capsys.readouterr().err == ""


def test_a_file_the_index_does_not_record_is_never_loaded(cache, capsys, monkeypatch):
    good, _, so = evaluate("function", "ct_unrecorded")
    (cache / compiled.INDEX).unlink()
    damage(so, "truncated")
    fresh(monkeypatch)
    again, info, _ = evaluate("function", "ct_unrecorded")
    np.testing.assert_array_equal(again, good)
    assert not info["cached"] and capsys.readouterr().err == ""


def test_an_unreadable_index_is_one_line(cache, capsys, monkeypatch):
    good, _, _ = evaluate("function", "ct_index")
    (cache / compiled.INDEX).write_text("{not json", encoding="utf-8")
    fresh(monkeypatch)
    capsys.readouterr()
    again, _, _ = evaluate("function", "ct_index")
    np.testing.assert_array_equal(again, good)
    assert capsys.readouterr().err.count("\n") == 1


def _read_only_folder(tmp_path) -> Path | None:
    ro = tmp_path / "ro"
    ro.mkdir()
    try:
        subprocess.run(["mount", "-t", "tmpfs", "-o", "ro,size=64k", "tmpfs", str(ro)], check=True,
                       capture_output=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        ro.chmod(0o555)
        if os.access(ro, os.W_OK):
            return None
    return ro


@pytest.mark.parametrize("kind", ["a-file", "below-a-file", "read-only"])
def test_an_unusable_cache_folder_falls_back_to_a_temporary_one(kind, tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("EMA_CASADI_CACHE", str(tmp_path / "sound"))
    fresh(monkeypatch)
    good, _, _ = evaluate("function", "ct_fallback")
    if kind == "read-only":
        where = _read_only_folder(tmp_path)
        if where is None:
            pytest.skip("no read-only folder for root here (cannot mount)")
    else:
        (tmp_path / "afile").write_text("x")
        where = tmp_path / "afile" / ("sub" if kind == "below-a-file" else "")
    monkeypatch.setenv("EMA_CASADI_CACHE", str(where))
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    monkeypatch.setattr("tempfile.tempdir", str(tmp_path))
    fresh(monkeypatch)
    capsys.readouterr()
    try:
        again, info, so = evaluate("function", "ct_fallback")
        err = capsys.readouterr().err
        np.testing.assert_array_equal(again, good)
        assert err.count("\n") == 1 and "cannot be used" in err and str(where).rstrip("/") in err, err
        assert so.parent.parent == tmp_path and so.parent.name.startswith("ema_casadi-cache-")
        from ema_casadi._util import _files

        assert so.parent in _files._live  # removed at exit, and by the interrupt handling
        _files._remove(so.parent)
    finally:
        if kind == "read-only":
            subprocess.run(["umount", "-l", str(where)], capture_output=True, timeout=10)


def _simulate(cache_dir: Path, tmpdir: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "EMA_CASADI_CACHE": str(cache_dir), "TMPDIR": str(tmpdir)}
    return subprocess.run([sys.executable, "-m", "ema_casadi.cli", "simulate", str(REFERENCE), "--t-end", "0.01",
                           "--json"], capture_output=True, text=True, env=env, timeout=300)


def test_the_command_line_survives_a_truncated_library_and_a_cache_that_is_a_file(tmp_path):
    """As processes: a truncated library (loaded, SIGBUS) and a cache path that is a
    file; the same final values as a sound cache, one line on stderr, no temporary
    folder left behind."""
    tmpdir = tmp_path / "TMPDIR"
    tmpdir.mkdir()
    sound = _simulate(tmp_path / "cache", tmpdir)
    assert sound.returncode == 0, sound.stderr
    final = json.loads(sound.stdout)["final"]
    for so in (tmp_path / "cache").glob("*.so"):
        damage(so, "truncated")
    hurt = _simulate(tmp_path / "cache", tmpdir)
    assert hurt.returncode == 0, hurt.stderr
    assert json.loads(hurt.stdout)["final"] == final
    assert hurt.stderr.count("\n") == 1 and "is damaged" in hurt.stderr, hurt.stderr
    (tmp_path / "afile").write_text("x")
    moved = _simulate(tmp_path / "afile", tmpdir)
    assert moved.returncode == 0, moved.stderr
    assert json.loads(moved.stdout)["final"] == final
    assert moved.stderr.count("\n") == 1 and "cannot be used" in moved.stderr, moved.stderr
    assert list(tmpdir.iterdir()) == []
