"""Readers: what people save (CSV, MATLAB v4-v7.3, Parquet, text logs) -> one :class:`Source` interface.

``open_source(path)`` picks the reader by extension (``.csv``/``.tsv``, ``.mat``, ``.parquet``/``.pq``,
``.txt``/``.log``/``.dat``) and, for other names, by the file's first bytes. Every reader lists its
variables (``cosim info``) and resolves a role map entry to a :class:`Signal` (values as stored, the
declared unit); :mod:`feeddrive.cosim.recorded` converts units and checks the time base.
"""
from __future__ import annotations

import glob
from pathlib import Path

from feeddrive.cosim.errors import DataError
from feeddrive.cosim.readers.source import Signal, Source, Variable

__all__ = ["RECORDING_SUFFIXES", "Signal", "Source", "Variable", "open_source"]

#: file name endings read as recordings (``cosim info`` takes other names as FMUs)
RECORDING_SUFFIXES = (".csv", ".tsv", ".mat", ".parquet", ".pq", ".txt", ".log", ".dat")


def _format(path: Path) -> str:
    suffix = path.suffix.lower()
    if suffix in (".csv", ".tsv"):
        return "csv"
    if suffix == ".mat":
        return "mat"
    if suffix in (".parquet", ".pq"):
        return "parquet"
    with path.open("rb") as f:
        head = f.read(4096)
    if head.startswith(b"MATLAB") or head.startswith(b"\x89HDF"):
        return "mat"
    if head.startswith(b"PAR1"):
        return "parquet"
    if head.lstrip()[:1] in (b"%", b"#"):
        return "textlog"
    if suffix in (".txt", ".log", ".dat"):  # whitespace-separated numbers without a header are a log too
        first = head.lstrip().split(b"\n", 1)[0].split()
        try:
            [float(x) for x in first]
        except ValueError:
            return "csv"
        return "textlog" if len(first) > 0 else "csv"
    return "csv"


def open_source(path: str | Path, delimiter: str | None = None, decimal: str | None = None,
                max_bytes: int | None = None) -> Source:
    """The reader of ``path`` (``delimiter``/``decimal``: the CSV dialect, detected when None; ``max_bytes``:
    the largest text file read, default ``csvfile.MAX_BYTES``).

    Raises
    ------
    cosim.errors.DataError
        Missing or unreadable file; the message names the file and what was expected.
    """
    path = Path(path)
    if not path.is_file():
        if path.is_dir():
            raise DataError(f"{path}: is a folder; expected a recording file")
        hits = sorted(glob.glob(str(path))) if any(c in str(path) for c in "*?[") else []
        if hits:  # cosim monitor 'run*.csv': a pattern is cosim estimate's; the monitor takes its recordings in turn
            shown = ", ".join(hits[:3]) + (", ..." if len(hits) > 3 else "")
            raise DataError(f"{path}: a file pattern ({len(hits)} files: {shown}); expected one recording here: give "
                            "each in turn, oldest first (cosim estimate takes a pattern)")
        raise DataError(f"{path}: no such file")
    kind = _format(path)
    if kind == "mat":
        from feeddrive.cosim.readers.matlab import MatSource

        return MatSource(path)
    if kind == "parquet":
        from feeddrive.cosim.readers.parquet import read_parquet

        return read_parquet(path)
    if kind == "textlog":
        from feeddrive.cosim.readers.textlog import read_text_log

        return read_text_log(path, max_bytes)
    if delimiter is None and path.suffix.lower() == ".tsv":
        delimiter = "tab"
    from feeddrive.cosim.readers.csvfile import CsvSource

    return CsvSource(path, delimiter, decimal, max_bytes)
