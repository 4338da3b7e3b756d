"""High-speed motions in a recording.

Three rules, in order of preference:

* ``nc``: from the NC state signal; a motion is a contiguous block of samples with state == 1 (rapid).
* ``speed``: from the speed profile; samples with ``|w| >= fraction * max|w|`` are active, active runs
  closer than ``merge_gap`` seconds are merged (a round trip with a short stop is one motion: the
  speed reversal is what separates Cd from an offset), each run is padded by ``pad`` seconds on both
  sides (the acceleration from standstill carries the inertia information) and runs shorter than
  ``min_duration`` seconds are dropped.
* ``none``: the whole record is one motion.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from feeddrive.estimator.errors import EstimatorInputError

MODES = ("auto", "nc", "none")


@dataclass(frozen=True)
class Segment:
    """Samples ``start <= k < stop`` of a recording."""

    start: int
    stop: int


def _runs(active: np.ndarray) -> list[Segment]:
    edges = np.flatnonzero(np.diff(np.concatenate([[0], active.astype(np.int8), [0]])))
    return [Segment(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2])]


def from_state(state: np.ndarray) -> list[Segment]:
    """Contiguous blocks of ``state == 1`` (rapid motion).

    Parameters
    ----------
    state : ndarray, shape (n,)
        NC state signal (1 = rapid, anything else = not).
    """
    return _runs(np.asarray(state) == 1)


def from_speed(w: np.ndarray, h: float, fraction: float = 0.1, merge_gap: float = 0.5, pad: float = 0.1,
               min_duration: float = 0.3) -> list[Segment]:
    """Motions found in the speed profile (see the module docstring).

    Parameters
    ----------
    w : ndarray, shape (n,)
        Motor speed [rad/s].
    h : float
        Sampling period [s].
    fraction : float
        Activity threshold as a fraction of ``max |w|``.
    merge_gap, pad, min_duration : float
        [s].
    """
    w = np.abs(np.asarray(w, dtype=float))
    peak = float(np.max(w)) if w.size else 0.0
    if peak <= 0:
        return []
    runs = _runs(w >= fraction * peak)
    merged: list[Segment] = []
    for r in runs:
        if merged and (r.start - merged[-1].stop) * h < merge_gap:
            merged[-1] = Segment(merged[-1].start, r.stop)
        else:
            merged.append(r)
    k = int(round(pad / h))
    padded = [Segment(max(0, s.start - k), min(len(w), s.stop + k)) for s in merged]
    return [s for s in padded if (s.stop - s.start) * h >= min_duration]


def segment(mode: str, n: int, h: float, w: np.ndarray | None = None, state: np.ndarray | None = None,
            ) -> list[Segment]:
    """Segments of a recording of ``n`` samples.

    Parameters
    ----------
    mode : str
        ``auto`` (NC state when given, else the speed profile), ``nc`` or ``none``.
    n : int
        Number of samples.
    h : float
        Sampling period [s].
    w, state : ndarray, shape (n,), optional
        Speed [rad/s] (or any speed estimate) and NC state.
    """
    if mode not in MODES:
        raise EstimatorInputError(f"segmentation mode must be one of {MODES}, got {mode!r}")
    if mode == "none":
        return [Segment(0, n)]
    if state is not None:
        return from_state(state)
    if mode == "nc":
        raise EstimatorInputError("segmentation 'nc' needs an NC state signal (role 'state')")
    if w is None:
        raise EstimatorInputError("automatic segmentation needs a speed or position signal")
    return from_speed(w, h)
