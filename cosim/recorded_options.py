"""Command-line options shared by ``cosim estimate`` and ``cosim monitor``: the data file(s), the role map,
the CSV dialect, the time base, the filter cut-off and the sampling of each quantity.

:mod:`feeddrive.cosim.recorded` re-exports them; they read ``args`` only and never load a recording.
"""
from __future__ import annotations

import argparse
from collections.abc import Iterable, Mapping

from feeddrive.cosim.errors import InputError

# -- command-line plumbing shared by ``cosim estimate`` and ``cosim monitor`` --------------------------

#: ``--delimiter`` and ``--decimal`` by name (a bare ``,`` or ``;`` reads badly in help and in shells);
#: the characters themselves are accepted too
DELIMITER_NAMES = {"comma": ",", "semicolon": ";", "tab": "tab", ",": ",", ";": ";", "\\t": "tab"}
DECIMAL_NAMES = {"point": ".", "comma": ",", ".": ".", ",": ","}
#: ``--missing``: a row with a missing value (NaN, an empty cell, inf) refuses the recording, or is dropped
MISSING = ("refuse", "drop")


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
        parser.add_argument("data", help="recording: CSV with a header row, MATLAB .mat (v4-v7.3), Parquet, or a "
                            "whitespace-separated text log with %% or # comment lines (cosim info DATA lists what it holds)")
    parser.add_argument("--map", action="extend", nargs="+", default=[], metavar="ROLE=COLUMN",
                        help=f"column or variable of a role ({', '.join(roles)}): a header, or in a MATLAB file "
                             "NAME.FIELD[ROWS,COLS] (0-based, e.g. rec.act_torque_abs_nm[:,0]); optionally "
                             "COLUMN*SCALE (a header's [unit] must agree with it) or COLUMN*SCALE [UNIT] (the scaled values' unit, e.g. "
                             "'speed=wheel*325.9 [rad/s]': a gear or radius changes the unit); several per --map, or repeat --map")
    timing = parser.add_mutually_exclusive_group()
    timing.add_argument("--sample-time", "--dt", dest="sample_time", type=float, default=None, metavar="H",
                        help="sampling period [s] (needed without a time column)")
    timing.add_argument("--rate", type=float, default=None, metavar="HZ",
                        help="sample rate [Hz] (needed without a time column; the alternative to --dt)")
    parser.add_argument("--resample", type=float, default=None, metavar="MAXGAP",
                        help="a time column with jitter or dropped samples: interpolate linearly onto the nominal "
                             "grid (its median step), refusing a gap longer than MAXGAP [s]")
    parser.add_argument("--split-gaps", action="store_true",
                        help="a time column with gaps: take the stretches between gaps as separate records "
                             "(with --resample: only the gaps longer than MAXGAP)")
    parser.add_argument("--missing", choices=MISSING, default="refuse",
                        help="a row where a mapped signal is missing (NaN, an empty cell, inf): refuse the recording "
                             "naming it (default), or drop such rows: they become time gaps, which --resample "
                             "bridges or --split-gaps splits at (without a time column: the times row x --dt)")
    parser.add_argument("--start-time", default=None, metavar="ISO",
                        help="calendar time of the first sample, e.g. 2024-03-01T10:00:00+01:00 (default: the "
                             "time column when it holds calendar time stamps, else the file's modification time)")
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


def _data_path(args: argparse.Namespace, path: str | None) -> str:
    """``path``, else the one recording of ``args.data`` (``cosim estimate`` takes a list of them)."""
    if path is not None:
        return path
    data = args.data
    if isinstance(data, list):
        if len(data) != 1:
            raise InputError(f"expected one recording here, got {len(data)}: {', '.join(map(str, data))}")
        return data[0]
    return data


#: quantities ``--sampling`` accepts and their estimator signal
SAMPLED = {"voltage": "u", "current": "i", "speed": "w"}


def sampling_modes(args: argparse.Namespace, columns: dict[str, str] | None = None,
                   path: str | None = None) -> dict[str, str]:
    """The ``--sampling`` options as quantity -> mode, refusing unknown quantities and modes; for the
    quantities it leaves out, the modes of their ``columns`` (quantity -> column) in the data's sidecar
    signals.meta.json (``cosim.recorder.read_sampling_sidecar``) beside ``path`` (default ``args.data``),
    said on stderr."""
    modes = pairs(args.sampling, "--sampling")
    for q, mode in modes.items():
        if q not in SAMPLED or mode not in ("instant", "mean"):
            raise InputError(f"--sampling {q}={mode}: expected QUANTITY=MODE with QUANTITY one of "
                             f"{', '.join(SAMPLED)} and MODE instant or mean")
    if columns:
        from feeddrive.cosim.recorder import sidecar_modes

        modes = sidecar_modes(_data_path(args, path), {q: c for q, c in columns.items() if q not in modes}) | modes
    return modes


def mapped_roles(args: argparse.Namespace, roles: Iterable[str]) -> dict[str, str]:
    """The ``--map`` options as role -> column, refusing roles not in ``roles``."""
    mapping = pairs(args.map, "--map")
    unknown = sorted(set(mapping) - set(roles))
    if unknown:
        raise InputError(f"--map: unknown role(s) {unknown}; roles are {list(roles)}")
    return mapping
