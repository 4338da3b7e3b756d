"""Fast kernels of the per-motion path (issue 26): each equals a straightforward computation it replaces.

The monitor treats every motion within its budget; these replace calls that did the same work many
times or through a general-purpose routine. Each is checked against the computation it replaces in
tests/estimator/test_speed.py (identical booleans, floats within 1e-12 relative).
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from feeddrive.estimator.columnwise import divide_columns, multiply_rows


def erode(mask: np.ndarray, radius: int, border: bool) -> np.ndarray:
    """1-D binary erosion: True where every sample within ``radius`` of it is True.

    The same booleans as ``scipy.ndimage.binary_erosion(mask, iterations=radius, border_value=border)``
    (and as one erosion by ``np.ones(2 radius + 1)``), from a running count of the False samples
    instead of ``radius`` passes over the array (a guard of 40 samples took 6 ms on 35000 samples).

    Parameters
    ----------
    mask : ndarray of bool, shape (n,)
    radius : int
        Half-width of the window [samples], >= 0.
    border : bool
        Value of the samples beyond both ends.

    Returns
    -------
    ndarray of bool, shape (n,)
    """
    mask = np.asarray(mask, dtype=bool)
    if radius <= 0:
        return mask.copy()
    n = mask.size
    pad = np.full(radius, not border)
    bad = np.concatenate([pad, ~mask, pad]).astype(np.int64)
    count = np.concatenate([[0], np.cumsum(bad)])
    # False samples in [k - radius, k + radius] of the padded signal, for each original sample k
    return count[2 * radius + 1:2 * radius + 1 + n] == count[:n]


def ar_order_bic(x: np.ndarray, maxlag: int) -> int:
    """Order of the AR model without trend that minimises BIC, as ``statsmodels``' ``ar_select_order(x,
    maxlag, ic="bic", trend="n")`` chooses it (the orders 0..maxlag fitted on the same ``n - maxlag``
    samples, ``bic = -2 llf + ln(nobs) (rank + 1)``), without its DataFrames and per-order model objects
    (40 ms of a 60 ms model check). Data whose lag matrix is rank-deficient or spans a constant (where
    statsmodels' bookkeeping of the degrees of freedom differs) go to statsmodels itself.

    Parameters
    ----------
    x : ndarray, shape (n,)
    maxlag : int

    Returns
    -------
    int
        The order, 0..maxlag (the largest lag of the selected model).
    """
    x = np.asarray(x, dtype=float)
    n = x.size
    y = x[maxlag:]
    X = np.column_stack([x[maxlag - j:n - j] for j in range(1, maxlag + 1)])
    nobs = y.size
    ones = np.ones(nobs)
    if nobs > maxlag + 1:
        sv = np.linalg.svd(X, compute_uv=False)
        q = thin_q(X)
        spans_one = np.linalg.norm(ones - q @ (q.T @ ones)) < 1e-6 * np.sqrt(nobs)
        regular = sv[-1] > 1e-8 * sv[0] and not spans_one and np.ptp(X, axis=0).min() > 0
    else:
        regular = False
    if not regular:
        from statsmodels.tsa.ar_model import ar_select_order

        lags = ar_select_order(x, maxlag=maxlag, ic="bic", trend="n").ar_lags
        return max(lags) if lags else 0
    best, best_ic = 0, np.inf
    # the nested fits from the one QR factorisation: the first `order` columns of q span those of X (full
    # rank, checked above), so each fit's residue is y less its projection on them: 13 products instead of 13
    # lstsq, the same residues to rounding (the chosen order differs only where two orders' BIC tie to the last
    # digits; statsmodels' choice on 62 series, tests/estimator/test_speed.py)
    qy = q.T @ y
    for order in range(maxlag + 1):
        r = y - q[:, :order] @ qy[:order] if order else y
        sigma2 = float(r @ r) / nobs
        llf = -nobs * (np.log(2 * np.pi * sigma2) + 1) / 2
        ic = -2 * llf + np.log(nobs) * (order + 1)
        if ic < best_ic:  # the first of equal values, as statsmodels' stable sort
            best, best_ic = order, ic
    return best


def thin_q(A: np.ndarray) -> np.ndarray:
    """``np.linalg.qr(A)[0]``: the orthonormal factor (m, k), k = min(m, n), of ``A`` (m, n).

    The same LAPACK routines (geqrf, orgqr) through ``scipy.linalg.qr(mode="economic")``: numpy's reduced QR
    took 1.3 ms on the residue check's 6101 x 6 instruments, scipy's 0.3 ms. The same bits here
    (tests/estimator/test_speed.py compares the two to 1e-12).
    """
    from scipy.linalg import qr  # here: the monitor's path imports scipy lazily

    return qr(A, mode="economic", check_finite=False)[0]


def right_singular(A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``np.linalg.svd(A, full_matrices=False)[1:]``: the singular values (k,) and right singular vectors
    ``Vt`` (k, n) of ``A`` (m, n), without the left ones (m, k).

    For ``m >= 11 n / 6`` LAPACK's gesdd itself factors ``A = Q R`` first and decomposes ``R``; here ``R`` is
    decomposed by the same gesdd without forming ``Q`` and ``U = Q U_R``, the two products over the m rows
    that were most of the time (6101 x 6: 0.7 -> 0.2 ms). The same values (tests/estimator/test_speed.py
    compares the two to 1e-12); a matrix not that tall goes to numpy's svd.
    """
    m, n = A.shape
    if n == 0 or m < int(n * 11 / 6) or not np.all(np.isfinite(A)):  # gesdd's own threshold (MNTHR)
        return np.linalg.svd(A, full_matrices=False)[1:]
    from scipy.linalg import lapack  # here: the monitor's path imports scipy lazily

    qr, _, _, info = lapack.dgeqrf(np.asarray(A, dtype=float))
    if info != 0:  # pragma: no cover - geqrf fails only on an illegal argument
        return np.linalg.svd(A, full_matrices=False)[1:]
    _, s, vt, info = lapack.dgesdd(np.triu(qr[:n]), compute_uv=1, full_matrices=0)
    if info != 0:  # not converged: numpy raises its LinAlgError for the same matrix
        return np.linalg.svd(A, full_matrices=False)[1:]
    return s, vt


def pinv_rank(A: np.ndarray) -> tuple[np.ndarray, int]:
    """``(np.linalg.pinv(A), np.linalg.matrix_rank(A))`` of ``A`` (m, n) from one SVD instead of two.

    The pseudo-inverse is numpy's arithmetic on numpy's SVD (the same bits); the rank counts the same
    singular values above numpy's tolerance ``max(s) max(m, n) eps``, here those of the SVD with vectors where
    ``matrix_rank`` takes the values alone (equal to rounding: the count differs only for a singular value
    within a rounding of the tolerance). A residue test asked for both of one matrix twice per motion.
    """
    A = np.asarray(A, dtype=float)
    m, n = A.shape
    if m == 0 or n == 0:
        return np.linalg.pinv(A), 0
    u, s, vt = np.linalg.svd(A, full_matrices=False)
    rank = int(np.count_nonzero(s > s.max(initial=0) * (max(m, n) * np.finfo(s.dtype).eps)))
    # numpy.linalg.pinv from here on (rcond 1e-15 of the largest singular value)
    cutoff = np.asarray(1e-15)[..., np.newaxis] * np.amax(s, axis=-1, keepdims=True)
    large = s > cutoff
    s = np.divide(1, s, where=large, out=s)
    s[~large] = 0
    return np.matmul(np.transpose(vt), np.multiply(s[..., np.newaxis], np.transpose(u))), rank


def line_fit(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Least squares of ``y ~ a x + b`` (both (k,)): ``[a, b]``, the residue (k,) and ``(X^T X)^-1`` (2, 2) of
    ``X = [x 1]``.

    In closed form on the centred ``x`` (the slope's sum over the centred products, the intercept from the means:
    ``lstsq`` and ``pinv``'s solution to ~1e-15 relative, tests/estimator/test_speed_linalg.py) instead of two LAPACK
    calls on a 2-column matrix, which cost 0.3 ms of each sensor pair's 0.5 ms inside the monitor's treatment (``validation.residue_test``). A
    constant ``x`` (a rank-deficient ``X``) goes to ``lstsq`` and ``pinv`` themselves (their minimum-norm answer).
    """
    k = x.size
    mx, my = x.sum() / k, y.sum() / k
    dx = x - mx
    sxx = float(dx @ dx)
    if not sxx > 1e-12 * k * (mx * mx + 1.0):
        X = np.column_stack([x, np.ones(k)])
        coef = np.linalg.lstsq(X, y, rcond=None)[0]
        return coef, y - X @ coef, np.linalg.pinv(X.T @ X)
    a = float(dx @ (y - my)) / sxx
    b = my - a * mx
    # (X^T X)^-1 = [[1, -mx], [-mx, sxx / k + mx^2]] / sxx, its determinant k sxx
    gram_inv = np.array([[1.0, -mx], [-mx, sxx / k + mx * mx]]) / sxx
    return np.array([a, b]), y - (a * x + b), gram_inv


#: largest condition number of the column-scaled regressor whose LS solution is taken from its Gram matrix's
#: eigendecomposition (the normal equations, refined once; their error ~ cond^2 eps before the refinement, 6e-13
#: here, its square after); above it lstsq
NORMAL_MAX_CONDITION = 50.0


def ls_theta(Xs: list[np.ndarray], ys: list[np.ndarray], eig: np.ndarray, V: np.ndarray, cond: float) -> np.ndarray:
    """Least squares of the stacked ``ys`` on the stacked ``Xs`` (each (n_k, p), columns scaled to unit norm).

    ``eig`` (p,) ascending and ``V`` (p, p) are the eigendecomposition of the Gram matrix ``sum X^T X`` that
    ``linear_fit._solve`` computed for the condition number ``cond``. A well-conditioned regressor (``cond`` at most
    ``NORMAL_MAX_CONDITION``) is solved from it, ``V diag(1 / eig) V^T sum X^T y`` (one pass over the samples
    instead of lstsq's SVD: 0.4 ms of 0.45 at 11426 x 3), refined once on its residue; the same solution to
    1e-12 (~1e-15 relative at the tool change's cond 5.8, tests/estimator/test_speed_linalg.py); otherwise
    ``numpy.linalg.lstsq``.
    """
    if cond <= NORMAL_MAX_CONDITION and eig.size == Xs[0].shape[1] and eig[0] > 0:
        def solve(b: np.ndarray) -> np.ndarray:
            return V @ ((V.T @ b) / eig)

        theta = solve(sum(X.T @ y for X, y in zip(Xs, ys)))
        # one step of refinement on the residue: the normal equations' error (cond^2 eps times the residue's
        # size relative to the fit's) becomes second order, lstsq's accuracy for any residue
        return theta + solve(sum(X.T @ (y - X @ theta) for X, y in zip(Xs, ys)))
    X = Xs[0] if len(Xs) == 1 else np.vstack(Xs)
    y = ys[0] if len(ys) == 1 else np.concatenate(ys)
    return np.linalg.lstsq(X, y, rcond=None)[0]


def lstsq(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``numpy.linalg.lstsq(A, b, rcond=None)[0]`` for a full-rank ``A`` (n, p) and ``b`` (n,): from the Gram matrix
    of the unit-norm columns when their condition number is at most ``NORMAL_MAX_CONDITION`` (``ls_theta``, the
    same solution to 1e-12), else lstsq itself."""
    norms = np.sqrt(np.einsum("ij,ij->j", A, A))
    if not np.all(norms > 0) or not np.all(np.isfinite(norms)):
        return np.linalg.lstsq(A, b, rcond=None)[0]
    As = divide_columns(A, norms)
    eig, V = np.linalg.eigh(As.T @ As)
    cond = float(np.sqrt(eig[-1] / eig[0])) if eig[0] > 0 else np.inf
    if cond > NORMAL_MAX_CONDITION:
        return np.linalg.lstsq(A, b, rcond=None)[0]
    return ls_theta([As], [b], eig, V, cond) / norms


def toeplitz_score_covariance(W: np.ndarray, e: np.ndarray, lags: int) -> np.ndarray:
    """``W^T Gamma W`` for one sample set of ``motion.stationary_score_covariance``, in the frequency domain.

    ``Gamma[s, t] = gamma(|s - t|)`` for ``|s - t| <= lags`` (0 beyond), ``gamma(l)`` the mean of
    ``e_t e_(t+l)`` over the pairs of used rows (``e != 0``). Every transform has length >= n + lags + 1,
    so no lag up to ``lags`` wraps around, and ``W^T Gamma W = Re(sum_k conj(FW_k) G_k FW_k^T) / N`` with
    ``G`` the transform of the circular kernel: five or six transforms instead of eleven (the count of
    used pairs comes from the runs of used rows, :func:`used_pairs`, without a transform unless they are
    many). Equal to the time-domain sum to ~1e-14 of the diagonal (tests/estimator/test_speed.py).

    Parameters
    ----------
    W : ndarray, shape (n, p)
        Instruments (or regressors), rows left out of the fit zero.
    e : ndarray, shape (n,)
        Equation errors, rows left out zero.
    lags : int
        Largest lag kept [samples].

    Returns
    -------
    ndarray, shape (p, p)
        Not symmetrised.
    """
    from scipy.fft import irfft, next_fast_len, rfft

    n = len(e)
    m = min(lags, n - 1)
    nfft = next_fast_len(n + m + 1, real=True)
    # e and the columns of W in one call: pocketfft takes the rows two at a time in the lanes of a vector (the same
    # bits per row as transformed alone), so the four rows of p = 3 are two passes instead of three
    # written into their zero-padded rows once: rfft's own padding copied a stacked copy into zeros (its values)
    X = np.empty((1 + W.shape[1], nfft))
    X[0, :n] = e
    X[1:, :n] = W.T
    X[:, n:] = 0.0
    F = rfft(X, axis=-1)
    fe, FW = F[0], F[1:]
    num = irfft(fe * np.conj(fe), nfft)[:m + 1]
    used = e != 0
    pairs = used_pairs(used, m)
    if pairs is None:
        fu = rfft(used.astype(float), nfft)
        pairs = np.rint(irfft(fu * np.conj(fu), nfft)[:m + 1])
    gamma = np.where(pairs > 0, num / np.maximum(pairs, 1.0), 0.0)
    if n <= m:
        return W.T @ (W * gamma[0])
    kernel = np.zeros(nfft)
    kernel[:m + 1] = gamma
    kernel[nfft - m:] = gamma[:0:-1]
    weight = rfft(kernel).real * 2.0  # a symmetric kernel: a real transform; each bin stands for +-k ...
    weight[0] /= 2.0
    if nfft % 2 == 0:  # ... but the zero and Nyquist bins
        weight[-1] /= 2.0
    return ((FW.conj() * weight) @ FW.T).real / nfft


#: most runs of used rows whose pair counts are summed run by run (beyond: one transform pair, O(n log n))
MAX_RUNS = 12


def used_pairs(used: np.ndarray, lags: int) -> np.ndarray | None:
    """``sum_t used_t used_(t+l)`` for ``l = 0 .. lags``, exactly, from the runs of True; None past ``MAX_RUNS`` runs.

    The rows a fit uses are a few stretches of the motion (fast samples between the zero crossings), so the
    count of used pairs at each lag is the overlap of every two runs shifted by ``l``: ``R^2`` clipped ramps
    instead of two transforms of length ~n (the same integers as rounding the transforms).

    Parameters
    ----------
    used : ndarray of bool, shape (n,)
    lags : int
        Largest lag [samples], < n.

    Returns
    -------
    ndarray of float, shape (lags + 1,), or None
    """
    if used.all():
        return (used.size - np.arange(lags + 1)).astype(float)
    edges = np.flatnonzero(np.diff(np.concatenate([[False], used, [False]]).view(np.int8)))
    start, stop = edges[::2], edges[1::2]  # run r is used[start[r]:stop[r]]
    if start.size > MAX_RUNS:
        return None
    lag = np.arange(lags + 1)
    # pairs (t, t + l) with t in run a and t + l in run b: t in [max(sa, sb - l), min(ea, eb - l))
    lo = np.maximum(start[:, None, None], start[None, :, None] - lag)
    hi = np.minimum(stop[:, None, None], stop[None, :, None] - lag)
    return np.clip(hi - lo, 0, None).sum(axis=(0, 1)).astype(float)


def bilinear_first_order(a1: float, a0: float, h: float) -> tuple[np.ndarray, np.ndarray]:
    """``scipy.signal.cont2discrete(([1], [a1, a0]), h, method="bilinear")``'s ``b`` (raveled) and ``a``.

    The model checks discretise ``1 / (L s + R)`` and ``1 / (Jt s + ft)`` a dozen times per motion with the
    same few parameter sets; scipy's general state-space route costs ~1 ms a call. Its scalar steps in
    estimator.lti (scipy's numbers bit for bit), kept per (a1, a0, h).
    """
    b, a = _bilinear(float(a1), float(a0), float(h))
    return b.copy(), a.copy()


@lru_cache(maxsize=256)
def _bilinear(a1: float, a0: float, h: float) -> tuple[np.ndarray, np.ndarray]:
    from feeddrive.estimator.lti import bilinear_first_order as tustin

    return tustin(a1, a0, h)


# --- the model's symbolic facts, derived once per model ---------------------------------------------------------
# A model is data that no one changes after it is built (``models.drives.drive_model`` and ``with_design`` give one
# object per kind and design), so what the estimator derives from its equations is kept per model object, as
# ``regression._derive`` keeps its regressions: CasADi's depends_on/symvar over the residuals, asked again for every
# signal of every half of every IV iteration, were ~45 ms of a 165 ms motion.

@lru_cache(maxsize=32)
def measured_signals(model) -> tuple[str, ...]:  # noqa: ANN001 - models.Model
    """``models.drives.measured(model)``, derived once per model object."""
    from feeddrive.models.drives import measured

    return measured(model)


@lru_cache(maxsize=32)
def parameter_defined_of(model) -> tuple[str, ...]:  # noqa: ANN001 - models.Model
    """``models.drives.parameter_defined(model)``, derived once per model object (CasADi's depends_on over every
    residual: 2 ms, asked by every ``prepare`` of a motion, its halves and re-fits)."""
    from feeddrive.models.drives import parameter_defined

    return parameter_defined(model)


@lru_cache(maxsize=64)
def equation_parameters_of(model, equation: str) -> tuple[str, ...]:  # noqa: ANN001
    """``regression.equation_parameters(model, equation)``, derived once per (model, equation)."""
    from feeddrive.estimator.regression import equation_parameters

    return equation_parameters(model, equation)


@lru_cache(maxsize=64)
def residual_symbols(model, equation: str) -> frozenset[str]:  # noqa: ANN001
    """Names of the symbols of ``regression.equation_residual(model, equation)``, once per (model, equation)."""
    import casadi as ca

    from feeddrive.estimator.regression import equation_residual

    return frozenset(x.name() for x in ca.symvar(equation_residual(model, equation)))


def column_norms(A: np.ndarray) -> np.ndarray:
    """Euclidean norm of each column of ``A`` (n, p): ``np.linalg.norm(A, axis=0)`` to rounding (1e-15 relative),
    in one pass without the n x p temporary of squares (0.2 ms instead of 0.8 ms at 30000 x 10)."""
    return np.sqrt(np.einsum("ij,ij->j", A, A))


def block_sums(x: np.ndarray, k: int) -> np.ndarray:
    """Sums over ``k`` consecutive blocks of equal length (the remainder goes to the last block), shape (k, ...)."""
    edges = np.linspace(0, x.shape[0], k + 1).astype(int)
    return np.add.reduceat(x, edges[:-1], axis=0)


def columns(blocks: list[np.ndarray]) -> np.ndarray:
    """``np.column_stack(blocks)`` (1-D columns and 2-D blocks of rows), C-ordered, written column by column: numpy
    copies a 2-D block into the wider result a row at a time (a call of its copy loop per row of a few values;
    the model check's (7000, 10) nuisance blocks), here one strided copy per column. The same values."""
    blocks = [np.asarray(b) for b in blocks]
    m = blocks[0].shape[0]
    out = np.empty((m, sum(1 if b.ndim == 1 else b.shape[1] for b in blocks)),
                   dtype=np.result_type(*blocks))
    j = 0
    for b in blocks:
        for col in (b,) if b.ndim == 1 else b.T:
            out[:, j] = col
            j += 1
    return out


def nonzero_norms(A: np.ndarray) -> np.ndarray:
    """:func:`column_norms` with the zero ones replaced by 1 (a zero column stays zero when divided)."""
    norms = column_norms(A)
    return np.where(norms > 0, norms, 1.0)


def block_iv(y: np.ndarray, W: list[np.ndarray], V: list[np.ndarray], k: int) -> tuple[np.ndarray, np.ndarray]:
    """IV estimate of ``y ~ [W_1 W_2 ...]`` with instruments ``[V_1 V_2 ...]``, and its batch-means covariance.

    The same numbers as with the stacked matrices ``Ws = np.column_stack(W)``, ``Vs = np.column_stack(V)``
    (``M = pinv(Vs^T Ws)``, ``beta = M Vs^T y``, ``G`` the sums of ``Vs * (y - Ws beta)`` over ``k`` blocks,
    ``cov = M G^T G M^T``; to rounding, tests/estimator/test_speed.py) from the blocks' products, without
    copying the n x p columns into two new matrices (a third of ``adequacy``'s lack-of-fit test).

    Parameters
    ----------
    y : ndarray, shape (n,)
    W, V : list of ndarray, shapes (n, p_j) and (n, r_j), sum p_j == sum r_j
    k : int
        Blocks of the batch-means covariance.

    Returns
    -------
    beta : ndarray, shape (p,)
    cov : ndarray, shape (p, p)
    """
    M = np.linalg.pinv(np.vstack([np.hstack([v.T @ w for w in W]) for v in V]))  # np.block's matrix, its copies
    beta = M @ np.concatenate([v.T @ y for v in V])
    edges = np.cumsum([0] + [w.shape[1] for w in W])
    r = y - sum(w @ beta[a:b] for w, a, b in zip(W, edges[:-1], edges[1:]))
    G = np.hstack([block_sums(multiply_rows(v, r), k) for v in V])
    return beta, M @ (G.T @ G) @ M.T


def last_columns_f_test(fit, q: int) -> tuple[float, float, float, float]:  # noqa: ANN001 - statsmodels results
    """statsmodels' ``fit.f_test(R)`` with ``R = [0 I_q]`` (are the last ``q`` coefficients zero?), bit for bit.

    ``R b`` and ``R C R^T`` of a 0/1 selection matrix are the coefficients' and covariance's last entries
    exactly, so the Wald statistic is formed from them with statsmodels' own arithmetic (``pinv`` of the
    covariance block, its rank as the numerator dof when deficient, ``df_resid`` as the denominator),
    without ``wald_test``'s constraint parsing (5 of a residue test's ~15 ms).

    Parameters
    ----------
    fit : statsmodels RegressionResults or estimator.glsar.GLSARFit
        An OLS or GLSAR fit (``params``, ``cov_params()``, ``df_resid``).
    q : int
        Number of trailing coefficients tested, >= 1.

    Returns
    -------
    tuple of float
        ``(F, df_num, df_denom, p_value)`` as ``f_test``'s ``fvalue``, ``df_num``, ``df_denom``, ``pvalue``.
    """
    from feeddrive.estimator.distributions import f_sf

    Rbq = np.asarray(fit.params)[-q:, None]
    cov = np.asarray(fit.cov_params())[-q:, -q:]
    if np.isnan(cov).max():
        raise ValueError("r_matrix performs f_test for using dimensions that are asymptotically non-normal")
    invcov, rank = pinv_rank(cov)
    J = float(min(q, rank))
    F = float(np.squeeze(np.dot(np.dot(Rbq.T, invcov), Rbq))) / J
    df_denom = float(getattr(fit, "df_resid_inference", fit.df_resid))
    return F, J, df_denom, float(f_sf(F, J, df_denom))


def label_runs(mask: np.ndarray) -> tuple[np.ndarray, int]:
    """1-D ``scipy.ndimage.label``: the runs of True numbered 1..n in time order, 0 elsewhere, and n.

    The same int32 labels as ndimage's (tests/estimator/test_speed.py), without importing scipy.ndimage
    (~0.3 s of a command's start: it pulls in scipy's array-API layer).

    Parameters
    ----------
    mask : ndarray of bool, shape (n,)

    Returns
    -------
    labels : ndarray of int32, shape (n,)
    count : int
    """
    mask = np.asarray(mask, dtype=bool).ravel()
    starts = mask.copy()
    starts[1:] &= ~mask[:-1]
    labels = np.cumsum(starts, dtype=np.int32)
    labels[~mask] = 0
    return labels, int(np.count_nonzero(starts))


def label_slices(labels: np.ndarray) -> list[tuple[slice] | None]:
    """1-D ``scipy.ndimage.find_objects``: for each label 1..max, ``(slice(first, last + 1),)``, None if absent.

    Parameters
    ----------
    labels : ndarray of int, shape (n,)
        0 for the background.

    Returns
    -------
    list of (slice,) or None, one per label 1..max
    """
    labels = np.asarray(labels).ravel()
    top = int(labels.max(initial=0))
    if top <= 0:
        return []
    # the runs of equal labels (a few, where the samples are thousands): a label's first sample is the start of
    # its first run, its last sample the end of its last run
    change = np.flatnonzero(labels[1:] != labels[:-1])
    start, stop = np.concatenate(([0], change + 1)), np.concatenate((change, [labels.size - 1]))
    lab = labels.take(start)
    used = lab > 0
    lab, start, stop = lab[used], start[used], stop[used]
    first, last = np.full(top + 1, -1), np.full(top + 1, -1)
    last[lab] = stop                   # the last assignment to a label wins: its last run's end
    first[lab[::-1]] = start[::-1]     # reversed: its first run's start
    return [(slice(int(first[m]), int(last[m]) + 1),) if last[m] >= 0 else None for m in range(1, top + 1)]

