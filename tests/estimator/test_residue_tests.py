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
