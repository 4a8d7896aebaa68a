"""The fitted parameter file: the input file's text with the estimates in place."""

from __future__ import annotations

import re
from pathlib import Path

from .._util._files import write_text

_LINE = re.compile(r"^(\s*)([A-Za-z_]\w*)(\s*=\s*\{\s*value\s*=\s*)([^,}]+?)(\s*,.*)$")
_TABLE = re.compile(r"^\s*\[([A-Za-z_]\w*)\]")


_VARIANT = re.compile(r'^(\s*)([A-Za-z_]\w*)(\s*=\s*)"[^"]*"(.*)$')


def write_fitted(params, values: dict, path: str | Path, header: str, variants: dict | None = None) -> Path:
    """The parameter file of ``params`` (its source text, layout and comments kept) with
    ``values`` (flat name -> SI) put in place; written atomically.

    Parameters
    ----------
    params : Parameters
        The set fitted (its ``source`` file is the template).
    values : dict
        Flat name -> new value (SI).
    path : str or Path
        Output file.
    header : str
        Comment lines written at the top.
    variants : dict, optional
        Variant and option choices to put in the ``[model]`` table (a structure chosen
        by comparison).
    """
    from ..model.params import GROUPS

    group_of = {f: g for g, cls in GROUPS.items() for f in cls.__dataclass_fields__}
    src = Path(str(params.source))
    comment = "".join(f"# {line}\n" for line in header.splitlines())
    if not src.is_file():
        return params.replace(**values).to_toml(path, header)
    lines = src.read_text(encoding="utf-8-sig").splitlines()
    table, done = None, set()
    variants = dict(variants or {})
    for i, line in enumerate(lines):
        m = _TABLE.match(line)
        if m:
            table = m.group(1)
            continue
        mv = _VARIANT.match(line)
        if table == "model" and mv and mv.group(2) in variants:
            lines[i] = f'{mv.group(1)}{mv.group(2)}{mv.group(3)}"{variants.pop(mv.group(2))}"{mv.group(4)}'
            continue
        m = _LINE.match(line)
        if m and m.group(2) in values and group_of.get(m.group(2)) == table:
            lines[i] = f"{m.group(1)}{m.group(2)}{m.group(3)}{float(values[m.group(2)])!r}{m.group(5)}"
            done.add(m.group(2))
    if variants:  # choices the [model] table does not name yet: added under its header
        at = next((i for i, line in enumerate(lines) if _TABLE.match(line) and _TABLE.match(line).group(1) == "model"),
                  None)
        new = [f'{k} = "{v}"  # chosen by the fit' for k, v in variants.items()]
        lines = (lines[: at + 1] + new + lines[at + 1 :]) if at is not None else ["[model]", *new, "", *lines]
    missing = [n for n in values if n not in done]
    if missing:  # keys the file does not set (defaults): written as the whole set instead
        return params.replace(**values).to_toml(path, header)
    return write_text(path, comment + "\n".join(lines) + "\n")
