"""The per-motion path after the work shared between its stages (issue 26, item 2), against the arithmetic
it replaces: the same floats within 1e-10 relative (most to ~1e-14), never a timing (benchmarks/ measure it).
"""
from __future__ import annotations

import numpy as np
import pytest

from feeddrive.estimator.identifiability import _newey_west_t, lag_terms
from feeddrive.estimator.kernels import MAX_RUNS, used_pairs


def _newey_west_by_lags(X: np.ndarray, e: np.ndarray, lags: int, theta: np.ndarray) -> float:
    """The textbook Newey-West t: Bartlett weights on each lag's score autocovariance, summed lag by lag."""
    n, p = X.shape
    S = X * e[:, None]
    omega = S.T @ S
    for lag in range(1, lags + 1):
        gam = S[:-lag].T @ S[lag:]
        omega += (1.0 - lag / (lags + 1)) * (gam + gam.T)
    G = np.linalg.pinv(X.T @ X)
    return float(theta[-1] / np.sqrt((G @ omega @ G)[-1, -1] * n / (n - p)))


@pytest.mark.parametrize(("n", "lags"), [(40, 1), (300, 25), (300, 299), (4000, 120)])
def test_newey_west_from_window_sums_is_the_lag_sum(n: int, lags: int) -> None:
    rng = np.random.default_rng(n + lags)
    X = rng.standard_normal((n, 4)) + np.array([3.0, 0.0, -1.0, 0.5])
    e = np.convolve(rng.standard_normal(n + 30), np.ones(30) / 30, "valid")[:n]  # a filtered, correlated residue
    theta = rng.standard_normal(4)
    t = _newey_west_t(X, e, lags, theta)
    assert t == pytest.approx(_newey_west_by_lags(X, e, lags, theta), rel=1e-12)


def test_used_pairs_from_runs_are_the_counted_pairs() -> None:
    """The pairs of used rows at each lag, run by run: the integers counted directly (and None past MAX_RUNS)."""
    rng = np.random.default_rng(8)
    seen = 0
    for _ in range(500):
        runs = rng.random(int(rng.integers(1, 2 * MAX_RUNS))) < 0.6
        used = np.repeat(runs, rng.integers(1, 40, runs.size))
        n = used.size
        lags = int(rng.integers(0, n))
        pairs = used_pairs(used, lags)
        if pairs is None:
            assert np.count_nonzero(np.diff(np.r_[0, used.astype(int), 0]) == 1) > MAX_RUNS
            continue
        seen += 1
        np.testing.assert_array_equal(pairs, [np.sum(used[:n - k] & used[k:]) for k in range(lags + 1)])
    assert seen > 100


def _regression_parts():
    """The mechanical regression of a noisy round trip at 1 kHz, its measured parts and two sets of instruments."""
    from synthetic import ROUND_TRIP, record

    from feeddrive.estimator import EstimationOptions, MotionData
    from feeddrive.estimator.estimate import prepare
    from feeddrive.estimator.model_terms import ls_parts

    d = record(ROUND_TRIP, 1e-3, snr_db=30.0, seed=2)
    options = EstimationOptions()
    p = prepare(MotionData(1e-3, u=d["u"], i=d["i"], w=d["w"]), options)
    reg = next(r for r in p.regressions if r.equation == "mechanical")
    y, Phi, _, rows = ls_parts(p, reg)[0]
    rng = np.random.default_rng(3)
    instruments = [Phi + 0.1 * rng.standard_normal(Phi.shape) * np.abs(Phi).max(axis=0) for _ in range(2)]
    return reg, p, options, y, Phi, rows, instruments


def test_kept_regressors_give_the_fits_of_a_fresh_solve() -> None:
    """IV iterations keep the measured regressors' rows and scale (``memo``); the instruments change. Each fit,
    and the last one's covariance completed afterwards, is the one solved from scratch, bit for bit."""
    from feeddrive.estimator.linear_fit import _solve

    reg, p, options, y, Phi, rows, instruments = _regression_parts()
    memo: dict = {}
    for Z in instruments + instruments[::-1]:
        parts = [(y, Phi, Z, rows)]
        kept = _solve(reg, parts, p.block, options, covariance=False, memo=memo)
        fresh = _solve(reg, parts, p.block, options)
        assert "regressors" in memo
        np.testing.assert_array_equal(kept.theta, fresh.theta)
        done = kept.complete()
        for a, b in ((done.theta, fresh.theta), (done.cov, fresh.cov), (done.theta_dof, fresh.theta_dof)):
            np.testing.assert_array_equal(a, b)
        assert (done.dof, done.cond, done.fit) == (fresh.dof, fresh.cond, fresh.fit)
    # another output (an equation whose constants moved) is not taken for the kept one
    doubled = [(2.0 * y, Phi, instruments[0], rows)]
    other = _solve(reg, doubled, p.block, options, covariance=False, memo=memo)
    np.testing.assert_array_equal(other.theta, _solve(reg, doubled, p.block, options).theta)
    np.testing.assert_allclose(other.theta, 2.0 * _solve(reg, [(y, Phi, instruments[0], rows)], p.block, options).theta,
                               rtol=1e-12)


def test_lag_terms_recover_the_lag_free_fit_and_test_the_lag():
    """An output that holds a lag term ``-tau Di`` (a measured current low-passed by tau): lag_terms gives the
    coefficients of the other columns without it (exactly, noise-free) and rejects the lag's term; without the
    term the Wald test does not reject it (p > 0.05 on this seed), and the coefficients are those of the plain fit."""
    rng = np.random.default_rng(3)
    n = 3000
    t = np.arange(n) * 1e-3
    Phi = np.column_stack([np.sin(2 * np.pi * t), np.cos(2 * np.pi * 3 * t), np.sign(np.sin(2 * np.pi * t))])
    Di = np.gradient(np.sin(2 * np.pi * 5 * t) + 0.3 * np.cos(2 * np.pi * 2 * t), 1e-3)
    theta = np.array([0.5, -0.2, 0.05])
    e = np.convolve(rng.standard_normal(n + 20), np.ones(20) / 20, "valid")[:n] * 1e-2
    lagged = lag_terms(Phi @ theta - 0.01 * Di + e, Phi, Di[:, None], 20)
    assert lagged["p_value"] < 1e-10
    np.testing.assert_allclose(lagged["theta"], theta, atol=3e-3)
    plain = lag_terms(Phi @ theta + e, Phi, Di[:, None], 20)
    assert plain["p_value"] > 0.05
    np.testing.assert_allclose(plain["theta"], np.linalg.lstsq(Phi, Phi @ theta + e, rcond=None)[0], atol=1e-3)


def test_columns_are_column_stack():
    """``kernels.columns``: numpy's column_stack written column by column: the same values, C-ordered, for 1-D
    columns and 2-D blocks in either memory order (a regression's F-ordered columns, the nuisance's C rows)."""
    from feeddrive.estimator.kernels import columns

    rng = np.random.default_rng(21)
    m = 257
    blocks = [rng.standard_normal((m, 3)), np.asfortranarray(rng.standard_normal((m, 2))), rng.standard_normal(m),
              rng.standard_normal((2 * m, 4))[::2], np.ones(m)]
    for k in range(1, len(blocks) + 1):
        out = columns(blocks[:k])
        np.testing.assert_array_equal(out, np.column_stack(blocks[:k]))
        assert out.flags.c_contiguous and out.dtype == np.float64
