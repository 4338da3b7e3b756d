"""Feasible GLS with AR(p) errors in numpy: statsmodels' ``GLSAR(y, X, rho=p).iterative_fit(maxiter)``.

The model check prewhitens a coloured residue by an AR model before its independence F-test
(estimator.residue_tests). statsmodels' GLSAR did it, at the price of importing statsmodels and pandas
(0.3-0.9 s, which ``cosim run`` preloaded inside its timed window, issue 23) and of printing a
``SingularMatrixWarning`` for the rank-deficient designs of some PMSM motions. This is the same
algorithm with the same arithmetic (tests/estimator/test_glsar.py: within 1e-10 of statsmodels):

1. ``rho = 0``; fit by OLS on the whitened data (pseudo-inverse through the SVD, singular values below
   ``1e-15`` of the largest dropped: a rank-deficient design has the minimum-norm solution, silently);
2. ``rho`` from the residue ``y - X beta`` by Yule-Walker (demeaned, autocovariances over ``n - k``);
3. repeat up to ``maxiter - 1`` fits, stopping early when no coefficient moved by more than ``rtol``
   relative; the last ``rho`` gives the returned fit.

The whitening ``e_t = u_t - sum_i rho_i u_(t-i)`` drops the first ``p`` samples.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: relative singular value below which a direction of the design is dropped (statsmodels' pinv_extended)
RCOND = 1e-15
#: largest condition number of a whitened design fitted from its QR factors (``_qr_fit``), else by the SVD
QR_MAX_CONDITION = 1e6


@dataclass(frozen=True)
class GLSARFit:
    """The last fit of :func:`glsar_fit`.

    Attributes
    ----------
    params : ndarray, shape (p,)
        Coefficients of the columns of ``X``.
    normalized_cov_params : ndarray, shape (p, p)
        ``pinv(Xw) pinv(Xw)^T`` of the whitened design.
    scale : float
        Residual variance of the whitened fit, ``ssr / df_resid``.
    df_resid : float
        Whitened samples (``n - order``) minus the design's rank.
    rho : ndarray, shape (order,)
        The AR coefficients the fit whitened with.
    iterations : int
        Fits done (statsmodels' ``results.iter``).
    converged : bool
        Stopped by ``rtol`` before ``maxiter``.
    """

    params: np.ndarray
    normalized_cov_params: np.ndarray
    scale: float
    df_resid: float
    rho: np.ndarray
    iterations: int
    converged: bool

    def cov_params(self) -> np.ndarray:
        """Covariance of the coefficients, shape (p, p)."""
        return self.normalized_cov_params * self.scale

    def whiten(self, x: np.ndarray) -> np.ndarray:
        """``x`` (n,) or (n, k) whitened by the fitted AR model: shape (n - order, ...)."""
        return whiten(x, self.rho)


def whiten(x: np.ndarray, rho: np.ndarray) -> np.ndarray:
    """``e_t = x_t - sum_i rho_i x_(t-i)`` along the first axis, the first ``len(rho)`` samples dropped."""
    x = np.asarray(x, dtype=np.float64)
    out = x.copy()
    for i, r in enumerate(rho, 1):  # in statsmodels' order: the rounding is its own
        out[i:] = out[i:] - r * x[:-i]
    return out[len(rho):]


def yule_walker(x: np.ndarray, order: int) -> np.ndarray:
    """AR(``order``) coefficients of ``x`` (n,) by Yule-Walker: demeaned, autocovariance at lag k summed over
    the ``n - k`` pairs and divided by ``n - k`` (statsmodels' ``method="adjusted"``)."""
    x = np.array(x, dtype=np.float64)
    x -= x.mean()
    n = x.shape[0]
    r = np.zeros(order + 1)
    r[0] = (x ** 2).sum() / n
    for k in range(1, order + 1):
        r[k] = (x[:-k] * x[k:]).sum() / (n - k)
    lags = np.abs(np.arange(order)[:, None] - np.arange(order)[None, :])
    R = r[:-1][lags]  # the symmetric Toeplitz matrix of r[0..order-1]
    try:
        return np.linalg.solve(R, r[1:])
    except np.linalg.LinAlgError:  # a constant residue: the pseudo-inverse, as statsmodels (without its warning)
        return np.linalg.pinv(R) @ r[1:]


def glsar_fit(y: np.ndarray, X: np.ndarray, order: int, maxiter: int = 3, rtol: float = 1e-4) -> GLSARFit:
    """Regression of ``y`` on ``X`` with AR(``order``) errors, by iterated feasible GLS.

    Parameters
    ----------
    y : ndarray, shape (n,)
    X : ndarray, shape (n, p)
        May be rank-deficient (minimum-norm coefficients, the rank in the degrees of freedom).
    order : int
        AR order, >= 1.
    maxiter : int
        Fits at most (statsmodels' ``iterative_fit(maxiter)``).
    rtol : float
        Stop when ``max |last - params| / |last| < rtol``.

    Returns
    -------
    GLSARFit
    """
    y = np.asarray(y, dtype=np.float64)
    X = np.asarray(X, dtype=np.float64)
    rho = np.zeros(int(order))
    converged, fits, last = False, 0, None
    for i in range(maxiter - 1):
        fit = _fit(y, X, rho)
        fits += 1
        if i > 0:
            with np.errstate(divide="ignore", invalid="ignore"):
                if np.max(np.abs(last - fit.params) / np.abs(last)) < rtol:
                    converged = True
                    break
        last = fit.params
        rho = yule_walker(y - X @ fit.params, int(order))
    fit = _fit(y, X, rho)
    return GLSARFit(fit.params, fit.normalized_cov_params, fit.scale, fit.df_resid, rho,
                    fits + (0 if converged else 1), converged)


def _fit(y: np.ndarray, X: np.ndarray, rho: np.ndarray) -> GLSARFit:
    """One whitened least-squares fit with ``rho`` (statsmodels' ``fit(method="pinv")``)."""
    wX, wy = whiten(X, rho), whiten(y, rho)
    qr = _qr_fit(wX, wy)
    if qr is not None:
        return GLSARFit(*qr, rho, 1, False)
    u, s, vt = np.linalg.svd(wX, False)
    inv = np.where(s > RCOND * np.max(s), 1.0 / np.where(s > 0, s, 1.0), 0.0)
    pinv = np.dot(np.transpose(vt), np.multiply(inv[:, np.newaxis], np.transpose(u)))
    # statsmodels' matrix_rank(diag(s)): its singular values are s itself (non-negative, in order), so its
    # tolerance and count are taken on s without a second SVD
    rank = int(np.count_nonzero(s > s.max(initial=0) * (s.size * np.finfo(s.dtype).eps)))
    beta = np.dot(pinv, wy)
    df_resid = float(wX.shape[0]) - rank
    wresid = wy - np.dot(wX, beta)
    return GLSARFit(beta, np.dot(pinv, np.transpose(pinv)), float(np.dot(wresid, wresid) / df_resid), df_resid,
                    rho, 1, False)


def _qr_fit(wX: np.ndarray, wy: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, float] | None:
    """``(beta, pinv pinv^T, scale, df_resid)`` of a tall full-rank whitened design from its QR factors, or None
    (not tall, rank-deficient by statsmodels' tolerance, or too ill-conditioned: the SVD pseudo-inverse then).

    For ``wX = Q R`` of full rank the pseudo-inverse is ``R^-1 Q^T``: ``beta = R^-1 (Q^T wy)`` and ``pinv pinv^T =
    R^-1 R^-T``, without the SVD's left singular vectors (n x p) and its products over the n rows (the model check's
    158 x 26 whitened designs: half the SVD's work). The rank is judged as statsmodels does, on the singular values
    of ``R`` (those of ``wX``); the numbers agree with the SVD's to ~1e-12 relative at condition numbers up to
    ``QR_MAX_CONDITION`` (tests/estimator/test_glsar.py).
    """
    from scipy.linalg import lapack, solve_triangular  # here: the monitor's path imports scipy lazily

    n, p = wX.shape
    if p == 0 or n < 2 * p or not np.all(np.isfinite(wX)):
        return None
    qr, tau, _, info = lapack.dgeqrf(wX)
    if info != 0:  # pragma: no cover - an illegal argument only
        return None
    R = np.triu(qr[:p])
    s = np.linalg.svd(R, compute_uv=False)
    if not (s[-1] > s[0] * (s.size * np.finfo(s.dtype).eps) and s[0] < QR_MAX_CONDITION * s[-1]):
        return None
    lwork = lapack.dormqr("L", "T", qr, tau, wy[:, None], -1)[1][0].real
    qty, _, info = lapack.dormqr("L", "T", qr, tau, wy[:, None].copy(), int(lwork))
    if info != 0:  # pragma: no cover
        return None
    beta = solve_triangular(R, qty[:p, 0], check_finite=False)
    Ri = solve_triangular(R, np.eye(p), check_finite=False)
    df_resid = float(n - p)
    wresid = wy - np.dot(wX, beta)
    return beta, Ri @ Ri.T, float(np.dot(wresid, wresid) / df_resid), df_resid
