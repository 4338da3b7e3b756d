"""The model check's Ljung-Box and OLS F-test in numpy (statsmodels and pandas are 1-2 s of imports, now
loaded only where an AR prewhitening or a sensor isolation needs them) give statsmodels' numbers."""
from __future__ import annotations

import numpy as np
import pytest

from feeddrive.estimator.residue_tests import ljung_box, ols_f_test


@pytest.mark.parametrize("seed", range(4))
def test_ljung_box_and_f_test_agree_with_statsmodels(seed):
    # imported here, not at collection: statsmodels and pandas are ~1-2 s of every xdist worker's collection
    from statsmodels.regression.linear_model import OLS
    from statsmodels.stats.diagnostic import acorr_ljungbox

    rng = np.random.default_rng(seed)
    n, p, q = 80, 7, 4
    X = rng.standard_normal((n, p))
    y = X @ rng.standard_normal(p) * (seed % 2) + rng.standard_normal(n)  # H0 true on even seeds, false on odd
    R = np.zeros((q, p))
    R[:, -q:] = np.eye(q)
    ref = OLS(y, X).fit().f_test(R)
    f, (df_num, df_den), pvalue = ols_f_test(y, X, R)
    assert f == pytest.approx(float(np.squeeze(ref.fvalue)), rel=1e-10)
    assert (df_num, df_den) == (float(ref.df_num), float(ref.df_denom)) == (4.0, 73.0)
    assert pvalue == pytest.approx(float(np.squeeze(ref.pvalue)), rel=1e-8, abs=1e-300)
    x = rng.standard_normal(60).cumsum() * (seed % 2) + rng.standard_normal(60)  # white, or a random walk
    lags = 10
    assert ljung_box(x, lags) == pytest.approx(acorr_ljungbox(x, lags=[lags])["lb_pvalue"].iloc[0], rel=1e-8,
                                               abs=1e-300)
