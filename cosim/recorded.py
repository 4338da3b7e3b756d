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
from dataclasses import dataclass, field, replace
from functools import lru_cache
from pathlib import Path

import numpy as np

from feeddrive.cosim.errors import DataError, InputError

#: Fewest samples a recording must have.
MIN_SAMPLES = 10
#: Largest CSV file read [bytes] (the rows are held in memory as text, ~10 times the file's size).
MAX_BYTES = 512 << 20
#: Largest relative deviation of a time step from the median step.
TIME_JITTER = 0.01


@dataclass(frozen=True)
class Recording:
    """Signals of a recording in SI units, each shape (n,), sampled every ``h`` seconds from ``t0``.

    Attributes
    ----------
    path : pathlib.Path
    h : float
        Sampling period [s].
    t0 : float
        Time of the first sample [s].
    signals : dict of str to ndarray
        Role -> values in SI (the ``time`` role excluded).
    columns : dict of str to str
        Role -> the column header it came from.
    units : dict of str to str
        Role -> the SI unit of its values (``m`` or ``rad`` for a position, ...), or ``""`` when the
        column gave no unit (values taken as they are).
    """

    path: Path
    h: float
    t0: float
    signals: dict[str, np.ndarray]
    columns: dict[str, str]
    units: dict[str, str] = field(default_factory=dict)

    @property
    def n(self) -> int:
        return len(next(iter(self.signals.values())))

    @property
    def side(self) -> str | None:
        """``table`` when a position, speed or torque column is a length, speed in m/s or force; ``motor``
        when one is an angle, rad/s or N.m; None when the columns say nothing."""
        sides = {SI_SIDE[u] for r, u in self.units.items() if u in SI_SIDE}
        return sides.pop() if len(sides) == 1 else None


#: SI unit each role is converted to, in order of preference; a unit that converts to a later entry of
#: position / speed / torque puts the data on the table side of a linear axis.
SI_UNITS = {"time": ("s",), "voltage": ("V",), "voltage_ref": ("V",), "current": ("A",), "current1": ("A",),
            "current2": ("A",), "speed": ("rad/s", "m/s"), "position": ("rad", "m"), "torque": ("N*m", "N"),
            "state": ()}
SI_SIDE = {"rad/s": "motor", "rad": "motor", "N*m": "motor", "m/s": "table", "m": "table", "N": "table"}
#: Largest magnitude accepted: the estimator squares and sums the samples, 1e300 would overflow
MAX_ABS = 1e100
DELIMITERS = {",": ",", ";": ";", "tab": "\t", "\\t": "\t", "\t": "\t"}


def _bare(header: str) -> str:
    """Header without a trailing unit: ``"i [A]"`` -> ``"i"``."""
    return re.sub(r"\s*[\[(][^\])]*[\])]\s*$", "", header.strip())


def _unit_text(header: str) -> str | None:
    """The unit in a header's trailing brackets (``"pos [mm]"`` -> ``"mm"``), or None."""
    m = re.search(r"[\[(]([^\])]*)[\])]\s*$", header.strip())
    return m.group(1).strip() if m else None


@lru_cache(maxsize=1)
def _registry():  # noqa: ANN202 - pint.UnitRegistry, built once (slow)
    import pint

    return pint.UnitRegistry()


def si_factor(unit: str, role: str, where: str) -> tuple[float, str]:
    """``(factor, si_unit)``: a value in ``unit`` times ``factor`` is in ``si_unit`` (pint does the work).

    ``N.m``, ``kg.m2`` and ``Ohm`` are read as ``N*m``, ``kg*m**2`` and ``ohm``. ``where`` names the file
    and column in the error.
    """
    import pint

    targets = SI_UNITS.get(role, ())
    if not targets or unit in ("", "1", "-"):
        return 1.0, ""
    text = re.sub(r"(?<=[A-Za-z])\.(?=[A-Za-z])", "*", unit)  # N.m -> N*m
    text = re.sub(r"(?<=[A-Za-z])(\d+)", r"**\1", text).replace("Ohm", "ohm")  # m2 -> m**2
    ureg = _registry()
    try:
        q = ureg.Quantity(1.0, text)
    except (pint.errors.PintError, ValueError, TypeError, AttributeError, SyntaxError):
        raise DataError(f"{where}: unknown unit {unit!r}; expected a unit such as {', '.join(targets)}") from None
    for target in targets:
        try:
            return float(q.to(target).magnitude), target
        except pint.errors.DimensionalityError:
            continue
    raise DataError(f"{where}: unit {unit!r} is not a unit of role {role} (expected one convertible to "
                    f"{' or '.join(targets)})")


def _dialect(text: str, delimiter: str | None, decimal: str | None, path: Path) -> tuple[str, str]:
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
    if decimal is None:
        sample = [c.strip() for line in head[1:] for c in fields(line, delimiter)]
        comma = any(re.fullmatch(r"[-+]?\d*,\d+([eE][-+]?\d+)?", c) for c in sample)
        decimal = "," if comma and delimiter != "," else "."
    if decimal not in (".", ","):
        raise DataError(f"{path}: --decimal {decimal!r}; expected '.' or ','")
    if decimal == delimiter:
        raise DataError(f"{path}: the decimal mark and the separator are both {decimal!r}; expected different ones")
    return delimiter, decimal


def split_scale(column: str) -> tuple[str, float | None]:
    """``"x*0.001"`` -> ``("x", 0.001)``: an explicit scale (overrides the header's unit); else ``(column, None)``."""
    name, sep, factor = column.rpartition("*")
    if sep and name.strip():
        try:
            value = float(factor)
        except ValueError:
            return column, None
        if not np.isfinite(value) or value == 0:
            raise InputError(f"--map {column!r}: the scale must be a finite non-zero number")
        return name.strip(), value
    return column, None


def load_recording(path: str | Path, role_map: Mapping[str, str], sample_time: float | None = None,
                   delimiter: str | None = None, decimal: str | None = None) -> Recording:
    """Read a CSV recording, converting every mapped column to SI.

    Parameters
    ----------
    path : str or Path
        CSV file with one header row; UTF-8 with or without a byte-order mark; separated by ``,``,
        ``;`` or tabs; decimal point or comma (both detected unless given).
    role_map : mapping of str to str
        Role -> column header (with or without its unit), optionally ``COLUMN*SCALE``: the values times
        SCALE are taken as SI, whatever unit the header states. Without a scale, a unit in the header
        (``pos [mm]``, ``n [rpm]``, ``I [mA]``) is converted to SI with pint. The ``time`` role is optional
        when ``sample_time`` is given.
    sample_time : float, optional
        Sampling period [s]; with a time column as well, the column must agree with it.
    delimiter : {",", ";", "tab"}, optional
    decimal : {".", ","}, optional

    Returns
    -------
    Recording

    Raises
    ------
    cosim.errors.DataError
        Missing file or column, not UTF-8, unknown unit, non-numeric, NaN, infinite or overflowing value
        (> 1e100), non-monotonic or non-uniform time, too few samples; the message names the file, the
        column and the row.
    """
    path = Path(path)
    if not path.is_file():
        raise DataError(f"{path}: no such file")
    if sample_time is not None and not sample_time > 0:
        raise DataError(f"{path}: sample time must be > 0 s, got {sample_time}")
    size = path.stat().st_size
    if size > MAX_BYTES:
        raise DataError(f"{path}: {size} bytes; expected a CSV file of at most {MAX_BYTES} bytes "
                        "(split the recording)")
    raw = path.read_bytes()
    try:  # utf-8-sig: a byte-order mark (spreadsheet exports) must not end up in the first header
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = raw[:exc.start].count(b"\n") + 1
        raise DataError(f"{path}: line {line}: byte 0x{exc.object[exc.start]:02x} is not UTF-8; "
                        "expected a UTF-8 CSV file") from None
    sep, dec = _dialect(text, delimiter, decimal, path)
    reader = csv.reader(io.StringIO(text, newline=""), delimiter=sep)
    try:
        rows = list(reader)
    except csv.Error as exc:  # a NUL byte, a field over the csv module's limit
        raise DataError(f"{path}: line {reader.line_num}: {exc}; expected a CSV text file") from None
    while rows and not any(c.strip() for c in rows[-1]):
        rows.pop()  # trailing empty lines
    if not rows:
        raise DataError(f"{path}: empty file, expected a header row")
    header = [h.strip() for h in rows[0]]
    index = {}
    for k, h in enumerate(header):
        index.setdefault(h, k)
        index.setdefault(_bare(h), k)
    columns, signals, units = {}, {}, {}
    for role, spec in role_map.items():
        column, scale = split_scale(spec)
        k = index.get(column.strip(), index.get(_bare(column)))
        if k is None:
            raise DataError(f"{path}: column {column!r} (role {role}) not found; columns are {header} "
                            f"(separator {sep!r}; set it with --delimiter)")
        where = f"{path}: column {header[k]!r} (role {role})"
        unit = _unit_text(header[k]) or ""
        factor, si = si_factor(unit, role, where) if scale is None else (scale, "")
        if scale is not None and unit:
            try:  # the header still says which side the data are on
                si = si_factor(unit, role, where)[1]
            except DataError:
                si = ""
        values = np.empty(len(rows) - 1)
        for r, row in enumerate(rows[1:]):
            cell = row[k].strip() if k < len(row) else ""
            try:
                values[r] = float(cell.replace(",", ".") if dec == "," else cell)
            except ValueError:
                raise DataError(f"{path}: column {header[k]!r} row {r + 2}: {cell!r} is not a number"
                                f"{' (decimal comma? use --decimal ,)' if ',' in cell else ''}") from None
        with np.errstate(over="ignore", invalid="ignore"):
            values *= factor
        bad = np.flatnonzero(~(np.abs(values) <= MAX_ABS))  # NaN fails the comparison too
        if bad.size:
            r = int(bad[0])
            cell = rows[r + 1][k].strip()
            raise DataError(f"{path}: column {header[k]!r} row {r + 2}: {cell!r} is "
                            f"{'not a finite number' if not np.isfinite(float(cell.replace(',', '.'))) else 'out of range'}"
                            f"; expected a finite value of magnitude <= {MAX_ABS:.0e} (SI)")
        columns[role], signals[role], units[role] = header[k], values, si
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
    return Recording(path, h, t0, signals, {k: v for k, v in columns.items() if k != "time"},
                     {k: v for k, v in units.items() if k != "time"})


# -- command-line plumbing shared by ``cosim estimate`` and ``cosim monitor`` --------------------------

#: ``--delimiter`` and ``--decimal`` by name (a bare ``,`` or ``;`` reads badly in help and in shells);
#: the characters themselves are accepted too
DELIMITER_NAMES = {"comma": ",", "semicolon": ";", "tab": "tab", ",": ",", ";": ";", "\\t": "tab"}
DECIMAL_NAMES = {"point": ".", "comma": ",", ".": ".", ",": ","}


def _named(names: Mapping[str, str], option: str):  # noqa: ANN202 - an argparse type
    """An argparse ``type`` mapping a name (or the character itself) to the character."""
    def convert(text: str) -> str:
        try:
            return names[text.strip().lower()]
        except KeyError:
            expected = ", ".join(n for n in names if n.isalpha())
            raise argparse.ArgumentTypeError(f"{text!r}: expected one of {expected}") from None
    convert.__name__ = option
    return convert


def pairs(items: list[str], what: str) -> dict[str, str]:
    """``["a=b", ...]`` from repeated ``NAME=VALUE`` options; ``what`` names the option in errors."""
    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip() or not value.strip():
            raise InputError(f"{what} {item!r}: expected NAME=VALUE")
        out[key.strip()] = value.strip()
    return out


def add_recording_arguments(parser: argparse.ArgumentParser, roles: Iterable[str], filter_cutoff_hz: float,
                            several: bool = False) -> None:
    """The data file and the options shared by ``cosim estimate`` and ``cosim monitor``.

    ``--map`` takes one or more ``ROLE=COLUMN[*SCALE]`` and may be repeated; ``--delimiter`` and
    ``--decimal`` override the detected CSV dialect; ``--speed-threshold`` is the absolute alternative to
    the relative default; ``--pitch``/``--ratio`` convert a table position (m) to the motor angle.
    """
    from feeddrive.estimator.segmentation import MODES

    if several:  # cosim estimate: repeated recordings of one machine, or a quoted glob pattern
        parser.add_argument("data", nargs="+", help="recording(s) of one machine, or a quoted glob pattern ('run*.csv')")
    else:
        parser.add_argument("data", help="CSV file with a header row (',', ';' or tab separated, UTF-8)")
    parser.add_argument("--map", action="extend", nargs="+", default=[], metavar="ROLE=COLUMN",
                        help=f"column of a role ({', '.join(roles)}), optionally COLUMN*SCALE to SI (overrides a "
                             "[unit] in the header); several per --map, or repeat --map")
    parser.add_argument("--sample-time", type=float, default=None, metavar="H",
                        help="sampling period [s] (needed without a time column)")
    parser.add_argument("--delimiter", default=None, type=_named(DELIMITER_NAMES, "--delimiter"),
                        metavar="{comma,semicolon,tab}",
                        help="column separator (default: detected from the header)")
    parser.add_argument("--decimal", default=None, type=_named(DECIMAL_NAMES, "--decimal"),
                        metavar="{point,comma}",
                        help="decimal mark (default: detected; comma with semicolon or tab separators)")
    parser.add_argument("--segment", choices=MODES, default="auto",
                        help="motions from the NC state or the speed profile (auto), the NC state (nc) "
                             "or the whole record (none)")
    parser.add_argument("--method", choices=("ls", "iv", "oe"), default="iv", help="estimator (default iv)")
    parser.add_argument("--filter-cutoff", type=float, default=None, metavar="HZ",
                        help=f"cut-off of the identical low-pass filter [Hz] (default {filter_cutoff_hz:g}, "
                             "lowered to 0.1 / sample time for slowly sampled data)")
    parser.add_argument("--speed-threshold", type=float, default=None, metavar="V",
                        help="absolute speed below which samples leave the sign(w) term, in the speed's SI unit "
                             "(rad/s or m/s); default: 3 %% of the motion's largest speed")
    parser.add_argument("--pitch", type=float, default=None, metavar="M",
                        help="ball-screw pitch [m]: converts a table position/speed/force to the motor side")
    parser.add_argument("--ratio", type=float, default=1.0, metavar="N",
                        help="motor turns per screw turn (belt or gear; default 1)")
    parser.add_argument("--sampling", action="append", default=[], metavar="QUANTITY=MODE",
                        help="what a sample of voltage, current or speed is: instant (default) or mean (the mean "
                             "over the interval before its time stamp, aligned to the interval's middle), "
                             "e.g. voltage=mean; repeat for each quantity")
    parser.add_argument("--json", action="store_true", help="print JSON instead of a table")
    parser.set_defaults(default_cutoff_hz=filter_cutoff_hz)


def filter_cutoff(args: argparse.Namespace, h: float) -> float:
    """``--filter-cutoff``, or the default lowered to ``0.1 / h`` (below the IV halves' limit of 0.1125 / h)."""
    if args.filter_cutoff is not None:
        return args.filter_cutoff
    return min(args.default_cutoff_hz, 0.1 / h)


def to_motor_side(rec: Recording, args: argparse.Namespace) -> Recording:
    """With ``--pitch``: a table-side recording (m, m/s, N) converted to the motor side (rad, rad/s, N.m)."""
    if args.pitch is None:
        return rec
    if not (args.pitch > 0 and args.ratio > 0):
        raise InputError(f"--pitch {args.pitch} --ratio {args.ratio}: expected positive numbers")
    if rec.side == "motor":
        raise InputError(f"{rec.path}: --pitch converts table-side columns (m, m/s, N), but the columns are on the "
                         f"motor side ({rec.units})")
    k = 2 * np.pi * args.ratio / args.pitch  # motor rad per m of table travel
    factors = {"position": k, "speed": k, "torque": 1 / k}
    units = {"position": "rad", "speed": "rad/s", "torque": "N*m"}
    signals = {r: v * factors.get(r, 1.0) for r, v in rec.signals.items()}
    return replace(rec, signals=signals, units=rec.units | {r: units[r] for r in rec.units if r in units})


#: quantities ``--sampling`` accepts and their estimator signal
SAMPLED = {"voltage": "u", "current": "i", "speed": "w"}


def sampling_modes(args: argparse.Namespace, columns: dict[str, str] | None = None) -> dict[str, str]:
    """The ``--sampling`` options as quantity -> mode, refusing unknown quantities and modes; for the
    quantities it leaves out, the modes of their ``columns`` (quantity -> column) in the data's sidecar
    signals.meta.json (``cosim.recorder.read_sampling_sidecar``), said on stderr."""
    modes = pairs(args.sampling, "--sampling")
    for q, mode in modes.items():
        if q not in SAMPLED or mode not in ("instant", "mean"):
            raise InputError(f"--sampling {q}={mode}: expected QUANTITY=MODE with QUANTITY one of "
                             f"{', '.join(SAMPLED)} and MODE instant or mean")
    if columns:
        from feeddrive.cosim.recorder import sidecar_modes

        modes = sidecar_modes(args.data, {q: c for q, c in columns.items() if q not in modes}) | modes
    return modes


def mapped_roles(args: argparse.Namespace, roles: Iterable[str]) -> dict[str, str]:
    """The ``--map`` options as role -> column, refusing roles not in ``roles``."""
    mapping = pairs(args.map, "--map")
    unknown = sorted(set(mapping) - set(roles))
    if unknown:
        raise InputError(f"--map: unknown role(s) {unknown}; roles are {list(roles)}")
    return mapping
