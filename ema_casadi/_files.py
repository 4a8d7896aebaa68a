"""The one atomic writer of the toolkit (SPEC §7: nothing half-written, ever).

Every file the toolkit writes goes through :func:`atomic_path` (or the small helpers
on top of it): the content is written to a temporary name beside the target and
renamed into place, so a reader sees the old file or the whole new one; the temporary
file is removed on any failure, including ``KeyboardInterrupt``.
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

__all__ = ["atomic_path", "write_text", "write_with"]


@contextlib.contextmanager
def atomic_path(path: str | Path, suffix: str = ""):
    """Yield a temporary path beside ``path``; on success rename it to ``path``.

    Parameters
    ----------
    path : str or Path
        The target file.
    suffix : str
        Ending of the temporary name (e.g. ``".png"``, ``".npz"``) for writers that
        choose the format by the file name.
    """
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp{suffix}")
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def write_with(path: str | Path, write, suffix: str = "") -> Path:
    """Call ``write(tmp_path)`` on a temporary file beside ``path``, then rename; returns ``path``."""
    with atomic_path(path, suffix) as tmp:
        write(tmp)
    return Path(path)


def write_text(path: str | Path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically; returns ``path``."""
    return write_with(path, lambda tmp: Path(tmp).write_text(text, encoding="utf-8"))
