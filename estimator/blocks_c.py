"""Sums of consecutive blocks of rows, ``x[:nb * block].reshape(nb, block, p).sum(axis=1)``, as a C loop.

The batch-means covariance (``motion.parameter_covariance``: the score's block sums and its parameters' block
variances) and the residue tests' block means (``residue_tests._blocks``) reduce the middle axis of an
(nb, block, p) view with a few columns (p = 3 to 6). numpy adds the rows of each block one after the other
into its output (not pairwise: the reduced axis is not the contiguous one), but its iterator then runs inner
loops of p elements: 0.23 ms for the 11426 x 3 scores of the tool change, four such sums per IV motion twice
over. Here the same additions in the same order (each output starts from 0 and adds its block's rows in
turn; compiled by ``estimator.compiled`` without fused multiply-adds), so the same bits (tests/estimator/test_speed_linalg.py compares the two exactly). Without a C compiler (or with
``$FEEDDRIVE_NO_COMPILED_BLOCKS`` set) numpy's own reduction is used.
"""
from __future__ import annotations

import ctypes
from functools import lru_cache

import numpy as np

_SOURCE = r"""
/* out (nb, p) = the sums of the nb blocks of block consecutive rows of x (nb * block, p), C order: row after row
   of each block added in turn, numpy's order for a reduction over the middle axis of (nb, block, p) */
void fd_block_sums(long nb, long block, long p, const double* x, double* out) {
  long b, t, j;
  for (b = 0; b < nb; ++b) {
    const double* xb = x + b * block * p;
    double* o = out + b * p;
    for (j = 0; j < p; ++j)
      o[j] = 0.0;  /* numpy starts from the identity: a block of -0.0 sums to +0.0 */
    for (t = 0; t < block; ++t)
      for (j = 0; j < p; ++j)
        o[j] += xb[t * p + j];
  }
}
"""


@lru_cache(maxsize=1)
def _library() -> ctypes.CDLL | None:
    from feeddrive.estimator.compiled import load_library  # casadi with it: only when first needed

    dp, n = ctypes.c_void_p, ctypes.c_long  # the arrays by address
    return load_library(_SOURCE, "FEEDDRIVE_NO_COMPILED_BLOCKS", {"fd_block_sums": [n, n, n, dp, dp]})


def available() -> bool:
    """True when the C loop could be built here."""
    return _library() is not None


def row_block_sums(x: np.ndarray, block: int) -> np.ndarray:
    """``x[:nb * block].reshape(nb, block, p).sum(axis=1)`` with ``nb = len(x) // block``, bit for bit.

    Parameters
    ----------
    x : ndarray, shape (n, p)
        Rows to sum in blocks (the rows after the last whole block are left out).
    block : int
        Rows per block, >= 1.

    Returns
    -------
    ndarray, shape (n // block, p)
    """
    nb = x.shape[0] // block
    lib = _library()
    # one column: numpy's iterator drops the unit axis and sums each block as a contiguous run, pairwise
    if lib is None or x.ndim != 2 or x.shape[1] < 2 or x.dtype != np.float64:
        return x[:nb * block].reshape(nb, block, *x.shape[1:]).sum(axis=1)
    x = np.ascontiguousarray(x)
    out = np.empty((nb, x.shape[1]))
    if out.size:
        lib.fd_block_sums(nb, int(block), x.shape[1], x.ctypes.data, out.ctypes.data)
    return out
