"""Every code block of README.md and of the documentation (``docs/**/*.md``) runs.

The ```python blocks of one page run in order as one script (a page reads like a
notebook: a later block may use what an earlier one defined), in a fresh process and
an empty temporary folder outside the repository, as a user who installed the package
runs them: no ``models/`` beside them (the docs load the packaged reference set,
``ema.load_parameters()``), and the user's PYTHONPATH replaced by the folder of the
package under test alone (the installed one, or the working tree being tested). A
block that is not meant to run says so in its fence, ```python {no-run} (keep those
rare); what the page shows them printing, in ```text {output} blocks, is what they
print (compared as ``_printed.mismatch`` says). Console blocks (```sh, ```console,
```shell) run the lines that call ``ema ... --help`` or ``ema --version``: each must
exit 0; the commands that do real work are covered by their own tests, and none names
``models/``; a console block's printed output is checked against a run in
``test_doc_outputs.py``.

The pages' code is written with short runs, so the whole test stays within tens of
seconds (each page is allowed ``TIMEOUT`` seconds, generous for a loaded machine).
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
#: Seconds one page's code may take (the slowest page measured ~10 s on the 2-core machine).
TIMEOUT = 240
_FENCE = re.compile(r"^(?P<indent> {0,3})(?P<fence>`{3,}|~{3,})(?P<info>[^\n`]*)\n"
                    r"(?P<body>.*?)^(?P=indent)(?P=fence)[ \t]*$", re.M | re.S)
NO_RUN = "{no-run}"
#: The fence of a ```text block that shows what the page's ```python blocks print.
OUTPUT = "{output}"
_CONSOLE = ("sh", "console", "shell", "bash")
#: The longest line of code a page shows (a wider one runs off behind a horizontal scroll).
LINE_LIMIT = 88


def _pages() -> list[Path]:
    docs = sorted(p for p in (ROOT / "docs").rglob("*.md") if "_build" not in p.parts)
    return [ROOT / "README.md", *docs]


def blocks(path: Path) -> list[tuple[str, str, str]]:
    """(language, options, code) of every fenced block of a Markdown file.

    Parameters
    ----------
    path : Path
        The Markdown file.
    """
    out = []
    for m in _FENCE.finditer(path.read_text(encoding="utf-8")):
        lang, _, options = m.group("info").strip().partition(" ")
        out.append((lang.strip().lower(), options.strip(), m.group("body")))
    return out


def _python(path: Path) -> str:
    return "\n".join(code for lang, opts, code in blocks(path) if lang == "python" and NO_RUN not in opts)


def _help_lines(path: Path) -> list[str]:
    lines = []
    for lang, opts, code in blocks(path):
        if lang not in _CONSOLE or NO_RUN in opts:
            continue
        for line in code.splitlines():
            line = line.strip().removeprefix("$ ").split("#")[0].strip()
            words = line.split()
            if words[:1] == ["ema"] and ("--help" in words or "--version" in words):
                lines.append(line)
    return lines


def _ids(pages):
    return [str(p.relative_to(ROOT)) for p in pages]


_CODE_PAGES = [p for p in _pages() if _python(p)]
_HELP_PAGES = [p for p in _pages() if _help_lines(p)]


def _workdir(tmp_path: Path) -> Path:
    assert ROOT not in tmp_path.resolve().parents, "the pages' code must run outside the repository"
    return tmp_path


def _env(tmp_path: Path) -> dict:
    """The environment of a page's code: the package under test and nothing else on the
    path (a folder holding only a link to the package: not the repository root, whose
    studies/, tests/ and models/ a user does not have)."""
    import ema_casadi

    site = tmp_path.parent / f"{tmp_path.name}_site"
    site.mkdir(exist_ok=True)
    link = site / "ema_casadi"
    if not link.exists():
        link.symlink_to(Path(ema_casadi.__file__).resolve().parent, target_is_directory=True)
    env = dict(os.environ, MPLBACKEND="Agg")
    env["PYTHONPATH"] = str(site)
    return env


def test_the_fence_parser_finds_blocks_and_options(tmp_path):
    """The extractor itself: language, the no-run option and the code, and nothing from
    prose between the fences (so a page whose blocks it missed would not pass silently)."""
    page = tmp_path / "page.md"
    page.write_text("text\n\n```python\nx = 1\n```\n\nmore `inline`\n\n```python {no-run}\nboom()\n```\n\n"
                    "```sh\nema --help\nls\n```\n", encoding="utf-8")
    assert blocks(page) == [("python", "", "x = 1\n"), ("python", "{no-run}", "boom()\n"),
                            ("sh", "", "ema --help\nls\n")]
    assert _python(page) == "x = 1\n"
    assert _help_lines(page) == ["ema --help"]


def test_the_readme_and_the_guide_have_code_to_run():
    """The README's API taste and the guide's pages are among the pages run below."""
    names = _ids(_CODE_PAGES)
    assert "README.md" in names
    assert sum(n.startswith("docs/guide/") for n in names) >= 5


def test_no_example_reads_the_repository_s_models_folder():
    """The pages' Python and their ``ema`` commands load the packaged files
    (``ema.load_parameters()``, the commands' defaults), never ``models/...``, which a
    user who installed the package does not have."""
    bad = []
    for page in _pages():
        for lang, _, code in blocks(page):
            lines = code.splitlines() if lang == "python" else \
                [ln for ln in code.splitlines() if ln.strip().removeprefix("$ ").startswith("ema ")] \
                if lang in _CONSOLE else []
            bad += [f"{page.relative_to(ROOT)}: {ln.strip()}" for ln in lines if "models/" in ln]
    assert not bad, bad


@pytest.mark.parametrize("page", _CODE_PAGES, ids=_ids(_CODE_PAGES))
def test_python_blocks_run(page, tmp_path):
    """The page's ```python blocks, as one script, exit 0 (its stderr is the message)."""
    script = _workdir(tmp_path) / "page_code.py"
    script.write_text(_python(page), encoding="utf-8")
    proc = subprocess.run([sys.executable, script.name], cwd=tmp_path, capture_output=True, text=True,
                          timeout=TIMEOUT, env=_env(tmp_path))
    assert proc.returncode == 0, f"{page.relative_to(ROOT)}: its code failed:\n{proc.stderr[-3000:]}"
    # the docs' examples step inside RK4's stability limit (a run above it warns on stderr)
    assert "StepLimitWarning" not in proc.stderr, f"{page.relative_to(ROOT)}: {proc.stderr[-3000:]}"
    shown = "".join(code for lang, opts, code in blocks(page) if lang == "text" and OUTPUT in opts)
    if shown:  # what the page says its code prints is what it printed (tests/meta/_printed.py)
        from _printed import mismatch

        err = mismatch(shown, proc.stdout)
        assert err is None, f"{page.relative_to(ROOT)}: its code no longer prints what the page shows:\n{err}"


@pytest.mark.parametrize("page", _HELP_PAGES, ids=_ids(_HELP_PAGES))
def test_help_commands_run(page, tmp_path):
    """Each ``ema ... --help`` / ``ema --version`` line of the page exits 0 and prints."""
    ema, cwd = [sys.executable, "-m", "ema_casadi.cli"], _workdir(tmp_path)
    for line in _help_lines(page):
        proc = subprocess.run(ema + shlex.split(line)[1:], cwd=cwd, capture_output=True,
                              text=True, timeout=60, env=_env(tmp_path))
        assert proc.returncode == 0 and proc.stdout.strip(), f"{page.relative_to(ROOT)}: '{line}' failed: {proc.stderr}"


def _typed_lines(lang: str, code: str) -> list[str]:
    """The lines of a block a reader types or reads as code: every line of a Python,
    shell or TOML block; of a console block the ``$`` lines and their continuations
    (what a command prints is shown as it prints it)."""
    if lang in ("python", "sh", "shell", "bash", "toml"):
        return code.splitlines()
    out, going_on = [], False
    for line in code.splitlines() if lang == "console" else ():
        if line.startswith("$ ") or going_on:
            out.append(line)
        going_on = (line.startswith("$ ") or going_on) and line.endswith("\\")
    return out


def test_code_lines_are_short():
    """No line of code in the README or the docs is longer than LINE_LIMIT characters:
    a trailing comment goes on its own line above, a long call is wrapped."""
    long = [f"{page.relative_to(ROOT)}: {len(line)}: {line.strip()[:60]}"
            for page in _pages() for lang, _, code in blocks(page) for line in _typed_lines(lang, code)
            if len(line) > LINE_LIMIT]
    assert not long, "\n".join(long)


def test_the_line_check_reads_console_commands_only():
    assert _typed_lines("console", "$ ema a \\\n    --b c\nprinted " + "x" * 100 + "\n") == ["$ ema a \\", "    --b c"]
    assert _typed_lines("text", "anything") == []
