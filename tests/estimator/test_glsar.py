"""estimator.glsar gives statsmodels' GLSAR numbers (it replaces statsmodels on the run path: 0.3-0.9 s of
imports with pandas), including rank-deficient designs, where it prints nothing."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

from feeddrive.estimator.glsar import glsar_fit
from feeddrive.estimator.kernels import last_columns_f_test

TOL = 1e-10


def _data(seed: int, n: int, p: int, phi: tuple[float, ...], deficient: bool) -> tuple[np.ndarray, np.ndarray]:
    """A regression with AR errors ``phi`` (the coloured residue of the model check); ``deficient``: the last
    column repeats a combination of two others (a PMSM design's collinear regressors)."""
    rng = np.random.default_rng(seed)
    X = rng.standard_normal((n, p))
    if deficient:
        X[:, -1] = X[:, 0] - 2.0 * X[:, 1]
    e = rng.standard_normal(n + 50)
    for t in range(len(phi), e.size):
        e[t] += sum(c * e[t - j] for j, c in enumerate(phi, 1))
    return X @ rng.standard_normal(p) * (seed % 2) + e[50:], X


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("order", [1, 2, 4])
def test_iterative_fit_is_statsmodels(seed, order):
    deficient = seed in (2, 3)
    y, X = _data(seed, 90 + 20 * seed, 6, ((0.6,), (0.5, -0.3), (0.9,))[seed % 3], deficient)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # statsmodels' rank-deficiency warning (ours prints nothing)
        from statsmodels.regression.linear_model import GLSAR  # imported here: ~1-2 s a collecting worker

        ref = GLSAR(y, X, rho=order).iterative_fit(maxiter=6)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # nothing printed, even for a rank-deficient design
        fit = glsar_fit(y, X, order, maxiter=6)
    np.testing.assert_allclose(fit.rho, ref.model.rho, rtol=TOL, atol=0)
    np.testing.assert_allclose(fit.params, ref.params, rtol=TOL, atol=TOL * np.max(np.abs(ref.params)))
    np.testing.assert_allclose(fit.cov_params(), ref.cov_params(), rtol=TOL,
                               atol=TOL * np.max(np.abs(ref.cov_params())))
    assert fit.df_resid == ref.df_resid == len(y) - order - (5 if deficient else 6)
    assert (fit.iterations, fit.converged) == (ref.iter, ref.converged)
    np.testing.assert_allclose(fit.whiten(X), ref.model.whiten(X), rtol=TOL, atol=TOL)
    # the model check's independence test on the last three columns: statistic and p-value
    mine, theirs = last_columns_f_test(fit, 3), last_columns_f_test(ref, 3)
    assert mine[1:3] == theirs[1:3]
    assert mine[0] == pytest.approx(theirs[0], rel=TOL)
    assert mine[3] == pytest.approx(theirs[3], rel=1e-8, abs=1e-300)


def test_ar_coefficients_of_a_long_ar2_record_are_recovered():
    """Physics of the whitening: the AR(2) errors' coefficients come back within their standard error."""
    y, X = _data(7, 20000, 3, (0.5, -0.3), False)
    fit = glsar_fit(y, X, 2, maxiter=6)
    np.testing.assert_allclose(fit.rho, [0.5, -0.3], atol=0.02)
    white = fit.whiten(y - X @ fit.params)
    lag1 = float(white[1:] @ white[:-1] / (white @ white))
    assert abs(lag1) < 0.03  # whitened: no correlation left at lag 1


@pytest.mark.parametrize("order", [1, 3])
def test_qr_fit_is_the_svd_fit_within_1e9(order, monkeypatch):
    """Stated method change: a tall full-rank whitened design is fitted from its QR factors, not statsmodels' SVD
    pseudo-inverse. On a model-check-sized record (158 x 26, AR errors) both give the same coefficients, covariance
    and independence F-test within 1e-9 relative (the SVD path forced by a zero condition limit)."""
    import feeddrive.estimator.glsar as glsar

    y, X = _data(4, 158, 26, (0.7, -0.2), False)
    X[:, 1] = X[:, 0] + 1e-3 * X[:, 1]  # a condition number ~1e3, as the lag regressors' near-collinear columns
    qr = glsar_fit(y, X, order, maxiter=6)
    assert glsar._qr_fit(*[glsar.whiten(a, qr.rho) for a in (X, y)]) is not None  # the QR path is taken
    monkeypatch.setattr(glsar, "QR_MAX_CONDITION", 0.0)
    svd = glsar_fit(y, X, order, maxiter=6)
    np.testing.assert_allclose(qr.rho, svd.rho, rtol=1e-9)
    np.testing.assert_allclose(qr.params, svd.params, rtol=1e-9, atol=1e-9 * np.max(np.abs(svd.params)))
    np.testing.assert_allclose(qr.cov_params(), svd.cov_params(), rtol=1e-9,
                               atol=1e-9 * np.max(np.abs(svd.cov_params())))
    assert (qr.df_resid, qr.iterations) == (svd.df_resid, svd.iterations)
    mine, theirs = last_columns_f_test(qr, 10), last_columns_f_test(svd, 10)
    assert mine[1:3] == theirs[1:3]
    assert mine[0] == pytest.approx(theirs[0], rel=1e-9)
    assert mine[3] == pytest.approx(theirs[3], rel=1e-9)
