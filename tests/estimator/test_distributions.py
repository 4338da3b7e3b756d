"""estimator.distributions against scipy.stats: the same numbers (1e-12 relative) over the arguments the
estimator gives them and at the edges of their domains (issue 23: scipy.stats costs 0.5-2 s to import)."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from feeddrive.estimator import distributions as d

RTOL = 1e-12
dof = st.one_of(st.integers(1, 10**6).map(float), st.floats(0.05, 1e7))
prob = st.floats(1e-300, 1.0, exclude_max=True)
stat = st.floats(-1e3, 1e6)


def close(a, b) -> None:
    np.testing.assert_allclose(a, b, rtol=RTOL, atol=0.0, equal_nan=True)


@settings(max_examples=300, deadline=None)
@given(x=stat, df=dof)
def test_t_sf(x, df):
    close(d.t_sf(x, df), stats.t.sf(x, df))


@settings(max_examples=300, deadline=None)
@given(q=prob, df=dof)
def test_t_ppf(q, df):
    close(d.t_ppf(q, df), stats.t.ppf(q, df))


@settings(max_examples=300, deadline=None)
@given(q=st.floats(0.0, 1.0))
def test_norm_ppf_and_isf(q):
    close(d.norm_ppf(q), stats.norm.ppf(q))
    close(d.norm_isf(q), stats.norm.isf(q))


@settings(max_examples=300, deadline=None)
@given(x=st.floats(-40.0, 40.0))
def test_norm_sf(x):
    close(d.norm_sf(x), stats.norm.sf(x))


@settings(max_examples=300, deadline=None)
@given(x=stat, df=dof)
def test_chi2_sf(x, df):
    close(d.chi2_sf(x, df), stats.chi2.sf(x, df))


@settings(max_examples=300, deadline=None)
@given(x=stat, dfn=dof, dfd=dof)
def test_f_sf(x, dfn, dfd):
    close(d.f_sf(x, dfn, dfd), stats.f.sf(x, dfn, dfd))


def test_arrays_broadcast_and_scalars_stay_scalars():
    """As the estimator calls them: ``t.ppf(0.975, dof)`` over an array of dof, ``2 t.sf(|z|, dof)``."""
    dofs = np.array([[1.0, 2.0, 7.0], [30.0, 1e4, np.inf]])
    close(d.t_ppf(0.975, dofs), stats.t.ppf(0.975, dofs))
    z = np.array([0.0, 1.5, 40.0])
    close(2 * d.t_sf(np.abs(z), 12.0), 2 * stats.t.sf(np.abs(z), 12.0))
    assert isinstance(d.t_ppf(0.975, 10), float) and isinstance(d.chi2_sf(3.0, 2), float)
    assert d.t_ppf(0.975, dofs).shape == (2, 3)
    # asked again (the quantile kept): the same values, and the caller's array its own
    first = d.t_ppf(0.975, dofs)
    first[:] = 0.0
    close(d.t_ppf(0.975, dofs), stats.t.ppf(0.975, dofs))
    assert d.t_ppf(0.975, 10) == d.t_ppf(0.975, 10.0)
    close(d.t_ppf(0.975, 10), stats.t.ppf(0.975, 10))


@pytest.mark.parametrize(("ours", "theirs", "args"), [
    (d.t_ppf, stats.t.ppf, [(0.0, 3.0), (1.0, 3.0), (1.5, 3.0), (-0.1, 3.0), (0.5, 0.0), (0.5, -2.0),
                            (np.nan, 3.0), (0.975, np.nan), (0.975, np.inf)]),
    (d.t_sf, stats.t.sf, [(np.inf, 3.0), (-np.inf, 3.0), (1.0, 0.0), (np.nan, 3.0), (1.0, np.inf)]),
    (d.chi2_sf, stats.chi2.sf, [(0.0, 3.0), (-1.0, 3.0), (np.inf, 3.0), (1.0, 0.0), (np.nan, 2.0), (2.0, np.nan)]),
    (d.f_sf, stats.f.sf, [(0.0, 2.0, 5.0), (-1.0, 2.0, 5.0), (np.inf, 2.0, 5.0), (1.0, 0.0, 5.0), (1.0, 2.0, -1.0),
                          (np.nan, 2.0, 5.0)]),
    (d.norm_ppf, stats.norm.ppf, [(0.0,), (1.0,), (-0.5,), (1.5,), (np.nan,)]),
    (d.norm_sf, stats.norm.sf, [(np.inf,), (-np.inf,), (np.nan,)]),
    (d.norm_isf, stats.norm.isf, [(0.0,), (1.0,), (-0.5,), (1.5,), (np.nan,)]),
])
def test_edges_of_the_domain_as_scipy_stats(ours, theirs, args):
    """Below the support, at probabilities 0 and 1, invalid degrees of freedom and NaN: scipy.stats' answers."""
    for a in args:
        with np.errstate(all="ignore"):
            close(ours(*a), theirs(*a))
