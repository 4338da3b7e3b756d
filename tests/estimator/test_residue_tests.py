"""The statistics of the model check (estimator/residue_tests.py) against simulation of their null."""
from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from feeddrive.estimator.residue_tests import integrated_noise_covariance, residue_tests


@pytest.mark.parametrize("rho, ratio", [(0.996, 0.044), (0.8, 1.0), (1.0, 0.1)])
def test_integrated_noise_covariance_matches_the_simulated_process(rho, ratio):
    """White unit noise plus an AR(1) started at zero: 40000 simulated segments of 30 blocks agree with
    the closed form to the Monte Carlo error (4 standard errors of a covariance estimate)."""
    rng = np.random.default_rng(3)
    nb, reps = 30, 40000
    v = np.sqrt(ratio) * rng.standard_normal((reps, nb))
    x = signal.lfilter([1.0], [1.0, -rho], v, axis=1)  # x[0] = v[0]: one innovation by the first block
    e = rng.standard_normal((reps, nb)) + x
    empirical = e.T @ e / reps
    expected = integrated_noise_covariance(nb, rho, ratio)
    se = np.sqrt((np.outer(np.diag(expected), np.diag(expected)) + expected ** 2) / reps)
    assert np.all(np.abs(empirical - expected) < 4 * se + 1e-12)
    assert expected[-1, -1] > 1 + ratio * (nb - 1) * rho ** (2 * nb)  # it grows along the segment


def test_null_covariance_keeps_the_level_of_the_speed_test():
    """A residue of white block noise plus integrated noise, regressed on smooth inputs unrelated to it:
    with the null covariance the independence test rejects at about its level (binomial bound at 150
    draws); with the AR stage alone it rejects far more often."""
    h, block, n = 1e-3, 20, 3000  # 50 Hz blocks, 150 of them
    t = np.arange(n) * h
    inputs = np.column_stack([np.sin(2 * np.pi * 0.4 * t) + 0.3 * np.sin(2 * np.pi * 2.1 * t)])
    rho, ratio = 0.996, 0.2
    nuisance = np.exp(-0.2 * t)[:, None]  # the segment's free response
    rng = np.random.default_rng(11)
    rejected = {"gls": 0, "ar": 0}
    for _ in range(150):
        blocks = rng.standard_normal(n // block) + signal.lfilter([1.0], [1.0, -rho], np.sqrt(ratio) * rng.standard_normal(n // block))
        residue = np.repeat(blocks, block) * np.sqrt(block)  # white within a block, block means as drawn
        for key, cov in (("gls", lambda nb: integrated_noise_covariance(nb, rho, ratio)), ("ar", None)):
            tests = residue_tests("speed", residue, nuisance, inputs, h, 0.05, 50.0, 10, None,
                                  segment_covariance=cov, constant=False)[0]
            rejected[key] += tests["independence"].p_value < 0.05
    assert rejected["gls"] <= 14, rejected  # P(X > 14 | n = 150, p = 0.05) < 1 %
    assert rejected["ar"] > 2 * rejected["gls"]


def test_peak_test_level_and_a_transient_of_a_few_blocks():
    """Gaussian block means with smooth nuisance columns: the peak test rejects at most at its level
    (Bonferroni over the blocks; 2000 draws); 3 blocks 8 noise levels out of 500 give p < 1e-6, which
    the mean square (the size test's statistic) barely notices (+40 %)."""
    from feeddrive.estimator.residue_tests import peak_test

    rng = np.random.default_rng(11)
    n = 500
    t = np.linspace(0, 1, n)
    nuisance = np.column_stack([np.ones(n), t, np.exp(-5 * t)])
    p = np.array([peak_test(rng.standard_normal(n) + nuisance @ rng.standard_normal(3), nuisance, [n]).p_value
                  for _ in range(2000)])
    assert 0.002 <= np.mean(p < 0.01) <= 0.015
    y = rng.standard_normal(n)
    y[200:203] += 8.0
    assert peak_test(y, nuisance, [n]).p_value < 1e-6
    assert np.mean(y ** 2) < 1.5


def test_peak_test_keeps_its_level_on_the_integrated_noise_of_each_segment():
    """The speed residue's integrated current noise (a near-unit root started at each segment's start):
    whitened by the null covariance, the peak test rejects at most at its level (400 draws)."""
    from feeddrive.estimator.residue_tests import peak_test

    rng = np.random.default_rng(12)
    sizes, rho, ratio = [150, 150], 0.996, 0.5
    cov = lambda nb: integrated_noise_covariance(nb, rho, ratio)  # noqa: E731
    nuisance = np.zeros((300, 2))
    nuisance[:150, 0] = rho ** np.arange(150)
    nuisance[150:, 1] = rho ** np.arange(150)
    rejected = []
    for _ in range(400):
        y = np.concatenate([np.linalg.cholesky(cov(s)) @ rng.standard_normal(s) for s in sizes])
        rejected.append(peak_test(y, nuisance, sizes, cov).p_value < 0.01)
    assert np.mean(rejected) <= 0.02
    y[100:102] += 6 * np.sqrt(np.diag(cov(150))[100:102])  # a transient of 2 blocks in the first segment
    assert peak_test(y, nuisance, sizes, cov).p_value < 1e-3


def test_segments_whitened_once_checked_are_scipys_solves() -> None:
    """_whiten_segments checks finiteness once per factor and array, then solves unchecked: the same bits as
    scipy's checked solve_triangular per segment, and scipy's error for a NaN."""
    from scipy import linalg

    from feeddrive.estimator.residue_tests import _whiten_segments, integrated_noise_covariance

    rng = np.random.default_rng(5)
    sizes, skip = [40, 55], 3
    cov = lambda nb: integrated_noise_covariance(nb, 0.8, 0.5)  # noqa: E731
    y, N = rng.standard_normal(95), rng.standard_normal((95, 2))
    got = _whiten_segments((y, N), sizes, cov, skip)
    for a, g in zip((y, N), got):
        c = [np.linalg.cholesky(cov(n + skip)[skip:, skip:]) for n in sizes]
        ref = np.concatenate([linalg.solve_triangular(c[0], a[:40], lower=True),
                              linalg.solve_triangular(c[1], a[40:], lower=True)])
        np.testing.assert_array_equal(g, ref)
    y[50] = np.nan
    with pytest.raises(ValueError, match="infs or NaNs"):
        _whiten_segments((y, N), sizes, cov, skip)
