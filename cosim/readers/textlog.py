"""Whitespace-separated text logs whose header lines are comments (``%`` or ``#``).

Loggers such as the REGBOT client describe their columns in comment lines that start with the
column numbers (1-based)::

    %  1    time 0.000 sec
    %  7  8 Motor voltage [V] left, right: 0.0 0.0

which gives the columns ``time`` and ``Motor voltage left`` / ``Motor voltage right`` [V]. Columns that
no comment names are ``colK`` (1-based); ``colK`` also works for every column.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from feeddrive.cosim.errors import DataError
from feeddrive.cosim.readers.csvfile import read_text
from feeddrive.cosim.readers.source import TableSource

_NUMBERED = re.compile(r"^[%#]+\s*((?:\d+\s+)+)(.*)$")
_NUMBER = re.compile(r"^[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$")


def _names(k: list[int], text: str) -> list[tuple[str, str]]:
    """``(name, unit)`` of the columns ``k`` from a comment's text (unit ``""`` when none).

    A bracketed unit belongs to its own item when every item has one (``voltage [V], current [A]``),
    else to all (``Motor voltage [V] left, right``).
    """
    def unit_of(part: str) -> str:
        m = re.search(r"\[([^\]]*)\]", part)
        return m.group(1).strip() if m else ""

    def strip(part: str) -> str:
        return re.sub(r"\s*\[[^\]]*\]", "", part).strip()

    if ":" not in text:
        words = strip(text).split()
        cut = next((j for j, w in enumerate(words) if _NUMBER.match(w.strip("(),"))), len(words))
        if len(k) == 1:  # 'time 0.000 sec': the name before the value, the word after it is its unit
            unit = unit_of(text) or (words[cut + 1] if cut + 1 < len(words) else "")
            return [(" ".join(words[:cut]), unit)]
        # '(mission 0), state 2, thread 1, line 0': the last len(k) items, their values dropped
        items = [" ".join(w for w in it.split() if not _NUMBER.match(w.strip("()"))).strip("() ")
                 for it in strip(text).split(",")]
        items = [it for it in items if it]
        if len(items) >= len(k):
            return [(it, unit_of(text)) for it in items[-len(k):]]
        return [(f"{strip(text)} {j + 1}", unit_of(text)) for j in range(len(k))]
    desc = text.split(":", 1)[0]
    parts = desc.split(",")
    own = len(parts) == len(k) and all(unit_of(p) for p in parts)
    units = [unit_of(p) for p in parts] if own else [unit_of(desc)] * len(k)
    items = [strip(p) for p in parts]
    if len(k) == 1:
        return [(strip(desc), units[0])]
    if len(items) == len(k) and items[0].split():  # 'Motor voltage left, right' -> 'Motor voltage right'
        words = items[0].split()
        prefix = " ".join(words[:-1])
        names = [items[0]] + [f"{prefix} {it}".strip() for it in items[1:]]
        return list(zip(names, units))
    return [(f"{strip(desc)} {j + 1}", units[0]) for j in range(len(k))]


def read_text_log(path: Path, max_bytes: int | None = None) -> TableSource:
    text = read_text(path, "text log", max_bytes)
    comments, rows, first = [], [], None
    for line_no, line in enumerate(text.splitlines(), 1):
        s = line.strip()
        if not s:
            continue
        if s[0] in "%#":
            comments.append(s)
            continue
        fields = s.split()
        if first is None:
            first = len(fields)
        elif len(fields) != first:
            raise DataError(f"{path}: line {line_no}: {len(fields)} fields, expected {first} as in the first data "
                            f"line{' (a truncated last line?)' if line_no == len(text.splitlines()) else ''}")
        try:
            rows.append([float(f) for f in fields])
        except ValueError:
            bad = next(f for f in fields if not _is_float(f))
            raise DataError(f"{path}: line {line_no}: {bad!r} is not a number; expected whitespace-separated "
                            "numbers after the comment lines") from None
    if not rows:
        raise DataError(f"{path}: no data lines (only comments or empty); expected whitespace-separated numbers")
    data = np.array(rows)
    n_col = data.shape[1]
    names: dict[int, str] = {}
    units: dict[int, str] = {}
    for c in comments:
        m = _NUMBERED.match(c)
        if not m:
            continue
        k = [int(x) for x in m.group(1).split()]
        if not all(1 <= j <= n_col for j in k):
            continue
        for j, (name, unit) in zip(k, _names(k, m.group(2))):
            if j not in names:
                names[j], units[j] = name, unit
    columns, unit_of = {}, {}
    for j in range(1, n_col + 1):
        name = names.get(j, f"col{j}")
        if name in columns or not name:
            name = f"col{j}"
        columns[name] = data[:, j - 1]
        unit_of[name] = units.get(j, "")
    table = TableSource(path, f"text log ({n_col} columns, {len(comments)} comment lines)", columns, unit_of)
    for j, name in enumerate(columns, 1):  # colK names every column too
        table.index.setdefault(f"col{j}", name)
    return table


def _is_float(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True
