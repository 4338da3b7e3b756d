"""Signal recorder: a preallocated array filled in blocks of rows, written to signals.csv.

Beside it, ``signals.meta.json`` says how each column was sampled (:class:`Sampling`), so that
``cosim estimate`` and ``cosim monitor`` read a run's own signals.csv right by default::

    {"format": "feeddrive-sampling/1", "step_s": 1e-4, "start_utc": "2026-11-26T23:04:22.118234+00:00",
     "columns": {"sensors.u": {"mode": "mean", "rate_hz": 10000.0, "window_s": 1e-4}, ...}}

``start_utc`` is the machine time of the run's first row: a replay of the file is dated by it, not by the
file's modification time (``cosim.recorded.start_clock``).
"""
from __future__ import annotations

import io
import json
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np


class Recorder:
    """Rows of recorded signals at t_n = t0 + n h, n = 0, 1, ...

    Parameters
    ----------
    names, units : sequence of str, length m
        ``component.port`` names and their units (``""`` when unknown).
    n_rows : int
        Capacity: ``n_steps + 1`` (the outputs at t0 and after every step).
    t0, h : float
        Start time and communication step [s].
    """

    def __init__(self, names: Sequence[str], units: Sequence[str], n_rows: int, t0: float, h: float) -> None:
        self.names, self.units = tuple(names), tuple(units)
        self.t0, self.h = t0, h
        self.data = np.empty((n_rows, len(self.names)))
        self.n = 0
        self._stream: Any = None
        self._stream_path: Path | None = None
        #: (rows written to the stream so far, the file's length in bytes then), set in one store: a block whose
        #: writing was interrupted (Ctrl-C) is written again from there, whole (``write_csv``). Skipped, the file
        #: had a row missing before the last; written after a write that had ended but was not yet counted, it had
        #: a block twice (its times going back 0.1 s)
        self._mark = (0, 0)
        #: a block's writing began and was not counted yet: the next write cuts the file back first (``_resume``)
        self._dirty = False

    def stream(self, path: str | Path) -> None:
        """Write signals.csv while recording: the header now, each block of rows as ``extend`` gets it.

        Each block is flushed to the operating system, so a process killed by a signal (an FMU that
        crashes) leaves the file complete up to its last block; ``write_csv`` to the same path closes it.
        """
        self._stream_path = Path(path)
        self._stream = open(path, "w", encoding="utf-8")  # noqa: SIM115 - closed by write_csv
        header = self._header() + "\n"
        self._stream.write(header)
        self._mark = (0, len(header.encode("utf-8")))
        self._write_rows()

    def _header(self) -> str:
        return ",".join(f"{n} [{u}]" if u else n for n, u in zip(("time",) + self.names, ("s",) + self.units))

    def _write_rows(self) -> None:
        """Write the rows recorded and not written yet, and flush them to the operating system."""
        if self._dirty:
            self._resume()
        (a, end), b = self._mark, self.n
        if b > a:
            text = format_rows(np.column_stack([self.t0 + self.h * np.arange(a, b), self.data[a:b]]))
            self._dirty = True
            self._stream.write(text)
            self._mark = (b, end + len(text))  # ASCII: as many bytes as characters
            self._dirty = False
        self._stream.flush()

    def _resume(self) -> None:
        """The stream cut back to its last block written and counted (an interruption may have left part of a block,
        or a whole one not yet counted, after it)."""
        self._stream.flush()
        end = self._mark[1]
        if self._stream_path.stat().st_size != end:
            self._stream.buffer.seek(end)
            self._stream.buffer.truncate()
        self._dirty = False

    def extend(self, rows: Sequence[Sequence[float]]) -> None:
        """Append rows (each one value per signal, in ``names`` order; a list, or an array of shape (rows, signals))."""
        if len(rows):
            self.data[self.n:self.n + len(rows)] = rows
            self.n += len(rows)
            if self._stream is not None:
                self._write_rows()

    @property
    def time(self) -> np.ndarray:
        """Times of the recorded rows [s], shape (n,), computed from the integer step count."""
        return self.t0 + self.h * np.arange(self.n)

    def signals(self) -> dict[str, np.ndarray]:
        """``name -> values`` of shape (n,) (views of the recorded rows)."""
        return {name: self.data[:self.n, j] for j, name in enumerate(self.names)}

    def write_csv(self, path: str | Path) -> Path:
        """Write ``time`` and every signal, units in the header (``plant.current [A]``); returns the path.

        Values are written with 10 significant digits; a run that failed leaves the rows recorded
        before the failure.
        """
        path = Path(path)
        if self._stream is not None and self._stream_path == path:
            self._write_rows()  # written block by block, but for a block an interruption cut short or did not count
            self._stream.close()
            self._stream = None
            return path
        with open(path, "w", encoding="utf-8") as out:
            out.write(self._header() + "\n")
            for a in range(0, self.n, ROWS_PER_WRITE):  # in blocks: the text of a long run at once would be GBs
                b = min(a + ROWS_PER_WRITE, self.n)
                out.write(format_rows(np.column_stack([self.t0 + self.h * np.arange(a, b), self.data[a:b]])))
        return path


#: rows formatted and written at a time by ``Recorder.write_csv``
ROWS_PER_WRITE = 20_000


@lru_cache(maxsize=1)
def _formatter():
    """The compiled library, or None when it cannot be built here: asked once per process, not once per block
    of rows (a compiler that fails would otherwise be run again for every block)."""
    from feeddrive.cosim.fastloop.build import BuildFailed, library

    try:
        return library()
    except BuildFailed:
        return None


def format_rows(table: np.ndarray) -> str:
    """The rows of ``table`` (shape (rows, columns)) as CSV text, each value as ``"%.10g"``, one line per row:
    what ``numpy.savetxt(fmt="%.10g", delimiter=",")`` writes, character for character.

    The compiled fine loop's library (cosim/fastloop/fineloop.c, ``fd_format_rows``) formats them when it can be
    built here: savetxt's Python formatting took about 1 s of a 4 s tool change's run. Otherwise numpy.savetxt.
    """
    table = np.ascontiguousarray(table, dtype=float)
    if table.ndim == 2 and table.size:
        lib = _formatter()
        if lib is not None:
            buf = np.empty(32 * table.size, dtype=np.uint8)
            n = lib.fd_format_rows(table.ctypes.data, table.shape[0], table.shape[1], buf.ctypes.data, buf.size)
            if n >= 0:
                return buf[:n].tobytes().decode("ascii")
    out = io.StringIO()
    np.savetxt(out, table, delimiter=",", fmt="%.10g")
    return out.getvalue()


SIDECAR_FORMAT = "feeddrive-sampling/1"
MODES = ("instant", "mean", "lowpass")


@dataclass(frozen=True)
class Sampling:
    """How one recorded column was sampled.

    Attributes
    ----------
    mode : {"instant", "mean", "lowpass"}
        The value at the time stamp; the mean over ``window_s`` before it; or the output of an
        anti-aliasing low-pass (``order``, ``cutoff_hz``) sampled at the time stamp.
    rate_hz : float
        Samples per second of the column [Hz].
    window_s : float or None
        Length of the averaging window of a ``mean`` [s] (one sampling interval for an integrating ADC).
    cutoff_hz, order : float or None, int or None
        The low-pass of a ``lowpass`` channel [Hz], [1].
    """

    mode: str
    rate_hz: float
    window_s: float | None = None
    cutoff_hz: float | None = None
    order: int | None = None

    def estimator_mode(self) -> str | None:
        """``instant`` or ``mean`` as ``--sampling`` means them (a mean over exactly one sampling interval),
        or None when the estimator has no model of this sampling (a low-pass, a longer window)."""
        if self.mode == "instant":
            return "instant"
        if self.mode == "mean" and self.window_s is not None and abs(self.window_s * self.rate_hz - 1) < 1e-6:
            return "mean"
        return None


def sidecar_path(csv: str | Path) -> Path:
    """``signals.csv`` -> ``signals.meta.json`` (same folder)."""
    csv = Path(csv)
    return csv.with_name(csv.stem + ".meta.json")


def write_sampling_sidecar(csv: str | Path, step: float, columns: Mapping[str, Sampling],
                           start: float | None = None) -> Path:
    """Write the sampling of each column of ``csv`` into its sidecar (see the module docstring); ``start`` is the
    machine time of its first row [s since 1970 UTC] (default: now, as the run's set-up opens its signals)."""
    import datetime as _dt
    import time as _time

    path = sidecar_path(csv)
    start = _time.time() if start is None else float(start)
    data = {"format": SIDECAR_FORMAT, "step_s": step,
            "start_utc": _dt.datetime.fromtimestamp(start, _dt.timezone.utc).isoformat(timespec="microseconds"),
            "columns": {k: {f: v for f, v in asdict(c).items() if v is not None} for k, c in columns.items()}}
    path.write_text(json.dumps(data, indent=1) + "\n", encoding="utf-8")
    return path


def read_sampling_sidecar(csv: str | Path) -> dict[str, Sampling] | None:
    """The sampling of each column of a recorded ``csv`` from its ``signals.meta.json``; None without one.

    Raises
    ------
    ValueError
        A sidecar that is not valid JSON of this format; the message names the file and what was expected.
    """
    path = sidecar_path(csv)
    if not path.is_file():
        return None
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        if data.get("format") != SIDECAR_FORMAT:
            raise ValueError(f"format {data.get('format')!r}")
        out = {}
        for name, c in data["columns"].items():
            s = Sampling(**c)
            if s.mode not in MODES or not float(s.rate_hz) > 0:
                raise ValueError(f"column {name!r}: mode {s.mode!r}, rate_hz {s.rate_hz!r}")
            out[name] = s
        return out
    except (ValueError, TypeError, KeyError, AttributeError) as exc:
        raise ValueError(f"{path}: not a sampling sidecar ({exc}); expected {{\"format\": \"{SIDECAR_FORMAT}\", "
                         "\"columns\": {name: {mode, rate_hz, ...}}}, or delete it") from None


def sidecar_start(csv: str | Path) -> tuple[float, Path] | None:
    """The machine time of the first row of a run's ``csv`` [s since 1970 UTC] from its sidecar's ``start_utc``,
    and the sidecar; None without a sidecar or that key (a sidecar of an earlier version).

    Raises
    ------
    ValueError
        A ``start_utc`` that is not an ISO 8601 time with its zone; the message names the file and the key.
    """
    import datetime as _dt

    path = sidecar_path(csv)
    if not path.is_file():
        return None
    try:
        text = json.loads(path.read_text(encoding="utf-8")).get("start_utc")
    except (ValueError, AttributeError):
        return None  # not this format: read_sampling_sidecar says so where the sampling is read
    if text is None:
        return None
    try:
        t = _dt.datetime.fromisoformat(str(text))
        if t.tzinfo is None:
            raise ValueError("no time zone")
    except ValueError:
        raise ValueError(f"{path}: start_utc {text!r}: expected an ISO 8601 time with its zone, e.g. "
                         "2026-11-26T23:04:22.118234+00:00, or delete the key") from None
    return t.timestamp(), path


def sidecar_modes(csv: str | Path, columns: Mapping[str, str]) -> dict[str, str]:
    """``quantity -> instant|mean`` for the estimator, from the sidecar of ``csv``; ``columns`` maps each
    quantity (voltage, current, speed) to its ``--map`` column (``COLUMN`` or ``COLUMN*SCALE``). A column the
    estimator cannot model (a low-pass, a longer window) keeps the default, with a note on stderr.

    Raises
    ------
    InputError
        An unreadable sidecar (the message names it).
    """
    import sys

    from feeddrive.cosim.errors import InputError

    try:
        side = read_sampling_sidecar(csv)
    except ValueError as exc:
        raise InputError(str(exc)) from None
    if side is None:
        return {}
    modes, said = {}, []
    for quantity, column in columns.items():
        s = side.get(column.split("*")[0].strip())
        if s is None:
            continue
        mode = s.estimator_mode()
        if mode is None:
            detail = (f"an order-{s.order} low-pass at {s.cutoff_hz:g} Hz" if s.mode == "lowpass"
                      else f"a mean over {s.window_s:g} s")
            said.append(f"{quantity}={column} is {detail}, not modelled: taken as instant")
            continue
        modes[quantity] = mode
        said.append(f"{quantity}={mode}")
    if said:
        print(f"sampling from {sidecar_path(csv).name}: {', '.join(said)} (--sampling overrides)", file=sys.stderr)
    return modes
