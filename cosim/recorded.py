"""Recorded data: a CSV file and a role map -> uniformly sampled signals.

A role map says which column plays which role, e.g. ``{"time": "time", "voltage": "u [V]",
"current": "Im2", "speed": "w_tach"}``. Column headers may carry a unit in brackets
(``i [A]``); a column is found with or without it.
"""
from __future__ import annotations

import argparse
import csv
import io
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from feeddrive.cosim.errors import DataError, InputError

#: Fewest samples a recording must have.
MIN_SAMPLES = 10
#: Largest relative deviation of a time step from the median step.
TIME_JITTER = 0.01


@dataclass(frozen=True)
class Recording:
    """Signals of a recording, each shape (n,), sampled every ``h`` seconds from ``t0``.

    Attributes
    ----------
    path : pathlib.Path
    h : float
        Sampling period [s].
    t0 : float
        Time of the first sample [s].
    signals : dict of str to ndarray
        Role -> values (the ``time`` role excluded).
    columns : dict of str to str
        Role -> the column header it came from.
    """

    path: Path
    h: float
    t0: float
    signals: dict[str, np.ndarray]
    columns: dict[str, str]

    @property
    def n(self) -> int:
        return len(next(iter(self.signals.values())))


def _bare(header: str) -> str:
    """Header without a trailing unit: ``"i [A]"`` -> ``"i"``."""
    return re.sub(r"\s*[\[(][^\])]*[\])]\s*$", "", header.strip())


def load_recording(path: str | Path, role_map: Mapping[str, str], sample_time: float | None = None) -> Recording:
    """Read a CSV recording.

    Parameters
    ----------
    path : str or Path
        CSV file with one header row.
    role_map : mapping of str to str
        Role -> column header (with or without its unit). The ``time`` role is optional when
        ``sample_time`` is given.
    sample_time : float, optional
        Sampling period [s]; with a time column as well, the column must agree with it.

    Returns
    -------
    Recording

    Raises
    ------
    cosim.errors.DataError
        Missing file or column, not UTF-8, non-numeric or NaN value, non-monotonic or non-uniform time,
        too few samples; the message names the file and the column.
    """
    path = Path(path)
    if not path.is_file():
        raise DataError(f"{path}: no such file")
    if sample_time is not None and not sample_time > 0:
        raise DataError(f"{path}: sample time must be > 0 s, got {sample_time}")
    raw = path.read_bytes()
    try:  # utf-8-sig: a byte-order mark (spreadsheet exports) must not end up in the first header
        rows = list(csv.reader(io.StringIO(raw.decode("utf-8-sig"), newline="")))
    except UnicodeDecodeError as exc:
        line = raw[:exc.start].count(b"\n") + 1
        raise DataError(f"{path}: line {line}: byte 0x{exc.object[exc.start]:02x} is not UTF-8; "
                        "expected a UTF-8 CSV file") from None
    if not rows:
        raise DataError(f"{path}: empty file, expected a header row")
    header = [h.strip() for h in rows[0]]
    index = {}
    for k, h in enumerate(header):
        index.setdefault(h, k)
        index.setdefault(_bare(h), k)
    columns, signals = {}, {}
    for role, column in role_map.items():
        k = index.get(column.strip(), index.get(_bare(column)))
        if k is None:
            raise DataError(f"{path}: column {column!r} (role {role}) not found; columns are {header}")
        values = np.empty(len(rows) - 1)
        for r, row in enumerate(rows[1:]):
            try:
                values[r] = float(row[k])
            except (ValueError, IndexError):
                cell = row[k] if k < len(row) else ""
                raise DataError(f"{path}: column {header[k]!r} row {r + 2}: {cell!r} is not a number") from None
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            raise DataError(f"{path}: column {header[k]!r} row {bad[0] + 2}: NaN or infinite value")
        columns[role], signals[role] = header[k], values
    n = len(rows) - 1
    if n < MIN_SAMPLES:
        raise DataError(f"{path}: {n} samples, need at least {MIN_SAMPLES}")
    time = signals.pop("time", None)
    if time is None:
        if sample_time is None:
            raise DataError(f"{path}: no time column (role time) and no sample time given")
        h, t0 = float(sample_time), 0.0
    else:
        dt = np.diff(time)
        if np.any(dt <= 0):
            r = int(np.flatnonzero(dt <= 0)[0]) + 3
            raise DataError(f"{path}: column {columns['time']!r} is not strictly increasing at row {r}")
        h, t0 = float(np.median(dt)), float(time[0])
        if np.max(np.abs(dt - h)) > TIME_JITTER * h:
            raise DataError(f"{path}: column {columns['time']!r} is not uniformly sampled "
                            f"(steps from {dt.min():.6g} to {dt.max():.6g} s)")
        if sample_time is not None:
            if abs(h - sample_time) > TIME_JITTER * sample_time:
                raise DataError(f"{path}: column {columns['time']!r} has steps of {h:.6g} s, "
                                f"the given sample time is {sample_time:.6g} s")
            h = float(sample_time)
    if not signals:
        raise DataError(f"{path}: the role map names no signal besides time")
    return Recording(path, h, t0, signals, {k: v for k, v in columns.items() if k != "time"})


# -- command-line plumbing shared by ``cosim estimate`` and ``cosim monitor`` --------------------------


def pairs(items: list[str], what: str) -> dict[str, str]:
    """``["a=b", ...]`` from repeated ``NAME=VALUE`` options; ``what`` names the option in errors."""
    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip() or not value.strip():
            raise InputError(f"{what} {item!r}: expected NAME=VALUE")
        out[key.strip()] = value.strip()
    return out


def add_recording_arguments(parser: argparse.ArgumentParser, roles: Iterable[str], filter_cutoff_hz: float) -> None:
    """The data file, ``--map``, ``--sample-time``, ``--segment``, ``--method``, ``--filter-cutoff``, ``--json``."""
    from feeddrive.estimator.segmentation import MODES

    parser.add_argument("data", help="CSV file with a header row")
    parser.add_argument("--map", action="append", default=[], metavar="ROLE=COLUMN",
                        help=f"column of a role ({', '.join(roles)}); repeat for each role")
    parser.add_argument("--sample-time", type=float, default=None, metavar="H",
                        help="sampling period [s] (needed without a time column)")
    parser.add_argument("--segment", choices=MODES, default="auto",
                        help="motions from the NC state or the speed profile (auto), the NC state (nc) "
                             "or the whole record (none)")
    parser.add_argument("--method", choices=("ls", "iv", "oe"), default="iv", help="estimator (default iv)")
    parser.add_argument("--filter-cutoff", type=float, default=filter_cutoff_hz, metavar="HZ",
                        help="cut-off of the identical low-pass filter [Hz] (default %(default)s)")
    parser.add_argument("--sampling", action="append", default=[], metavar="QUANTITY=MODE",
                        help="what a sample of voltage, current or speed is: instant (default) or mean (the mean "
                             "over the interval before its time stamp, aligned to the interval's middle), "
                             "e.g. voltage=mean; repeat for each quantity")
    parser.add_argument("--json", action="store_true", help="print JSON instead of a table")


#: quantities ``--sampling`` accepts and their estimator signal
SAMPLED = {"voltage": "u", "current": "i", "speed": "w"}


def sampling_modes(args: argparse.Namespace) -> dict[str, str]:
    """The ``--sampling`` options as quantity -> mode, refusing unknown quantities and modes."""
    modes = pairs(args.sampling, "--sampling")
    for q, mode in modes.items():
        if q not in SAMPLED or mode not in ("instant", "mean"):
            raise InputError(f"--sampling {q}={mode}: expected QUANTITY=MODE with QUANTITY one of "
                             f"{', '.join(SAMPLED)} and MODE instant or mean")
    return modes


def mapped_roles(args: argparse.Namespace, roles: Iterable[str]) -> dict[str, str]:
    """The ``--map`` options as role -> column, refusing roles not in ``roles``."""
    mapping = pairs(args.map, "--map")
    unknown = sorted(set(mapping) - set(roles))
    if unknown:
        raise InputError(f"--map: unknown role(s) {unknown}; roles are {list(roles)}")
    return mapping

