"""Time stamps as loggers write them: jitter and gaps measured, then resampled or split only when asked.

A step longer than ``GAP_FACTOR`` times the median step is a gap (at least one dropped sample); the
jitter is the largest relative deviation of the other steps from the median. A record is uniform when
it has no gap and its jitter is at most ``TIME_JITTER``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from feeddrive.cosim.errors import DataError

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
        text = f"{self.n} samples, median step {self.h:.6g} s ({1 / self.h:.6g} Hz), jitter {jitter_text(self.jitter)}"
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


def jitter_text(jitter: float) -> str:
    """``0.42 %``, or ``below 0.0001 %`` for the rounding of decimal time stamps."""
    return f"{100 * jitter:.2g} %" if jitter >= 1e-6 else "below 0.0001 %"


def measure(t: np.ndarray) -> Timing:
    """Timing of strictly increasing time stamps ``t`` shape (n,), n >= 2 [s]."""
    dt = np.diff(t)
    h = float(np.median(dt))
    gap = dt > GAP_FACTOR * h
    rest = dt[~gap]
    jitter = float(np.max(np.abs(rest - h)) / h) if rest.size else 0.0
    gaps = tuple((int(k), float(t[k] - t[0]), float(dt[k])) for k in np.flatnonzero(gap))
    return Timing(len(t), h, jitter, gaps)


def resample_grid(t: np.ndarray, signals: dict[str, np.ndarray], h: float, hold: frozenset[str] = frozenset(),
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


def mend(where: str, time: np.ndarray, signals: dict[str, np.ndarray], timing: Timing, h: float,
         resample: float | None, split_gaps: bool, hold: frozenset[str] = frozenset(),
         ) -> tuple[dict[str, np.ndarray], list[tuple[int, float]], str]:
    """A non-uniform record resampled onto the ``h`` grid (gaps up to ``resample`` s) and/or split at its
    other gaps (``split_gaps``).

    Returns the signals (the records one after the other), ``(first sample, its time)`` of each record and
    what was done, in words. ``where`` (file and time column) starts every error message.
    """
    cut = [g for g in timing.gaps if resample is None or g[2] > resample]
    if cut and not split_gaps:
        k, t, length = max(cut, key=lambda g: g[2])
        raise DataError(f"{where} has a gap of {length:.6g} s at t = {t:.6g} s (after sample {k}), "
                        f"over --resample {resample:g} s; raise MAXGAP or add --split-gaps")
    bounds = [0] + [k + 1 for k, _, _ in cut] + [len(time)]
    parts, pieces, dropped, n = [], [], 0, 0
    for a, b in zip(bounds[:-1], bounds[1:]):
        if b - a < 2:  # a lone sample between two gaps has no step
            dropped += 1
            continue
        t, part = time[a:b], {r: x[a:b] for r, x in signals.items()}
        if resample is not None:
            t, part = resample_grid(t, part, h, hold)
        elif (jitter := measure(t).jitter) > TIME_JITTER:
            raise DataError(f"{where} jitters by {100 * jitter:.3g} % of its step between t = {t[0] - time[0]:.6g} "
                            f"and {t[-1] - time[0]:.6g} s; add --resample MAXGAP to put it on the nominal grid")
        pieces.append((n, float(t[0])))
        parts.append(part)
        n += len(t)
    if not parts:
        raise DataError(f"{where}: no two consecutive samples between the gaps; nothing to estimate")
    actions = []
    if resample is not None:
        actions.append(f"resampled onto the {h:.6g} s grid by linear interpolation (gaps up to {resample:g} s)")
    if split_gaps:
        actions.append(f"split at {len(cut)} gap{'s' * (len(cut) != 1)} into {len(pieces)} records"
                       + (f" ({dropped} single samples dropped)" if dropped else ""))
    return {r: np.concatenate([p[r] for p in parts]) for r in signals}, pieces, "; ".join(actions)
