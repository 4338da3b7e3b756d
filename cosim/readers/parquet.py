"""Parquet recordings (pyarrow): numeric columns and time stamps.

A column's unit is the ``unit`` (or ``units``) entry of its field metadata, else the bracketed unit of
its name (``i [A]``). Timestamp columns become seconds since 1970-01-01 UTC (an absolute time).
Text, list and struct columns are listed by ``cosim info`` but cannot be mapped.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from feeddrive.cosim.errors import DataError
from feeddrive.cosim.readers.csvfile import unit_text
from feeddrive.cosim.readers.source import TableSource


def read_parquet(path: Path) -> TableSource:
    import pyarrow as pa
    import pyarrow.parquet as pq

    try:
        table = pq.read_table(path)
    except (pa.ArrowException, OSError) as exc:
        raise DataError(f"{path}: not a readable Parquet file ({' '.join(str(exc).split())})") from None
    columns, units, absolute, skipped = {}, {}, {}, {}
    for field, col in zip(table.schema, table.columns):
        meta = {k.decode(errors="replace"): v.decode(errors="replace") for k, v in (field.metadata or {}).items()}
        unit = meta.get("unit", meta.get("units", "")) or unit_text(field.name) or ""
        t = field.type
        if pa.types.is_timestamp(t):
            ns = col.cast(pa.timestamp("ns", tz=t.tz)).cast(pa.int64()).to_numpy(zero_copy_only=False)
            if len(ns) == 0:
                skipped[field.name] = "empty timestamp column"
                continue
            columns[field.name] = (ns - ns[0]).astype(float) / 1e9  # exact steps: counted from the first stamp
            units[field.name] = "s"
            absolute[field.name] = float(ns[0]) / 1e9
        elif pa.types.is_integer(t) or pa.types.is_floating(t) or pa.types.is_boolean(t) or pa.types.is_decimal(t):
            values = col.cast(pa.float64()).to_numpy(zero_copy_only=False)
            columns[field.name] = np.asarray(values, dtype=float)  # nulls are NaN: refused by name later
            units[field.name] = unit
        else:
            skipped[field.name] = f"{t} column, not numbers"
    return TableSource(path, f"Parquet ({table.num_rows} rows)", columns, units, absolute, skipped)
