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
