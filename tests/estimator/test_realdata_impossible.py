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


@pytest.fixture(scope="module")
def umich():
    if not UMICH.is_file():
        pytest.skip(f"real recording not found: {UMICH}")
    import pandas as pd

    d = pd.read_csv(UMICH, usecols=["X1_OutputVoltage", "X1_CurrentFeedback", "X1_ActualVelocity"])
    data = MotionData(0.1, u=d["X1_OutputVoltage"].to_numpy(float), i=d["X1_CurrentFeedback"].to_numpy(float),
                      w=1e-3 * d["X1_ActualVelocity"].to_numpy(float))  # m/s: K in N/A
    return estimate_parameters(data, EstimationOptions(method="iv", filter=FilterSpec(1.0)))


def test_umich_k_is_not_given_on_r_below_zero(umich):
    assert umich.fixed["R"] < 0 and "physically impossible, the others' intervals do not assume it" in umich.refused["R"]
    # K is given only with an interval that does not assume R = -0.618 Ohm: it was 717.8 [481, 954] (+-33 %)
    k = umich.parameters["K"]
    assert 1.2 * (954.4 - 717.8) < k.ci95[1] - k.value <= 1.96 * 0.3 * k.value, k  # wider, within the rule


def test_umich_split_sample_iv_says_why_it_failed(umich):
    # its halves derived the mechanical equation that LS had refused (22 usable samples) and failed on it with
    # "simulation needs parameter 'Jt'"; restricted to LS's equations, the current simulated at LS's R < 0, L < 0
    # diverges and IV's system is singular (numpy's "Singular matrix"): the message says so with the numbers
    msg = umich.result.message
    assert umich.result.method_used == "iv-lag" and "simulation needs parameter" not in msg
    assert ("the split-sample IV failed (the electrical equation's instruments simulated at R = -0.7761, L = "
            "-0.04652, K = 779.7 leave its parameters undetermined (a singular system: the simulated i [A] peaks at "
            in msg) and msg.endswith("an unstable simulation))")
