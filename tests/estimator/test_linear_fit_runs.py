"""``linear_fit._solve`` copies the usable rows run by run (``_used_runs``) where it gathered them by index: the
same rows in the same (C) order, so the same fits bit for bit, LS and IV, on a motion whose sign guard leaves
several runs (the speed reversals of a round trip)."""
from __future__ import annotations

import numpy as np

from feeddrive.estimator import EstimationOptions, MotionData, estimate_motion, linear_fit
from feeddrive.estimator.design import simulate_closed_loop


def test_used_runs_are_the_true_rows():
    rng = np.random.default_rng(3)
    for n in (1, 2, 7, 500):
        for _ in range(20):
            r = rng.random(n) < rng.uniform(0.05, 0.95)
            r[rng.integers(0, n, size=3)] = rng.random(3) < 0.5
            runs = linear_fit._used_runs(r)
            idx = np.flatnonzero(r)
            if isinstance(runs, np.ndarray):  # more than MAX_RUNS runs: the indices themselves
                np.testing.assert_array_equal(runs, idx)
            else:
                np.testing.assert_array_equal(np.concatenate([np.arange(a, b) for a, b in runs] or [[]]), idx)


def test_fits_from_runs_are_the_fits_from_indices(monkeypatch):
    h = 1e-3
    t = np.arange(1600) * h
    sig = simulate_closed_loop(np.interp(t, [0, 0.05, 0.35, 0.6, 0.9, 1.0, 1.3, 1.59], [0, 0, 60, 60, 0, -60, -60, 0]), h)
    rng = np.random.default_rng(5)
    data = MotionData(h, **{k: sig[k] + rng.standard_normal(sig[k].size) * 0.01 * np.std(sig[k])
                            for k in ("u", "i", "w")})
    options = EstimationOptions(method="iv")
    runs = estimate_motion(data, options)
    monkeypatch.setattr(linear_fit, "MAX_RUNS", 0)  # every set of rows gathered by index, as before
    indices = estimate_motion(data, options)
    for mine, theirs in ((runs.ls, indices.ls), (runs.iv, indices.iv)):
        np.testing.assert_array_equal(mine.values, theirs.values)
        np.testing.assert_array_equal(mine.covariance, theirs.covariance)
    # physics: the noise-free model's parameters within their intervals
    truth = dict(zip(runs.iv.names, runs.iv.values))
    assert abs(truth["R"] - 0.6) < 0.05 * 0.6 + 3 * np.sqrt(runs.iv.covariance[0, 0])


def test_column_reference_is_the_norm_of_the_repeated_row():
    """``_column_reference``: the norm of n equal values taken as |value| sqrt(n), within 1e-14 of the n-sample
    norm it replaced (the row evaluated once and repeated n times), for both equations of a motion."""
    from feeddrive.estimator.estimate import prepare
    from feeddrive.estimator.model_terms import signals_for

    h = 1e-3
    t = np.arange(1600) * h
    sig = simulate_closed_loop(np.interp(t, [0, 0.05, 0.35, 0.6, 0.9, 1.0, 1.3, 1.59], [0, 0, 60, 60, 0, -60, -60, 0]), h)
    p = prepare(MotionData(h, u=sig["u"], i=sig["i"], w=sig["w"]), EstimationOptions())
    for reg in p.regressions:
        s = signals_for(p, reg)
        n = len(s["w"])
        proxy = {k: (1.0 if k == "sgn_w" else float(np.sqrt(np.mean(np.square(s[k[1:]] if k.startswith("D") else s[k]))))
                     / (n * p.h if k.startswith("D") else 1.0)) for k in reg.signals}
        y1, Phi1 = reg.evaluate({k: np.full(1, v) for k, v in proxy.items()})
        Phi = np.repeat(np.vstack([y1, Phi1.T]), n, axis=1)[1:].T
        np.testing.assert_allclose(linear_fit._column_reference(reg, s, p.h), np.sqrt(np.einsum("ij,ij->j", Phi, Phi)),
                                   rtol=1e-14)
