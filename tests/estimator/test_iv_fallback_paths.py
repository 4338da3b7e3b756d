"""One IV fall-back chain for every caller (lagged_iv.iv_with_fallbacks), and only the estimator's own failures fall back.

``estimate_motion`` (a campaign's per-method table) fell back from the split-sample IV straight to LS, where the
monitor and ``cosim estimate`` (``partial.estimate_parameters``) ran the lagged IV: the same motion got another
estimate under the same label ``iv``. And ``partial._iv`` caught every ValueError, so a coding error (a numpy shape
mismatch) became "IV failed, fell back" with a plausible LS estimate printed.
"""
from __future__ import annotations

import numpy as np
import pytest
from synthetic import ROUND_TRIP, TRUTH, record

from feeddrive.estimator import EstimationOptions, FilterSpec, MotionData, estimate_motion
from feeddrive.estimator import lagged_iv as lagged_module
from feeddrive.estimator.errors import FAILURES, NumericalFailure
from feeddrive.estimator.lagged_iv import LABEL, LAGGED
from feeddrive.estimator.partial import estimate_parameters

H = 1e-3


@pytest.fixture(scope="module")
def noisy():
    """40 dB on u, i and w, 100 Hz filter: LS's Jt is ~25 % low (tests/estimator/test_lagged_iv.py)."""
    d = record(ROUND_TRIP, H, snr_db=40, seed=0)
    return MotionData(H, u=d["u"], i=d["i"], w=d["w"])


def test_estimate_motion_and_the_monitor_path_give_the_same_iv_with_the_same_label(noisy):
    """One iteration: the split-sample IV does not settle (48 standard errors). Both paths run the lagged IV,
    labelled ``iv`` with the same reason, the same numbers, and Jt within 6 % (LS: -25 %)."""
    options = EstimationOptions(method="iv", filter=FilterSpec(100.0), iv_iterations=1)
    est = estimate_motion(noisy, options)
    campaign = est.iv
    monitor = estimate_parameters(noisy, options).iv
    for res in (campaign, monitor):
        assert res.method == "iv" and res.method_used == LAGGED
        assert res.message.startswith(LABEL) and "did not converge in 1 iterations" in res.message
    assert campaign.message == monitor.message
    np.testing.assert_allclose(campaign.values, monitor.values, rtol=1e-12)
    assert campaign.parameters["Jt"].value == pytest.approx(TRUTH["Jt"], rel=0.06)
    assert est.ls.parameters["Jt"].value / TRUTH["Jt"] - 1 < -0.2  # what the campaign printed as "iv" before


@pytest.mark.parametrize("path", [estimate_motion, estimate_parameters])
def test_a_coding_error_in_the_iv_is_raised_not_taken_for_an_iv_failure(noisy, monkeypatch, path):
    """A ValueError that is none of the estimator's own failures (``errors.FAILURES``) reaches the caller, in the
    split-sample IV and in its lagged fall-back alike; a NumericalFailure still falls back, labelled."""
    options = EstimationOptions(method="iv", filter=FilterSpec(100.0))

    def broken(*args, **kwargs):
        raise ValueError("operands could not be broadcast together with shapes (10,) (9,)")

    def failing(*args, **kwargs):
        raise NumericalFailure("the simulation of the electrical equation(s) is unstable")

    assert not issubclass(ValueError, FAILURES)
    with monkeypatch.context() as m:
        m.setattr(lagged_module, "instrumental_variables", broken)
        with pytest.raises(ValueError, match="broadcast"):
            path(noisy, options)
    with monkeypatch.context() as m:
        m.setattr(lagged_module, "instrumental_variables", failing)
        res = path(noisy, options).iv
        assert res.method_used == LAGGED and "unstable" in res.message
        m.setattr(lagged_module, "lagged_iv", broken)  # the fall-back's own coding error
        with pytest.raises(ValueError, match="broadcast"):
            path(noisy, options)
