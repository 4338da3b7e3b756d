"""The per-motion path's shortcuts through LAPACK (issue 26) against the numpy calls they replace.

Each takes the same LAPACK routines on the same numbers, so the results are the same bits on this machine;
the tests allow 1e-12 relative, as the other kernels whose arithmetic could be ordered differently elsewhere
(tests/estimator/test_speed.py). Timing is measured in benchmarks/, never asserted here.
"""
from __future__ import annotations

from fractions import Fraction

import numpy as np

from feeddrive.estimator.kernels import (
    NORMAL_MAX_CONDITION,
    line_fit,
    ls_theta,
    lstsq,
    pinv_rank,
    right_singular,
    thin_q,
)


def _matrices(rng: np.random.Generator):
    """Tall matrices like the checks' (rows 2..8000, 1..12 columns, column scales over six decades), in both
    memory orders, and a few not tall enough for gesdd's QR path, a rank-deficient and a zero column."""
    for k in range(60):
        m, n = int(rng.integers(2, 8000)), int(rng.integers(1, 13))
        A = rng.standard_normal((m, n)) * np.logspace(0, rng.uniform(0, 6), n)
        yield np.asfortranarray(A) if k % 2 else A
    A = rng.standard_normal((500, 4))
    yield np.column_stack([A, A[:, :1] + A[:, 1:2], np.zeros(500)])
    yield rng.standard_normal((7, 6))


def test_thin_q_is_numpys_reduced_qr() -> None:
    rng = np.random.default_rng(11)
    for A in _matrices(rng):
        want = np.linalg.qr(A)[0]
        got = thin_q(A)
        assert got.shape == want.shape
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)  # orthonormal columns: unit scale


def test_right_singular_is_numpys_svd_without_u() -> None:
    rng = np.random.default_rng(12)
    for A in _matrices(rng):
        _, s_want, vt_want = np.linalg.svd(A, full_matrices=False)
        s, vt = right_singular(A)
        assert s.shape == s_want.shape and vt.shape == vt_want.shape
        np.testing.assert_allclose(s, s_want, rtol=0, atol=1e-12 * s_want.max(initial=0.0))
        # the vectors of singular values above rounding: the null space of a rank-deficient matrix is any basis
        big = s_want > 1e-10 * s_want.max(initial=0.0)
        np.testing.assert_allclose(vt[big], vt_want[big], rtol=0, atol=1e-12)
    assert right_singular(np.zeros((5, 0)))[0].shape == (0,)


def test_pinv_rank_is_numpys_pinv_and_matrix_rank() -> None:
    rng = np.random.default_rng(13)
    cases = [rng.standard_normal((int(rng.integers(1, 200)), int(rng.integers(1, 30)))) for _ in range(60)]
    B = rng.standard_normal((120, 5))
    cases += [np.column_stack([B, B @ rng.standard_normal((5, 3))]), np.zeros((4, 3)), np.diag([1.0, 1e-20, 0.0])]
    for A in cases:
        pinv, rank = pinv_rank(A)
        np.testing.assert_array_equal(pinv, np.linalg.pinv(A))  # numpy's arithmetic on numpy's SVD: the same bits
        assert rank == np.linalg.matrix_rank(A)


def _scaled_regressor(rng: np.random.Generator, n: int, p: int, cond: float) -> np.ndarray:
    """Unit-norm columns whose condition number is about ``cond`` (two columns made nearly collinear)."""
    X = rng.standard_normal((n, p))
    X[:, 1] = X[:, 0] + X[:, 1] * (2.0 / cond)
    return X / np.linalg.norm(X, axis=0)


def test_ls_from_the_gram_matrix_is_lstsq_when_well_conditioned() -> None:
    """_solve's LS from the eigendecomposition of its Gram matrix: lstsq's solution to 1e-12 up to the condition
    number it is used at, and lstsq itself (the same bits) above it or for several sample sets alike."""
    rng = np.random.default_rng(14)
    seen = []
    for k in range(40):
        p = int(rng.integers(2, 6))
        Xs = [_scaled_regressor(rng, int(rng.integers(200, 3000)), p, float(rng.uniform(1.0, 3 * NORMAL_MAX_CONDITION)))
              for _ in range(1 + k % 2)]
        scale = np.sqrt(sum(np.einsum("ij,ij->j", X, X) for X in Xs))
        Xs = [X / scale for X in Xs]
        ys = [X @ rng.standard_normal(p) * 10.0 ** rng.uniform(-3, 3) + rng.standard_normal(len(X)) for X in Xs]
        eig, V = np.linalg.eigh(sum(X.T @ X for X in Xs))
        cond = float(np.sqrt(eig[-1] / eig[0]))
        want = np.linalg.lstsq(np.vstack(Xs), np.concatenate(ys), rcond=None)[0]
        got = ls_theta(Xs, ys, eig, V, cond)
        if cond > NORMAL_MAX_CONDITION:
            np.testing.assert_array_equal(got, want)
        else:
            np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * np.linalg.norm(want))
        seen.append(cond <= NORMAL_MAX_CONDITION)
    assert 10 < sum(seen) < 35  # both branches exercised


def test_line_fit_is_lstsq_and_pinv_of_the_two_column_regressor() -> None:
    """validation.residue_test's window regression ``means ~ a levels + b``: lstsq's coefficients and residue and
    pinv(X^T X) to 1e-12, levels around zero or away from it (cond(X) up to ~200); a constant level goes to lstsq
    and pinv themselves."""
    rng = np.random.default_rng(15)
    for k in range(60):
        n = int(rng.integers(8, 400))
        spread = 10.0 ** rng.uniform(-3, 3)  # a sensor's window levels: their mean up to 100 times their spread
        x = rng.standard_normal(n) * spread + (spread * 10.0 ** rng.uniform(-2, 2) if k % 2 else 0.0)
        y = 10.0 ** rng.uniform(-4, 1) * x + rng.standard_normal(n) * 10.0 ** rng.uniform(-6, 0) + rng.uniform(-1, 1)
        X = np.column_stack([x, np.ones(n)])
        coef, resid, gram_inv = line_fit(x, y)
        want = np.linalg.lstsq(X, y, rcond=None)[0]
        np.testing.assert_allclose(coef, want, rtol=1e-12, atol=1e-12 * np.abs(y).max())
        np.testing.assert_allclose(resid, y - X @ want, rtol=0, atol=1e-12 * np.abs(y).max())
        # (X^T X)^-1 exactly (rational arithmetic on the same floats): pinv(X^T X) itself errs by cond(X)^2 eps,
        # 1e-11 where the levels are far from zero against their spread; the closed form is within 1e-12
        sxx, sx = sum(Fraction(v) ** 2 for v in x), sum(Fraction(v) for v in x)
        det = n * sxx - sx * sx
        exact = np.array([[float(n / det), float(-sx / det)], [float(-sx / det), float(sxx / det)]])
        np.testing.assert_allclose(gram_inv, exact, rtol=1e-12, atol=0)
        if np.linalg.cond(X) < 1e2:
            np.testing.assert_allclose(gram_inv, np.linalg.pinv(X.T @ X), rtol=1e-12, atol=0)
    x = np.full(20, 3.0)
    coef, resid, gram_inv = line_fit(x, np.arange(20.0))
    X = np.column_stack([x, np.ones(20)])
    np.testing.assert_array_equal(coef, np.linalg.lstsq(X, np.arange(20.0), rcond=None)[0])
    np.testing.assert_array_equal(gram_inv, np.linalg.pinv(X.T @ X))


def test_lstsq_of_unscaled_columns_is_numpys() -> None:
    """linear_fit.lstsq (the model check's residue less its nuisance part): numpy's lstsq to 1e-12 on columns of
    any scale, the same bits where the unit-norm columns' condition number is above NORMAL_MAX_CONDITION."""
    rng = np.random.default_rng(16)
    for k in range(30):
        p = int(rng.integers(2, 7))
        A = _scaled_regressor(rng, int(rng.integers(100, 3000)), p, float(rng.uniform(1.0, 3 * NORMAL_MAX_CONDITION)))
        A = A * 10.0 ** rng.uniform(-4, 4, p)
        b = A @ rng.standard_normal(p) + rng.standard_normal(len(A))
        want = np.linalg.lstsq(A, b, rcond=None)[0]
        np.testing.assert_allclose(A @ lstsq(A, b), A @ want, rtol=0, atol=1e-12 * np.linalg.norm(A @ want))
        np.testing.assert_allclose(lstsq(A, b), want, rtol=1e-12 * NORMAL_MAX_CONDITION)
    A = np.column_stack([np.ones(50), np.zeros(50)])  # a zero column: numpy's minimum-norm answer
    np.testing.assert_array_equal(lstsq(A, np.arange(50.0)), np.linalg.lstsq(A, np.arange(50.0), rcond=None)[0])


def test_the_spline_without_its_c_loops_is_the_same(monkeypatch) -> None:
    """simulation._spline in C (estimator.spline_c) and in numpy: the same bits, both scipy's CubicSpline's
    (tests/estimator/test_speed.py compares the C path with scipy)."""
    from feeddrive.estimator import simulation, spline_c

    rng = np.random.default_rng(17)
    x = np.arange(0, 2901, 2.0)
    x[-1] -= 1.0
    Y = np.cumsum(rng.standard_normal((2, x.size)), axis=1)
    at = np.arange(x[-1] + 1) + 1 / 6
    compiled = simulation._spline(x, Y, at)
    assert spline_c.available()
    monkeypatch.setenv("FEEDDRIVE_NO_COMPILED_SPLINE", "1")
    spline_c._library.cache_clear()
    try:
        assert not spline_c.available()
        np.testing.assert_array_equal(simulation._spline(x, Y, at), compiled)
    finally:
        monkeypatch.delenv("FEEDDRIVE_NO_COMPILED_SPLINE")
        spline_c._library.cache_clear()


def test_block_sums_in_c_are_numpys_middle_axis_sums(monkeypatch) -> None:
    """estimator.blocks_c.row_block_sums against ``x[:nb * block].reshape(nb, block, p).sum(axis=1)``: the same bits
    (the batch-means covariance and the residue tests' block means), for the scores' shapes, a remainder left out,
    a block of -0.0 (numpy starts from +0), one column (numpy's pairwise sum: left to numpy), a column slice, and
    the numpy path without the C loop."""
    from feeddrive.estimator import blocks_c

    rng = np.random.default_rng(23)
    cases = [(11426, 3, 167), (5712, 3, 83), (7003, 5, 13), (9, 2, 10), (400, 1, 7), (50, 4, 1)]
    arrays = [(rng.standard_normal((n, p)) * np.exp(3 * rng.standard_normal((n, p))), b) for n, p, b in cases]
    arrays.append((np.where(np.arange(12)[:, None] < 6, -0.0, np.ones((12, 2))), 3))
    arrays.append((rng.standard_normal((300, 6))[:, ::2], 10))  # not contiguous
    assert blocks_c.available()
    for x, b in arrays:
        nb = x.shape[0] // b
        want = x[:nb * b].reshape(nb, b, x.shape[1]).sum(axis=1)
        got = blocks_c.row_block_sums(x, b)
        assert got.shape == want.shape
        np.testing.assert_array_equal(got.view(np.int64), want.view(np.int64))  # -0.0 told from +0.0
    monkeypatch.setenv("FEEDDRIVE_NO_COMPILED_BLOCKS", "1")
    blocks_c._library.cache_clear()
    try:
        assert not blocks_c.available()
        x, b = arrays[0]
        np.testing.assert_array_equal(blocks_c.row_block_sums(x, b), x[:11356].reshape(68, b, 3).sum(axis=1))
    finally:
        monkeypatch.delenv("FEEDDRIVE_NO_COMPILED_BLOCKS")
        blocks_c._library.cache_clear()


def test_rows_transformed_together_are_the_rows_transformed_alone() -> None:
    """kernels.toeplitz_score_covariance transforms the residue and the instruments in one ``rfft`` call: each row
    of a batch has the bits of its own transform (pocketfft pairs rows in the lanes of a vector, the same
    operations), for the tool change's lengths (LS and the IV halves) and 1 to 5 rows."""
    from scipy.fft import rfft

    rng = np.random.default_rng(29)
    for n, nfft in ((11426, 11664), (5712, 5832), (901, 960)):
        for rows in range(1, 6):
            X = rng.standard_normal((rows, n)) * np.logspace(0, 6, rows)[:, None]
            together = rfft(X, nfft, axis=-1)
            for r in range(rows):
                np.testing.assert_array_equal(together[r], rfft(X[r], nfft))
            padded = np.zeros((rows, nfft))  # the kernels' rows written into their zero padding: rfft's own padding
            padded[:, :n] = X
            np.testing.assert_array_equal(rfft(padded, axis=-1), together)


def test_score_covariance_of_the_sets_together_is_each_set_alone() -> None:
    """toeplitz.score_covariance_sum transforms the IV halves' residues, instruments and kernels together: the same
    bits as toeplitz_score_covariance of each half added in turn (halves one sample apart in length, unused rows
    zero, a set of another transform length, one set alone), and the time-domain sum W^T Gamma W to rounding."""
    from feeddrive.estimator.kernels import toeplitz_score_covariance
    from feeddrive.estimator.toeplitz import score_covariance_sum

    rng = np.random.default_rng(31)

    def part(n: int, unused: slice | None = None) -> tuple[np.ndarray, np.ndarray]:
        W, e = rng.standard_normal((n, 3)) * [1.0, 1e3, 1e-2], rng.standard_normal(n)
        if unused is not None:
            W[unused], e[unused] = 0.0, 0.0
        return W, e

    cases = [[part(5712), part(5713)], [part(5712, slice(2000, 2600)), part(5713, slice(100, 900))],
             [part(901), part(2400)], [part(1200)]]
    for parts in cases:
        alone = np.zeros((3, 3))
        for W, e in parts:
            alone += toeplitz_score_covariance(W, e, 83)
        np.testing.assert_array_equal(score_covariance_sum(parts, 83), alone)
    W, e = part(700, slice(300, 350))
    lags = 25
    used = (e != 0).astype(float)
    gamma = [float(e[: e.size - k] @ e[k:]) / float(used[: e.size - k] @ used[k:]) for k in range(lags + 1)]
    lag = np.abs(np.subtract.outer(np.arange(e.size), np.arange(e.size)))
    Gamma = np.where(lag <= lags, np.take(gamma + [0.0], np.minimum(lag, lags + 1)), 0.0)
    np.testing.assert_allclose(score_covariance_sum([(W, e), (W, e)], lags), 2 * W.T @ Gamma @ W, rtol=1e-11,
                               atol=1e-11 * np.abs(W.T @ Gamma @ W).max())


def test_column_by_column_scaling_is_numpys_broadcast() -> None:
    """estimator.columnwise: X / s and X * v[:, None] column by column on C-ordered (n, k) arrays, the same bits
    and a C-ordered result; other arrays (F order, one column, wide, short, a scale of another shape) go to
    numpy."""
    from feeddrive.estimator.columnwise import divide_columns, multiply_rows

    rng = np.random.default_rng(41)
    for X in (rng.standard_normal((5713, 3)) * [1.0, 1e3, 1e-2], np.asfortranarray(rng.standard_normal((500, 4))),
              rng.standard_normal((300, 1)), rng.standard_normal((40, 30)), rng.standard_normal((2000, 4))[::2],
              rng.standard_normal((100, 3))):  # the last: too short, numpy's
        s, v = rng.uniform(0.5, 2.0, X.shape[1]), rng.standard_normal(X.shape[0])
        for fast, ref in ((divide_columns(X, s), X / s), (multiply_rows(X, v), X * v[:, None])):
            np.testing.assert_array_equal(fast, ref)
            assert fast.flags.c_contiguous == ref.flags.c_contiguous
    X = rng.standard_normal((600, 3))
    np.testing.assert_array_equal(divide_columns(X, np.array([2.0])), X / 2.0)  # a broadcast scale: numpy's
    with np.errstate(divide="ignore"):  # a zero scale: the same signed infinities
        np.testing.assert_array_equal(divide_columns(X, np.array([1.0, 0.0, -0.0])), X / np.array([1.0, 0.0, -0.0]))
