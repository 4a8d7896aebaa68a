"""The one atomic writer of the toolkit (the reliability contract, docs: reliability: nothing half-written, ever).

Every file the toolkit writes goes through :func:`atomic_path` (or the small helpers
on top of it): the content is written to a temporary name beside the target and
renamed into place, so a reader sees the old file or the whole new one. A folder of
outputs is assembled the same way by :func:`atomic_dir`: built in a temporary folder
beside the target and renamed into place at the end.

A temporary file or folder is removed on any failure, including ``KeyboardInterrupt``
and the CLI's SIGINT/SIGTERM handling; every one on disk is listed, so an interrupt
that cannot unwind normally can still remove them (:func:`remove_temporaries`).

Inside :func:`transaction` (the CLI runs every command in one) the renames are
deferred to its end: the outputs of a command appear together, and a failure or an
interrupt anywhere before that leaves none of them. Files written into a temporary
folder of the writer (a folder being assembled, a :func:`scratch_dir`) are private
and renamed at once.

Before any work, :func:`check_file` and :func:`check_folder` tell whether a target
can be written at all (a folder that exists and takes a file, no folder where a file
is wanted, nothing below a regular file), by creating and removing a probe file.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
import threading
from pathlib import Path

from ._errors import InputError

__all__ = [
    "atomic_path", "atomic_dir", "write_text", "write_with", "transaction", "scratch_dir", "remove_temporaries",
    "check_file", "check_folder", "OutputPathError", "after_commit", "on_error",
]


class OutputPathError(InputError, ValueError):
    """An output path that cannot be written (one line, names the path)."""


_lock = threading.RLock()
#: temporary files and folders on disk now
_live: set[Path] = set()
#: staged renames of the open transaction, in order: (temporary, target, is_folder)
_staged: list | None = None
#: callables of the open transaction to run once its renames are done
_after: list = []
#: callables of the open transaction to run if it fails with an error (not an interrupt)
_on_error: list = []


def _temp_name(path: Path, suffix: str = "") -> Path:
    # process and thread: two threads writing the same target (a compiled library both
    # build on a cold cache) must not share the temporary (one renamed it away first)
    return path.with_name(f".{path.name}.{os.getpid()}.{threading.get_ident()}.tmp{suffix}")


def _remove(p: Path) -> None:
    """Remove a temporary file or folder (missing is fine) and forget it."""
    with _lock:
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p, ignore_errors=True)
        else:
            p.unlink(missing_ok=True)
        _live.discard(p)


def _commit(tmp: Path, target: Path, folder: bool) -> None:
    """Rename ``tmp`` onto ``target``; a folder replaces an existing folder whole (but for
    the subfolders :func:`atomic_dir` was told to keep, moved into the new one first)."""
    with _lock:
        keep = _kept.pop(tmp, ()) if folder else ()
        if folder and target.is_dir():
            for name in keep:
                if (target / name).is_dir() and not (tmp / name).exists():
                    os.rename(target / name, tmp / name)
            old = target.with_name(f".{target.name}.{os.getpid()}.old")
            os.rename(target, old)
            try:
                os.rename(tmp, target)
            except BaseException:
                os.rename(old, target)
                raise
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(tmp, target)
        _live.discard(tmp)


def _in_temporary(target: Path) -> bool:
    """True when ``target`` lies in a temporary folder of the writer (a folder being
    assembled, a scratch folder): private, so its files need not wait."""
    parents = set(Path(os.path.abspath(target)).parents)
    return any(p.is_dir() and Path(os.path.abspath(p)) in parents for p in _live)


def _finish(tmp: Path, target: Path, folder: bool) -> None:
    """At the end of a successful write: stage the rename in the open transaction, or do it."""
    with _lock:
        if _staged is not None and not _in_temporary(target):
            _staged.append((tmp, target, folder))
            return
    _commit(tmp, target, folder)


@contextlib.contextmanager
def atomic_path(path: str | Path, suffix: str = "", *, stage: bool = True):
    """Yield a temporary path beside ``path``; on success rename it to ``path``.

    Parameters
    ----------
    path : str or Path
        The target file.
    suffix : str
        Ending of the temporary name (e.g. ``".png"``, ``".npz"``) for writers that
        choose the format by the file name.
    stage : bool
        Inside a :func:`transaction`, defer the rename to its end (default). Files the
        toolkit reads back at once (the compiled-code cache) pass False.
    """
    path = Path(path)
    tmp = _temp_name(path, suffix)
    with _lock:
        _live.add(tmp)
    try:
        with _cannot_write(path):
            yield tmp
            if stage:
                _finish(tmp, path, folder=False)
            else:
                _commit(tmp, path, folder=False)
    except BaseException:
        _remove(tmp)
        raise


#: Subfolders an :func:`atomic_dir` carries over from the folder it replaces, by temporary.
_kept: dict = {}


@contextlib.contextmanager
def _cannot_write(target: Path):
    """An OSError while an output is written (a full disk, a quota, a read-only
    filesystem) as one line naming the output: :class:`OutputPathError`."""
    try:
        yield
    except OutputPathError:
        raise
    except OSError as exc:
        raise OutputPathError(f"{_shown(target)}: cannot write ({exc.strerror or exc})") from None


#: folders being assembled -> the folder they become (messages name the latter)
_folders: dict = {}


def _shown(target: Path) -> Path:
    """``target`` as the user named it: a file inside a folder being assembled is named
    inside the folder it will become."""
    for tmp, real in list(_folders.items()):
        try:
            return real / Path(target).relative_to(tmp)
        except ValueError:
            continue
    return target


@contextlib.contextmanager
def atomic_dir(path: str | Path, keep: tuple = ()):
    """Yield an empty temporary folder beside ``path``; on success it becomes ``path``.

    An existing folder ``path`` is replaced whole (callers decide beforehand, with
    :func:`check_folder`, whether that is allowed), except its subfolders named in
    ``keep``, which move into the new folder. On failure the temporary folder and
    everything in it are removed and ``path`` is untouched.

    Parameters
    ----------
    path : str or Path
        The target folder.
    keep : tuple of str
        Subfolders of an existing ``path`` to carry over (another command's output).
    """
    path = Path(path)
    tmp = _temp_name(path)
    with _lock:
        _live.add(tmp)
        _kept[tmp] = tuple(keep)
    _folders[tmp] = path
    try:
        with _cannot_write(path):
            tmp.mkdir()
            yield tmp  # the files inside are private until the folder moves: not staged
            _finish(tmp, path, folder=True)
    except BaseException:
        _kept.pop(tmp, None)
        _remove(tmp)
        raise
    finally:
        _folders.pop(tmp, None)


@contextlib.contextmanager
def transaction():
    """Defer the renames of every atomic write inside to its end.

    Each temporary file is complete when its writer returns; the renames happen
    together when the block ends without an exception, and on an exception (an error,
    an interrupt) every staged temporary is removed instead. Nested transactions join
    the outer one.
    """
    global _staged
    with _lock:
        if _staged is not None:
            outer = True
        else:
            outer, _staged = False, []
    if outer:
        yield
        return
    try:
        yield
    except BaseException as exc:
        with _lock:
            staged, _staged = _staged, None
            _after.clear()
            undo = list(_on_error) if isinstance(exc, Exception) else []
            _on_error.clear()
        for tmp, _, _ in staged:
            _remove(tmp)
        for fn in undo:
            fn()
        raise
    with _lock:
        staged, _staged = _staged, None
        try:
            for tmp, target, folder in staged:
                try:
                    _commit(tmp, target, folder)
                except OSError as exc:
                    raise OutputPathError(f"{target}: cannot write ({exc.strerror or exc})") from exc
        except BaseException as exc:
            for tmp, _, _ in staged:
                _remove(tmp)
            _after.clear()
            undo = list(_on_error) if isinstance(exc, Exception) else []
            _on_error.clear()
            for fn in undo:
                fn()
            raise
        todo = list(_after)
        _after.clear()
        _on_error.clear()
    for fn in todo:
        fn()


def on_error(fn) -> None:
    """Call ``fn()`` if the open :func:`transaction` fails with an error (not on an
    interrupt, not on success); nothing outside a transaction. For what a failed
    command must not leave: a new sweep journal whose table could not be written.

    Parameters
    ----------
    fn : callable
        Called without arguments.
    """
    with _lock:
        if _staged is not None:
            _on_error.append(fn)


def after_commit(fn) -> None:
    """Call ``fn()`` once the open :func:`transaction` has renamed its outputs into
    place (not at all if it fails); at once outside a transaction. For what must
    outlive a failed command and go with a successful one: the journal of a sweep is
    removed only once its table is in place.

    Parameters
    ----------
    fn : callable
        Called without arguments.
    """
    with _lock:
        if _staged is not None:
            _after.append(fn)
            return
    fn()


@contextlib.contextmanager
def scratch_dir(near: str | Path | None = None):
    """A private working folder, removed at the end of the block, on failure and on
    interrupt; files written into it are not staged.

    Parameters
    ----------
    near : str or Path, optional
        Folder to create it in (default the system's temporary folder).
    """
    tmp = Path(tempfile.mkdtemp(prefix=".ema_casadi-", dir=near))
    with _lock:
        _live.add(tmp)
    try:
        yield tmp
    finally:
        _remove(tmp)


def remove_temporaries() -> list[Path]:
    """Remove every temporary file and folder the writer has on disk now (interrupt
    handling); returns them."""
    with _lock:
        left = sorted(_live)
        for p in left:
            _remove(p)
        return left


def write_with(path: str | Path, write, suffix: str = "", *, stage: bool = True) -> Path:
    """Call ``write(tmp_path)`` on a temporary file beside ``path``, then rename; returns ``path``.

    Parameters
    ----------
    path : str or Path
        The target file.
    write : callable
        ``write(tmp_path)`` writes the whole content to ``tmp_path``.
    suffix : str
        Ending of the temporary name (for writers that choose the format by it).
    stage : bool
        Defer the rename to the end of an open :func:`transaction` (default).
    """
    with atomic_path(path, suffix, stage=stage) as tmp:
        write(tmp)
    return Path(path)


def write_text(path: str | Path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically; returns ``path``.

    Parameters
    ----------
    path : str or Path
        The target file.
    text : str
        The content.
    """
    return write_with(path, lambda tmp: Path(tmp).write_text(text, encoding="utf-8"))


# -- checks before any work -----------------------------------------------------------
def _probe(folder: Path, what: str) -> None:
    """OutputPathError unless a file can be created in ``folder``."""
    if not folder.exists():
        up = next((q for q in folder.parents if q.exists()), None)
        if up is not None and not up.is_dir():
            raise OutputPathError(f"{what}: {up} is a file, not a folder")
        raise OutputPathError(f"{what}: folder {folder} does not exist")
    if not folder.is_dir():
        raise OutputPathError(f"{what}: {folder} is a file, not a folder")
    try:
        fd, name = tempfile.mkstemp(prefix=".ema-probe.", dir=folder)
    except OSError as exc:
        raise OutputPathError(f"{what}: cannot write in {folder} ({exc.strerror or exc})") from None
    os.close(fd)
    os.unlink(name)


def _given(path, what: str) -> Path:
    """``path`` as a Path; an empty one is refused (it would mean wherever the user
    stands), as is one naming no file (``.``, ``/``)."""
    if not str(path).strip():
        raise OutputPathError(f"{what}: empty path; name the output")
    p = Path(path)
    if p.name in ("", ".", ".."):
        raise OutputPathError(f"{what}: names no file or folder of its own; name the output")
    return p


def check_file(path: str | Path, what: str | None = None) -> Path:
    """Check that the file ``path`` can be written (before any work); returns it.

    Parameters
    ----------
    path : str or Path
        The output file.
    what : str, optional
        How to name it in the message (default the path), e.g. ``"--out run.csv"``.
    """
    what = what or str(path)
    path = _given(path, what)
    if path.is_dir():
        raise OutputPathError(f"{what}: is a folder; expected a file name")
    _probe(path.parent, what)
    return path


def check_folder(path: str | Path, names=(), what: str | None = None, keep: tuple = ()) -> Path:
    """Check that the output folder ``path`` can be assembled beside and moved into
    place (before any work); returns it.

    An existing folder may be replaced only when it holds nothing but files of the
    given ``names`` (an earlier run of the same command) or nothing at all; a folder
    with anything else in it is refused, so no other file is ever removed.

    Parameters
    ----------
    path : str or Path
        The output folder.
    names : iterable of str
        The files the command writes into it.
    what : str, optional
        How to name it in the message (default the path), e.g. ``"--out out"``.
    keep : tuple of str
        Subfolders that may be there (kept across the replacement, :func:`atomic_dir`).
    """
    what = what or str(path)
    path = _given(path, what)
    if path.exists() and not path.is_dir():
        raise OutputPathError(f"{what}: exists and is not a folder")
    _probe(path.parent, what)
    if path.is_dir():
        names = set(names)
        foreign = sorted(p.name for p in path.iterdir()
                         if not (p.name in names and p.is_file()) and not (p.name in keep and p.is_dir()))
        if foreign:
            shown = ", ".join(foreign[:3]) + (", ..." if len(foreign) > 3 else "")
            raise OutputPathError(f"{what}: the folder exists and holds other files ({shown}); it would be "
                                  "replaced whole: remove it or choose a new folder")
    return path
