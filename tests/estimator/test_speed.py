"""The fast kernels of the per-motion path (issue 26) against the straightforward computations they replace.

Timing is never asserted here (benchmarks/bench_monitor.py and bench_estimator.py measure it); these
tests pin the results: identical booleans, the same floats to the last bit where the arithmetic is the
same, within 1e-12 relative where the summation order differs.
"""
from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy import ndimage, signal

from feeddrive.estimator import lti, simulation
from feeddrive.estimator.filtering import FilterSpec
from feeddrive.estimator.kernels import ar_order_bic, erode, label_runs, label_slices, toeplitz_score_covariance

PARAMS = {"R": 0.6, "L": 4e-3, "K": 1.05, "Jt": 0.1, "ft": 0.02, "Cd": 1.2}


@pytest.mark.parametrize("border", [True, False])
def test_erode_is_scipy_binary_erosion(border: bool) -> None:
    rng = np.random.default_rng(3)
    for _ in range(400):
        n, radius = int(rng.integers(1, 120)), int(rng.integers(0, 15))
        mask = rng.random(n) < rng.uniform(0.3, 1.0)
        iterated = ndimage.binary_erosion(mask, iterations=radius, border_value=border) if radius else mask
        window = ndimage.binary_erosion(mask, np.ones(2 * radius + 1, dtype=bool), border_value=border)
        np.testing.assert_array_equal(erode(mask, radius, border), iterated)
        np.testing.assert_array_equal(erode(mask, radius, border), window)


def test_run_labels_and_their_slices_are_scipy_label_and_find_objects() -> None:
    rng = np.random.default_rng(5)
    for _ in range(400):
        n = int(rng.integers(1, 120))
        mask = rng.random(n) < rng.uniform(0.0, 1.0)
        labels, count = label_runs(mask)
        want, want_count = ndimage.label(mask)
        assert labels.dtype == want.dtype and count == want_count
        np.testing.assert_array_equal(labels, want)
        assert label_slices(labels) == ndimage.find_objects(want)
        holes = np.where(np.isin(labels, [1, 3]), 0, labels)  # absent labels and bounding boxes of any labels
        scattered = np.where(rng.random(n) < 0.5, holes, holes[::-1])
        assert label_slices(scattered) == ndimage.find_objects(scattered)
    assert label_runs(np.zeros(0, bool))[1] == 0 and label_slices(np.zeros(0, np.int32)) == []


def test_filter_in_one_call_is_one_call_per_signal() -> None:
    """The signals of one length filtered as one 2-D array: bit for bit the 1-D sosfiltfilt of each."""
    rng = np.random.default_rng(4)
    h, spec = 1e-4, FilterSpec(100.0, 4)
    raw = {"u": rng.standard_normal(5000), "i": np.cumsum(rng.standard_normal(5000)), "w": None,
           "short": rng.standard_normal(700)}
    out = spec.apply(raw, h)
    sos = signal.butter(4, 100.0, fs=1 / h, output="sos")
    assert list(out) == list(raw) and out["w"] is None
    for k in ("u", "i", "short"):
        np.testing.assert_array_equal(out[k], lti.sosfiltfilt(sos, raw[k]))
        # estimator.lti replaces scipy.signal on the run path (tests/estimator/test_lti.py): its numbers
        np.testing.assert_allclose(out[k], signal.sosfiltfilt(sos, raw[k]), rtol=0,
                                   atol=1e-12 * np.max(np.abs(out[k])))
    np.testing.assert_array_equal(spec.sos(h), sos)


def _ar(rng: np.random.Generator, n: int, coefs: list[float]) -> np.ndarray:
    x = np.zeros(n + 100)
    e = rng.standard_normal(n + 100)
    for t in range(n + 100):
        x[t] = e[t] + sum(a * x[t - 1 - j] for j, a in enumerate(coefs) if t - 1 - j >= 0)
    return x[100:]


def test_ar_order_is_statsmodels_bic_choice() -> None:
    from statsmodels.tsa.ar_model import ar_select_order

    rng = np.random.default_rng(5)
    cases = [_ar(rng, int(rng.integers(40, 600)), list(rng.uniform(-0.8, 0.8, int(rng.integers(0, 4)))))
             for _ in range(60)]
    cases += [np.cumsum(_ar(rng, 300, [0.5])), np.r_[np.ones(30), np.zeros(30)]]  # near unit root; degenerate
    chosen = []
    for x in cases:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            lags = ar_select_order(x, maxlag=12, ic="bic", trend="n").ar_lags
            mine = ar_order_bic(x, 12)
        assert mine == (max(lags) if lags else 0)
        chosen.append(mine)
    assert len(set(chosen)) >= 3  # the cases exercise several orders, not only 0


def test_toeplitz_score_covariance_is_the_time_domain_sum() -> None:
    """``W^T Gamma W`` with Gamma the Toeplitz matrix of the used pairs' mean lagged products."""
    rng = np.random.default_rng(6)
    n, p, lags = 900, 3, 40
    e = np.convolve(rng.standard_normal(n), np.ones(15) / 15, mode="same")
    W = rng.standard_normal((n, p)) * [1.0, 1e3, 1e-3]
    for used_all in (True, False):
        if not used_all:
            e[100:180] = 0.0
            W[100:180] = 0.0
        used = e != 0
        gamma = np.array([e[:n - k] @ e[k:] / max((used[:n - k] & used[k:]).sum(), 1) for k in range(lags + 1)])
        lag = np.abs(np.subtract.outer(np.arange(n), np.arange(n)))
        Gamma = np.where(lag <= lags, gamma[np.minimum(lag, lags)], 0.0)
        direct = W.T @ Gamma @ W
        fast = toeplitz_score_covariance(W, e, lags)
        scale = np.sqrt(np.outer(np.diag(direct), np.diag(direct)))
        assert np.max(np.abs(fast - direct) / scale) < 1e-12


@pytest.mark.parametrize("equations, inputs, x0, step", [
    (("electrical",), ("u", "w"), {"i": 0.1}, None),
    (("mechanical",), ("i",), {"w": 2.0}, 6e-4),
    (("electrical", "mechanical"), ("u",), {"i": 0.0, "w": 0.0}, 6e-4),
])
def test_compiled_rollout_is_casadi_mapaccum(monkeypatch: pytest.MonkeyPatch, equations, inputs, x0, step) -> None:
    """The RK4 rollout compiled from CasADi's generated C gives CasADi's own numbers, bit for bit."""
    rng = np.random.default_rng(7)
    n = 2000
    signals = {"u": 20 * np.sin(np.arange(n) * 3e-3) + rng.standard_normal(n),
               "w": 10 * np.sin(np.arange(n) * 3e-3), "i": 5 * np.sign(np.sin(np.arange(n) * 2e-3)) + 0.1}
    given = {k: signals[k] for k in inputs}
    simulation._step.cache_clear()
    assert simulation._step(simulation.MODEL, equations, tuple(sorted(inputs)), 2 if step else 1)[1] is not None, \
        "the C compiler could not build the rollout"
    compiled = simulation.simulate(equations, given, PARAMS, 1e-4, x0, step)
    monkeypatch.setenv("FEEDDRIVE_NO_COMPILED_ROLLOUT", "1")
    simulation._step.cache_clear()
    try:
        reference = simulation.simulate(equations, given, PARAMS, 1e-4, x0, step)
    finally:
        simulation._step.cache_clear()
    for k in reference:
        assert np.all(np.isfinite(reference[k]))
        np.testing.assert_array_equal(compiled[k], reference[k])


def test_filtered_signals_are_reused_only_for_the_same_values() -> None:
    """A second stage filtering the same values (another array object) gets the first result; an array
    changed in place since is filtered again."""
    from feeddrive.estimator.filtering import clear_filter_memo

    rng = np.random.default_rng(8)
    h, spec = 1e-4, FilterSpec(100.0, 4)
    sos = signal.butter(4, 100.0, fs=1 / h, output="sos")
    clear_filter_memo()
    x = rng.standard_normal(3000)
    first = spec.apply({"x": x}, h)["x"]
    again = spec.apply({"y": x.copy()}, h)["y"]
    assert again is first and not first.flags.writeable  # shared, so read-only
    x[1] += 1.0  # the key's samples (first, middle, last) unchanged, the values not
    changed = spec.apply({"x": x}, h)["x"]
    np.testing.assert_array_equal(changed, lti.sosfiltfilt(sos, x))
    assert not np.array_equal(changed, first)


def test_validation_passes_on_its_signals_filtered() -> None:
    """The signals measurement validation passes on (the mean of two sensors) are given to the estimator's
    filter as the same mean of the sensors' filtered rows: within 1e-12 of filtering the mean again (F is
    linear; only the rounding of one addition differs), and a mean changed since is filtered again."""
    from feeddrive.estimator.filtering import clear_filter_memo, share_filtered
    from feeddrive.estimator.validation import validate_measurements

    rng = np.random.default_rng(11)
    h, spec = 1e-4, FilterSpec(100.0, 4)
    t = np.arange(8000) * h
    w = 70.0 * np.sin(2 * np.pi * t / 0.8)
    i = 2.0 * np.cos(2 * np.pi * t / 0.8)
    u = 0.6 * i + 1.05 * w
    noisy = {k: x + s * rng.standard_normal(t.size) for k, x, s in (("Im1", i, 0.05), ("Im2", i, 0.05), ("u", u, 0.2),
                                                                     ("u_ref", u, 0.2), ("w_tach", w, 0.05),
                                                                     ("w_enc", w, 0.05))}
    clear_filter_memo()
    v = validate_measurements(noisy, h, {"R": 0.6, "L": 4e-3, "K": 1.05}, spec)
    shared = spec.apply({"u": v.u, "i": v.i, "w": v.w}, h)
    assert all(p.residue.kind == "none" for p in v.pairs.values())  # healthy sensors: each passes on the mean
    for k, x, (s1, s2) in (("u", v.u, ("u", "u_ref")), ("i", v.i, ("Im1", "Im2")), ("w", v.w, ("w_tach", "w_enc"))):
        pair = lti.sosfiltfilt(spec.sos(h), np.vstack([noisy[s1], noisy[s2]]))
        np.testing.assert_array_equal(shared[k], 0.5 * (pair[0] + pair[1]))  # not filtered again
        direct = lti.sosfiltfilt(spec.sos(h), x)
        assert not shared[k].flags.writeable
        np.testing.assert_allclose(shared[k], direct, rtol=0, atol=1e-12 * np.max(np.abs(direct)))
    # the means are validation's own arrays: kept in the memo themselves (no copy), so read-only for everyone
    from feeddrive.estimator.filtering import _MEMO
    assert any(kept is v.u for kept, _ in _MEMO.values())
    with pytest.raises(ValueError, match="read-only"):
        v.u[5] += 1.0  # a change behind the memo's back is refused, never a stale filtered signal
    x = v.u.copy()
    x[5] += 1.0  # not the values shared: filtered afresh
    np.testing.assert_array_equal(spec.apply({"u": x}, h)["u"], lti.sosfiltfilt(spec.sos(h), x))
    share_filtered(FilterSpec(100.0, 4, zero_phase=False), h, x, np.zeros_like(x))  # a causal filter: not shared
    assert not np.array_equal(FilterSpec(100.0, 4, zero_phase=False).apply({"u": x}, h)["u"], 0.0)
    clear_filter_memo()


@pytest.mark.parametrize("kind", ["dc", "pmsm", "pmsm-spm"])
def test_model_facts_kept_per_model_are_the_derived_ones(kind: str) -> None:
    """The estimator's per-model facts (kernels: measured signals, each equation's parameters and residual
    symbols) are those derived from the equations, for every drive kind and a changed design."""
    import casadi as ca

    from feeddrive.estimator import kernels
    from feeddrive.estimator.model_terms import owners
    from feeddrive.estimator.regression import equation_parameters, equation_residual
    from feeddrive.models.drives import drive_model, measured, with_design

    base = drive_model(kind)
    models = [base] + ([with_design(base, {"p": 4})] if kind != "dc" else [])
    for model in models:
        assert kernels.measured_signals(model) == measured(model)
        assert owners(model) is not owners(model)  # a new dict each call: callers may change theirs
        for eq in model.equations:
            assert kernels.equation_parameters_of(model, eq) == equation_parameters(model, eq)
            assert kernels.residual_symbols(model, eq) == {x.name() for x in ca.symvar(equation_residual(model, eq))}
    expected = {"dc": ("i", "w", "u"), "pmsm": ("i_q", "i_d", "w", "u_d", "u_q")}
    assert kernels.measured_signals(base) == expected.get(kind, expected["pmsm"])


def test_column_norms_are_numpy_norms() -> None:
    from feeddrive.estimator.kernels import column_norms, nonzero_norms

    rng = np.random.default_rng(9)
    A = rng.standard_normal((5000, 6)) * [1.0, 1e-8, 1e8, 3.0, 0.0, 1.0]
    ref = np.linalg.norm(A, axis=0)
    np.testing.assert_allclose(column_norms(A), ref, rtol=1e-14, atol=0)
    np.testing.assert_allclose(nonzero_norms(A), np.where(ref > 0, ref, 1.0), rtol=1e-14, atol=0)


def test_block_iv_is_the_stacked_iv() -> None:
    """The lack-of-fit test's IV from the blocks' products equals the IV of the stacked matrices (pinv of
    ``Vs^T Ws``, batch-means covariance over k blocks), a single block bit for bit."""
    from feeddrive.estimator.kernels import block_iv, block_sums

    rng = np.random.default_rng(10)
    n, k = 7001, 30
    X = rng.standard_normal((n, 3))
    Z = X + 0.3 * rng.standard_normal((n, 3))
    B = rng.standard_normal((n, 4)) @ rng.standard_normal((4, 4))
    y = X @ [1.0, -2.0, 0.5] + B @ [0.1, 0.0, -0.3, 0.2] + np.convolve(rng.standard_normal(n), np.ones(9), "same")

    def stacked(W: np.ndarray, V: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        M = np.linalg.pinv(V.T @ W)
        beta = M @ (V.T @ y)
        G = block_sums(V * (y - W @ beta)[:, None], k)
        return beta, M @ (G.T @ G) @ M.T

    for fast, ref in ((block_iv(y, [X], [Z], k), stacked(X, Z)),):
        np.testing.assert_array_equal(fast[0], ref[0])
        np.testing.assert_array_equal(fast[1], ref[1])
    fast = block_iv(y, [X, B], [Z, B], k)
    ref = stacked(np.column_stack([X, B]), np.column_stack([Z, B]))
    np.testing.assert_allclose(fast[0], ref[0], rtol=1e-12, atol=0)
    np.testing.assert_allclose(fast[1], ref[1], rtol=1e-11, atol=1e-12 * np.abs(ref[1]).max())
    assert block_sums(np.arange(10.0), 3).tolist() == [3.0, 12.0, 30.0]  # 10 rows in blocks of 3, 3, 4


def test_noise_std_is_scipy_mad() -> None:
    from scipy import special, stats

    from feeddrive.estimator.validation import NORMAL_MAD, noise_std

    assert NORMAL_MAD == special.ndtri(0.75)
    rng = np.random.default_rng(11)
    for n in (2, 3, 10, 1001, 34879):
        x = np.cumsum(rng.standard_normal(n)) * 1e-3 + rng.standard_normal(n)
        assert noise_std(x) == float(stats.median_abs_deviation(np.diff(x), scale="normal") / np.sqrt(2.0))
    assert np.isnan(noise_std(np.array([0.0, np.nan, 1.0, 2.0])))
    for n in (4, 5, 1001):  # one NaN or many, anywhere: NaN (numpy's median), read from the selection's upper part
        for k in (1, 3, n // 2 + 1):
            x = rng.standard_normal(n)
            x[rng.choice(n, k, replace=False)] = np.nan
            assert np.isnan(noise_std(x))
    x = np.round(rng.standard_normal(2000), 1)  # many equal differences: the two middle ranks tied or not
    assert noise_std(x) == float(stats.median_abs_deviation(np.diff(x), scale="normal") / np.sqrt(2.0))


def test_the_speed_noise_and_the_peak_test_keep_numpys_medians() -> None:
    """speed_noise and peak_test select their medians in place (estimator/medians.py): np.median's bits."""
    from feeddrive.estimator.medians import mad_in_place, median_in_place
    from feeddrive.estimator.residue_tests import peak_test
    from feeddrive.estimator.segmentation import speed_noise

    rng = np.random.default_rng(12)
    for n in (2, 3, 10, 1001, 34879):
        for x in (rng.standard_normal(n), np.round(rng.standard_normal(n), 1)):  # ties at the middle ranks or not
            assert median_in_place(x.copy()) == np.median(x)
            assert mad_in_place(x.copy()) == np.median(np.abs(x - np.median(x)))
            w = np.cumsum(x)
            d2 = w[2:] - 2.0 * w[1:-1] + w[:-2]
            if d2.size:
                assert speed_noise(w) == float(1.4826 * np.median(np.abs(d2 - np.median(d2))) / np.sqrt(6.0))
    y = rng.standard_normal(500)
    y[7] += 8.0  # a peak: d.max() read from the reordered deviations
    kept = y.copy()
    z = peak_test(y, np.empty((500, 0)), [500]).statistic
    assert np.array_equal(y, kept)  # the caller's residue is not reordered
    assert z == float(np.abs(y - np.median(y)).max() / (1.4826 * float(np.median(np.abs(y - np.median(y))))))
    w = np.cumsum(rng.standard_normal(1000))
    w[[3, 500]] = np.nan, np.inf  # non-finite samples left out (a gathered copy only then)
    assert speed_noise(w) == speed_noise(w[np.isfinite(w)]) > 0
    w = np.array([0.0, 1e308, -1e308, 1e308, 0.0, 1.0])  # second differences overflow: numpy's median and NaN rule
    with np.errstate(over="ignore", invalid="ignore"):
        d2 = w[2:] - 2.0 * w[1:-1] + w[:-2]
        np.testing.assert_equal(speed_noise(w), float(1.4826 * np.median(np.abs(d2 - np.median(d2))) / np.sqrt(6.0)))


def test_percentiles_selected_in_place_are_numpys() -> None:
    """medians.percentiles_in_place (partial's speed spread): np.percentile's bits (method "linear") for two
    percentiles, sizes 2 to thousands, ties, equal percentiles and the ends."""
    from feeddrive.estimator.medians import percentiles_in_place

    rng = np.random.default_rng(13)
    for n in (2, 3, 4, 7, 20, 101, 1000, 11426):
        for x in (np.abs(rng.standard_normal(n)) * 1e3, np.round(np.abs(rng.standard_normal(n)), 1)):
            for q in ((5, 95), (0, 100), (50, 50), (25, 75), (99.9, 100)):
                np.testing.assert_array_equal(percentiles_in_place(x.copy(), q), np.percentile(x, q))


def test_simulated_segments_are_nan_exactly_between_them() -> None:
    """mismatch.simulate_segments writes NaN between its segments only: np.full(n, nan) with the segments' Tustin
    responses written over it, bit for bit (segments at the ends and in the middle)."""
    from feeddrive.estimator import lti
    from feeddrive.estimator.kernels import bilinear_first_order
    from feeddrive.estimator.mismatch import simulate_segments

    rng = np.random.default_rng(17)
    n, h = 900, 1e-3
    i, w = rng.standard_normal(n), np.abs(rng.standard_normal(n)) + 1.0
    p = {"K": 0.2, "Jt": 1e-3, "ft": 2e-3, "Cd": 0.01}
    for runs in (((0, 200), (350, 600)), ((10, 300), (300, 500), (700, 900))):
        labels = np.zeros(n, dtype=int)
        for k, (a, b) in enumerate(runs, 1):
            labels[a:b] = k
        ref = np.full(n, np.nan)
        bb, aa = bilinear_first_order(p["Jt"], p["ft"], h)
        for a, b in runs:
            drive = p["K"] * i[a:b] - p["Cd"] * np.sign(w[a]) - 0.0
            ref[a:b] = lti.lfilter(bb, aa, drive, zi=[w[a] - bb[0] * drive[0]])[0]
        np.testing.assert_array_equal(simulate_segments(i, w, labels, p, h), ref)


def test_an_eroded_mask_is_within_the_mask() -> None:
    """estimate.prepare counts the sign guard's samples as fast - used (no fast & ~r array): r is within
    erode(fast), which is within fast, for any radius and border."""
    from feeddrive.estimator.kernels import erode

    rng = np.random.default_rng(19)
    for radius in (0, 1, 5, 40):
        for border in (False, True):
            fast = rng.random(3000) < 0.8
            r = (rng.random(3000) < 0.9) & erode(fast, radius, border=border)
            assert np.count_nonzero(fast & ~r) == fast.size - (fast.size - np.count_nonzero(fast)) - np.count_nonzero(r)


def test_free_responses_are_the_powers_of_the_pole_per_segment() -> None:
    """mismatch.free_responses writes pole ** k (float exponents) into its columns: np.column_stack of the
    columns pole ** np.arange(length) (int exponents) zero outside each segment, bit for bit."""
    from feeddrive.estimator.kernels import bilinear_first_order
    from feeddrive.estimator.mismatch import free_responses

    labels = np.zeros(3000, dtype=int)
    labels[10:1200], labels[1500:2999] = 1, 2
    params, h = {"Jt": 1.2e-4, "ft": 2e-3}, 1e-3
    pole = -float(np.ravel(bilinear_first_order(params["Jt"], params["ft"], h)[1])[1])
    cols = []
    for a, b in ((10, 1200), (1500, 2999)):
        col = np.zeros(labels.size)
        col[a:b] = pole ** np.arange(b - a)
        cols.append(col)
    np.testing.assert_array_equal(free_responses(labels, params, h), np.column_stack(cols))
    assert free_responses(np.zeros(5, dtype=int), params, h).shape == (5, 0)


@pytest.mark.parametrize("step", [1, 2, 3])
def test_model_check_upsampling_is_np_interp(step: int) -> None:
    from feeddrive.estimator.mismatch import _upsample

    rng = np.random.default_rng(step)
    for n in (7, 8, 1001):
        y = rng.standard_normal(len(range(0, n, step)))
        y[1] = np.nan  # the residue is NaN where it is not tested
        ref = np.interp(np.arange(n), np.arange(0, n, step), y)
        np.testing.assert_array_equal(_upsample(y, step, n), ref)


def test_last_columns_f_test_is_statsmodels_f_test() -> None:
    """The residue tests' F test of the last q coefficients: statsmodels' f_test bit for bit, for OLS and
    GLSAR fits and a rank-deficient covariance block."""
    from statsmodels.regression.linear_model import GLSAR, OLS

    from feeddrive.estimator.kernels import last_columns_f_test

    rng = np.random.default_rng(12)
    n = 300
    X = rng.standard_normal((n, 7))
    y = X @ [0.5, 1.0, 0.0, 0.0, 0.1, 0.0, 0.02] + np.convolve(rng.standard_normal(n), [1, 0.6], "same")
    collinear = np.column_stack([X, X[:, -1]])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # statsmodels' warnings on the rank-deficient design, wanted here
        cases = ((OLS(y, X).fit(), 4), (OLS(y, X).fit(), 1), (GLSAR(y, X, rho=2).iterative_fit(maxiter=6), 3),
                 (OLS(y, collinear).fit(), 3))
        for fit, q in cases:
            R = np.zeros((q, fit.params.size))
            R[:, -q:] = np.eye(q)
            ref = fit.f_test(R)
            expected = (float(np.squeeze(ref.fvalue)), float(ref.df_num), float(ref.df_denom),
                        float(np.squeeze(ref.pvalue)))
            assert last_columns_f_test(fit, q) == expected
    assert last_columns_f_test(cases[-1][0], 3)[1] == 2.0  # the rank, as statsmodels


@pytest.mark.parametrize("lag", [1, 40, 400])
def test_adequacy_rows_read_lagged_terms_as_np_roll(lag: int) -> None:
    """check_adequacy reads its lagged terms on the tested rows only (``x[rows -+ lag]``): the rows that
    ``_rows`` keeps leave ``lag`` samples at both ends, so these are np.roll's values there, bit for bit."""
    from feeddrive.estimator.adequacy import _legendre, _rows

    rng = np.random.default_rng(13)
    n, h = 6000, 1e-4
    w = np.sin(np.linspace(0, 9, n)) + 0.01 * rng.standard_normal(n)
    x = rng.standard_normal(n)
    rows = _rows(w, h, 100.0, 0.03, lag)
    take = np.flatnonzero(rows)
    assert take.size > 100 and take[0] >= lag and take[-1] + lag < n
    rolled = 0.5 * (np.roll(x, lag) + np.roll(x, -lag))
    np.testing.assert_array_equal(0.5 * (x.take(take - lag) + x.take(take + lag)), rolled[rows])
    position = np.roll(np.cumsum(w), lag)
    lo, hi = position[rows].min(), position[rows].max()
    full = np.polynomial.legendre.legval(2 * (position - lo) / (hi - lo) - 1, [0, 0, 1])  # P2 over the rows' range
    np.testing.assert_array_equal(_legendre(np.cumsum(w).take(take - lag), range(2, 3))[:, 0], full[rows])


def test_simulation_spline_is_scipy_cubic_spline() -> None:
    from scipy.interpolate import CubicSpline

    rng = np.random.default_rng(3)
    for n in (4, 5, 9, 1450, 1451):
        x = np.arange(n) * 4.0
        x[-1] -= 1.0  # a shorter last step, as the simulation's last sample
        Y = np.cumsum(rng.standard_normal((2, n)), axis=1) * 1e3
        for at in (np.arange(x[-1] + 1) + 1 / 6, np.arange(x[-1] + 1) - 0.25, np.arange(x[-1] + 1),
                   rng.permutation(np.arange(x[-1] + 1)) + 0.5):  # sorted (knots counted among them) or not
            np.testing.assert_array_equal(simulation._spline(x, Y, at), CubicSpline(x, Y, axis=1)(at))
            # again on the same knots and times (the intervals kept from the call before), then on times changed
            # in place (found again)
            np.testing.assert_array_equal(simulation._spline(x, -0.5 * Y, at), CubicSpline(x, -0.5 * Y, axis=1)(at))
            at += 0.375
            np.testing.assert_array_equal(simulation._spline(x, Y, at), CubicSpline(x, Y, axis=1)(at))


def test_residue_segments_are_each_labels_samples() -> None:
    from feeddrive.estimator.residue_tests import _segments

    rng = np.random.default_rng(5)
    for groups in (np.repeat([1, 2, 4, 5], [30, 1, 200, 7]), np.ones(50, dtype=int), rng.integers(0, 4, 300)):
        expected = [np.flatnonzero(groups == g) for g in np.unique(groups)]
        got = _segments(groups)
        assert len(got) == len(expected)
        for a, b in zip(got, expected):
            np.testing.assert_array_equal(a, b)


def test_sosfilt_zi_kept_per_filter_is_not_shared() -> None:
    sos = FilterSpec(100.0).sos(1e-4)
    first = lti.sosfilt_zi(sos)
    np.testing.assert_array_equal(first, signal.sosfilt_zi(sos))
    first[:] = 0.0  # a caller's array of its own: the kept design is unchanged
    np.testing.assert_array_equal(lti.sosfilt_zi(sos), signal.sosfilt_zi(sos))
