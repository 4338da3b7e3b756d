"""Signal recorder: a preallocated array filled in blocks of rows, written to signals.csv."""
from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

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

    def extend(self, rows: Sequence[Sequence[float]]) -> None:
        """Append rows (each one value per signal, in ``names`` order)."""
        if rows:
            self.data[self.n:self.n + len(rows)] = rows
            self.n += len(rows)

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
        header = ",".join(f"{n} [{u}]" if u else n for n, u in zip(("time",) + self.names, ("s",) + self.units))
        table = np.column_stack([self.time, self.data[:self.n]])
        np.savetxt(path, table, delimiter=",", header=header, comments="", fmt="%.10g")
        return path
