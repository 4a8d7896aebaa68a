"""Whole-or-nothing outputs: an FMU archive, an export folder (the reliability contract, docs: reliability).

Files go through :mod:`ema_casadi._util._files`; a folder is assembled in a temporary folder
beside the target and moved into place at the end (:func:`ema_casadi._util._files.atomic_dir`). An existing
target folder is replaced only when an earlier export of this package wrote it (its
marker file names the format); any other existing path is refused.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import tempfile
import zipfile
from pathlib import Path

from ..._util._files import atomic_dir, write_text, write_with
from .._errors import ExportError

__all__ = ["write_zip", "export_folder", "check_target", "identifier", "MARKER"]

#: File naming the export format in every folder this package writes.
MARKER = "ema_layout.json"


def identifier(stem: str, default: str) -> str:
    """A C identifier from a file stem (the FMU's model identifier, the C prefix)."""
    name = re.sub(r"\W", "_", stem)
    if not name:
        return default
    return name if re.match(r"[A-Za-z_]", name) else f"ema_{name}"


def check_target(path, kind: str) -> Path:
    """Refuse a target that cannot be written, before any work.

    Parameters
    ----------
    path : str or Path
        Target file (``kind="file"``) or folder (``kind="folder"``).
    kind : {"file", "folder"}
    """
    path = Path(path)
    parent = path.parent
    if not parent.is_dir():
        raise ExportError(f"{path}: folder {parent} does not exist")
    try:  # a real probe: permissions, read-only file systems, root alike
        fd, probe = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".probe", dir=parent)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise ExportError(f"{path}: folder {parent} is not writable ({exc.strerror or exc})") from None
    if kind == "file" and path.is_dir():
        raise ExportError(f"{path}: is a folder, expected a file name")
    if kind == "folder" and path.exists():
        if not path.is_dir() or not (path / MARKER).is_file():
            raise ExportError(f"{path}: exists and is not a folder written by 'ema export'; "
                              "remove it or choose another --out")
    if path.exists() and not os.access(path, os.W_OK):
        raise ExportError(f"{path}: exists and is not writable")
    return path


def write_zip(path, members: dict) -> Path:
    """Write a zip archive atomically; ``members`` maps archive names to local files.

    Parameters
    ----------
    path : str or Path
        The archive (e.g. ``ema.fmu``).
    members : dict
        Archive name -> local file (a Path) or content (bytes or str).
    """

    def write(tmp):
        with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
            for arc, src in members.items():
                if isinstance(src, Path):
                    z.write(src, arc)
                else:
                    z.writestr(arc, src)

    return write_with(path, write)


@contextlib.contextmanager
def export_folder(target, fmt: str, layout_doc: dict):
    """Yield a temporary folder beside ``target``; on success it becomes ``target``.

    The marker file (the layout, with ``format``) is written last. An existing export
    folder at ``target`` is swapped out and deleted after the new one is in place.

    Parameters
    ----------
    target : str or Path
        The folder to create.
    fmt : str
        Export format written into the marker.
    layout_doc : dict
        The layout (names, units, functions) stored in the marker file.
    """
    with atomic_dir(target) as tmp:  # replaced whole; removed on failure and interrupt
        yield tmp
        write_text(tmp / MARKER, json.dumps({"format": f"ema_casadi.{fmt}/1", **layout_doc}, indent=1))
