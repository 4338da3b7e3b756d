"""Least squares with Newey-West (HAC) standard errors, in numpy.

statsmodels' ``OLS(y, X).fit(cov_type="HAC", cov_kwds={"maxlags": L})`` with its defaults (Bartlett weights
``1 - j / (L + 1)``, no small-sample correction, normal quantiles for the intervals): the parameters from the
pseudo-inverse, the sandwich ``H S H'`` with ``H = pinv(X) pinv(X)'`` and ``S`` the weighted autocovariances of
the scores ``X e``, the same operations in the same order (tests/estimator/test_hac.py compares the two). The
sensor isolation of a faulty pair (Fig. 6) and the servo drive's phase-current checks use it; importing
statsmodels' regression module for them took 2.3 s of CPU (pandas, scipy.stats) in the motion that first met a
faulty sensor, which pushed that motion past the paper's 2 s budget on its processing alone.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from feeddrive.estimator.columnwise import multiply_rows
from feeddrive.estimator.distributions import norm_isf


@dataclass(frozen=True)
class HACFit:
    """``params`` (k,) and their HAC covariance ``cov`` (k, k)."""

    params: np.ndarray
    cov: np.ndarray

    def conf_int(self, alpha: float = 0.05) -> np.ndarray:
        """(k, 2) two-sided ``1 - alpha`` intervals with normal quantiles (statsmodels' ``conf_int`` here)."""
        half = float(norm_isf(alpha / 2)) * np.sqrt(np.diag(self.cov))
        return np.column_stack([self.params - half, self.params + half])


def ols_hac(y: np.ndarray, X: np.ndarray, maxlags: int = 16) -> HACFit:
    """OLS fit of ``y`` (n,) on ``X`` (n, k) with Newey-West errors over ``maxlags`` lags; see the module docstring."""
    pinv = np.linalg.pinv(X)
    params = pinv @ y
    scores = multiply_rows(X, y - X @ params)
    weights = 1 - np.arange(maxlags + 1) / (maxlags + 1.0)
    S = weights[0] * np.dot(scores.T, scores)
    for lag in range(1, maxlags + 1):
        s = np.dot(scores[lag:].T, scores[:-lag])
        S += weights[lag] * (s + s.T)
    H = np.dot(pinv, pinv.T)
    return HACFit(params, np.dot(np.dot(H, S), H.T))
