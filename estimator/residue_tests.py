"""The independence and size tests of one output-error residue (the model check's statistics).

``residue_tests`` is called by ``mismatch.check_model``, which explains the tests; this module holds
the statistics: block means at the test rate, the null covariance of the speed residue, the GLS and
AR prewhitening, the F-tests, the residue-input correlation and its band.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy import linalg

from feeddrive.estimator.blocks_c import row_block_sums
from feeddrive.estimator.distributions import chi2_sf, f_sf, norm_isf, t_sf
from feeddrive.estimator.errors import EstimatorInputError
from feeddrive.estimator.glsar import glsar_fit
from feeddrive.estimator.kernels import ar_order_bic, columns, last_columns_f_test, lstsq, pinv_rank
from feeddrive.estimator.medians import mad_in_place

#: largest prewhitening AR order tried (at the decimated rate); the order is chosen by BIC
MAX_AR = 12
#: singular values of the standardised lag regressors below this fraction of the largest are not tested
LAG_RCOND = 1e-9
#: after the null covariance, an AR stage is fitted only if Ljung-Box rejects whiteness at this level
WHITE_ALPHA = 0.01
#: asymptotic efficiency of the MAD as a scale estimate of Gaussian data: the peak test's t quantile has
#: this fraction of the blocks as degrees of freedom
MAD_EFFICIENCY = 0.37


@dataclass(frozen=True)
class TestResult:
    """One test of one residue: ``statistic`` (F), its degrees of freedom and p-value."""

    __test__ = False  # not a pytest class

    name: str
    statistic: float
    df: tuple[float, float]
    p_value: float

    def to_dict(self) -> dict:
        return {"statistic": self.statistic, "df": list(self.df), "p_value": self.p_value}


def ljung_box(x: np.ndarray, lags: int) -> float:
    """p-value of the Ljung-Box test of whiteness of ``x`` up to ``lags`` (statsmodels' ``acorr_ljungbox``:
    demeaned, biased autocovariances, chi2 with ``lags`` degrees of freedom)."""
    x = np.asarray(x, dtype=float) - np.mean(x)
    n = x.size
    acov = np.array([x[k:] @ x[:n - k] for k in range(lags + 1)]) / n
    rho = acov[1:] / acov[0]
    q = n * (n + 2) * np.sum(rho ** 2 / (n - np.arange(1, lags + 1)))
    return float(chi2_sf(q, lags))


def ols_f_test(y: np.ndarray, X: np.ndarray, R: np.ndarray) -> tuple[float, tuple[float, float], float]:
    """F-test of ``R beta = 0`` in the OLS fit of ``y`` on ``X`` (statsmodels' ``OLS(y, X).fit().f_test(R)``:
    pseudo-inverse fit, residual variance on ``n - rank(X)`` degrees of freedom). Returns (F, (q, dof), p)."""
    pinv, rank = pinv_rank(X)
    beta = pinv @ y
    dof = float(X.shape[0] - rank)
    scale = float(np.sum((y - X @ beta) ** 2) / dof)
    rb = R @ beta
    q = float(R.shape[0])
    fvalue = float(rb @ np.linalg.pinv(scale * R @ (pinv @ pinv.T) @ R.T) @ rb / q)
    return fvalue, (q, dof), float(f_sf(fvalue, q, dof))


def block_samples(rate_hz: float, h: float) -> int:
    """Samples per block of the tests' decimated rate ``rate_hz`` [Hz] at sample time ``h`` [s]."""
    return max(1, int(round(1.0 / (rate_hz * h))))


def _blocks(x: np.ndarray, block: int) -> np.ndarray:
    nb = x.shape[0] // block
    if x.ndim == 2:  # numpy's mean over the middle axis: its sum (row after row, blocks_c), then / block
        return row_block_sums(x, block) / block
    return x[:nb * block].reshape(nb, block, *x.shape[1:]).mean(axis=1)


def integrated_noise_covariance(nb: int, rho: float, ratio: float) -> np.ndarray:
    """Covariance, up to scale, of ``nb`` block means of the speed residue of one segment, shape (nb, nb).

    Under the null the residue is the speed sensor's noise (its block means white, variance 1 here)
    plus the first current sensor's noise integrated by the model from the segment's start: an AR(1)
    at the block rate, ``x[b] = rho x[b-1] + v[b]``, ``x[0] = 0``, ``var v = ratio``, so
    ``cov(x[b], x[c]) = ratio rho^|b-c| (1 - rho^(2 min(b, c))) / (1 - rho^2)`` (blocks from 1). The
    sensor noises are white at the sample rate, so their block means are white whatever the filter
    (its cut-off is above the block rate). Ignoring the integrated part, the prewhitening AR model
    met a near-unit root it could not estimate from a few dozen blocks, and the test rejected healthy
    motions several times more often than its level.
    """
    b = np.arange(1, nb + 1, dtype=float)
    lo = np.minimum.outer(b, b)
    if rho < 1.0:
        x = rho ** np.abs(np.subtract.outer(b, b)) * (1.0 - rho ** (2 * lo)) / (1.0 - rho ** 2)
    else:
        x = lo
    return np.eye(nb) + ratio * x


def _whiten_segments(arrays: Sequence[np.ndarray], sizes: Sequence[int], covariance: Callable[[int], np.ndarray],
                     skip: int) -> list[np.ndarray]:
    # rows of each segment times the inverse Cholesky factor of its blocks' covariance (the first
    # ``skip`` blocks, the lags' warm-up, are not in the arrays); each factor formed once for all the arrays
    factors = [np.linalg.cholesky(covariance(n + skip)[skip:, skip:]) for n in sizes]
    # solve_triangular's finiteness check (a pass over the (n, n) factor per array and segment) made once per
    # factor and per array, with its error: the same solves
    if not all(np.isfinite(x).all() for x in (*factors, *arrays)):
        raise ValueError("array must not contain infs or NaNs")
    out = []
    for a in arrays:
        parts, start = [], 0
        for n, c in zip(sizes, factors):
            parts.append(linalg.solve_triangular(c, a[start:start + n], lower=True, check_finite=False))
            start += n
        out.append(np.concatenate(parts))
    return out


def _segments(groups: np.ndarray) -> list[np.ndarray]:
    """The samples of each label of ``groups`` (n,), labels in increasing order: ``np.flatnonzero(groups == g)`` for
    each ``g`` of ``np.unique(groups)``. Segment labels are non-decreasing in time (``ndimage.label``), so the runs
    are read from where the label changes, without sorting n labels and comparing them once per label."""
    if groups.size == 0 or not np.all(groups[1:] >= groups[:-1]):
        return [np.flatnonzero(groups == g) for g in np.unique(groups)]
    edges = np.concatenate([[0], np.flatnonzero(groups[1:] != groups[:-1]) + 1, [groups.size]])
    return [np.arange(a, b) for a, b in zip(edges[:-1].tolist(), edges[1:].tolist())]


def _orthonormal_nuisance(N: np.ndarray) -> np.ndarray:
    # columns scaled to a unit peak; nearly collinear ones (a constant and a flat sensitivity) dropped
    N = N[:, np.abs(N).max(axis=0) > 0]
    N = N / np.abs(N).max(axis=0)
    if N.shape[1]:
        u_, s_, _ = np.linalg.svd(N, full_matrices=False)
        N = u_[:, s_ > 1e-9 * s_[0]]
    return N


def peak_test(y: np.ndarray, nuisance: np.ndarray, sizes: Sequence[int],
              segment_covariance: Callable[[int], np.ndarray] | None = None) -> TestResult:
    """Is one block of the residue far outside the others? (a transient the model lacks)

    The independence and size tests average over the motion: a fault that acts for a few blocks
    (backlash crossed at a start or a reversal of a slow motion, ~0.1 s in 10 s) moves neither,
    though it stands 10-50 times above the residue's noise there. Under the null the block means,
    with the nuisance removed (and each segment whitened by its null covariance, as the
    independence test), are Gaussian with one scale: ``z = max |e_b - median(e)| / (1.4826 MAD)``,
    and ``p = min(1, n 2 t.sf(z, MAD_EFFICIENCY n))`` (Bonferroni over the ``n`` blocks: conservative
    where neighbouring blocks are correlated). The MAD scale ignores the few blocks of a transient.

    Parameters
    ----------
    y : ndarray, shape (n,)
        Block means of the residue, segment after segment.
    nuisance : ndarray, shape (n, k)
        Block means of the nuisance regressors.
    sizes : sequence of int
        Blocks per segment (sum n).
    segment_covariance : callable, optional
        ``nb -> (nb, nb)`` null covariance of one segment's blocks (the speed residue).

    Returns
    -------
    TestResult
        ``peak``: statistic z, df ``(n, MAD_EFFICIENCY n)``.
    """
    N = _orthonormal_nuisance(nuisance)
    if segment_covariance is not None:
        y, N = _whiten_segments((y, N), sizes, segment_covariance, 0)
    e = y - N @ np.linalg.lstsq(N, y, rcond=None)[0] if N.shape[1] else np.array(y, dtype=float)
    n = e.size
    if n < 2 or e.ndim != 1 or not np.isfinite(e).all():  # numpy's median and its NaN rule
        d = np.abs(e - np.median(e))
        scale = 1.4826 * float(np.median(d))
    else:  # e is ours: the same medians by one selection each, d = |e - median(e)| left in e (reordered)
        scale = 1.4826 * float(mad_in_place(e))
        d = e
    dof = MAD_EFFICIENCY * n
    if not scale > 0:
        return TestResult("peak", 0.0, (float(n), dof), 1.0)
    z = float(d.max() / scale)
    return TestResult("peak", z, (float(n), dof), float(min(1.0, n * 2 * t_sf(z, dof))))


def residue_tests(name: str, residue: np.ndarray, nuisance: np.ndarray, inputs: np.ndarray, h: float,
                  alpha: float, rate_hz: float = 50.0, lags: int = 10, ar_order: int | None = None,
                  noise_std: float | None = None, noise_dof: float = np.inf,
                  groups: np.ndarray | None = None, constant: bool = True,
                  segment_covariance: Callable[[int], np.ndarray] | None = None) -> tuple[dict[str, TestResult], float, np.ndarray, float]:
    """Independence and size tests of one residue; see the module docstring.

    Parameters
    ----------
    residue : ndarray, shape (n,)
        ``measured - simulated`` on the samples tested (signal's unit).
    nuisance : ndarray, shape (n, k)
        Columns whose effect is not a mismatch (sensitivities to the parameters).
    inputs : ndarray, shape (n, m)
        The simulation's inputs.
    h : float
        Sample time [s].
    alpha : float
        Level of the correlation band (the tests return p-values).
    rate_hz, lags, ar_order : float, int, int
        Decimated rate [Hz], input lags (at that rate) and order of the prewhitening AR model.
    noise_std : float or None
        Sensor noise standard deviation of the measured signal (None: no size test).
    noise_dof : float
        Degrees of freedom of ``noise_std`` (the samples it was estimated from).
    groups : ndarray of int, shape (n,), optional
        Segment labels: blocks never straddle two segments.
    constant : bool
        A constant is a nuisance regressor.
    segment_covariance : callable, optional
        ``nb -> (nb, nb)`` null covariance of one segment's blocks (see ``integrated_noise_covariance``).
        With it (the null of the residue is known) ``peak_test`` runs too.

    Returns
    -------
    tests : dict of str to TestResult
    rms : float
        RMS of the residue without its least-squares nuisance part (signal's unit).
    correlation : ndarray, shape (lags + 1, m)
    band : float
    """
    block = block_samples(rate_hz, h)
    groups = np.ones(residue.size, dtype=int) if groups is None else np.asarray(groups)
    parts = _segments(groups)
    # the current: a constant (a voltage or current sensor offset) is a nuisance. Not for the speed: a
    # constant and the segments' free responses (nuisance) span the response to a constant torque, so a
    # load torque or a friction change between two segments would pass unseen
    Z = columns([nuisance, np.ones(residue.size)]) if constant else nuisance
    r_all, Z_all, lagged = [], [], []  # block means of each segment; lagged inputs after the warm-up
    for idx in parts:
        nb = idx.size // block
        if nb <= lags + 1:
            continue
        take = idx[:nb * block]
        if take[-1] - take[0] + 1 == take.size:  # a segment's samples are consecutive: views, not copies
            take = slice(int(take[0]), int(take[-1]) + 1)
        r_, Z_, X_ = _blocks(residue[take], block), _blocks(Z[take], block), _blocks(inputs[take], block)
        r_all.append(r_)
        Z_all.append(Z_)
        lagged.append(np.column_stack([X_[lags - k:nb - k, j] for j in range(X_.shape[1])
                                       for k in range(lags + 1)]))
    rb = [r[lags:] for r in r_all]  # the independence test starts after the lags' warm-up
    if not rb or sum(len(r) for r in rb) < (lags + 1) * inputs.shape[1] + Z.shape[1] + 10:
        raise EstimatorInputError(f"model check ({name}): {residue.size} samples give too few {rate_hz:g} Hz blocks "
                                  f"for {lags} lags of {inputs.shape[1]} input(s)")
    y, N, L = np.concatenate(rb), np.vstack([Z_[lags:] for Z_ in Z_all]), np.vstack(lagged)
    L = (L - L.mean(axis=0)) / L.std(axis=0).clip(1e-300)
    # lags of smooth inputs are nearly collinear: test the well-conditioned principal directions only
    uL, sL, _ = np.linalg.svd(L, full_matrices=False)
    T = uL[:, sL > LAG_RCOND * sL[0]]
    N = _orthonormal_nuisance(N)
    if segment_covariance is not None:
        # GLS first stage: each segment whitened by the covariance the model implies under the null
        sizes = [len(r) for r in rb]
        y, N, T, L = _whiten_segments((y, N, T, L), sizes, segment_covariance, lags)
    design = np.column_stack([N, T])
    if ar_order is None or ar_order < 0:
        # prewhitening order chosen by an information criterion on the OLS residue: the open-loop residue
        # carries the integrated input noise, more colour than a fixed AR(2) whitens
        r0 = y - design @ np.linalg.lstsq(design, y, rcond=None)[0]
        if segment_covariance is not None and ljung_box(r0, max(1, min(10, r0.size // 5))) >= WHITE_ALPHA:
            # the null covariance already whitened the residue: an AR model chosen on a few dozen blocks
            # overfits (BIC picked AR(3) on 54 blocks of a healthy fast motion) and its feasible GLS
            # F-test rejected healthy motions at several times its level
            ar_order = 0
        else:
            ar_order = ar_order_bic(r0, MAX_AR)  # statsmodels' ar_select_order(ic="bic", trend="n")
    if ar_order == 0 and segment_covariance is not None:
        q = T.shape[1]
        restriction = np.zeros((q, design.shape[1]))
        restriction[:, -q:] = np.eye(q)
        fvalue, df, pvalue = ols_f_test(y, design, restriction)
        whiten = np.asarray
    else:
        # statsmodels' GLSAR(y, design, rho=p).iterative_fit(maxiter=6) in numpy (estimator.glsar)
        fit = glsar_fit(y, design, max(ar_order, 1), maxiter=6)
        whiten = fit.whiten
        fvalue, df_num, df_denom, pvalue = last_columns_f_test(fit, T.shape[1])  # fit.f_test([0 I]), bit for bit
        df = (df_num, df_denom)
    tests = {"independence": TestResult("independence", fvalue, df, pvalue)}
    # the correlation plot: residue and inputs prewhitened by the fitted AR model, after the nuisance
    white = whiten(y - N @ np.linalg.lstsq(N, y, rcond=None)[0])
    wl = whiten(L)
    corr = (wl.T @ white) / np.sqrt(np.sum(wl ** 2, axis=0) * (white @ white)).clip(1e-300)
    correlation = corr.reshape(inputs.shape[1], lags + 1).T
    band = float(norm_isf(alpha / 2) / np.sqrt(white.size))
    if segment_covariance is not None:
        tests["peak"] = peak_test(np.concatenate(r_all), np.vstack(Z_all), [len(r) for r in r_all],
                                  segment_covariance)
    Zfull = Z[:, [bool(Z[:, j].any()) for j in range(Z.shape[1])]]  # the non-zero columns (a column at a time:
    # a reduction along the rows of a C-ordered (n, k) array costs ~7x more)
    e = residue - Zfull @ lstsq(Zfull, residue)  # all samples: from the Gram matrix when well conditioned
    rms = float(np.sqrt(np.mean(e ** 2)))
    if noise_std is not None and noise_std > 0:
        dof = float(y.size)  # the residue is correlated over about a block: one degree of freedom per block
        ratio = rms ** 2 / noise_std ** 2
        tests["size"] = TestResult("size", ratio, (dof, float(noise_dof)), float(f_sf(ratio, dof, noise_dof)))
    return tests, rms, correlation, band
