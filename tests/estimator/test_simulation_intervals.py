"""The simulation's spline intervals from the integers (``simulation.uniform_intervals``) are the search's
(``simulation._interval_of``): every stride, record length and read-off shift the instruments use, and times
before the first knot and past the last (extrapolated), the same integers."""
from __future__ import annotations

import numpy as np
import pytest

from feeddrive.estimator.simulation import _interval_of, simulate, uniform_intervals


def _knots(n: int, k: int) -> np.ndarray:
    idx = np.arange(0, n, k)
    return (idx if idx[-1] == n - 1 else np.append(idx, n - 1)).astype(float)


@pytest.mark.parametrize("k", [1, 2, 3, 4, 7])
@pytest.mark.parametrize("n", [9, 10, 11, 57, 5712, 5713])
def test_uniform_intervals_are_the_search(n, k):
    if (n - 1) // k + 1 + int((n - 1) % k != 0) < 2:
        pytest.skip("fewer than two knots")
    x = _knots(n, k)
    for shift in (0.0, 0.5 / 3, -0.5 / 3, 0.25, -0.25, 0.5 / 7, -0.5 / 7, 0.999999, -1.0, 1.0):
        at = np.arange(n) + shift
        np.testing.assert_array_equal(uniform_intervals(n, k, at), _interval_of(x, at))
    rng = np.random.default_rng(n + k)
    at = np.sort(rng.uniform(-3 * k, n + 3 * k, 300))  # outside the knots too: the end intervals extrapolate
    np.testing.assert_array_equal(uniform_intervals(n, k, at), _interval_of(x, at))
    np.testing.assert_array_equal(uniform_intervals(n, k, at[::-1]), _interval_of(x, at[::-1]))


def test_simulated_current_reads_the_analytic_first_order_response():
    """Physics through the spline: L di/dt + R i = u - K w with a voltage step from rest is
    i = u / R (1 - exp(-R t / L)); the states integrated every 4th sample and read half a sample off."""
    h, n = 1e-4, 4001
    params = {"R": 0.6, "L": 4e-3, "K": 1.05, "Jt": 0.1, "ft": 0.02, "Cd": 1.2}
    u, w = np.full(n, 12.0), np.zeros(n)
    at = np.arange(n) + 0.5
    i = simulate(("electrical",), {"u": u, "w": w}, params, h, {"i": 0.0}, step=4 * h, at=at)["i"]
    t = at * h
    exact = 12.0 / 0.6 * (1.0 - np.exp(-0.6 * t / 4e-3))
    np.testing.assert_allclose(i, exact, atol=1e-4)  # RK4 at 0.4 ms on a 6.7 ms time constant: 7e-6 A of 20 A
