"""The identical low-pass filter (paper eq. 8)."""
from __future__ import annotations

import numpy as np
import pytest

from feeddrive.estimator import EstimatorInputError, FilterSpec, lowpass

H = 1e-4


def sine(f_hz: float, n: int = 20000) -> np.ndarray:
    return np.sin(2 * np.pi * f_hz * np.arange(n) * H)


def mid_amplitude(x: np.ndarray) -> float:
    mid = x[len(x) // 4: 3 * len(x) // 4]
    return float(np.sqrt(2 * np.mean(mid ** 2)))


def test_identical_filtering_keeps_a_linear_relation():
    rng = np.random.default_rng(0)
    x = rng.standard_normal(5000)
    f = FilterSpec(100.0).apply({"u": 3 * x - 2 * np.roll(x, 1), "a": x, "b": np.roll(x, 1)}, H)
    np.testing.assert_allclose(f["u"], 3 * f["a"] - 2 * f["b"], atol=1e-12)


def test_zero_phase_response_gain_and_no_delay():
    spec = FilterSpec(50.0, order=4)
    slow = spec.apply({"x": sine(5.0)}, H)["x"]
    assert mid_amplitude(slow) == pytest.approx(1.0, abs=1e-3)
    np.testing.assert_allclose(slow[5000:15000], sine(5.0)[5000:15000], atol=2e-3)  # no phase lag
    at_cutoff = spec.apply({"x": sine(50.0)}, H)["x"]
    assert mid_amplitude(at_cutoff) == pytest.approx(0.5, abs=0.01)  # |H|^2 at the -3 dB point


def test_causal_option_has_the_butterworth_gain_and_a_delay():
    x = lowpass({"x": sine(50.0)}, H, 50.0, zero_phase=False)["x"]
    assert mid_amplitude(x) == pytest.approx(2 ** -0.5, abs=0.01)
    slow = lowpass({"x": sine(5.0)}, H, 50.0, zero_phase=False)["x"]
    ref = sine(5.0)[5000:15000]
    delay = min(range(200), key=lambda s: np.sum((slow[5000 + s:15000 + s] - ref) ** 2))
    # low-frequency group delay of a 4th-order Butterworth: 2.61 / (2 pi fc) = 8.3 ms = 83 samples
    assert delay == pytest.approx(83, abs=3)


def test_wrapper_equals_the_spec():
    x = {"x": sine(30.0, 3000)}
    np.testing.assert_array_equal(lowpass(x, H, 80.0, order=2)["x"], FilterSpec(80.0, 2).apply(x, H)["x"])


@pytest.mark.parametrize("kwargs", [dict(cutoff_hz=0.0), dict(cutoff_hz=10.0, order=0), dict(cutoff_hz=10.0, order=2.5)])
def test_bad_specs_are_refused(kwargs):
    with pytest.raises(EstimatorInputError):
        FilterSpec(**kwargs)


def test_cutoff_too_close_to_nyquist_is_refused():
    with pytest.raises(EstimatorInputError, match="Nyquist"):
        FilterSpec(2300.0).apply({"x": sine(1.0)}, H)
