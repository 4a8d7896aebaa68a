"""Printed output shown in the docs, against the output of a real run.

A page shows what a run prints in two ways:

- a console block (```console) whose ``$ ema ...`` line is followed by the lines it
  prints: the command is run and its stdout compared with those lines (a ``$`` line
  followed by no output is not run here: its command has its own tests);
- a ```text {output} block: the stdout of the page's ```python blocks, run as one
  script (the page's {output} blocks, in order, are the whole of it).

Comparison, line by line (:func:`mismatch`): the words must be equal (runs of spaces
count as one: a table's alignment follows its numbers' widths), each number within
its tolerance: one unit of the last digit shown (the rounding of a value that sits on a
digit's edge), or ``rtol`` of it where the fence says so (```console {rtol=0.02}: a
number that legitimately varies, an iteration count). ``...`` in a line stands for
any text (a wall time); a line that is only ``...`` for any number of lines.
"""

from __future__ import annotations

import re
import shlex

#: A number as the reports print it (``-13.5``, ``1.04e+03``, ``−0.57``).
NUMBER = r"[-+\u2212]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_NUMBER = re.compile(NUMBER)
_ANY_LINES = "..."


def options(info: str) -> dict:
    """The ``{key=value ...}`` options of a fence (``{output rtol=0.02}`` ->
    ``{"output": True, "rtol": 0.02}``)."""
    out: dict = {}
    for word in re.findall(r"\{([^}]*)\}", info):
        for part in word.split():
            key, eq, value = part.partition("=")
            out[key] = float(value) if eq else True
    return out


def console_runs(code: str) -> list[tuple[list[str], str]]:
    """(the command's words, the output shown) of each ``$ ema`` line of a console
    block that is followed by output (a line ending in ``\\`` continues)."""
    runs, lines, k = [], code.splitlines(), 0
    while k < len(lines):
        line = lines[k]
        if not line.startswith("$ "):
            k += 1
            continue
        command = line[2:]
        while command.endswith("\\") and k + 1 < len(lines):
            k += 1
            command = command[:-1] + " " + lines[k].strip()
        k += 1
        shown = []
        while k < len(lines) and not lines[k].startswith("$ "):
            shown.append(lines[k])
            k += 1
        words = shlex.split(command, comments=True)
        if words[:1] == ["ema"] and any(s.strip() for s in shown):
            runs.append((words, "\n".join(shown)))
    return runs


def _digit_unit(text: str) -> float:
    """One unit of the last digit of a printed number (``13.47`` -> 0.01, ``1.04e+03`` -> 10)."""
    mantissa, _, exponent = text.lower().partition("e")
    decimals = len(mantissa.partition(".")[2])
    return 10.0 ** (int(exponent or 0) - decimals)


def _value(text: str) -> float:
    return float(text.replace("\u2212", "-"))


def _line_pattern(expected: str) -> tuple[re.Pattern, list[str]]:
    """The regular expression of an expected line (its numbers captured) and the numbers."""
    parts, numbers, pos = [], [], 0
    for m in _NUMBER.finditer(expected):
        parts.append(expected[pos:m.start()])
        numbers.append(m.group())
        pos = m.end()
    parts.append(expected[pos:])
    regex = ""
    for k, text in enumerate(parts):
        words = [re.escape(w) for w in re.split(r"\s+", text)]
        regex += r"\s+".join(words).replace(re.escape("..."), ".*?")
        if k < len(numbers):
            regex += f"({NUMBER})"
    return re.compile(regex), numbers


def _line_error(expected: str, actual: str, rtol: float) -> str | None:
    pattern, numbers = _line_pattern(expected.strip())
    m = pattern.fullmatch(actual.strip())
    if m is None:
        return "the words differ"
    for want, got in zip(numbers, m.groups(), strict=True):
        tol = max(_digit_unit(want), rtol * abs(_value(want)))
        if abs(_value(got) - _value(want)) > tol * (1 + 1e-9):
            return f"{got} where the page shows {want} (tolerance {tol:.3g})"
    return None


def mismatch(expected: str, actual: str, rtol: float = 0.0) -> str | None:
    """None if ``actual`` (a run's stdout) matches the ``expected`` block, else the first
    difference, one line.

    Parameters
    ----------
    expected : str
        The block as the page shows it.
    actual : str
        What the run printed.
    rtol : float
        Relative tolerance of every number (beyond one unit of its last digit).
    """
    want = [ln.rstrip() for ln in expected.strip("\n").splitlines()]
    got = [ln.rstrip() for ln in actual.strip("\n").splitlines()]
    best: list = [None]

    def match(i: int, j: int) -> bool:
        if i == len(want):
            ok = j == len(got)
            if not ok and best[0] is None:
                best[0] = f"the run prints more lines from: {got[j]!r}"
            return ok
        if want[i].strip() == _ANY_LINES:
            return any(match(i + 1, jj) for jj in range(j, len(got) + 1))
        if j == len(got):
            best[0] = best[0] or f"the run ends before the page's line {want[i]!r}"
            return False
        err = _line_error(want[i], got[j], rtol)
        if err is not None:
            best[0] = best[0] or f"page {want[i].strip()!r}\n  run  {got[j].strip()!r}: {err}"
            return False
        return match(i + 1, j + 1)

    return None if match(0, 0) else best[0]
