"""The simulation's not-a-knot cubic spline (``simulation._spline``) with its elementwise steps in C.

``simulation._spline`` repeats scipy's ``CubicSpline`` arithmetic step by step in numpy: about thirty array
operations over the knots and the sample times, each a pass over memory, 0.3 ms a call and eight calls per
motion (the IV instruments of two equations, two halves, two iterations). Here the tridiagonal system's
diagonals and right-hand side are formed in one C loop, solved by the same LAPACK routine (gtsv), and the
polynomial is evaluated in a second C loop: the same floating-point operations in the same order (compiled
with ``-ffp-contract=off`` by ``estimator.compiled``: no fused multiply-add), so the same bits
(tests/estimator/test_speed.py compares ``_spline`` with scipy's ``CubicSpline`` exactly). Without a C compiler
(or with ``$FEEDDRIVE_NO_COMPILED_SPLINE`` set) ``available()`` is False and ``_spline`` keeps its numpy steps.
"""
from __future__ import annotations

import ctypes
from functools import lru_cache

import numpy as np

_SOURCE = r"""
/* scipy's CubicSpline (not-a-knot), its operations in its order: slopes, the banded system of solve_banded */
void fd_spline_system(long n, const double* x, const double* y, double* dx, double* slope, double* lower,
                      double* diag, double* upper, double* b) {
  long i;
  double d;
  for (i = 0; i < n - 1; ++i) {
    dx[i] = x[i + 1] - x[i];
    slope[i] = (y[i + 1] - y[i]) / dx[i];
  }
  for (i = 1; i < n - 1; ++i) {
    diag[i] = 2 * (dx[i - 1] + dx[i]);
    upper[i] = dx[i - 1];
    lower[i - 1] = dx[i];
    b[i] = 3 * (dx[i] * slope[i - 1] + dx[i - 1] * slope[i]);
  }
  d = x[2] - x[0];
  diag[0] = dx[1];
  upper[0] = d;
  b[0] = ((dx[0] + 2 * d) * dx[1] * slope[0] + dx[0] * dx[0] * slope[1]) / d;
  d = x[n - 1] - x[n - 3];
  diag[n - 1] = dx[n - 3];
  lower[n - 2] = d;
  b[n - 1] = (dx[n - 2] * dx[n - 2] * slope[n - 3] + (2 * d + dx[n - 2]) * dx[n - 3] * slope[n - 2]) / d;
}
/* the spline with knot derivatives s at the times at (interval j of each): PPoly's c_k u^k summed as scipy's
   evaluate: res = c3 ... built from the constant up, z the running power of u */
void fd_spline_eval(long q, const double* x, const double* y, const double* s, const double* dx,
                    const double* slope, const long* j, const double* at, double* out) {
  long k, i;
  double t, u, z, res;
  for (k = 0; k < q; ++k) {
    i = j[k];
    t = (s[i] + s[i + 1] - 2 * slope[i]) / dx[i];
    u = at[k] - x[i];
    z = u;
    res = 0.0 + y[i] * 1.0;
    res = res + s[i] * z;
    z = z * u;
    res = res + ((slope[i] - s[i]) / dx[i] - t) * z;
    z = z * u;
    res = res + (t / dx[i]) * z;
    out[k] = res;
  }
}
"""


@lru_cache(maxsize=1)
def _library() -> ctypes.CDLL | None:
    from feeddrive.estimator.compiled import load_library

    dp, n = ctypes.c_void_p, ctypes.c_long  # the arrays by address
    return load_library(_SOURCE, "FEEDDRIVE_NO_COMPILED_SPLINE",
                        {"fd_spline_system": [n] + [dp] * 8, "fd_spline_eval": [n] + [dp] * 8})


def available() -> bool:
    """True when the C loops could be built here."""
    return _library() is not None


def spline(x: np.ndarray, Y: np.ndarray, at: np.ndarray, j: np.ndarray) -> np.ndarray:
    """``CubicSpline(x, Y, axis=1)(at)`` (not-a-knot, extrapolated), bit for bit.

    Parameters
    ----------
    x : ndarray, shape (n,)
        Increasing knots, n >= 4.
    Y : ndarray, shape (m, n)
        Finite values at the knots.
    at : ndarray, shape (q,)
        Times to evaluate at.
    j : ndarray of intp, shape (q,)
        The interval of ``x`` each time falls in (``simulation._interval_of``).

    Returns
    -------
    ndarray, shape (m, q)

    Raises
    ------
    numpy.linalg.LinAlgError
        A singular system (gtsv's ``info > 0``), as ``_spline``.
    """
    from scipy.linalg.lapack import dgtsv  # here: the monitor's path imports scipy lazily

    lib = _library()
    x = np.ascontiguousarray(x, dtype=float)
    at = np.ascontiguousarray(at, dtype=float)
    j = np.ascontiguousarray(j, dtype=np.intp)
    n, q = x.size, at.size
    out = np.empty((Y.shape[0], q))
    dx, slope = np.empty(n - 1), np.empty(n - 1)
    lower, diag, upper, b = np.empty(n - 1), np.empty(n), np.empty(n - 1), np.empty((n, 1))
    for r in range(Y.shape[0]):
        y = np.ascontiguousarray(Y[r], dtype=float)
        lib.fd_spline_system(n, x.ctypes.data, y.ctypes.data, dx.ctypes.data, slope.ctypes.data, lower.ctypes.data,
                             diag.ctypes.data, upper.ctypes.data, b.ctypes.data)
        s, info = dgtsv(lower, diag, upper, b, 1, 1, 1, 1)[3:]
        if info > 0:
            raise np.linalg.LinAlgError("singular matrix")
        s = np.ascontiguousarray(s[:, 0])
        lib.fd_spline_eval(q, x.ctypes.data, y.ctypes.data, s.ctypes.data, dx.ctypes.data, slope.ctypes.data,
                           j.ctypes.data, at.ctypes.data, out[r].ctypes.data)
    return out
