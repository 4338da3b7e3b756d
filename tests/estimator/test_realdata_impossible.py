"""No interval is given conditional on a refused parameter at a physically impossible estimate (partial._rule).

A parameter refused by the relative standard error rule is fixed at its own estimate for the others: their
intervals hold given that value. When the value cannot be the parameter's (R < 0), that interval holds for no
drive: on the UMich mill (X axis, 10 Hz, ../shared/realdata) `cosim estimate --method iv` gave K = 717.8 N/A with
[481, 954] given R = -0.618 Ohm (refused). Now an impossible estimate is marginalised over, not conditioned on:
the others are given with the interval that holds whatever its value, or refused naming both intervals.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from feeddrive.estimator import EstimationOptions, FilterSpec, MotionData
from feeddrive.estimator.motion import MethodResult
from feeddrive.estimator.partial import _rule, estimate_parameters

UMICH = Path(__file__).resolve().parents[2] / ".." / "shared" / "realdata" / "umich_cnc" / "experiment_01.csv"


def _result(r: float, sd_r: float, sd_k: float, rho: float) -> MethodResult:
    cov = np.array([[sd_r ** 2, rho * sd_r * sd_k], [rho * sd_r * sd_k, sd_k ** 2]])
    return MethodResult("ls", ("R", "K"), np.array([r, 700.0]), cov, dof=100_000, condition_number=1.0,
                        fit_error=0.1)


def test_an_interval_given_an_impossible_estimate_is_not_given():
    # K: standard error 50 % of its value alone, sqrt(1 - 0.95^2) of that (15.6 %) given R; R: 83 %, refused
    refused, fixed = {}, {}
    out = _rule(_result(-0.6, 0.5, 350.0, 0.95), EstimationOptions(), refused, fixed)
    assert list(refused) == ["R", "K"]
    assert "not positive: physically impossible, the others' intervals do not assume it" in refused["R"]
    # judged on its interval whatever R is (+-98 %), with the one given R = -0.6 named (+-31 %)
    assert refused["K"].startswith("95 % interval +-98% of the value, more than +-59%")
    assert refused["K"].endswith("; +-31% given the physically impossible R = -0.6)")
    assert not np.any(out.covariance)


def test_an_interval_given_a_possible_estimate_is_kept():
    refused, fixed = {}, {}
    out = _rule(_result(0.6, 0.5, 350.0, 0.95), EstimationOptions(), refused, fixed)
    assert list(refused) == ["R"] and fixed == {"R": 0.6}
    np.testing.assert_allclose(out.covariance[1, 1], 350.0 ** 2 * (1 - 0.95 ** 2), rtol=1e-12)  # the Schur complement


@pytest.mark.skipif(not UMICH.is_file(), reason=f"real recording not found: {UMICH}")
def test_umich_k_is_not_given_on_r_below_zero():
    import pandas as pd

    d = pd.read_csv(UMICH, usecols=["X1_OutputVoltage", "X1_CurrentFeedback", "X1_ActualVelocity"])
    data = MotionData(0.1, u=d["X1_OutputVoltage"].to_numpy(float), i=d["X1_CurrentFeedback"].to_numpy(float),
                      w=1e-3 * d["X1_ActualVelocity"].to_numpy(float))  # m/s: K in N/A
    est = estimate_parameters(data, EstimationOptions(method="iv", filter=FilterSpec(1.0)))
    assert est.fixed["R"] < 0 and "physically impossible, the others' intervals do not assume it" in est.refused["R"]
    # K is given only with an interval that does not assume R = -0.618 Ohm: it was 717.8 [481, 954] (+-33 %)
    k = est.parameters["K"]
    assert 1.2 * (954.4 - 717.8) < k.ci95[1] - k.value <= 1.96 * 0.3 * k.value, k  # wider, within the rule
