"""Column by column arithmetic on C-ordered ``(n, k)`` arrays of a few columns (issue 26).

numpy broadcasts a ``(k,)`` scale or an ``(n, 1)`` weight over a C-ordered ``(n, k)`` array through its buffered
iterator, a copy of a few values per row into its buffers: ~7 times the time of the same operation on each
column (a strided 1-D loop with a scalar or a vector, unbuffered). The fits' usable rows are C-ordered (their
products' order, linear_fit), so their scaling and their scores go column by column here: the same elementwise
operations, the same bits, and a C-ordered result as numpy's.
"""
from __future__ import annotations

import numpy as np

#: widest array taken column by column (a wide one has long rows: numpy's loop is then fast)
MAX_COLUMNS = 16
#: fewest rows taken column by column: a short array costs numpy's call overhead, one call per column
MIN_ROWS = 512


def _columnwise(X: np.ndarray, other: np.ndarray) -> bool:
    return (X.ndim == 2 and X.dtype == np.float64 and X.flags.c_contiguous and 1 < X.shape[1] <= MAX_COLUMNS
            and X.shape[0] >= MIN_ROWS and other.dtype == np.float64)


def divide_columns(X: np.ndarray, s: np.ndarray) -> np.ndarray:
    """``X / s``: each column ``X[:, j]`` (shape (n, k)) divided by ``s[j]`` (shape (k,))."""
    X, s = np.asarray(X), np.asarray(s)
    if not (_columnwise(X, s) and s.shape == X.shape[1:]):
        return X / s
    out = np.empty(X.shape)
    for j in range(X.shape[1]):
        np.divide(X[:, j], s[j], out=out[:, j])
    return out


def multiply_rows(X: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``X * v[:, None]``: each row of ``X`` (shape (n, k)) times its weight ``v`` (shape (n,))."""
    X, v = np.asarray(X), np.asarray(v)
    if not (_columnwise(X, v) and v.shape == X.shape[:1]):
        return X * v[:, None]
    out = np.empty(X.shape)
    for j in range(X.shape[1]):
        np.multiply(X[:, j], v, out=out[:, j])
    return out
