"""The identical low-pass filter of every measured signal (paper eq. 8).

Filtering all signals with the same linear filter F leaves the model unchanged
(``H = Y/U = FY/FU``) while removing the noise the derivative operator would amplify.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from feeddrive.estimator import lti
from feeddrive.estimator.errors import EstimatorInputError


@dataclass(frozen=True)
class FilterSpec:
    """The one place that decides the filter F.

    Attributes
    ----------
    cutoff_hz : float
        -3 dB cut-off of the Butterworth low-pass [Hz]; must be below 0.45 of the Nyquist frequency.
    order : int
        Butterworth order (the zero-phase filter squares the magnitude response).
    zero_phase : bool
        True: forward-backward (``sosfiltfilt``, offline, no delay). False: causal (``sosfilt``).
    """

    cutoff_hz: float
    order: int = 4
    zero_phase: bool = True

    def __post_init__(self) -> None:
        if not self.cutoff_hz > 0:
            raise EstimatorInputError(f"filter cutoff_hz must be > 0 Hz, got {self.cutoff_hz}")
        if int(self.order) != self.order or self.order < 1:
            raise EstimatorInputError(f"filter order must be a positive integer, got {self.order}")

    def sos(self, h: float) -> np.ndarray:
        """Second-order sections of the filter for sampling period ``h`` [s]."""
        nyquist = 0.5 / h
        if self.cutoff_hz >= 0.45 * nyquist:
            raise EstimatorInputError(
                f"filter cutoff {self.cutoff_hz} Hz must be below 0.45 x Nyquist ({0.45 * nyquist:g} Hz at h={h:g} s)")
        return _butter_sos(int(self.order), float(self.cutoff_hz), float(h)).copy()  # a writable copy: the cached one is shared

    def apply(self, signals: Mapping[str, np.ndarray], h: float, remember: bool = True) -> dict[str, np.ndarray]:
        """Filter every signal identically.

        Parameters
        ----------
        signals : mapping of str to ndarray, each shape (n,)
            Signals sampled every ``h`` seconds (None values are passed through).
        h : float
            Sampling period [s].
        remember : bool
            Keep the results for a later call on the same values (``_MEMO``: a copy of each signal). False for
            signals no later phase filters again (the IV halves' samples): no copy, no memo entry.

        Returns
        -------
        dict of str to ndarray, shape (n,)
            Filtered signals, same keys.
        """
        sos = self.sos(h)
        out = {}
        if self.zero_phase:
            pad = 3 * (2 * len(sos) + 1)
            same: dict[int, list[str]] = {}  # signals of one length go through sosfiltfilt as one 2-D array
            for name, x in signals.items():
                if x is None:
                    out[name] = None
                    continue
                x = np.asarray(x, dtype=float)
                if x.size <= pad:
                    raise EstimatorInputError(f"signal {name!r}: {x.size} samples, the zero-phase filter needs > {pad}")
                same.setdefault(x.size, []).append(name)
            for names in same.values():
                arrays = {k: np.asarray(signals[k], dtype=float) for k in names}
                todo = []
                for k in names:
                    hit = _MEMO.get(_key(self, h, arrays[k]))
                    if hit is not None and np.array_equal(hit[0], arrays[k]):
                        out[k] = hit[1]
                    else:
                        todo.append(k)
                if not todo:
                    continue
                # row by row the same arithmetic as one call per signal (tests/estimator/test_speed.py)
                # the rows written once, into the extension, which is kept as the memo's copy of the values
                y, kept = lti.sosfiltfilt(sos, [arrays[k] for k in todo], keep_input=True) if remember else \
                    (lti.sosfiltfilt(sos, [arrays[k] for k in todo]), None)
                y.setflags(write=False)  # shared by the callers that filter the same array
                for j, (k, row) in enumerate(zip(todo, y)):
                    out[k] = row
                    if remember:
                        _remember(_key(self, h, arrays[k]), (kept[j], row))
            return {k: out[k] for k in signals}
        for name, x in signals.items():
            if x is None:
                out[name] = None
                continue
            x = np.asarray(x, dtype=float)
            out[name] = lti.sosfilt(sos, x, zi=lti.sosfilt_zi(sos) * x[0])[0]
        return out


#: Largest phase ``2 pi fc (2 h D)`` of the filter's cut-off at the IV halves' sample period after decimation by D
#: [rad]: half the sample-period rule's ``partial.MAX_HALF_PHASE`` (1.0), where the halves start to alias. At the
#: monitor's 10 kHz and 50 Hz: D = 7 (the halves at 1.2 ms, the whole record at 0.7 ms, ``w h D`` = 0.22 rad at the
#: cut-off, where the zero-forcing operator with the matched average is exact to ~1e-4 in gain and phase).
MAX_DECIMATED_PHASE = 0.5
#: Fewest samples a record keeps after decimation (a shorter record is not decimated at all).
MIN_DECIMATED_SAMPLES = 2000


def check_decimation(value: object) -> None:
    """``EstimationOptions.decimation``: "auto" or an integer >= 1, else one line naming it."""
    if value != "auto" and not (isinstance(value, int | np.integer) and not isinstance(value, bool) and value >= 1):
        raise EstimatorInputError(f"decimation must be 'auto' or an integer >= 1, got {value!r}")


def decimation_factor(cutoff_hz: float, h: float, n: int, requested: int | str = "auto") -> int:
    """How many samples of a low-passed record the estimator steps over: every D-th filtered sample is kept.

    The filtered signals carry nothing above a few cut-offs (the zero-phase Butterworth of order 4 is down
    80 dB at 10 cut-offs), so the samples between every D-th add no information on the model, only on the
    noise that the filter left, which is correlated over ~1 / cutoff anyway; the estimator's work is
    proportional to the samples it keeps. D is the largest integer with ``2 pi fc (2 h D) <=
    MAX_DECIMATED_PHASE`` (the IV halves, sampled every 2 h D, stay far from aliasing and the zero-forcing
    derivative at h D far from its error), and 1 when fewer than ``MIN_DECIMATED_SAMPLES`` would be left.

    Parameters
    ----------
    cutoff_hz : float
        Cut-off of the identical low-pass [Hz].
    h : float
        Sample period of the record [s].
    n : int
        Samples of the record.
    requested : int or "auto"
        ``EstimationOptions.decimation``: "auto" (the rule above), or a factor >= 1 (1: every sample).

    Returns
    -------
    int
        D >= 1.
    """
    if requested != "auto":
        return int(requested)
    d = int(np.floor(MAX_DECIMATED_PHASE / (2 * np.pi * cutoff_hz * 2 * h) + 1e-9))
    d = min(d, n // MIN_DECIMATED_SAMPLES)
    return max(d, 1)


def check_rate_factor(cutoff_hz: float, h: float, n: int, requested: int | str = "auto", rate_hz: float = 50.0) -> int:
    """D of the model checks (``mismatch.check_model``, ``adequacy.check_adequacy``): every D-th filtered sample.

    A check simulates or differentiates the filtered signals at h D and tests averages over blocks of many
    samples; it has no split halves, whose period 2 h D bounds the estimator's D (:func:`decimation_factor`).
    "auto": the largest D with ``2 pi fc h D <= MAX_DECIMATED_PHASE``, 1 when fewer than
    ``MIN_DECIMATED_SAMPLES`` would be left; a factor given is taken as it is. Either is then lowered to a
    divisor of the output-error check's block of ``1 / rate_hz`` s, so that its blocks keep their duration: with
    67 samples of 0.3 ms for 200 of 0.1 ms (20.1 ms) it rejected 4 of 150 healthy motions at alpha = 0.01, with
    100 of 0.2 ms 1 (as D = 1). At 10 kHz with the monitor's 100 Hz filter: D = 5 (7, lowered; the estimator's
    D is 3). Paired on the first runs of the issue-12 campaigns (benchmarks/bench_model_check_rate.py), the
    output-error check at D = 5 against D = 2: 3 and 4 of 100 healthy motions rejected at alpha 1 % (the same
    but one), 9 and 9 of the vendor FMU's (the same), every Cd step (30) and backlash (60) at both; the residue
    check at D = 5 against D = 3: the same verdicts on all 290 (at D = 7 it lost one of its two backlash
    detections). Those healthy figures were measured before the output-error check took the parameters a motion
    does not determine as free (``mismatch.check_model``'s ``undetermined``): at D = 5 it then rejected 0 of
    100 healthy and 2 of 100 vendor motions.
    """
    if requested == "auto":
        d = int(np.floor(MAX_DECIMATED_PHASE / (2 * np.pi * cutoff_hz * h) + 1e-9))
        d = max(1, min(d, n // MIN_DECIMATED_SAMPLES))
    else:
        d = int(requested)
    from feeddrive.estimator.residue_tests import block_samples  # here: it imports scipy.linalg

    block = block_samples(rate_hz, h)
    while d > 1 and block % d:
        d -= 1
    return d


def lowpass(signals: Mapping[str, np.ndarray], h: float, cutoff_hz: float, order: int = 4,
            zero_phase: bool = True) -> dict[str, np.ndarray]:
    """Thin wrapper: ``FilterSpec(cutoff_hz, order, zero_phase).apply(signals, h)``."""
    return FilterSpec(cutoff_hz, order, zero_phase).apply(signals, h)


@lru_cache(maxsize=64)
def _butter_sos(order: int, cutoff_hz: float, h: float) -> np.ndarray:
    """The Butterworth sections, designed once per (order, cut-off, rate): ``butter`` costs ~1 ms a call and
    a motion's treatment asked for the same filter ten times. Read-only: the cached array is shared."""
    sos = lti.butter_sos(order, cutoff_hz, 1.0 / h)
    sos.setflags(write=False)
    return sos


#: (spec, h, n, three samples) -> (the signal's values, filtered): a motion's treatment filters the same
#: sensor signals several times (validation, the residue check, the estimator, the model check), not
#: always as the same array object; every value is compared before a result is reused
_MEMO: dict = {}
_MEMO_SIZE = 24
#: and at most this many bytes (values and results): a 30 s motion at 10 kHz keeps its last ten signals
_MEMO_BYTES = 48 * 2 ** 20


def _key(spec: FilterSpec, h: float, x: np.ndarray) -> tuple:
    n = x.size
    return spec, h, n, float(x[0]), float(x[n // 2]), float(x[-1])


def _remember(key: tuple, value: tuple) -> None:
    _MEMO.pop(key, None)
    _MEMO[key] = value
    while len(_MEMO) > _MEMO_SIZE or sum(x.nbytes + y.nbytes for x, y in _MEMO.values()) > _MEMO_BYTES:
        _MEMO.pop(next(iter(_MEMO)))


def share_filtered(spec: FilterSpec, h: float, x: np.ndarray, filtered: np.ndarray, own: bool = False) -> None:
    """Let ``spec.apply`` give ``filtered`` for ``x`` (sampled every ``h`` [s]) without filtering it again.

    For a signal built as a linear combination of signals already filtered (measurement validation's mean of
    two sensors, or a sensor corrected by its gain and offset): F is linear, so the same combination of their
    filtered rows is F of it, to the rounding of one addition (~1e-16 of the signal) instead of a filter pass.
    ``x`` (n,) is copied (its values are compared before ``filtered`` is given for it); with ``own`` (the
    caller made ``x`` and owns its memory) ``x`` itself is made read-only and kept instead of a copy.
    ``filtered`` (n,) is made read-only and shared, as ``apply``'s results are.
    """
    x = np.asarray(x, dtype=float)
    if spec.zero_phase and x.ndim == 1 and np.shape(filtered) == x.shape:
        filtered = np.asarray(filtered, dtype=float)
        filtered.setflags(write=False)
        if own and x.base is None:  # nothing else writes to its memory once read-only
            x.setflags(write=False)
        else:
            x = x.copy()
        _remember(_key(spec, h, x), (x, filtered))


def clear_filter_memo() -> None:
    """Forget the filtered signals kept for reuse (benchmarks: each timed motion is then filtered afresh)."""
    _MEMO.clear()
