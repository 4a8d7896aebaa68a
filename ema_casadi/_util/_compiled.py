"""Compile CasADi Functions to native code with an on-disk cache.

The generated C source is hashed; the shared library lives in the cache folder under
that hash, so a second run (or another process) loads it without recompiling. Where
no C compiler is found, or compilation fails, the Function runs in CasADi's virtual
machine instead (slower, same results) and a warning says so once.

Cache folder: ``$EMA_CASADI_CACHE`` or ``~/.cache/ema_casadi``.

The cache verifies what it loads: every library it writes is recorded with its size
and SHA-256 in the folder's index (``index-v1.json``, rewritten atomically under a file
lock), and a library is loaded only when it matches its record. A recorded library
that does not (garbage, truncated, empty: loading it could crash the process with
SIGBUS) is rebuilt, with one line on stderr; a file the index does not record is not
an entry and is rebuilt silently. When the folder cannot be used (it is a file, or
read-only) the libraries are built in a temporary folder removed at exit, with one
line on stderr. The compilers run with ``TMPDIR`` in a private folder, so an
interrupted build leaves nothing in the system's temporary folder.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import shutil
import subprocess
import sys
import threading
import warnings
from pathlib import Path

import casadi as ca
import numpy as np

from ._files import scratch_dir, write_with

__all__ = ["compile_function", "compile_keyed", "compile_source", "cache_dir", "compiler", "BufferCall", "CFLAGS"]

#: Compiler flags of every compiled library (part of the cache keys of compile_source).
CFLAGS = ("-O2",)

_lock = threading.Lock()
_loaded: dict[str, ca.Function] = {}
_warned = False


#: The cache's record of its libraries: file name -> {"size": bytes, "sha256": hex}.
INDEX = "index-v1.json"
_usable: dict = {}  # configured folder -> the folder used (itself or a temporary fallback)


def cache_dir() -> Path:
    """The folder holding compiled models: ``$EMA_CASADI_CACHE`` or
    ``~/.cache/ema_casadi``, or a temporary folder (one line on stderr) when that one
    cannot be created or written."""
    d = Path(os.environ.get("EMA_CASADI_CACHE", Path.home() / ".cache" / "ema_casadi"))
    with _lock:
        if str(d) not in _usable:
            _usable[str(d)] = _usable_folder(d)
        return _usable[str(d)]


def _usable_folder(d: Path) -> Path:
    import atexit
    import tempfile

    from . import _files

    try:
        d.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(prefix=".ema-probe.", dir=d)
        os.close(fd)
        os.unlink(probe)
        return d
    except OSError as exc:
        up = next((q for q in (d, *d.parents) if q.exists()), None)
        why = f"{up} is a file" if up is not None and not up.is_dir() else (exc.strerror or str(exc))
    tmp = Path(tempfile.mkdtemp(prefix="ema_casadi-cache-"))
    with _files._lock:
        _files._live.add(tmp)  # removed on an interrupt too
    atexit.register(_files._remove, tmp)
    _note(f"compile cache {d} cannot be used ({why}); building in a temporary folder for this run")
    return tmp


_noted: set = set()


def _note(text: str, kind: str = "") -> None:
    """One line on stderr (the cache's own reports), once per process for each ``kind``."""
    if kind and kind in _noted:
        return
    _noted.add(kind)
    sys.stderr.write(f"ema: {text}\n")
    sys.stderr.flush()


def _digest(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


@contextlib.contextmanager
def _index_lock(folder: Path):
    """An exclusive lock on the folder's index across processes (POSIX; elsewhere none)."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not POSIX
        yield
        return
    with open(folder / ".index.lock", "a") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def _read_index(folder: Path) -> dict:
    import json

    try:
        data = json.loads((folder / INDEX).read_text(encoding="utf-8"))
        return data if isinstance(data, dict) else {}
    except FileNotFoundError:
        return {}
    except (OSError, ValueError):
        _note(f"compile cache {folder / INDEX} is unreadable; its libraries are rebuilt", "index")
        return {}


def _record(so: Path) -> None:
    """Record a library just written (size, hash) in its folder's index, atomically."""
    import json

    entry = {"size": so.stat().st_size, "sha256": _digest(so)}
    with _index_lock(so.parent):
        index = _read_index(so.parent)
        index[so.name] = entry
        write_with(so.parent / INDEX, lambda t: Path(t).write_text(json.dumps(index, indent=0), encoding="utf-8"),
                   stage=False)


def _verified(so: Path) -> bool:
    """True when ``so`` exists and matches its record in the index; a recorded library
    that does not is removed (one line on stderr), so that it is rebuilt."""
    if not so.exists():
        return False
    entry = _read_index(so.parent).get(so.name)
    if not isinstance(entry, dict):
        return False  # not an entry of this cache: rebuilt (and recorded)
    try:
        size = so.stat().st_size
        why = (f"{size} bytes instead of {entry.get('size')}" if size != entry.get("size") else
               "its content does not match its hash" if _digest(so) != entry.get("sha256") else None)
    except OSError as exc:
        why = exc.strerror or str(exc)
    if why is None:
        return True
    _note(f"compile cache: {so} is damaged ({why}); rebuilding it (and any other damaged entry)", "damaged")
    with contextlib.suppress(OSError):
        so.unlink()
    return False


def run_compilers(commands: list) -> list[tuple[int, str]]:
    """Run compiler command lines in parallel, each in its own process group with
    ``TMPDIR`` in a private folder (removed after, also on an interrupt: killed
    compilers leave no temporaries); returns (exit status, output) of each.

    Parameters
    ----------
    commands : list of list of str
        The command lines.
    """
    import signal

    with scratch_dir() as tmp:
        env = {**os.environ, "TMPDIR": str(tmp), "TMP": str(tmp), "TEMP": str(tmp)}
        procs = [subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env,
                                  start_new_session=True) for cmd in commands]
        out = []
        try:
            for proc in procs:
                log, _ = proc.communicate()
                out.append((proc.returncode, log))
        except BaseException:
            for proc in procs:
                with contextlib.suppress(OSError):
                    os.killpg(proc.pid, signal.SIGKILL)
            for proc in procs:
                proc.wait()
                proc.stdout.close()  # communicate() did not get to it: the pipe is closed here
            raise
    return out


def compiler() -> str | None:
    """The C compiler used (``$CC``, else cc or gcc on PATH), or None."""
    for name in (os.environ.get("CC"), "cc", "gcc"):
        if name and shutil.which(name):
            return shutil.which(name)
    return None


def compile_function(f: ca.Function, jit: bool = True) -> tuple[ca.Function, dict]:
    """Return a native version of ``f`` (or ``f`` itself without a compiler).

    Parameters
    ----------
    f : casadi.Function
        The function to compile (C code generated, built once and cached on disk).
    jit : bool
        False returns ``f`` unchanged.

    Returns
    -------
    function : casadi.Function
        The native function, or ``f``.
    info : dict
        ``compiled`` (bool), ``cached`` (bool, loaded without compiling) and
        ``compile_time`` (s).
    """
    global _warned
    info = {"compiled": False, "cached": False, "compile_time": 0.0}
    if not jit:
        return f, info
    cc = compiler()
    if cc is None:
        if not _warned:
            warnings.warn("no C compiler found: running the model in CasADi's VM (slower)", stacklevel=3)
            _warned = True
        return f, info
    import time

    t0 = time.perf_counter()
    name = f.name()
    gen = ca.CodeGenerator(f"{name}.c", {"with_header": False})
    gen.add(f)
    src = inline_min_max(gen.dump())
    key = hashlib.sha256((src + ca.__version__ + sys.platform).encode()).hexdigest()[:20]
    so = cache_dir() / f"{name}_{key}.so"
    with _lock:
        if str(so) in _loaded:
            info.update(compiled=True, cached=True)
            return _loaded[str(so)], info
        if not _verified(so):
            failed = _build_library(cc, src, name, so)
            if failed:
                warnings.warn(f"C compilation failed, using CasADi's VM: {failed}", stacklevel=3)
                return f, info
        else:
            info["cached"] = True
        g = ca.external(name, str(so))
        _loaded[str(so)] = g
    info["compiled"] = True
    info["compile_time"] = time.perf_counter() - t0
    return g, info


def compile_keyed(name: str, key_parts, build, jit: bool = True) -> tuple[ca.Function, dict]:
    """Like :func:`compile_function`, but looked up by a key the caller computes
    cheaply (e.g. the serialised model plus the rollout options), so that a cached
    library is loaded without building the Function at all. Building a long
    ``mapaccum`` rollout takes ~1 s, longer than loading it.

    Parameters
    ----------
    name : str
        File-name stem of the cached library.
    key_parts : iterable of str or bytes
        What determines the generated code; hashed into the cache key.
    build : callable
        ``build() -> casadi.Function``; only called on a cache miss or without ``jit``.
    jit : bool
        False builds and returns the Function uncompiled.

    Returns
    -------
    function, info
        As :func:`compile_function`.
    """
    if not jit or compiler() is None:
        return compile_function(build(), jit)
    h = hashlib.sha256()
    for part in (*key_parts, ca.__version__, sys.platform, CODEGEN_REVISION):
        h.update(part if isinstance(part, bytes) else str(part).encode())
    so = cache_dir() / f"{name}_k{h.hexdigest()[:20]}.so"
    with _lock:
        if str(so) in _loaded:
            return _loaded[str(so)], {"compiled": True, "cached": True, "compile_time": 0.0}
        if _verified(so):
            g = ca.external(name, str(so))
            _loaded[str(so)] = g
            return g, {"compiled": True, "cached": True, "compile_time": 0.0}
    import time

    t0 = time.perf_counter()
    g, info = compile_function(build(), jit)
    if info["compiled"]:
        src = Path(_loaded_path(g))
        write_with(so, lambda t: shutil.copyfile(src, t), suffix=".so", stage=False)
        _record(so)
    info["compile_time"] = time.perf_counter() - t0
    return g, info


#: CasADi's generated helpers for fmax/fmin call libm (C99); each call spills every live
#: floating-point register (all are caller-saved) in the long straight-line code of a
#: step. The replacements are C99's fmax/fmin inline: the larger (smaller) of the two,
#: the other argument where one is NaN, and the second one where they compare equal
#: (+0 and -0), which is what glibc's x86-64 fmax/fmin (maxsd/minsd) return: the same
#: bits, checked by tests/regression. 13 % fewer cycles per RK4 step of the thermal
#: model (0.23 -> 0.20 s for 4e5 steps, best of 8, user time).
_MIN_MAX = (("return fmax(x, y);", "return (x > y || y != y) ? x : y;"),
            ("return fmin(x, y);", "return (x < y || y != y) ? x : y;"))
#: Changes with the post-processing of generated code: part of every cache key.
CODEGEN_REVISION = "inline-min-max-1"


def inline_min_max(src: str) -> str:
    """CasADi-generated C with its fmax/fmin helpers inline (see :data:`_MIN_MAX`);
    unchanged where a CasADi version emits them otherwise."""
    for old, new in _MIN_MAX:
        src = src.replace(old, new)
    return src


def _build_library(cc: str, src: str, name: str, so: Path, flags=()) -> str | None:
    """Compile C source ``src`` into the shared library ``so`` (atomically: other
    processes see the whole library or none), with :data:`CFLAGS` and ``flags``; the
    compiler's complaint, or None."""
    with scratch_dir() as tmp:  # removed on an interrupt too
        c_file = Path(tmp) / f"{name}.c"
        c_file.write_text(src)
        tmp_so = Path(tmp) / so.name
        cmd = [cc, *CFLAGS, *flags, "-fPIC", "-shared", str(c_file), "-o", str(tmp_so), "-lm"]
        [(code, log)] = run_compilers([cmd])
        if code != 0:
            return log.strip()[:200] or f"{cc} exit status {code}"
        # loaded at once: not deferred to the end of the command's outputs
        write_with(so, lambda t: shutil.move(str(tmp_so), str(t)), suffix=".so", stage=False)
        _record(so)
    return None


def compile_source(name: str, key_parts, build, flags=()) -> tuple[Path | None, dict]:
    """A shared library built from C source of the caller's (e.g. a hand-written driver
    appended to CasADi-generated code, loaded with :mod:`ctypes`), cached on disk under
    a key the caller computes cheaply, like :func:`compile_keyed`.

    Parameters
    ----------
    name : str
        File-name stem of the cached library.
    key_parts : iterable of str or bytes
        What determines the source; hashed into the cache key.
    build : callable
        ``build() -> str``, the C source; only called on a cache miss.
    flags : tuple of str
        Compiler flags after :data:`CFLAGS` (none that changes floating-point results).

    Returns
    -------
    path : pathlib.Path or None
        The library, or None without a C compiler or when compilation failed (a
        warning says why).
    info : dict
        ``compiled``, ``cached`` and ``compile_time`` (s), as :func:`compile_function`.
    """
    import time

    info = {"compiled": False, "cached": False, "compile_time": 0.0}
    cc = compiler()
    if cc is None:
        return None, info
    h = hashlib.sha256()
    for part in (*key_parts, ca.__version__, sys.platform, CODEGEN_REVISION, " ".join((*CFLAGS, *flags))):
        h.update(part if isinstance(part, bytes) else str(part).encode())
    so = cache_dir() / f"{name}_s{h.hexdigest()[:20]}.so"
    t0 = time.perf_counter()
    with _lock:
        if _verified(so):
            info.update(compiled=True, cached=True)
            return so, info
        failed = _build_library(cc, build(), name, so, flags)
    if failed:
        warnings.warn(f"C compilation of {name} failed: {failed}", stacklevel=3)
        return None, info
    info.update(compiled=True, compile_time=time.perf_counter() - t0)
    return so, info


def _loaded_path(g: ca.Function) -> str:
    for path, fn in _loaded.items():
        if fn is g:
            return path
    raise KeyError(g.name())


class BufferCall:
    """Call a Function on NumPy arrays without CasADi's per-element conversions.

    CasADi's ordinary call converts every input and output element through Python
    (~100 ns each), which dominates long rollouts; ``Function.buffer`` reads and
    writes column-major NumPy memory directly. Each thread gets its own buffer (and
    CasADi memory), so one BufferCall may be used from several threads at once.

    Parameters
    ----------
    f : casadi.Function
        The function called.
    """

    def __init__(self, f: ca.Function):
        self.f = f
        self._local = threading.local()

    def _mine(self):
        mine = getattr(self._local, "buf", None)
        if mine is None:
            buf, ev = self.f.buffer()
            out = [np.zeros(self.f.size_out(i), order="F") for i in range(self.f.n_out())]
            for i, o in enumerate(out):
                buf.set_res(i, memoryview(o.reshape(-1, order="F")))
            mine = self._local.buf = (buf, ev, out)
        return mine

    def __call__(self, *args) -> list[np.ndarray]:
        return [o.copy(order="F") for o in self.view(*args)]

    def view(self, *args) -> list[np.ndarray]:
        """Like calling it, but the results are this thread's buffers themselves (no
        copy): read them before its next call."""
        buf, ev, out = self._mine()
        keep = []
        for i, a in enumerate(args):
            a = np.asfortranarray(np.asarray(a, dtype=float).reshape(self.f.size_in(i), order="F"))
            keep.append(a)
            buf.set_arg(i, memoryview(a.reshape(-1, order="F")))
        ev()
        return out

    def stats(self) -> dict:
        """Statistics of this thread's last call (e.g. CVODES ``nsteps``)."""
        return self._mine()[0].stats()
