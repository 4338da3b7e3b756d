"""High-speed motions in a recording.

Three rules, in order of preference:

* ``nc``: from the NC state signal; a motion is a contiguous block of samples with state == 1 (rapid).
* ``speed``: from the speed profile; samples with ``|w| >= fraction * max|w|`` are active, active runs
  closer than ``merge_gap`` seconds are merged (a round trip with a short stop is one motion: the
  speed reversal is what separates Cd from an offset), each run is padded by ``pad`` seconds on both
  sides (the acceleration from standstill carries the inertia information) and runs shorter than
  ``min_duration`` seconds are dropped.
* ``none``: the whole record is one motion.

Before any of them, a speed that never rises above its own noise holds no motion at all (``at_rest``): an axis
at rest, or a plant that did not move, gets "no high-speed motion: nothing to judge" with the threshold used, not
a motion cut from its sensor's noise whose every parameter is then refused.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from feeddrive.estimator.errors import EstimatorInputError
from feeddrive.estimator.medians import mad_in_place

MODES = ("auto", "nc", "none")
#: A speed whose largest |value| is not above this many times its noise (``speed_noise``) holds no motion
#: (white noise alone exceeds 4 of its rms once in ~16000 samples, 10 never).
REST_SNR = 10.0


@dataclass(frozen=True)
class Segment:
    """Samples ``start <= k < stop`` of a recording."""

    start: int
    stop: int


def speed_noise(w: np.ndarray) -> float:
    """The rms of a speed's white noise, from its second differences ``w[k+1] - 2 w[k] + w[k-1]`` (their rms is
    sqrt(6) times the noise's), robustly (1.4826 times their median absolute deviation): a motion adds to them only
    where its acceleration changes, so a ramp or a cruise leaves the estimate unchanged. Same unit as ``w``; 0 for
    fewer than 3 samples (and for a speed quantised so finely that most second differences are 0)."""
    return _speed_noise(_finite(w))


def _finite(w: np.ndarray) -> np.ndarray:
    """The finite samples of ``w`` as a 1-D float array (``w`` itself when all are: no gathered copy)."""
    w = np.asarray(w, dtype=float).ravel()  # a boolean mask's order: a view of a 1-D array
    finite = np.isfinite(w)
    return w if finite.all() else w[finite]


def _speed_noise(w: np.ndarray) -> float:
    """:func:`speed_noise` of finite samples."""
    if w.size < 3:
        return 0.0
    d2 = w[2:] - 2.0 * w[1:-1] + w[:-2]
    if not np.isfinite(d2).all():  # an overflow: numpy's median and its NaN rule
        return float(1.4826 * np.median(np.abs(d2 - np.median(d2))) / np.sqrt(6.0))
    return float(1.4826 * mad_in_place(d2) / np.sqrt(6.0))  # d2 is ours: np.median's value without its copies


def at_rest(w: np.ndarray, unit: str = "rad/s", threshold: float | None = None) -> str | None:
    """Why the speed ``w`` holds no motion to judge, or None when it moves.

    Parameters
    ----------
    w : ndarray, shape (n,)
        Speed [``unit``].
    unit : str
        Its unit, for the message.
    threshold : float or None
        An absolute speed threshold [``unit``] (the monitor's ``speed_threshold``): the motion's samples below it
        are left out of the estimation. None: ``REST_SNR`` times the speed's noise (``speed_noise``).

    Returns
    -------
    str or None
        ``no high-speed motion: nothing to judge (largest |speed| ..., not above ...: how the threshold was set)``.
    """
    w = _finite(w)
    peak = float(np.max(np.abs(w))) if w.size else 0.0
    if threshold is None:
        noise = _speed_noise(w)
        limit, how = REST_SNR * noise, (f"{REST_SNR:g} x the speed's noise, {noise:.3g} {unit} rms from its second "
                                        f"differences")
    else:
        limit, how = float(threshold), "speed_threshold"
    if peak > limit:
        return None
    if peak == 0:
        return f"no high-speed motion: nothing to judge (the speed is 0 on all {w.size} samples)"
    return (f"no high-speed motion: nothing to judge (largest |speed| {peak:.3g} {unit}, not above {limit:.3g} "
            f"{unit}: {how})")


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
