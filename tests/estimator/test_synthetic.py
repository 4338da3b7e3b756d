"""The synthetic records' smoothing (tests/estimator/synthetic.py) is scipy's Gaussian filter, formed by FFT."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter1d
from synthetic import gaussian_smoothed


@pytest.mark.parametrize(("n", "sigma"), [(10, 0.7), (50, 3.0), (300, 200.0), (5000, 400.0)])
def test_gaussian_smoothed_is_gaussian_filter1d_nearest(n, sigma):
    """The same kernel and edge extension, a kernel shorter and longer than the signal: equal to rounding."""
    x = np.cumsum(np.random.default_rng(n).standard_normal(n))
    expected = gaussian_filter1d(x, sigma, mode="nearest")
    np.testing.assert_allclose(gaussian_smoothed(x, sigma), expected, rtol=0, atol=1e-12 * np.abs(x).max())
