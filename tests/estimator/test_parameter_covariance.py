"""Per-parameter batch-means covariance and degrees of freedom (estimator.motion.parameter_covariance).

A regressor that lives in a few blocks (like di/dt for L: only the current transients) leaves its
parameter's batch-means variance resting on those blocks, whatever the blocks count, and the
parameter's own estimate absorbs part of their residual. Without the correction the 95 % interval
covers far less than 95 %.
"""
import numpy as np
import pytest
from scipy import signal
from scipy.linalg import toeplitz

from feeddrive.estimator.motion import MethodResult, long_run_covariance, parameter_covariance

N, BLOCK = 4000, 100  # 40 blocks


def test_equal_shares_keep_the_all_blocks_covariance():
    rng = np.random.default_rng(0)
    G = rng.standard_normal((N, 2))
    cov, dof, nb = parameter_covariance(G, np.eye(2), BLOCK)
    S, _ = long_run_covariance(G, BLOCK)
    assert nb == 40 and np.all((dof > 30) & (dof <= 38))
    # k / (k - 1) for k ~ 37 is below nb / (nb - p): no inflation
    assert cov == pytest.approx(S, rel=1e-12)


def test_one_block_gives_one_degree_of_freedom_and_an_inflated_variance():
    G = np.zeros((N, 2))
    G[:, 0] = np.where(np.arange(N) % 2, 1.0, -1.0)
    G[1000:1100, 1] = np.linspace(1, 2, 100)  # only block 10 carries parameter 1
    cov, dof, nb = parameter_covariance(G, np.eye(2), BLOCK)
    S, _ = long_run_covariance(G, BLOCK)
    assert dof[0] == 38 and dof[1] == 1
    assert cov[0, 0] == pytest.approx(S[0, 0]) and cov[1, 1] > 10 * S[1, 1]


def coverage(pulses, reps=600, seed=1):
    """Monte-Carlo coverage of b in y = a x1 + b x2 + AR(1) noise, x2 Hann pulses at ``pulses``."""
    rng = np.random.default_rng(seed)
    x1 = np.sin(np.arange(N) * 2 * np.pi / 700)
    x2 = np.zeros(N)
    for start in pulses:
        x2[start:start + 60] = np.hanning(60)
    X = np.column_stack([x1, x2])
    Ai = np.linalg.inv(X.T @ X)
    hits, hits_all_blocks = [], []
    for _ in range(reps):
        y = X @ [1.0, 2.0] + signal.lfilter([1.0], [1.0, -0.8], rng.standard_normal(N))
        theta = Ai @ X.T @ y
        G = X * (y - X @ theta)[:, None]
        cov, dof, nb = parameter_covariance(G, Ai, BLOCK)
        result = MethodResult("ls", ("a", "b"), theta, cov, nb - 2, 1.0, 0.0, parameter_dof=dof)
        lo, hi = result.parameters["b"].ci95
        hits.append(lo <= 2.0 <= hi)
        S, _ = long_run_covariance(G, BLOCK)  # the former interval: all blocks, nb - p dof
        plain = MethodResult("ls", ("a", "b"), theta, Ai @ S @ Ai, nb - 2, 1.0, 0.0)
        lo, hi = plain.parameters["b"].ci95
        hits_all_blocks.append(lo <= 2.0 <= hi)
    return np.mean(hits), np.mean(hits_all_blocks)


@pytest.mark.parametrize("pulses", [(500, 1900, 3300), (500, 1200, 1900, 2500, 3300, 3800)])
def test_sparse_regressor_interval_covers_with_its_own_blocks_and_not_without(pulses):
    covered, covered_all_blocks = coverage(pulses)
    assert 0.94 <= covered <= 0.995
    assert covered_all_blocks < 0.92 and covered - covered_all_blocks > 0.04


def test_the_stationary_error_covariance_is_the_true_variance_of_a_sparse_parameter():
    """``stationary_score_covariance``: the error's autocovariance from every sample and the regressor's
    exact structure give b's variance within 5 % of its analytic value on average (three pulses carry b), its
    10-90 % spread over the draws is below 1.6, where the batch-means value scatters twice as much or more."""
    from feeddrive.estimator.motion import stationary_score_covariance

    rng = np.random.default_rng(7)
    x1 = np.sin(np.arange(N) * 2 * np.pi / 700)
    x2 = np.zeros(N)
    for start in (500, 1900, 3300):
        x2[start:start + 60] = np.hanning(60)
    X = np.column_stack([x1, x2])
    Ai = np.linalg.inv(X.T @ X)
    b, stationary, batch = [], [], []
    for _ in range(400):
        y = X @ [1.0, 2.0] + signal.lfilter([1.0], [1.0, -0.8], rng.standard_normal(N))
        theta = Ai @ X.T @ y
        e = y - X @ theta
        b.append(theta[1])
        stationary.append((Ai @ stationary_score_covariance([(X, e)], BLOCK) @ Ai)[1, 1])
        batch.append(parameter_covariance(X * e[:, None], Ai, BLOCK)[0][1, 1])
    # the analytic variance: the AR(1) error's Toeplitz covariance 0.8^|l| / (1 - 0.64)
    true = (Ai @ X.T @ toeplitz(0.8 ** np.arange(N) / 0.36) @ X @ Ai)[1, 1]
    assert np.var(b, ddof=1) == pytest.approx(true, rel=0.2)  # 400 draws: +-14 % at 2 sigma
    assert np.mean(stationary) == pytest.approx(true, rel=0.05)
    spread = np.percentile(stationary, 90) / np.percentile(stationary, 10)
    assert spread < 1.6 and np.percentile(batch, 90) / np.percentile(batch, 10) > 2 * spread  # what it is for


@pytest.mark.parametrize("pulses", [(500, 1900, 3300), (500, 1200, 1900, 2500, 3300, 3800)])
def test_the_stationary_floor_keeps_the_coverage(pulses):
    """With the floor, the sparse parameter's 95 % interval covers 94 - 99.5 % of the draws (not 100 %)."""
    from feeddrive.estimator.motion import stationary_score_covariance

    rng = np.random.default_rng(3)
    x1 = np.sin(np.arange(N) * 2 * np.pi / 700)
    x2 = np.zeros(N)
    for start in pulses:
        x2[start:start + 60] = np.hanning(60)
    X = np.column_stack([x1, x2])
    Ai = np.linalg.inv(X.T @ X)
    hits = []
    for _ in range(600):
        y = X @ [1.0, 2.0] + signal.lfilter([1.0], [1.0, -0.8], rng.standard_normal(N))
        theta = Ai @ X.T @ y
        e = y - X @ theta
        cov, dof, nb = parameter_covariance(X * e[:, None], Ai, BLOCK, stationary_score_covariance([(X, e)], BLOCK))
        lo, hi = MethodResult("ls", ("a", "b"), theta, cov, nb - 2, 1.0, 0.0, parameter_dof=dof).parameters["b"].ci95
        hits.append(lo <= 2.0 <= hi)
    assert 0.94 <= np.mean(hits) <= 0.995
