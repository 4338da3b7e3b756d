"""Tail probabilities and quantiles of the t, normal, chi-square and F distributions (scipy.special).

``scipy.stats`` builds the docstrings of its ~130 distributions when it is imported (0.5-2 s, more than
a motion's whole treatment); the estimator needs seven functions of four of them. These are the special
functions ``scipy.stats`` evaluates itself for them (``t._ppf`` is ``stdtrit``, ``chi2._sf`` is ``chdtrc``,
...), with its answers outside the special functions' domain: a statistic below the support has tail
probability 1, a probability of 0 or 1 has the support's end as quantile, and an invalid argument (a
probability outside [0, 1], degrees of freedom <= 0, NaN) gives NaN. tests/estimator/test_distributions.py
checks each against scipy.stats.

Every function takes scalars or arrays (broadcast together) and returns a float for scalar arguments,
else an ndarray of the broadcast shape. ``scipy.special`` is imported by the first call (0.6 s): the
modules that import these functions (the monitor's configuration, read by every ``cosim`` command that
loads a scenario) do not pay for it.
"""
from __future__ import annotations

import numpy as np

__all__ = ["chi2_sf", "f_sf", "norm_isf", "norm_ppf", "norm_sf", "t_ppf", "t_sf"]


def _out(value: np.ndarray) -> float | np.ndarray:
    return float(value) if np.ndim(value) == 0 else value


def _positive(df: np.ndarray) -> np.ndarray:
    """Valid degrees of freedom: > 0 (``inf`` included: the limit distribution). NaN is not."""
    return df > 0


def t_sf(x: float | np.ndarray, df: float | np.ndarray) -> float | np.ndarray:
    """``P(T > x)`` of Student's t with ``df`` degrees of freedom (``scipy.stats.t.sf``)."""
    from scipy import special

    x, df = np.broadcast_arrays(np.asarray(x, dtype=float), np.asarray(df, dtype=float))
    return _out(np.where(_positive(df), special.stdtr(df, -x), np.nan))


#: the last quantiles of ``t_ppf`` by their arguments' bytes: ``stdtrit`` inverts the distribution iteratively
#: (0.05-0.2 ms a call), and a motion asks for the same ones again (the three residue tests' 95 % quantile at
#: the same windows count, every equation's interval with the same degrees of freedom), as does the next motion
_T_PPF: dict = {}
_T_PPF_SIZE = 64


def t_ppf(q: float | np.ndarray, df: float | np.ndarray) -> float | np.ndarray:
    """Quantile ``x`` with ``P(T <= x) = q`` of Student's t (``scipy.stats.t.ppf``)."""
    q, df = np.asarray(q, dtype=float), np.asarray(df, dtype=float)
    if q.ndim or df.ndim:  # two scalars (most calls) are their own broadcast
        q, df = np.broadcast_arrays(q, df)
    key = (q.shape, q.tobytes(), df.tobytes())
    out = _T_PPF.get(key)
    if out is None:
        from scipy import special

        valid = _positive(df) & (q >= 0) & (q <= 1)
        with np.errstate(invalid="ignore"):
            out = special.stdtrit(df, q)
        out = np.where(q == 0, -np.inf, np.where(q == 1, np.inf, out))
        out = np.where(valid, out, np.nan)
        out.setflags(write=False)
        if len(_T_PPF) >= _T_PPF_SIZE:
            try:  # the oldest; another thread may have emptied or changed the dict meanwhile
                _T_PPF.pop(next(iter(_T_PPF)), None)
            except (StopIteration, RuntimeError):
                pass
        _T_PPF[key] = out
    return _out(out.copy())  # the caller's own array (it may write to it)


def norm_ppf(q: float | np.ndarray) -> float | np.ndarray:
    """Quantile of the standard normal distribution (``scipy.stats.norm.ppf``)."""
    from scipy import special

    q = np.asarray(q, dtype=float)
    return _out(np.where((q >= 0) & (q <= 1), special.ndtri(q), np.nan))


def norm_sf(x: float | np.ndarray) -> float | np.ndarray:
    """``P(Z > x)`` for the standard normal distribution (``scipy.stats.norm.sf``)."""
    from scipy import special

    return _out(special.ndtr(-np.asarray(x, dtype=float)))


def norm_isf(q: float | np.ndarray) -> float | np.ndarray:
    """``z`` with ``P(Z > z) = q`` for the standard normal distribution (``scipy.stats.norm.isf``)."""
    from scipy import special

    q = np.asarray(q, dtype=float)
    return _out(np.where((q >= 0) & (q <= 1), -special.ndtri(q), np.nan))


def chi2_sf(x: float | np.ndarray, df: float | np.ndarray) -> float | np.ndarray:
    """``P(X > x)`` of the chi-square distribution with ``df`` degrees of freedom (``scipy.stats.chi2.sf``)."""
    from scipy import special

    x, df = np.broadcast_arrays(np.asarray(x, dtype=float), np.asarray(df, dtype=float))
    with np.errstate(invalid="ignore"):
        out = np.where(x <= 0, 1.0, special.chdtrc(df, np.maximum(x, 0.0)))
    return _out(np.where(_positive(df) & ~np.isnan(x), out, np.nan))


def f_sf(x: float | np.ndarray, dfn: float | np.ndarray, dfd: float | np.ndarray) -> float | np.ndarray:
    """``P(F > x)`` of the F distribution with ``dfn`` and ``dfd`` degrees of freedom (``scipy.stats.f.sf``)."""
    from scipy import special

    x, dfn, dfd = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (x, dfn, dfd)))
    with np.errstate(invalid="ignore"):
        out = np.where(x <= 0, 1.0, special.fdtrc(dfn, dfd, np.maximum(x, 0.0)))
    return _out(np.where(_positive(dfn) & _positive(dfd) & ~np.isnan(x), out, np.nan))
