"""The zero-forcing #1 derivative operator (paper eq. 3)."""
from __future__ import annotations

import numpy as np
import pytest

from feeddrive.estimator import EstimatorInputError, zero_forcing_derivative
from feeddrive.estimator.derivative import ZERO_FORCING_WEIGHTS

H = 1e-3


def test_weights_are_the_papers_and_have_zero_sum_and_unit_first_moment():
    assert ZERO_FORCING_WEIGHTS == (0.2047, 0.886, -1.386, 0.2953)
    offsets = np.array([1, 0, -1, -2])
    assert sum(ZERO_FORCING_WEIGHTS) == pytest.approx(0.0, abs=1e-15)
    assert offsets @ ZERO_FORCING_WEIGHTS == pytest.approx(1.0, abs=1.5e-4)  # 1.0001 as published
    assert offsets ** 2 @ ZERO_FORCING_WEIGHTS == pytest.approx(0.0, abs=1.5e-4)


@pytest.mark.parametrize("coef", [(3.0, 0, 0), (1.0, -2.0, 0), (0.5, 4.0, -7.0)])
def test_exact_on_polynomials_of_degree_two_up_to_the_published_rounding(coef):
    t = np.arange(50) * H
    a, b, c = coef
    dx, valid = zero_forcing_derivative(a + b * t + c * t ** 2, H)
    exact = b + 2 * c * t[valid]
    # the 4-digit weights have first moment 1.0001: relative error 1e-4 of the slope
    assert np.max(np.abs(dx - exact)) <= 1.5e-4 * (abs(b) + 2 * abs(c) * t[-1] + abs(c) * H) + 1e-12


def test_edges_are_dropped_not_invented():
    x = np.arange(10.0) ** 2
    dx, valid = zero_forcing_derivative(x, 1.0)
    assert dx.shape == (7,) and valid == slice(2, 9)
    # sample k uses x[k+1], x[k], x[k-1], x[k-2]
    k = 2
    assert dx[0] == pytest.approx(0.2047 * x[k + 1] + 0.886 * x[k] - 1.386 * x[k - 1] + 0.2953 * x[k - 2])


def test_sinusoid_error_is_second_order_in_the_step():
    def error(h):
        t = np.arange(int(1 / h)) * h
        dx, valid = zero_forcing_derivative(np.sin(2 * np.pi * 5 * t), h)
        return np.max(np.abs(dx - 2 * np.pi * 5 * np.cos(2 * np.pi * 5 * t[valid])))

    # above the floor set by the published rounding (1e-4 of the slope)
    assert error(4e-3) / error(8e-3) == pytest.approx(0.25, abs=0.05)


@pytest.mark.parametrize("x, h", [(np.zeros(3), 1.0), (np.zeros((4, 2)), 1.0), (np.zeros(5), 0.0)])
def test_bad_input_is_refused(x, h):
    with pytest.raises(EstimatorInputError):
        zero_forcing_derivative(x, h)


def test_matched_average_is_its_two_forms():
    """``matched_average``: the 4-tap FIR ``S`` at samples 2 .. n-2 (where the derivative is), the symmetric
    second-order form ``m1 x + m3 / 6 (x[k+1] - 2 x[k] + x[k-1])`` at sample 1 and ``m1 x`` at both ends; bit for
    bit for every length (the symmetric form is computed at sample 1 only), and a constant passes with gain m1."""
    from feeddrive.estimator.derivative import _M1, _M3, _S, matched_average

    rng = np.random.default_rng(12)
    for n in [*range(1, 12), 997]:
        x = rng.standard_normal(n) * 10.0 ** rng.uniform(-4, 4)
        expected = _M1 * x
        expected[1:-1] += _M3 / 6.0 * (x[2:] - 2.0 * x[1:-1] + x[:-2])
        if n >= 4:
            expected[2:n - 1] = _S[0] * x[3:] + _S[1] * x[2:n - 1] + _S[2] * x[1:n - 2] + _S[3] * x[:n - 3]
        np.testing.assert_array_equal(matched_average(x), expected)
    np.testing.assert_allclose(matched_average(np.full(50, 3.0)), 3.0 * _M1, rtol=1e-14)


def test_derivative_is_the_expression_bit_for_bit():
    """The operator written into one array (two buffers, no temporaries) gives the bits of its expression
    ``(a x[k+1] + b x[k] + c x[k-1] + d x[k-2]) / h`` for every length."""
    a, b, c, d = ZERO_FORCING_WEIGHTS
    rng = np.random.default_rng(13)
    for n in [*range(4, 12), 997]:
        x = rng.standard_normal(n) * 10.0 ** rng.uniform(-4, 4)
        dx, valid = zero_forcing_derivative(x, 7e-5)
        np.testing.assert_array_equal(dx, (a * x[3:] + b * x[2:n - 1] + c * x[1:n - 2] + d * x[:n - 3]) / 7e-5)
        assert valid == slice(2, n - 1)
