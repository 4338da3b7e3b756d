"""Medians by one selection (issue 26): ``np.median``'s value of an array the caller owns and lets reorder.

``np.median`` copies its input and selects its two middle ranks (and the last, for its NaN check) with one
multi-rank partition; here the upper middle rank is selected in place and the lower middle value is the largest
of the part below it. The same one or two order statistics, averaged as numpy does (their sum halved), so the
same bits for a finite array (tests/estimator/test_speed.py).
"""
from __future__ import annotations

import numpy as np


def median_in_place(a: np.ndarray) -> float:
    """``np.median(a)`` of a finite 1-D float array of size >= 2 that may be reordered (it is partitioned)."""
    half = a.size // 2
    a.partition(half)
    if a.size % 2:
        return a[half]
    return (a[:half].max() + a[half]) / 2.0


def mad_in_place(a: np.ndarray) -> float:
    """``np.median(np.abs(a - np.median(a)))`` of a finite 1-D float array of size >= 2 that may be overwritten
    (it holds the absolute deviations afterwards): the median absolute deviation, unscaled."""
    med = median_in_place(a)
    return median_in_place(np.abs(a - med, out=a))


def percentiles_in_place(a: np.ndarray, q: tuple[float, float]) -> np.ndarray:
    """``np.percentile(a, q)`` (method "linear") of a finite 1-D float array of size >= 2 that may be reordered,
    for two percentiles ``q[0] <= q[1]`` in [0, 100]: the four order statistics by two single-rank selections and
    two minima instead of numpy's selection of six ranks, then numpy's own interpolation (its virtual indices,
    weights and ``_lerp``), on the same values. Returns shape (2,)."""
    n = a.size
    quantiles = np.true_divide(np.asarray(q, dtype=float), 100)
    virtual = (n - 1) * quantiles
    previous = np.floor(virtual)
    gamma = np.asanyarray(virtual - previous, dtype=virtual.dtype)
    at = previous.astype(np.intp)
    above = virtual >= n - 1  # numpy takes the largest value there
    at[above] = n - 1
    lower, upper = np.empty(2), np.empty(2)
    start = 0  # a[start:] holds the ranks from start on (the previous selection's upper part)
    for j in range(2):
        k = int(at[j])
        part = a[start:]
        part.partition(k - start)
        lower[j] = part[k - start]
        upper[j] = lower[j] if above[j] else part[k - start + 1:].min()  # the next rank: the upper part's least
        start = k
    diff = upper - lower  # numpy's _lerp
    out = np.add(lower, diff * gamma)
    np.subtract(upper, diff * (1 - gamma), out=out, where=gamma >= 0.5)
    return out
