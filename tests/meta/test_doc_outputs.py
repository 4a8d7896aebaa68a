"""The output the docs and the README show is the output the code prints (``_printed``).

Each console block's ``$ ema ...`` line that is followed by its output is run, in an
empty folder outside the repository as a user runs it, and its stdout (and, for a run
that ends with an error, its stderr: the one line) compared with the lines shown
(numbers within one unit of their last digit, or the fence's ``{rtol=...}``; ``...``
for what varies, a wall time); the ```text {output} blocks
are compared with the page's Python in ``test_doc_code_blocks``. A block whose run
takes longer than the suite allows says ``{slow}`` in its fence and is checked with the
slow studies (``make test-all``); before it, the page's ``$ python studies/...`` lines
run, as the page says.
"""

from __future__ import annotations

import shlex
import subprocess
import sys

import pytest
from _printed import console_runs, mismatch, options
from test_doc_code_blocks import NO_RUN, ROOT, TIMEOUT, _env, _pages, _workdir, blocks


def _cases():
    cases = []
    for page in _pages():
        for k, (lang, opts, code) in enumerate(blocks(page)):
            if lang != "console" or NO_RUN in opts:
                continue
            o = options(opts)
            for words, shown in console_runs(code):
                marks = [pytest.mark.slow] if o.get("slow") else []
                cases.append(pytest.param(page, words, shown, o.get("rtol", 0.0), bool(o.get("slow")), marks=marks,
                                          id=f"{page.relative_to(ROOT)}:{k}:{' '.join(words[:2])}"))
    return cases


_CASES = _cases()


def _setup_lines(page) -> list[list[str]]:
    """The page's ``$ python studies/...`` lines (the files a slow block reads)."""
    out = []
    for lang, _, code in blocks(page):
        for line in code.splitlines() if lang == "console" else ():
            words = shlex.split(line[2:], comments=True) if line.startswith("$ ") else []
            if words[:1] == ["python"] and len(words) > 1 and (ROOT / words[1]).is_file():
                out.append([sys.executable, str(ROOT / words[1]), *words[2:]])
    return out


def _ema(words: list[str], cwd, env) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "ema_casadi.cli", *words[1:]], cwd=cwd, capture_output=True,
                          text=True, timeout=TIMEOUT, env=env)


def test_every_printed_block_is_checked():
    """The README's and getting-started's printed blocks are among the checked ones (the
    pages a new user reads first)."""
    ids = [c.id for c in _CASES]
    assert any(i.startswith("README.md:") for i in ids)
    assert sum(i.startswith("docs/getting-started.md") for i in ids) >= 2


@pytest.mark.parametrize("page, words, shown, rtol, slow", _CASES)
def test_printed_output_matches_a_run(page, words, shown, rtol, slow, tmp_path):
    env, cwd = _env(tmp_path), _workdir(tmp_path)
    for setup in _setup_lines(page) if slow else ():
        subprocess.run(setup, cwd=cwd, check=True, capture_output=True, timeout=TIMEOUT, env=env)
    proc = _ema(words, cwd, env)
    # a refused or failed run shows its one line from stderr; a run that works shows its stdout
    err = mismatch(shown, proc.stdout + (proc.stderr if proc.returncode else ""), rtol)
    assert err is None, f"{page.relative_to(ROOT)}: '{' '.join(words)}' no longer prints what the page shows:\n{err}"


STALE = """\
loop margins (closed other loops; requirement GM and gain-reduction margin >= 6 dB at every phase crossover, ...)
  loop        GM dB    at Hz  GRM dB    at Hz  PM deg    at Hz  disk a  dGM dB dPM deg  ok
  position    35.84      180     inf -   76.07     13.7   1.246   12.68   63.83  yes
  velocity   -13.47     24.5     inf -   73.26     52.7   1.284   13.23   65.41  yes
...
"""


def test_a_stale_block_fails_the_check(tmp_path):
    """A block as the docs showed it before the margin convention changed (velocity GM
    -13.5 dB where the code prints GM inf and a gain-reduction margin) fails against a
    real run of ``ema margins``, with the line that differs; the same block with the
    current line passes (so the failure is the stale line, not the check)."""
    proc = _ema(["ema", "margins"], _workdir(tmp_path), _env(tmp_path))
    err = mismatch(STALE, proc.stdout)
    assert err is not None and "velocity" in err, err
    fresh = STALE.replace("velocity   -13.47     24.5     inf -", "velocity      inf -   13.47     24.5")
    assert mismatch(fresh, proc.stdout) is None


@pytest.mark.parametrize("page, run, verdict", [
    ("x 1.04e+03 Hz", "x 1.04e+03 Hz", None), ("x 1.04e+03 Hz", "x 1.06e+03 Hz", "1.06e+03"),
    ("a 13.5 dB", "a 13.6 dB", None), ("a 13.5 dB", "a 13.7 dB", "13.7"), ("a 13.5 dB", "a  13.5  dB", None),
    ("t in ... s", "t in 0.123 s", None), ("one\n...\nthree", "one\ntwo\n2b\nthree", None),
    ("one\nthree", "one\ntwo\nthree", "words differ"), ("GM -13.5 dB", "GM inf dB", "words differ"),
    ("one", "one\ntwo", "more lines"), ("one\ntwo", "one", "ends before"),
])
def test_the_comparison(page, run, verdict):
    """Words exact (spaces collapsed), numbers within a unit of the last digit shown
    (13.5 takes 13.4..13.6: a value on a digit's edge rounds either way), ``...`` for
    any text or lines."""
    err = mismatch(page, run)
    assert (err is None) if verdict is None else (err is not None and verdict in err), err


def test_a_stated_tolerance_widens_the_numbers():
    assert mismatch("1644 steps", "1690 steps") is not None
    assert mismatch("1644 steps", "1690 steps", rtol=0.05) is None
    assert options("{slow rtol=0.02}") == {"slow": True, "rtol": 0.02}


def test_the_readme_lists_the_parser_s_commands():
    """The README's command list is the parser's, in its order (a new command that the
    README leaves out, or a removed one it still names, fails here)."""
    import re

    from ema_casadi.cli._parser import build_parser

    text = (ROOT / "README.md").read_text(encoding="utf-8")
    listed = re.search(r"Commands, as `ema --help` lists them: (.*?);", text, re.S)
    assert listed, "README.md: no 'Commands, as `ema --help` lists them: ...;' line"
    assert re.findall(r"`([a-z-]+)`", listed.group(1)) == list(build_parser()[1])
