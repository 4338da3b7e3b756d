"""Signal recorder: a preallocated array filled in blocks of rows, written to signals.csv."""
from __future__ import annotations

from collections.abc import Sequence
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

    def stream(self, path: str | Path) -> None:
        """Write signals.csv while recording: the header now, each block of rows as ``extend`` gets it.

        Each block is flushed to the operating system, so a process killed by a signal (an FMU that
        crashes) leaves the file complete up to its last block; ``write_csv`` to the same path closes it.
        """
        self._stream_path = Path(path)
        self._stream = open(path, "w", encoding="utf-8")  # noqa: SIM115 - closed by write_csv
        self._stream.write(self._header() + "\n")
        self._write_rows(0, self.n)

    def _header(self) -> str:
        return ",".join(f"{n} [{u}]" if u else n for n, u in zip(("time",) + self.names, ("s",) + self.units))

    def _write_rows(self, a: int, b: int) -> None:
        if b > a:
            table = np.column_stack([self.t0 + self.h * np.arange(a, b), self.data[a:b]])
            np.savetxt(self._stream, table, delimiter=",", fmt="%.10g")
        self._stream.flush()

    def extend(self, rows: Sequence[Sequence[float]]) -> None:
        """Append rows (each one value per signal, in ``names`` order)."""
        if rows:
            self.data[self.n:self.n + len(rows)] = rows
            self.n += len(rows)
            if self._stream is not None:
                self._write_rows(self.n - len(rows), self.n)

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
            self._stream.close()  # already written block by block
            self._stream = None
            return path
        header = self._header()
        table = np.column_stack([self.time, self.data[:self.n]])
        np.savetxt(path, table, delimiter=",", header=header, comments="", fmt="%.10g")
        return path
