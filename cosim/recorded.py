"""Recorded data: a recording (CSV, MATLAB, Parquet, text log) and a role map -> uniformly sampled signals.

A role map says which column or variable plays which role, e.g. ``{"time": "time", "voltage": "u [V]",
"current": "Im2", "speed": "w_tach"}`` or, in a MATLAB file, ``{"torque": "rec.act_torque_abs_nm[:,0]"}``.
The readers (:mod:`feeddrive.cosim.readers`) turn the file into signals with their declared units; here
they are converted to SI, the time base is checked (jitter and gaps measured, resampled or split only
when asked) and the command-line plumbing shared by ``cosim estimate`` and ``cosim monitor`` lives.
"""
from __future__ import annotations

import argparse
import datetime as _dt
import sys
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from feeddrive.cosim.errors import DataError, InputError
from feeddrive.cosim.readers.timebase import TIME_JITTER, Timing, jitter_text, measure, mend
from feeddrive.cosim.recorded_options import (  # noqa: F401 - the shared options, re-exported
    DECIMAL_NAMES,
    DELIMITER_NAMES,
    MISSING,
    SAMPLED,
    _data_path,
    add_recording_arguments,
    filter_cutoff,
    mapped_roles,
    pairs,
    sampling_modes,
)
from feeddrive.cosim.recorded_time import motion_units_note, time_note
from feeddrive.cosim.recorded_units import (  # noqa: F401 - the units, re-exported
    MAX_ABS,
    MECHANICAL,
    SI_SIDE,
    SI_UNITS,
    column_factor,
    si_factor,
    split_map,
)

__all__ = ["TIME_JITTER", "Recording", "load_recording", "si_factor", "split_map"]

#: Fewest samples a recording must have.
MIN_SAMPLES = 10
#: Largest CSV or text-log file read [bytes] (the rows are held in memory as text, ~10 times the file's size).
MAX_BYTES = 512 << 20
#: Time stamps above this many seconds are calendar times (seconds since 1970: after 1973-03-03).
ABSOLUTE_AFTER = 1e8


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
        Role -> the column header or variable expression it came from.
    units : dict of str to str
        Role -> the SI unit of its values (``m`` or ``rad`` for a position, ...), or ``""`` when the
        column gave no unit (values taken as they are).
    timing : dict
        The time base as measured (``samples``, ``median_step_s``, ``rate_hz``, ``jitter``, ``gaps``,
        ``largest_gap_s``, ``largest_gap_at_s``), where it came from (``source``) and what was done to it
        (``action``: ``none``, resampled, split).
    clock : float or None
        Calendar time of the first sample [s since 1970-01-01 UTC] when the time column holds calendar
        time stamps.
    pieces : tuple of (int, float)
        ``(first sample, its time [s])`` of each record after ``--split-gaps`` (empty: one record).
    notes : tuple of str
        Units assumed, one line each (a position, speed or torque column with no unit in its header or the
        map): printed on stderr and kept in the JSON (``unit_assumptions``).
    """

    path: Path
    h: float
    t0: float
    signals: dict[str, np.ndarray]
    columns: dict[str, str]
    units: dict[str, str] = field(default_factory=dict)
    timing: dict = field(default_factory=dict)
    clock: float | None = None
    pieces: tuple[tuple[int, float], ...] = ()
    notes: tuple[str, ...] = ()

    @property
    def n(self) -> int:
        return len(next(iter(self.signals.values())))

    @property
    def side(self) -> str | None:
        """``table`` when a position, speed or torque column is a length, speed in m/s or force; ``motor``
        when one is an angle, rad/s or N.m; None when the columns say nothing (or both)."""
        sides = {SI_SIDE[u] for r, u in self.units.items() if u in SI_SIDE and r in MECHANICAL}
        return sides.pop() if len(sides) == 1 else None

    def bounds(self) -> list[tuple[int, int]]:
        """``(start, stop)`` sample ranges of the records (one unless split at gaps)."""
        starts = [k for k, _ in self.pieces] or [0]
        return list(zip(starts, starts[1:] + [self.n]))

    def gradient(self, x: np.ndarray) -> np.ndarray:
        """d``x``/dt by central differences within each record (never across a gap), shape (n,)."""
        out = np.empty(len(x))
        for a, b in self.bounds():
            out[a:b] = np.gradient(x[a:b], self.h) if b - a > 1 else 0.0
        return out

    def time(self, k: int) -> float:
        """Time of sample ``k`` [s] (the records of a split recording keep their own start times)."""
        for start, t in reversed(self.pieces):
            if k >= start:
                return t + (k - start) * self.h
        return self.t0 + k * self.h



def load_recording(path: str | Path, role_map: Mapping[str, str], sample_time: float | None = None,
                   delimiter: str | None = None, decimal: str | None = None, *, resample: float | None = None,
                   split_gaps: bool = False, missing: str = "refuse") -> Recording:
    """Read a recording (CSV, MATLAB, Parquet, text log: :func:`feeddrive.cosim.readers.open_source`),
    converting every mapped signal to SI.

    Parameters
    ----------
    path : str or Path
    role_map : mapping of str to str
        Role -> column header (with or without its unit) or, in a MATLAB file, a variable expression
        (``rec.act_torque_abs_nm[:,0]``, ``data[:,3]``); optionally ``...*SCALE``: the values times SCALE are
        taken as SI, whatever unit the header states. Without a scale, a unit in the header (``pos [mm]``,
        ``n [rpm]``, ``I [mA]``) is converted to SI with pint. The ``time`` role is optional when
        ``sample_time`` is given.
    sample_time : float, optional
        Sampling period [s]; with a time column as well, the column must agree with it.
    delimiter : {",", ";", "tab"}, optional
    decimal : {".", ","}, optional
        CSV dialect (detected when not given).
    resample : float, optional
        Largest gap [s] bridged by linear interpolation onto the nominal grid (the median step) when the
        time column is not uniform; a longer gap is refused (or split at, with ``split_gaps``).
    split_gaps : bool
        Take the stretches between gaps as separate records (``Recording.pieces``).
    missing : {"refuse", "drop"}
        A row where a mapped signal is not finite (NaN, an empty cell, inf): refused, naming it (``refuse``), or
        dropped (``drop``): the rows left keep their times (without a time column: row number x
        ``sample_time``), so the dropped rows are gaps for ``resample``/``split_gaps``; the ``timing`` says how
        many rows were dropped and where the first one was (``dropped_rows``, ``first_dropped``,
        ``first_dropped_at_s``).

    Returns
    -------
    Recording

    Raises
    ------
    cosim.errors.DataError
        Missing file, column or variable, unknown unit, non-numeric, NaN, infinite or overflowing value
        (> 1e100), non-monotonic time, non-uniform time without ``resample``/``split_gaps``, too few samples;
        the message names the file, the column or variable and the row or sample.
    """
    from feeddrive.cosim.readers import open_source
    from feeddrive.cosim.readers.csvfile import CsvSource

    if sample_time is not None and not sample_time > 0:
        raise DataError(f"{path}: sample time must be > 0 s, got {sample_time}")
    if missing not in MISSING:
        raise InputError(f"--missing {missing}: expected one of {', '.join(MISSING)}")
    if resample is not None and not resample > 0:
        raise InputError(f"--resample {resample}: expected the largest gap to bridge, in seconds (> 0)")
    source = open_source(path, delimiter, decimal, MAX_BYTES)
    path, what = source.path, "column" if not hasattr(source, "tree") else "variable"
    if missing == "drop" and hasattr(source, "empty_missing"):
        source.empty_missing = True  # an empty cell is a missing value, as NaN
    columns, signals, units, lengths, time_sig = {}, {}, {}, {}, None
    missing_rows, first = {}, (np.inf, "")
    for role, spec in role_map.items():
        whole = spec.strip()  # a CSV header given whole, with its unit ("I [A]" beside "I [mA]")
        sig = source.resolve(whole if whole in getattr(source, "header", ()) else split_map(spec)[0], role)
        where = f"{path}: {what} {sig.label!r} (role {role})"
        factor, si = column_factor(spec, sig.unit, role, where)
        with np.errstate(over="ignore", invalid="ignore"):
            values = sig.values * factor
        gone = ~np.isfinite(sig.values)  # NaN, an empty cell, +-inf: a missing value
        bad = np.flatnonzero(~(np.abs(values) <= MAX_ABS) & ~gone if missing == "drop" else ~(np.abs(values) <= MAX_ABS))
        if bad.size:
            r = int(bad[0])
            if not np.isfinite(sig.values[r]):
                raise DataError(f"{path}: {source.locate(sig, r)} is not a finite number; expected a finite value, or "
                                f"--missing drop to drop the rows with a missing value (the gaps left: --resample "
                                f"MAXGAP or --split-gaps)")
            raise DataError(f"{path}: {source.locate(sig, r)} is out of range; expected a finite value of magnitude "
                            f"<= {MAX_ABS:.0e} (SI)")
        if gone.any():
            r = int(np.argmax(gone))
            first = min(first, (r, source.locate(sig, r)))
            missing_rows[role] = gone
        columns[role], signals[role], units[role], lengths[role] = sig.label, values, si, len(values)
        time_sig = sig if role == "time" else time_sig
    if len(set(lengths.values())) > 1:
        sizes = ", ".join(f"{r} {columns[r]!r}: {k}" for r, k in lengths.items())
        raise DataError(f"{path}: the mapped signals differ in length ({sizes}); expected one length")
    n = next(iter(lengths.values()), 0)
    if n < MIN_SAMPLES:
        raise DataError(f"{path}: {n} samples, need at least {MIN_SAMPLES}")
    rows, dropped = np.arange(n), {}  # rows: each sample's row in the file (rows dropped: not in it)
    if missing_rows:  # --missing drop: the rows left are samples at their times, the rows dropped gaps between them
        drop = np.logical_or.reduce(list(missing_rows.values()))
        if "time" not in signals and sample_time is not None:  # a uniform grid: row number x the sample time
            signals["time"], units["time"] = np.arange(n) * sample_time, "s"
        rows, n = np.flatnonzero(~drop), int(n - drop.sum())
        t = signals.get("time")
        at = float(t[first[0]] - t[rows[0]]) if t is not None and n and np.isfinite(t[first[0]]) else None
        dropped = {"dropped_rows": int(drop.sum()), "first_dropped": first[1], "first_dropped_at_s": at}
        signals = {r: v[rows] for r, v in signals.items()}
        if n < MIN_SAMPLES:
            raise DataError(f"{path}: {n} samples left after --missing drop dropped {dropped['dropped_rows']} rows "
                            f"with a missing value, need at least {MIN_SAMPLES}")
    time = signals.pop("time", None)
    time_stated = bool(units.get("time"))  # a header or map unit: else seconds are assumed, and said
    columns = {k: v for k, v in columns.items() if k != "time"}
    units = {k: v for k, v in units.items() if k != "time"}
    if not signals:
        raise DataError(f"{path}: the role map names no signal besides time")
    if time is None:
        if sample_time is None:
            raise DataError(f"{path}: no time column (role time) and no sample time given; map one "
                            "(--map time=COLUMN) or give the sampling: --rate HZ or --dt SECONDS")
        timing = {"source": "--rate/--dt", "samples": n, "median_step_s": float(sample_time),
                  "rate_hz": 1 / sample_time, "jitter": 0.0, "gaps": 0, "largest_gap_s": 0.0,
                  "largest_gap_at_s": None, "action": "none"}
        return Recording(path, float(sample_time), 0.0, signals, columns, units, timing=timing)
    named = f"{what} {time_sig.label!r}" if time_sig is not None else "the times of --rate/--dt (row x sample time)"
    dt = np.diff(time)
    if np.any(dt <= 0):
        i = int(rows[np.flatnonzero(dt <= 0)[0] + 1])
        at = f"row {i + 2}" if isinstance(source, CsvSource) else f"sample {i}"
        raise DataError(f"{path}: {named} is not strictly increasing at {at}")
    clock = None
    if time_sig is not None and time_sig.absolute:  # calendar time stamps: keep the date, count from 0
        clock, time = time_sig.origin + float(time[0]), time - time[0]
    elif time[0] > ABSOLUTE_AFTER:  # seconds since 1970 as numbers
        clock, time = float(time[0]), time - time[0]
    timing = measure(time)
    h = timing.h
    if sample_time is not None:
        if abs(h - sample_time) > TIME_JITTER * sample_time:
            raise DataError(f"{path}: {named} has steps of {h:.6g} s, "
                            f"the given sample time is {sample_time:.6g} s")
        h = float(sample_time)
    info = timing.to_dict() | {"source": named if time_sig is not None else "--rate/--dt", "action": "none",
                               "unit_stated": bool(time_stated or clock is not None)} | dropped
    if timing.uniform:
        return Recording(path, h, float(time[0]), signals, columns, units, timing=info, clock=clock)
    if resample is None and not split_gaps:
        why = (f" after --missing drop dropped {dropped['dropped_rows']} rows (the first: {dropped['first_dropped']})"
               if dropped else "")
        raise DataError(f"{path}: {named} is not uniformly sampled ({timing.describe()}){why}; "
                        f"use --resample MAXGAP (linear interpolation onto the {h:.6g} s grid, refusing gaps over "
                        "MAXGAP s) or --split-gaps (the stretches between gaps as separate records)")
    return _mended(Recording(path, h, float(time[0]), signals, columns, units, timing=info, clock=clock),
                   named, time, timing, resample, split_gaps)


def _mended(rec: Recording, label: str, time: np.ndarray, timing: Timing, resample: float | None,
            split_gaps: bool) -> Recording:
    """A non-uniform record resampled (gaps up to ``resample`` s) and/or split at its other gaps."""
    signals, pieces, action = mend(f"{rec.path}: {label}", time, rec.signals, timing, rec.h, resample, split_gaps,
                                   hold=frozenset({"state"}))
    return replace(rec, t0=pieces[0][1], signals=signals, timing=rec.timing | {"action": action,
                   "records": len(pieces)}, pieces=tuple(pieces) if len(pieces) > 1 else ())


def to_motor_side(rec: Recording, args: argparse.Namespace) -> Recording:
    """Every position, speed and torque on one side; with ``--pitch``, the table-side ones moved to the motor side.

    A column declared in a motor-side unit (rad, rad/s, rpm, N.m) is never scaled by the pitch; one
    without a unit takes the side the declared columns agree on (the table side when none declares
    one, as ``--pitch`` says). Without ``--pitch``, columns on both sides are refused, naming them.
    """
    sided = {r: SI_SIDE[u] for r, u in rec.units.items() if u in SI_SIDE and r in MECHANICAL}
    declared = set(sided.values())
    pitch = getattr(args, "pitch", None)
    if pitch is None:
        if len(declared) > 1:
            table = [f"{rec.columns[r]!r} (role {r}, {rec.units[r]})" for r, s in sided.items() if s == "table"]
            motor = [f"{rec.columns[r]!r} (role {r}, {rec.units[r]})" for r, s in sided.items() if s == "motor"]
            raise InputError(f"{rec.path}: {', '.join(table)} on the table side but {', '.join(motor)} on the motor "
                             "side; give --pitch (and --ratio) to convert the table-side ones, or map one side only")
        return rec
    if not (pitch > 0 and args.ratio > 0):
        raise InputError(f"--pitch {pitch} --ratio {args.ratio}: expected positive numbers")
    if declared == {"motor"} and "x_lin" not in rec.signals:  # a linear scale: the pitch puts the encoder by it
        raise InputError(f"{rec.path}: --pitch converts table-side columns (m, m/s, N), but the columns are on the "
                         f"motor side ({rec.units})")
    mechanical = MECHANICAL
    for r in mechanical:
        if r in rec.signals and r not in sided and declared == {"table", "motor"}:
            raise InputError(f"{rec.path}: column {rec.columns[r]!r} (role {r}) states no unit, and the others are "
                             "on both sides; give its unit in the header or a scale (--map ROLE=COLUMN*SCALE)")
    k = 2 * np.pi * args.ratio / pitch  # motor rad per m of table travel
    factors = {"position": k, "speed": k, "torque": 1 / k, "torque_ref": 1 / k}
    units = {"position": "rad", "speed": "rad/s", "torque": "N*m", "torque_ref": "N*m"}
    convert = [r for r in mechanical if r in rec.signals and sided.get(r, "table") == "table"]
    signals = {r: v * factors[r] if r in convert else v for r, v in rec.signals.items()}
    return replace(rec, signals=signals, units=rec.units | {r: units[r] for r in convert if r in rec.units})


def read_recording(args: argparse.Namespace, role_map: Mapping[str, str], path: str | None = None) -> Recording:
    """The recording ``path`` (default ``args.data``) with the shared options applied; a resampled or split
    record is said so on stderr (and in the JSON's ``timing``)."""
    sample_time = args.sample_time
    if getattr(args, "rate", None) is not None:
        if not args.rate > 0:
            raise InputError(f"--rate {args.rate}: expected a sample rate in Hz (> 0)")
        sample_time = 1.0 / args.rate
    rec = load_recording(_data_path(args, path), role_map, sample_time, args.delimiter, args.decimal,
                         resample=getattr(args, "resample", None), split_gaps=getattr(args, "split_gaps", False),
                         missing=getattr(args, "missing", None) or "refuse")
    rec = to_motor_side(rec, args)
    rec = replace(rec, notes=assumed_units(rec))  # said by the commands with their results (never silently)
    t = rec.timing
    if t.get("dropped_rows"):  # --missing drop: never silently (the JSON's timing has it too)
        at = "" if t["first_dropped_at_s"] is None else f" at t = {t['first_dropped_at_s']:.6g} s"
        print(f"cosim: {rec.path}: --missing drop: dropped {t['dropped_rows']} rows with a missing value (the first: "
              f"{t['first_dropped']}{at}); the rows left keep their times", file=sys.stderr)
    if t.get("action", "none") != "none":  # never resampled or split silently (the JSON has it too)
        print(f"cosim: {rec.path}: time from {t['source']}: {t['samples']} samples, median step "
              f"{t['median_step_s']:.6g} s, jitter {jitter_text(t['jitter'])}, {t['gaps']} gaps; {t['action']}",
              file=sys.stderr)
    return rec


def assumed_units(rec: Recording) -> tuple[str, ...]:
    """One line per signal whose unit nothing states (header, map or ``--pitch``): what it is taken as (a position,
    speed or torque on the side the other columns state, the motor's when none does), and how to state it.

    A time column's seconds are checked against the data when a position and a speed are mapped
    (:func:`feeddrive.cosim.recorded_time.time_note`: a gain a unit explains is refused, a DataError)."""
    side = rec.side or "motor"
    out = []
    if rec.timing.get("unit_stated") is False:  # a time in ms taken for s made Jt 1e6 times too large, unsaid
        source = rec.timing["source"].split(" ", 1)[1]
        note = (f"time: {source} states no unit (not in the header, not in the map): taken as s (a step of "
                f"{rec.h:.6g} s, {1 / rec.h:.6g} Hz); state it: --map 'time={source.strip(chr(39))} [UNIT]' (e.g. ms)")
        out.append(time_note(rec, note))  # a position and a speed mapped: checked against d(position)/dt = speed
    else:  # the time's unit known: a bare speed or position checked the same way (a speed in rpm read as rad/s)
        checked = motion_units_note(rec)
        out += [checked] if checked else []
    for role in rec.signals:
        if rec.units.get(role) or len(SI_UNITS.get(role, ())) == 0:
            continue
        if role in MECHANICAL:
            unit = dict(zip(("motor", "table"), SI_UNITS[role]))[side].replace("*", ".")  # N.m, as printed elsewhere
            taken, example = f"{unit} ({side} side)", ""
        else:  # a current in mA taken for A made R and K 1000 times too small, unsaid and physically possible
            taken = SI_UNITS[role][0]
            example = {"A": " (e.g. mA)", "V": " (e.g. mV)"}.get(taken, "")
        out.append(f"{role}: {rec.columns[role]!r} states no unit (not in the header, not in the map): taken as "
                   f"{taken}; state it: --map '{role}={rec.columns[role]}*SCALE [UNIT]'{example}")
    return tuple(out)


def motions(args: argparse.Namespace, rec: Recording, speed: np.ndarray | None,
            state: np.ndarray | None) -> list:
    """``--segment``'s motions of each record (a split recording's motions never cross a gap); none from the speed
    profile of a recording at rest (``segmentation.at_rest``: its noise would be cut into motions)."""
    from feeddrive.estimator.segmentation import Segment, at_rest, segment

    if args.segment == "nc" and state is None:
        raise InputError("--segment nc: the NC state is not mapped; expected --map state=COLUMN (1 = rapid), or "
                         "--segment auto (the speed profile) or none (the whole recording)")
    if args.segment == "auto" and state is None and speed is not None and at_rest(speed) is not None:
        return []
    out = []
    for a, b in rec.bounds():
        part = segment(args.segment, b - a, rec.h, None if speed is None else speed[a:b],
                       None if state is None else state[a:b])
        out += [Segment(s.start + a, s.stop + a) for s in part]
    return out


def no_motion(args: argparse.Namespace, rec: Recording, speed: np.ndarray | None, state: np.ndarray | None) -> str:
    """Why ``motions`` found no motion, in one line with its numbers: the recording at rest (the threshold it used),
    an NC state never 1, or no run of the speed long enough."""
    from feeddrive.estimator.segmentation import at_rest

    unit = "m/s" if rec.side == "table" else "rad/s"
    if state is not None:
        return (f"no high-speed motion: nothing to judge (the NC state is never 1 (rapid) in {rec.n} samples; values "
                f"{', '.join(f'{v:g}' for v in np.unique(state)[:5])}; --segment none takes the whole recording)")
    rest = None if speed is None else at_rest(speed, unit)
    return rest or (f"no high-speed motion found (--segment {args.segment}: no run of |speed| above 10 % of its largest "
                    f"value lasts 0.3 s; --segment none takes the whole recording)")


def start_clock(rec: Recording, start_time: str | None = None) -> tuple[float, str]:
    """Calendar time of the recording's first sample [s since 1970 UTC] and where it came from.

    In order: ``--start-time`` (ISO 8601; without a zone, UTC), the time column's calendar time stamps, a run's
    own signals.csv's ``start_utc`` (signals.meta.json: the machine time of its first row), else the file's
    modification time taken as the end of the recording (said so).
    """
    if start_time is not None:
        try:
            t = _dt.datetime.fromisoformat(start_time.strip().replace("Z", "+00:00"))
        except ValueError:
            raise InputError(f"--start-time {start_time!r}: expected an ISO 8601 time such as "
                             "2024-03-01T10:00:00+01:00") from None
        t = t if t.tzinfo else t.replace(tzinfo=_dt.timezone.utc)
        return t.timestamp(), f"--start-time {start_time}"
    if rec.clock is not None:
        return rec.clock, f"time stamps of {rec.timing.get('source', 'the time column')} in {rec.path}"
    from feeddrive.cosim.recorder import sidecar_start

    try:  # a run's own signals.csv: its first row's machine time (a copy's modification time would date it anew)
        run = sidecar_start(rec.path)
    except ValueError as exc:
        raise InputError(str(exc)) from None
    if run is not None:
        return run[0], f"start_utc of {run[1]} (the machine time of the run's first row)"
    end = rec.time(rec.n - 1) - rec.t0
    return (rec.path.stat().st_mtime - end,
            f"file modification time of {rec.path} (taken as the end of the recording; set --start-time ISO)")


def recording_json(rec: Recording, clock_source: str | None = None) -> dict:
    """The recording's keys for ``--json`` and report.json: ``timing`` (and ``time_source``)."""
    out = {"timing": rec.timing}
    if rec.notes:
        out["unit_assumptions"] = list(rec.notes)
    if clock_source is not None:
        out["time_source"] = clock_source
    return out
