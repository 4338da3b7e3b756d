"""High-speed motions found in a recording."""
from __future__ import annotations

import numpy as np
import pytest
from plant_data import CORNERS, H, w_ref

from feeddrive.estimator import EstimatorInputError
from feeddrive.estimator.segmentation import Segment, from_speed, from_state, segment


def test_nc_state_blocks_are_the_motions():
    state = np.array([0, 1, 1, 1, 0, 0, 2, 1, 1, 0, 1])
    assert from_state(state) == [Segment(1, 4), Segment(7, 9), Segment(10, 11)]


def test_a_round_trip_with_a_short_stop_is_one_motion_padded():
    t = np.arange(int(CORNERS[-1] / H) + 1) * H
    (seg,) = from_speed(w_ref(t), H)
    # active from |w| >= 7 rad/s (0.1 of 70) on the first ramp to the same level on the last ramp
    first = CORNERS[1] + 0.1 * 0.38
    last = CORNERS[-2] - 0.1 * 0.38
    assert seg.start * H == pytest.approx(first - 0.1, abs=2 * H)
    assert seg.stop * H == pytest.approx(last + 0.1, abs=2 * H)


def test_motions_apart_by_a_long_stop_are_separate():
    t = np.arange(0, 4.0, H)
    w = np.where((t > 0.5) & (t < 1.5), 50.0, 0.0) + np.where((t > 2.5) & (t < 3.0), -30.0, 0.0)
    segs = from_speed(w, H)
    assert [(round(s.start * H, 3), round(s.stop * H, 3)) for s in segs] == [(0.4, 1.6), (2.4, 3.1)]


def test_modes():
    w = np.zeros(100)
    assert segment("none", 100, H) == [Segment(0, 100)]
    assert segment("auto", 100, H, w=w, state=np.r_[np.zeros(50), np.ones(50)]) == [Segment(50, 100)]
    assert segment("auto", 100, H, w=w) == []
    with pytest.raises(EstimatorInputError, match="NC state"):
        segment("nc", 100, H, w=w)
    with pytest.raises(EstimatorInputError, match="mode"):
        segment("fast", 100, H, w=w)
