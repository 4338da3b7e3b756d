"""The stationary-error score covariance of several sample sets in one set of transforms.

``motion.stationary_score_covariance`` adds ``W^T Gamma W`` (:func:`kernels.toeplitz_score_covariance`) over the
independent sample sets of one fit: the IV halves, two sets of nearly the same length whose transforms have the
same length. Their residues and instruments go through one ``rfft`` call, their autocovariances through one
``irfft`` and their kernels through one ``rfft``: pocketfft takes the rows two at a time in the lanes of a vector,
each row with the bits of its own transform (tests/estimator/test_speed_linalg.py), so a lone row per set (the
residue's autocovariance, the kernel) no longer fills a pass alone. The same numbers as one call per set.
"""
from __future__ import annotations

import numpy as np

from feeddrive.estimator.kernels import toeplitz_score_covariance, used_pairs


def score_covariance_sum(parts: list[tuple[np.ndarray, np.ndarray]], lags: int) -> np.ndarray:
    """``sum_parts W^T Gamma W`` (not symmetrised), as ``toeplitz_score_covariance`` of each part added in turn.

    Parameters
    ----------
    parts : list of (W (n_k, p), e (n_k,))
        Instruments (or regressors) and equation errors of each sample set, unused rows zero in both.
    lags : int
        Largest lag kept [samples].

    Returns
    -------
    ndarray, shape (p, p)
    """
    from scipy.fft import irfft, next_fast_len, rfft

    p = parts[0][0].shape[1]
    S = np.zeros((p, p))
    ns = [len(e) for _, e in parts]
    m = min(lags, min(ns) - 1)
    nffts = {next_fast_len(n + m + 1, real=True) for n in ns}
    if len(parts) == 1 or len(nffts) > 1 or any(min(lags, n - 1) != m or n <= m for n in ns):
        for W, e in parts:  # one set, or sets whose transforms differ in length: each alone
            S += toeplitz_score_covariance(W, e, lags)
        return S
    nfft = nffts.pop()
    rows = 1 + p  # each set's residue, then its instruments' columns (toeplitz_score_covariance's order)
    # every set's rows zero-padded to nfft here (a shorter set's too), each value written once: rfft's own padding
    # copied X into zeros of that length (the same values)
    X = np.empty((len(parts) * rows, nfft))
    for k, (W, e) in enumerate(parts):
        X[k * rows, :e.size] = e
        X[k * rows + 1:(k + 1) * rows, :e.size] = W.T
        X[k * rows:(k + 1) * rows, e.size:] = 0.0  # the padding only
    F = rfft(X, axis=-1)
    fe = F[::rows]
    num = irfft(fe * np.conj(fe), nfft)[:, :m + 1]
    kernel = np.zeros((len(parts), nfft))
    for k, (_, e) in enumerate(parts):
        used = e != 0
        pairs = used_pairs(used, m)
        if pairs is None:
            fu = rfft(used.astype(float), nfft)
            pairs = np.rint(irfft(fu * np.conj(fu), nfft)[:m + 1])
        gamma = np.where(pairs > 0, num[k] / np.maximum(pairs, 1.0), 0.0)
        kernel[k, :m + 1] = gamma
        kernel[k, nfft - m:] = gamma[:0:-1]
    weight = rfft(kernel, axis=-1).real * 2.0  # symmetric kernels: each bin stands for +-k ...
    weight[:, 0] /= 2.0
    if nfft % 2 == 0:  # ... but the zero and Nyquist bins
        weight[:, -1] /= 2.0
    for k in range(len(parts)):
        FW = F[k * rows + 1:(k + 1) * rows]
        S += ((FW.conj() * weight[k]) @ FW.T).real / nfft
    return S
