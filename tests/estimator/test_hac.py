"""estimator.hac.ols_hac is statsmodels' OLS with HAC (Newey-West) errors, without statsmodels' imports."""
from __future__ import annotations

import numpy as np
import pytest
from statsmodels.regression.linear_model import OLS

from feeddrive.estimator.hac import ols_hac


@pytest.mark.parametrize(("n", "k", "lags"), [(500, 2, 16), (60, 3, 16), (2000, 2, 4)])
def test_the_same_fit_as_statsmodels(n, k, lags):
    """Coloured residuals (a moving average of 10 samples) on a random walk and a constant: the parameters and the
    covariance agree to 1e-12 relative, the 95 % and 99 % intervals to 1e-12 absolute."""
    rng = np.random.default_rng(n + k)
    X = np.column_stack([np.cumsum(rng.standard_normal(n)) for _ in range(k - 1)] + [np.ones(n)])
    y = X @ np.linspace(1.03, 0.2, k) + np.convolve(rng.standard_normal(n + 9), np.ones(10) / 10, "valid")
    ref = OLS(y, X).fit(cov_type="HAC", cov_kwds={"maxlags": lags})
    fit = ols_hac(y, X, maxlags=lags)
    np.testing.assert_allclose(fit.params, ref.params, rtol=1e-12)
    np.testing.assert_allclose(fit.cov, ref.cov_params(), rtol=1e-12)
    for alpha in (0.05, 0.01):
        np.testing.assert_allclose(fit.conf_int(alpha), ref.conf_int(alpha), rtol=0, atol=1e-12)


def test_isolating_a_faulty_sensor_imports_no_statsmodels():
    """The first motion with a faulty sensor paid statsmodels' regression import (2.3 s of CPU) inside its
    processing time; the isolation and the servo checks no longer import it."""
    import subprocess
    import sys

    code = ("import sys, numpy as np\n"
            "from feeddrive.estimator.isolation import isolate\n"
            "from feeddrive.estimator.validation import ValidationOptions\n"
            "t = np.linspace(0, 4, 40000); ref = 10 * np.sin(t)\n"
            "a, b = isolate(1.03 * ref + 0.2, ref, ref, ('Im1', 'Im2'), 1e-4, 100.0, ValidationOptions())\n"
            "assert a.faulty and not b.faulty, (a, b)\n"
            "print('statsmodels' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False"
