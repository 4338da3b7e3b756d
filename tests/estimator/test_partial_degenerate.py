"""No parameter is given with an interval of no width (estimator.partial._rule, found by audit4).

A parameter's interval given the refused ones at their own estimates (the Schur complement) can vanish: on 2 s of
an axis at rest (noise only, taken as one motion) ft was given as 0.2003 N.m.s/rad with [0.2003, 0.2003], Cd
flagged with a point interval, both given K = -0.158 and Jt = -0.0015 at their refused estimates. (No interval is
conditional on an impossible estimate any more, test_realdata_impossible.py: the voltage's sign reversed, K = +0.158
and Jt = +0.0015 are possible and the same degenerate interval arises given them.)
"""
from __future__ import annotations

import numpy as np

from feeddrive.estimator import EstimationOptions, FilterSpec, MotionData
from feeddrive.estimator.partial import estimate_parameters


def test_a_parameter_with_no_interval_given_the_refused_ones_is_refused():
    rng = np.random.default_rng(0)
    n = 2000
    data = MotionData(1e-3, u=-0.01 * rng.standard_normal(n), i=0.005 * rng.standard_normal(n),
                      w=0.002 * rng.standard_normal(n))
    est = estimate_parameters(data, EstimationOptions(method="iv", filter=FilterSpec(50.0)))
    for name, p in est.parameters.items():
        assert p.ci95[1] > p.ci95[0], (name, p)
    assert "ft" not in est.parameters and "its interval given them has no width" in est.refused["ft"]
