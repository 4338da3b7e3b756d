"""What every reader returns: a recording's variables, and role-map expressions resolved against them.

Two kinds of source:

* a **table** (CSV, Parquet, text log): named columns of one length; a role names a column, with or
  without the unit in its header (``i [A]`` or ``i``);
* a **tree** (MATLAB files): variables that are matrices or structs (dicts), navigated by an
  expression ``NAME(.FIELD | [INDEX, ...])*``, e.g. ``rec.act_torque_abs_nm[:,0]`` or ``data[:,3]``.
  Indices are Python's (0-based, ``:``, ``a:b``, negative from the end). 2-D matrices are held
  samples-first: a matrix stored with fewer rows than columns (MATLAB loggers often write one channel
  per row) is transposed, so that ``[:, k]`` is channel ``k`` in both layouts; ``cosim info`` says so.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from feeddrive.cosim.errors import DataError


@dataclass(frozen=True)
class Variable:
    """One entry of ``cosim info``: a column, a matrix or a struct field.

    Attributes
    ----------
    name : str
        As a role map names it (``rec.act_torque_abs_nm``, ``u [V]``).
    shape : tuple of int
        Samples-first shape.
    dtype : str
        ``float64``, ``int32``, ``text``, ``struct`` ...
    unit : str
        Unit from the header or the file's metadata, ``""`` when the file states none.
    note : str
        E.g. ``stored 6 x 2501`` for a transposed matrix.
    """

    name: str
    shape: tuple[int, ...]
    dtype: str
    unit: str = ""
    note: str = ""


@dataclass(frozen=True)
class Signal:
    """A resolved role: ``values`` shape (n,), float, as stored (no unit conversion yet).

    ``label`` names it in messages; ``unit`` is its declared unit (``""`` when none); ``absolute`` is true
    for time stamps that are calendar times: ``values`` are then seconds after ``origin`` [s since
    1970-01-01 UTC] (counted from the first stamp, so that float64 keeps sub-microsecond steps).
    """

    label: str
    values: np.ndarray
    unit: str = ""
    absolute: bool = False
    origin: float = 0.0


class Source:
    """Base of the readers: ``path``, a one-line ``kind``, ``variables()`` and ``resolve(expr, role)``."""

    path: Path
    kind: str = ""

    def variables(self) -> list[Variable]:  # pragma: no cover - every reader overrides
        raise NotImplementedError

    def resolve(self, expr: str, role: str) -> Signal:  # pragma: no cover - every reader overrides
        raise NotImplementedError

    def locate(self, signal: Signal, r: int) -> str:
        """Where sample ``r`` of ``signal`` is in the file, for messages."""
        return f"{signal.label!r} sample {r}: {float(signal.values[r])!r}"

    def names(self) -> str:
        """The variables as a short list for error messages."""
        items = [f"{v.name} {tuple(v.shape)}" if len(v.shape) > 1 else v.name for v in self.variables()
                 if v.dtype != "struct"]
        more = f" ... ({len(items) - 40} more; see cosim info)" if len(items) > 40 else ""
        return ", ".join(items[:40]) + more


def samples_first(a: np.ndarray) -> tuple[np.ndarray, str]:
    """A numeric matrix with samples along its first axis, and a note when it was transposed.

    1-row and 1-column matrices become vectors (MATLAB has no vectors).
    """
    if a.ndim == 2 and 1 in a.shape:
        return a.reshape(-1), ""
    if a.ndim == 2 and a.shape[0] < a.shape[1]:
        return a.T, f"stored {a.shape[0]} x {a.shape[1]}"
    return a, ""


_STEP = re.compile(r"\.\s*([A-Za-z_]\w*)|\[([^\[\]]*)\]")
_NAME = re.compile(r"\s*([A-Za-z_]\w*)")


def _index(text: str, expr: str, where: str) -> tuple[int | slice, ...]:
    """``":,0"`` -> ``(slice(None), 0)``."""
    out: list[int | slice] = []
    for part in text.split(","):
        part = part.strip()
        try:
            if ":" in part:
                bits = [b.strip() for b in part.split(":")]
                if len(bits) > 3:
                    raise ValueError
                out.append(slice(*[int(b) if b else None for b in bits]))
            else:
                out.append(int(part))
        except ValueError:
            raise DataError(f"{where}: {expr!r}: index [{text}] is not a list of integers or ':' "
                            "(0-based, e.g. [:,0])") from None
    return tuple(out)


def resolve_tree(tree: dict, expr: str, role: str, path: Path, listing: str) -> tuple[np.ndarray, str]:
    """Follow ``expr`` through a tree of dicts (structs), object arrays (struct arrays) and matrices.

    Returns the value reached (any shape) and the expression as written. Every failure is a DataError
    naming the file, the role and what exists (``listing``).
    """
    where = f"{path}: role {role}"
    m = _NAME.match(expr)
    if not m:
        raise DataError(f"{where}: {expr!r} is not a variable expression (NAME, NAME.FIELD, NAME[:,k]); "
                        f"variables are {listing}")
    name = m.group(1)
    if name not in tree:
        raise DataError(f"{where}: no variable {name!r}; variables are {listing}")
    value, done, pos = tree[name], name, m.end()
    while pos < len(expr.rstrip()):
        step = _STEP.match(expr, pos)
        if not step:
            raise DataError(f"{where}: {expr!r}: cannot read {expr[pos:]!r} after {done!r} (expected .FIELD or "
                            f"[INDEX]); variables are {listing}")
        field, index = step.groups()
        if field is not None:
            if isinstance(value, np.ndarray) and value.dtype == object and value.size == 1:
                value = value.reshape(-1)[0]  # a 1 x 1 struct array
            if isinstance(value, np.ndarray) and value.dtype == object and value.size > 1:
                raise DataError(f"{where}: {done!r} is a struct array of shape {value.shape}; index it first, "
                                f"e.g. {done}[0].{field}")
            if not isinstance(value, dict):
                raise DataError(f"{where}: {done!r} is not a struct (no field {field!r})")
            if field not in value:
                raise DataError(f"{where}: {done!r} has no field {field!r}; its fields are {', '.join(value)}")
            value = value[field]
        else:
            arr = np.asarray(value) if not isinstance(value, dict) else None
            if arr is None:
                raise DataError(f"{where}: {done!r} is a struct; name a field ({', '.join(value)})")
            idx = _index(index, expr, where)
            if len(idx) > arr.ndim:
                raise DataError(f"{where}: {expr!r}: {len(idx)} indices for {done!r} of shape {arr.shape}")
            for axis, k in enumerate(idx):
                if isinstance(k, int) and not -arr.shape[axis] <= k < arr.shape[axis]:
                    raise DataError(f"{where}: {expr!r}: index {k} out of range for {done!r} of shape "
                                    f"{arr.shape} (0-based)")
            try:
                value = arr[idx]
            except (IndexError, ValueError) as exc:  # e.g. a zero slice step
                raise DataError(f"{where}: {expr!r}: {exc}") from None
        done = expr[:step.end()].strip()
        pos = step.end()
    return value, done


def as_signal(value: object, label: str, where: str) -> np.ndarray:
    """A resolved value as a float vector shape (n,), or a DataError saying what it is instead."""
    if isinstance(value, dict):
        raise DataError(f"{where}: {label!r} is a struct; name one of its fields ({', '.join(value)})")
    arr = np.asarray(value)
    if arr.dtype == object or arr.dtype.kind not in "biuf":
        kind = "cells or a struct array (index it: NAME[k].FIELD)" if arr.dtype == object else ("text" if arr.dtype.kind in "US" else arr.dtype.name)
        raise DataError(f"{where}: {label!r} holds {kind}, expected numbers")
    if arr.ndim > 1 and sum(s > 1 for s in arr.shape) <= 1:
        arr = arr.reshape(-1)
    if arr.ndim == 0:
        raise DataError(f"{where}: {label!r} is a single value; expected a signal (one value per sample)")
    if arr.ndim != 1:
        example = f"{label}[:,0]" if arr.ndim == 2 and "[" not in label else "NAME[:,k] with one index per dimension"
        raise DataError(f"{where}: {label!r} has shape {arr.shape}; expected one column, e.g. {example}")
    return arr.astype(float)


def tree_variables(tree: dict, notes: dict[str, str], prefix: str = "") -> list[Variable]:
    """``cosim info`` rows of a tree, struct fields as ``parent.field``."""
    out = []
    for name, value in tree.items():
        full = f"{prefix}{name}"
        if isinstance(value, dict):
            out.append(Variable(full, (len(value),), "struct", note=f"fields: {', '.join(value)}"))
            out += tree_variables(value, notes, full + ".")
            continue
        arr = np.asarray(value)
        if arr.dtype == object and arr.size and all(isinstance(x, dict) for x in arr.flat):
            fields = ", ".join(next(iter(arr.flat)))
            out.append(Variable(full, tuple(arr.shape), "struct array", note=f"{full}[k].FIELD, fields: {fields}"))
            continue
        dtype = "text" if arr.dtype.kind in "US" else ("cells" if arr.dtype == object else arr.dtype.name)
        out.append(Variable(full, tuple(arr.shape), dtype, note=notes.get(full, "")))
    return out


class TableSource(Source):
    """Named columns of one length, already numeric (Parquet, text logs).

    ``columns``: name -> values shape (n,); ``units``: name -> declared unit; ``absolute``: calendar-time column
    name -> its origin [s since 1970] (the column holds seconds after it). A role names a column with or without its bracketed unit.
    """

    def __init__(self, path: Path, kind: str, columns: dict[str, np.ndarray], units: dict[str, str],
                 absolute: dict[str, float] | None = None, skipped: dict[str, str] | None = None) -> None:
        self.path, self.kind, self.columns, self.units = path, kind, columns, units
        self.absolute = absolute or {}
        self.skipped = skipped or {}
        self.index: dict[str, str] = {}
        for name in columns:
            self.index.setdefault(name, name)
            self.index.setdefault(re.sub(r"\s*[\[(][^\])]*[\])]\s*$", "", name), name)

    def resolve(self, expr: str, role: str) -> Signal:
        name = self.index.get(expr.strip()) or self.index.get(re.sub(r"\s*[\[(][^\])]*[\])]\s*$", "", expr.strip()))
        if name is None:
            why = f" ({self.skipped[expr.strip()]})" if expr.strip() in self.skipped else ""
            raise DataError(f"{self.path}: column {expr!r} (role {role}) not found{why}; columns are "
                            f"{list(self.columns)}")
        return Signal(name, np.asarray(self.columns[name], dtype=float), self.units.get(name, ""),
                      name in self.absolute, self.absolute.get(name, 0.0))

    def variables(self) -> list[Variable]:
        out = [Variable(k, v.shape, "datetime" if k in self.absolute else v.dtype.name, self.units.get(k, ""))
               for k, v in self.columns.items()]
        return out + [Variable(k, (), "-", note=why) for k, why in self.skipped.items()]
