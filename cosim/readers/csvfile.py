"""CSV recordings: one header row, ``,`` ``;`` or tab separated, decimal point or comma (detected).

Column headers may carry a unit in brackets (``i [A]``); a column is found with or without it. A time
column may hold ISO 8601 time stamps (``2024-03-01T10:00:00.004``) instead of seconds.
"""
from __future__ import annotations

import codecs
import csv
import datetime as _dt
import io
import re
from operator import itemgetter
from pathlib import Path

import numpy as np

from feeddrive.cosim.errors import DataError
from feeddrive.cosim.readers.source import Signal, Source, Variable

#: Largest CSV file read [bytes] (the rows are held in memory as text, ~10 times the file's size).
MAX_BYTES = 512 << 20
DELIMITERS = {",": ",", ";": ";", "tab": "\t", "\\t": "\t", "\t": "\t"}


def bare(header: str) -> str:
    """Header without a trailing unit: ``"i [A]"`` -> ``"i"``."""
    return re.sub(r"\s*[\[(][^\])]*[\])]\s*$", "", header.strip())


def unit_text(header: str) -> str | None:
    """The unit in a header's trailing brackets (``"pos [mm]"`` -> ``"mm"``), or None."""
    m = re.search(r"[\[(]([^\])]*)[\])]\s*$", header.strip())
    return m.group(1).strip() if m else None


def dialect(text: str, delimiter: str | None, decimal: str | None, path: Path) -> tuple[str, str]:
    """The separator and decimal mark: given, or detected from the header and the first rows.

    A header that splits into more fields on ``;`` or tab than on ``,`` uses that separator (European
    spreadsheet exports use ``;`` with a decimal comma); the decimal mark is a comma when the
    separator is not and the first rows hold numbers like ``1,5``.
    """
    if delimiter is not None:
        if delimiter not in DELIMITERS:
            raise DataError(f"{path}: --delimiter {delimiter!r}; expected one of ',', ';', 'tab'")
        delimiter = DELIMITERS[delimiter]
    head = text.splitlines()[:20]

    def fields(line: str, sep: str) -> list[str]:
        try:
            return next(csv.reader([line], delimiter=sep), [])
        except csv.Error:  # a NUL byte or an oversized field: the full read names its line
            return []

    if delimiter is None:
        header = head[0] if head else ""
        counts = {d: len(fields(header, d)) for d in (",", ";", "\t")}
        delimiter = max(counts, key=lambda d: (counts[d], d == ","))
    # pandas' to_csv(decimal=",") with the default separator quotes every such cell: "0,5","1,25"
    quoted = any('"' in line for line in head[1:])
    if decimal is None:
        sample = [c.strip() for line in head[1:] for c in fields(line, delimiter)]
        comma = any(re.fullmatch(r"[-+]?\d*,\d+([eE][-+]?\d+)?", c) for c in sample)
        # quoted with a comma separator, "1,234" beside "0.5" is a thousands separator: taken as no decimal comma
        dots = quoted and any(re.fullmatch(r"[-+]?\d*\.\d+([eE][-+]?\d+)?", c) for c in sample)
        decimal = "," if comma and (delimiter != "," or (quoted and not dots)) else "."
    if decimal not in (".", ","):
        raise DataError(f"{path}: --decimal {decimal!r}; expected '.' or ','")
    if decimal == delimiter and not (decimal == "," and quoted):
        raise DataError(f"{path}: the decimal mark and the separator are both {decimal!r}; expected different ones "
                        "(or the cells in quotes)")
    return delimiter, decimal


def read_text(path: Path, what: str, max_bytes: int | None = None) -> str:
    """The file as UTF-8 text (a byte-order mark dropped), refusing files over ``max_bytes`` (MAX_BYTES)."""
    return read_utf8(path, what, max_bytes)[0]


def read_utf8(path: Path, what: str, max_bytes: int | None = None) -> tuple[str, bytes]:
    """The file as UTF-8 text and as its bytes, both without a byte-order mark, refusing files over
    ``max_bytes`` (MAX_BYTES)."""
    size, limit = path.stat().st_size, MAX_BYTES if max_bytes is None else max_bytes
    if size > limit:
        raise DataError(f"{path}: {size} bytes; expected a {what} file of at most {limit} bytes "
                        "(split the recording)")
    raw = path.read_bytes()
    if raw.startswith(codecs.BOM_UTF8):  # spreadsheet exports: it must not end up in the first header
        raw = raw[len(codecs.BOM_UTF8):]
    try:
        return raw.decode("utf-8"), raw
    except UnicodeDecodeError as exc:
        line = raw[:exc.start].count(b"\n") + 1
        raise DataError(f"{path}: line {line}: byte 0x{exc.object[exc.start]:02x} is not UTF-8; "
                        f"expected a UTF-8 {what} file") from None


def iso_time(cell: str) -> _dt.datetime | None:
    """An ISO 8601 time stamp (naive ones taken as UTC), else None."""
    try:
        t = _dt.datetime.fromisoformat(cell.strip().replace("Z", "+00:00"))
    except ValueError:
        return None
    return t if t.tzinfo is not None else t.replace(tzinfo=_dt.timezone.utc)


def arrow_numbers(raw: bytes, sep: str, dec: str) -> tuple[int, dict[int, np.ndarray]] | None:
    """The number of data rows and the numeric columns, by index, of a CSV file's UTF-8 bytes, by Arrow's C++ reader.

    Only columns whose every cell Arrow read as a number (float64 or int64: correctly rounded, so the same
    values as ``float(cell)``) are returned; the others (text, time stamps, an empty cell, ``-0``, ...) are
    left to the csv module's path, which names a bad cell's row. Empty lines are kept, not skipped, so a
    column with a numeric type has no empty row and the row count is the csv module's. Returns None where
    Arrow cannot read the file at all (rows of different lengths, no header, ...). Ten times the csv
    module's speed on one thread (one thread: a campaign's zygote forks runs and must stay single-threaded).
    """
    import pyarrow as pa
    import pyarrow.csv as pcsv

    try:
        table = pcsv.read_csv(
            pa.BufferReader(raw),
            read_options=pcsv.ReadOptions(use_threads=False),
            parse_options=pcsv.ParseOptions(delimiter=sep, ignore_empty_lines=False),
            convert_options=pcsv.ConvertOptions(null_values=[], strings_can_be_null=False, decimal_point=dec))
    except (pa.ArrowException, ValueError):
        return None
    out = {}
    for k, field in enumerate(table.schema):
        if pa.types.is_float64(field.type) or pa.types.is_int64(field.type):
            out[k] = table.column(k).to_numpy().astype(float)  # a writable copy
    return table.num_rows, out


class CsvSource(Source):
    """A CSV file as a table of columns, converted to numbers column by column when a role asks."""

    def __init__(self, path: Path, delimiter: str | None = None, decimal: str | None = None,
                 max_bytes: int | None = None) -> None:
        self.path = path
        self._text, raw = read_utf8(path, "CSV", max_bytes)
        self.sep, self.dec = dialect(self._text, delimiter, decimal, path)
        self._rows: list[list[str]] | None = None
        #: an empty cell is a missing value (NaN) rather than an error naming it (``load_recording(missing="drop")``)
        self.empty_missing = False
        #: the columns Arrow's reader parsed as numbers, by index (None: it could not read the file)
        arrow = arrow_numbers(raw, self.sep, self.dec)
        self._numbers = None if arrow is None else arrow[1]
        if arrow is None:
            header = self._read_rows()  # the csv module names the line of whatever stopped Arrow
        else:
            header = next(csv.reader(io.StringIO(self._text, newline=""), delimiter=self.sep))
            self.n_rows = arrow[0]
        self.header = [h.strip() for h in header]
        self.index: dict[str, int] = {}
        #: name without its unit -> the headers it names (``I`` -> ``I [A]``, ``I [mA]``: a converted copy beside it)
        self.named: dict[str, list[str]] = {}
        for k, h in enumerate(self.header):
            self.index.setdefault(h, k)
            self.index.setdefault(bare(h), k)
            self.named.setdefault(bare(h), []).append(h)
        sep = {"\t": "tab"}.get(self.sep, self.sep)
        self.kind = f"CSV ('{sep}' separated, decimal '{self.dec}')"

    def _read_rows(self) -> list[str]:
        """Every row as text (the csv module); returns the header row. Done once, when a column needs it."""
        reader = csv.reader(io.StringIO(self._text, newline=""), delimiter=self.sep)
        try:
            rows = list(reader)
        except csv.Error as exc:  # a NUL byte, a field over the csv module's limit
            raise DataError(f"{self.path}: line {reader.line_num}: {exc}; expected a CSV text file") from None
        while rows and not any(c.strip() for c in rows[-1]):
            rows.pop()  # trailing empty lines
        if not rows:
            raise DataError(f"{self.path}: empty file, expected a header row")
        self._rows, self.n_rows = rows[1:], len(rows) - 1
        return rows[0]

    @property
    def rows(self) -> list[list[str]]:
        """The data rows as text cells (read on first use: Arrow already gave the numeric columns)."""
        if self._rows is None:
            self._read_rows()
        return self._rows

    def _cell(self, r: int, k: int) -> str:
        row = self.rows[r]
        return row[k].strip() if k < len(row) else ""

    def _number(self, cell: str) -> float:
        return float(cell.replace(",", ".") if self.dec == "," else cell)

    def column(self, k: int, role: str = "") -> Signal:
        """Column ``k`` as numbers; a time column of ISO time stamps as seconds since 1970 (absolute)."""
        if self._numbers is not None and k in self._numbers:
            return Signal(self.header[k], self._numbers[k], unit_text(self.header[k]) or "", False, 0.0)
        origin = iso_time(self._cell(0, k)) if role == "time" and self.rows else None
        absolute = origin is not None
        if not absolute:
            try:  # the common case in C (float() strips blanks as _cell does); any bad cell: the loop below names it
                cells = list(map(itemgetter(k), self.rows))
                if self.dec == ",":
                    cells = [c.replace(",", ".") for c in cells]
                values = np.fromiter(map(float, cells), float, len(cells))
                return Signal(self.header[k], values, unit_text(self.header[k]) or "", False, 0.0)
            except (ValueError, IndexError):
                pass
        values = np.empty(len(self.rows))
        for r in range(len(self.rows)):
            cell = self._cell(r, k)
            if not cell and self.empty_missing:  # --missing drop: a missing value, as NaN (the row is dropped)
                values[r] = np.nan
                continue
            try:
                if absolute:
                    t = iso_time(cell)
                    if t is None:
                        raise ValueError
                    values[r] = (t - origin).total_seconds()  # exact to the microsecond
                else:
                    values[r] = self._number(cell)
            except ValueError:
                kind = "an ISO 8601 time stamp" if absolute else "a number"
                raise DataError(f"{self.path}: column {self.header[k]!r} row {r + 2}: {cell!r} is not {kind}"
                                f"{' (decimal comma? use --decimal ,)' if ',' in cell and not absolute else ''}"
                                f"{' (a truncated last line?)' if r == len(self.rows) - 1 else ''}"
                                f"{' (a missing value? --missing drop drops such rows)' if not cell else ''}") from None
        return Signal(self.header[k], values, "s" if absolute else (unit_text(self.header[k]) or ""), absolute,
                      origin.timestamp() if absolute else 0.0)

    def resolve(self, expr: str, role: str) -> Signal:
        same = self.named.get(bare(expr), []) if expr.strip() not in self.header else []
        if len(same) > 1:  # the first one taken silently could be the mA copy read as A
            raise DataError(f"{self.path}: column {expr!r} (role {role}) names {len(same)} columns, "
                            f"{', '.join(map(repr, same))}; expected one: name it whole, e.g. --map '{role}={same[0]}'")
        k = self.index.get(expr.strip(), self.index.get(bare(expr)))
        if k is None:
            raise DataError(f"{self.path}: column {expr!r} (role {role}) not found; columns are {self.header} "
                            f"(separator {self.sep!r}; set it with --delimiter)")
        return self.column(k, role)

    def locate(self, signal: Signal, r: int) -> str:
        return f"column {signal.label!r} row {r + 2}: {self._cell(r, self.header.index(signal.label))!r}"

    def variables(self) -> list[Variable]:
        out = []
        for k, h in enumerate(self.header):
            try:
                s = self.column(k, "time" if k == 0 else "")
                dtype = "datetime" if s.absolute else "float64"
            except DataError:
                dtype = "text"
            out.append(Variable(h or f"(column {k + 1}, no header)", (self.n_rows,), dtype, unit_text(h) or ""))
        return out
