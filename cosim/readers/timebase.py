"""Time stamps as loggers write them: jitter and gaps measured, then resampled or split only when asked.

A step longer than ``GAP_FACTOR`` times the median step is a gap (at least one dropped sample); the
jitter is the largest relative deviation of the other steps from the median. A record is uniform when
it has no gap and its jitter is at most ``TIME_JITTER``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Largest relative deviation of a time step from the median step of a uniform record.
TIME_JITTER = 0.01
#: A step longer than this many median steps is a gap.
GAP_FACTOR = 1.5


@dataclass(frozen=True)
class Timing:
    """What the time column says about the sampling.

    Attributes
    ----------
    n : int
        Samples.
    h : float
        Median step [s] (the nominal sampling period).
    jitter : float
        Largest |step - h| / h over the steps that are not gaps.
    gaps : tuple of (int, float, float)
        ``(k, t, length)``: the step from sample ``k`` to ``k + 1`` starting at time ``t`` [s, from the first
        sample] lasts ``length`` seconds.
    """

    n: int
    h: float
    jitter: float
    gaps: tuple[tuple[int, float, float], ...]

    @property
    def uniform(self) -> bool:
        return not self.gaps and self.jitter <= TIME_JITTER

    def largest(self) -> tuple[int, float, float] | None:
        return max(self.gaps, key=lambda g: g[2]) if self.gaps else None

    def describe(self) -> str:
        """``2501 samples, median step 4 ms (250 Hz), jitter 0.01 %, 3 gaps (largest 0.024 s at t = 1.2 s)``."""
        jitter = f"{100 * self.jitter:.2g} %" if self.jitter >= 1e-6 else "below 0.0001 %"
        text = f"{self.n} samples, median step {self.h:.6g} s ({1 / self.h:.6g} Hz), jitter {jitter}"
        big = self.largest()
        if big is None:
            return text + ", no gaps"
        return (text + f", {len(self.gaps)} gap{'s' * (len(self.gaps) > 1)} (largest {big[2]:.6g} s at t = "
                f"{big[1]:.6g} s, after sample {big[0]})")

    def to_dict(self) -> dict:
        big = self.largest()
        return {"samples": self.n, "median_step_s": self.h, "rate_hz": 1 / self.h, "jitter": self.jitter,
                "gaps": len(self.gaps), "largest_gap_s": big[2] if big else 0.0,
                "largest_gap_at_s": big[1] if big else None}


def measure(t: np.ndarray) -> Timing:
    """Timing of strictly increasing time stamps ``t`` shape (n,), n >= 2 [s]."""
    dt = np.diff(t)
    h = float(np.median(dt))
    gap = dt > GAP_FACTOR * h
    rest = dt[~gap]
    jitter = float(np.max(np.abs(rest - h)) / h) if rest.size else 0.0
    gaps = tuple((int(k), float(t[k] - t[0]), float(dt[k])) for k in np.flatnonzero(gap))
    return Timing(len(t), h, jitter, gaps)


def resample(t: np.ndarray, signals: dict[str, np.ndarray], h: float, hold: frozenset[str] = frozenset(),
             ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Signals on the grid ``t[0] + k h`` by linear interpolation (``hold``: previous value, for states)."""
    n = int(np.floor((t[-1] - t[0]) / h * (1 + 1e-12))) + 1
    grid = t[0] + h * np.arange(n)
    out = {}
    for name, x in signals.items():
        if name in hold:
            k = np.clip(np.searchsorted(t, grid + 1e-9 * h, side="right") - 1, 0, len(t) - 1)
            out[name] = x[k]
        else:
            out[name] = np.interp(grid, t, x)
    return grid, out
