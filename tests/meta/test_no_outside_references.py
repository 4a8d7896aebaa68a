"""The repository stands on its own: no file points to notes outside it (a parent folder's ``shared``
folder, ``SPEC.md`` and its sections, ``AIRCRAFT.md``, ``STYLE.md``, ``STACK_NOTES``),
and no file names an internal tracker number ("issue 13"): what a user needs is in
the documentation (``docs/``), and a feature is called by its name."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
#: the parent folder's notes, spelled so that this file does not name them itself
OUTSIDE = r"\.\./" + "shared"
PATTERN = re.compile(OUTSIDE + r"|SPEC\.md|SPEC §|AIRCRAFT\.md|STYLE\.md|STACK_NOTES|\b[Ii]ssue \d+")
#: Text files are read; these endings are binary or generated.
_SKIP = (".png", ".fmu", ".so", ".mat", ".npz", ".pyc")


def _files() -> list[Path]:
    try:
        out = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True).stdout
        return [ROOT / f for f in out.splitlines()]
    except (OSError, subprocess.CalledProcessError):  # not a clone: walk the tree
        return [p for p in ROOT.rglob("*") if p.is_file() and ".git" not in p.parts and ".venv" not in p.parts]


def offenders(files) -> list[str]:
    """``path:line: text`` of every match.

    Parameters
    ----------
    files : iterable of Path
        The files to read (binary ones are skipped).
    """
    hits = []
    for path in files:
        if path.suffix.lower() in _SKIP or not path.is_file() or path == Path(__file__).resolve():
            continue
        try:
            text = path.read_text(encoding="utf-8")
        except (UnicodeDecodeError, OSError):
            continue
        for n, line in enumerate(text.splitlines(), 1):
            if PATTERN.search(line):
                hits.append(f"{path.relative_to(ROOT)}:{n}: {line.strip()[:100]}")
    return hits


def test_the_pattern_catches_what_it_should(tmp_path):
    """Each kind of reference is caught, and ordinary text is not."""
    bad = ["see ../" + "shared/SPEC.md", "(SPEC §7)", "AIRCRAFT.md §3", "issue 13", "Issue 4: margins", "STACK_NOTES"]
    good = ["the reliability contract (docs: reliability)", "SWEEP.toml", "an issue with the solver",
            "§3.6 of the book"]
    assert all(PATTERN.search(s) for s in bad)
    assert not any(PATTERN.search(s) for s in good)


def test_no_file_points_outside_the_repository():
    hits = offenders(_files())
    assert not hits, "references to notes outside the repository or to tracker numbers:\n" + "\n".join(hits[:40])
