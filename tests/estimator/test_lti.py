"""estimator.lti gives scipy.signal's numbers (it replaces scipy.signal on the run path: ~1 s of imports).

Random inputs, the orders and cut-offs the project uses (the identical filter: order 4 at 50-100 Hz on
1-10 kHz records; the sensors' anti-aliasing filter up to a quarter of the plant's rate; the model checks'
first-order Tustin models of ``1 / (L s + R)`` and ``1 / (Jt s + ft)``), compared within 1e-12 relative.
"""
from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy import signal

from feeddrive.estimator import lti

RTOL = 1e-12
#: cut-off / sampling rate: from the identical filter at 50 Hz on 10 kHz to the anti-aliasing filter at fs / 4
RATIOS = st.floats(0.004, 0.3)


def close(actual: np.ndarray, expected: np.ndarray) -> None:
    """Bit for bit with the compiled loops (scipy's order of operations); without them (no C compiler) within
    RTOL of the largest value (a filtered signal crosses zero: elementwise relative means nothing there)."""
    if lti._library() is not None:
        np.testing.assert_array_equal(actual, expected)
    else:
        np.testing.assert_allclose(actual, expected, rtol=RTOL, atol=RTOL * float(np.max(np.abs(expected))))


@pytest.fixture(params=["compiled", "numpy"])
def loops(request, monkeypatch):
    """Both evaluations of the recursions: the C loops, and the block-wise numpy one used without a compiler."""
    if request.param == "numpy":
        monkeypatch.setattr(lti, "_library", lambda: None)
    else:
        assert lti._library() is not None, "no C compiler here: the compiled loops are not tested"
    return request.param


@settings(max_examples=60, deadline=None)
@given(order=st.integers(1, 10), ratio=st.floats(0.001, 0.49), fs=st.sampled_from([1e3, 2e3, 1e4, 1e5]))
def test_butter_sections_are_scipys(order, ratio, fs):
    expected = signal.butter(order, ratio * fs, fs=fs, output="sos")
    actual = lti.butter_sos(order, ratio * fs, fs)
    assert actual.shape == expected.shape
    np.testing.assert_allclose(actual, expected, rtol=RTOL, atol=0)
    assert np.array_equal(actual == 0, expected == 0)  # same pairing of poles and zeros into the sections


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(order=st.integers(1, 8), ratio=RATIOS, n=st.integers(40, 3000), rows=st.integers(1, 5),
       seed=st.integers(0, 2 ** 32 - 1))
def test_sosfiltfilt_and_sosfilt_are_scipys(loops, order, ratio, n, rows, seed):
    rng = np.random.default_rng(seed)
    x = rng.standard_normal((rows, n)).cumsum(axis=1) + 5.0  # a drifting signal with an offset: the edges matter
    sos = signal.butter(order, ratio, fs=1.0, output="sos")
    ntaps = 2 * len(sos) + 1 - (order % 2)
    if n <= 3 * ntaps:
        with pytest.raises(ValueError):
            lti.sosfiltfilt(sos, x)
        return
    close(lti.sosfiltfilt(sos, x), signal.sosfiltfilt(sos, x, axis=-1))
    close(lti.sosfiltfilt(sos, x[0]), signal.sosfiltfilt(sos, x[0]))
    zi = signal.sosfilt_zi(sos)
    np.testing.assert_allclose(lti.sosfilt_zi(sos), zi, rtol=RTOL, atol=RTOL)
    y, zf = lti.sosfilt(sos, x[0], zi=zi * x[0, 0])
    y_ref, zf_ref = signal.sosfilt(sos, x[0], zi=zi * x[0, 0])
    close(y, y_ref)
    close(zf, zf_ref)
    close(lti.sosfilt(sos, x[0]), signal.sosfilt(sos, x[0]))
    # several rows at once (the C loop takes them two by two, a last odd one alone), each from its own state
    zr = zi[:, None, :] * x[None, :, :1] * np.linspace(0.5, 1.5, rows)[None, :, None]
    y, zf = lti.sosfilt(sos, x, zi=zr)
    y_ref, zf_ref = signal.sosfilt(sos, x, axis=-1, zi=zr)
    close(y, y_ref)
    close(zf, zf_ref)


def test_many_rows_are_filtered_as_each_alone(loops):
    """More rows than the C loop takes per call (``ROWS_PER_CALL``): the same numbers as scipy's, row by row."""
    rng = np.random.default_rng(4)
    x = rng.standard_normal((2 * lti.ROWS_PER_CALL + 3, 300)).cumsum(axis=1)
    sos = signal.butter(4, 0.05, output="sos")
    close(lti.sosfiltfilt(sos, x), signal.sosfiltfilt(sos, x, axis=-1))
    zi = signal.sosfilt_zi(sos)[:, None, :] * x[None, :, :1]
    for actual, expected in zip(lti.sosfilt(sos, x, zi=zi), signal.sosfilt(sos, x, axis=-1, zi=zi)):
        close(actual, expected)


@pytest.mark.parametrize("order", [3, 4])
def test_two_sections_rows_in_groups_are_scipys(order):
    """Two sections (the identical 4th-order filter) take the C loop's pairs three at a time with their states in
    registers, and a last odd row alone: 1 to 8 rows (groups of 3, 2 and 1 pairs, with and without an odd row),
    both directions, from their own initial states, bit for bit with scipy, final states too."""
    assert lti._library() is not None, "no C compiler here: the compiled loops are not tested"
    rng = np.random.default_rng(order)
    sos = signal.butter(order, 0.01, output="sos")
    assert len(sos) == 2
    for rows in range(1, 9):
        x = rng.standard_normal((rows, 700)).cumsum(axis=1) + 3.0
        np.testing.assert_array_equal(lti.sosfiltfilt(sos, x), signal.sosfiltfilt(sos, x, axis=-1))
        np.testing.assert_array_equal(lti.sosfiltfilt(sos, list(x)), signal.sosfiltfilt(sos, x, axis=-1))  # rows given
        # the forward pass out of the extension into another array: the same bits, the input's values kept
        y, kept = lti.sosfiltfilt(sos, list(x), keep_input=True)
        np.testing.assert_array_equal(y, signal.sosfiltfilt(sos, x, axis=-1))
        np.testing.assert_array_equal(kept, x)
        assert not kept.flags.writeable
        zi = signal.sosfilt_zi(sos)[:, None, :] * x[None, :, :1] * np.linspace(0.5, 1.5, rows)[None, :, None]
        for actual, expected in zip(lti.sosfilt(sos, x, zi=zi), signal.sosfilt(sos, x, axis=-1, zi=zi)):
            np.testing.assert_array_equal(actual, expected)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(a1=st.floats(1e-5, 1.0), a0=st.floats(1e-3, 10.0), h=st.sampled_from([1e-5, 1e-4, 1e-3]),
       n=st.integers(1, 2000), seed=st.integers(0, 2 ** 32 - 1))
def test_first_order_tustin_and_lfilter_are_scipys(loops, a1, a0, h, n, seed):
    b_ref, a_ref = signal.cont2discrete(([1.0], [a1, a0]), h, method="bilinear")[:2]
    b, a = lti.bilinear_first_order(a1, a0, h)
    # bit for bit: the model checks' near-unit poles carry any rounding difference into their p-values
    assert np.array_equal(b, np.ravel(b_ref)) and np.array_equal(a, a_ref)
    # and the transform itself: h / (2 a1 + a0 h) and (a0 h - 2 a1) / (2 a1 + a0 h), up to scipy's cancellation
    c, d = Fraction(a1), Fraction(a0) * Fraction(h)
    exact_b, exact_a1 = Fraction(h) / (2 * c + d), (d - 2 * c) / (2 * c + d)
    tol = RTOL + 1e-14 * a1 / (a0 * h)
    assert abs(Fraction(b[0]) / exact_b - 1) < tol and abs(Fraction(b[1]) / exact_b - 1) < tol
    assert abs(Fraction(a[1]) - exact_a1) < tol
    x = np.random.default_rng(seed).standard_normal(n) + 1.0
    zi = signal.lfilter_zi(b, a)
    np.testing.assert_allclose(lti.lfilter_zi(b, a), zi, rtol=RTOL)
    y, zf = lti.lfilter(b, a, x, zi=zi * x[0])
    y_ref, zf_ref = signal.lfilter(b, a, x, zi=zi * x[0])
    close(y, y_ref)
    close(zf, zf_ref)


@pytest.mark.parametrize("n", [1, 127, 128, 129, 1000])
def test_lfilter_of_a_higher_order_with_unnormalised_coefficients(loops, n):
    """Any block remainder, and ``a[0] != 1`` (scipy divides by it): the recursion is scipy's."""
    x = np.random.default_rng(n).standard_normal(n)
    b, a = [0.5, -0.2, 0.1, 0.05], [2.0, -1.6, 0.5]
    close(lti.lfilter(b, a, x), signal.lfilter(b, a, x))
    zi = signal.lfilter_zi(b, a)
    y, zf = lti.lfilter(b, a, x, zi=zi)
    y_ref, zf_ref = signal.lfilter(b, a, x, zi=zi)
    close(y, y_ref)
    close(zf, zf_ref)


def test_a_step_passes_a_lowpass_unchanged_and_bad_designs_are_refused(loops):
    """Physics: a Butterworth low-pass has unit DC gain, -3 dB at its cut-off, and its steady-state start
    leaves a constant signal constant."""
    sos = lti.butter_sos(4, 100.0, 1e4)
    x = np.full(500, 3.0)
    np.testing.assert_allclose(lti.sosfiltfilt(sos, x), x, rtol=1e-12)
    np.testing.assert_allclose(lti.sosfilt(sos, x, zi=lti.sosfilt_zi(sos) * 3.0)[0], x, rtol=1e-12)
    z = np.exp(2j * np.pi * 100.0 / 1e4)
    gain = np.prod([np.polyval(r[:3], z) / np.polyval(r[3:], z) for r in sos])
    assert abs(gain) == pytest.approx(2 ** -0.5, rel=1e-12)
    for order, cutoff in ((0, 100.0), (4, 0.0), (4, 5000.0)):
        with pytest.raises(ValueError):
            lti.butter_sos(order, cutoff, 1e4)
