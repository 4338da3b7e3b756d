"""The linear fit of one regression on one or more sample sets: LS or basic IV, column-scaled, with its
sandwich covariance (``_solve``), and the column scale a regressor would have (``_column_reference``).

Kept apart from :mod:`feeddrive.estimator.estimate` (which assembles the methods from it) so that the
per-parameter estimate (``estimator.partial``) shares the same arithmetic.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from feeddrive.estimator.columnwise import divide_columns, multiply_rows
from feeddrive.estimator.errors import NotEnoughExcitation
from feeddrive.estimator.kernels import ls_theta
from feeddrive.estimator.motion import EstimationOptions, parameter_covariance, stationary_score_covariance
from feeddrive.estimator.regression import Regression


@dataclass
class _Fit:
    theta: np.ndarray
    cov: np.ndarray
    dof: int
    cond: float
    fit: float
    theta_dof: np.ndarray  # (p,) effective dof of each theta's variance
    #: d theta for a change dy of the outputs (one array per sample set, all samples): theta is linear in y
    lin: Callable[[list[np.ndarray]], np.ndarray] | None = None
    #: a fit solved without its covariance (``_solve(..., covariance=False)``): the same fit with it, from the
    #: same arrays (the IV's last iteration, without solving it again)
    complete: Callable[[], _Fit] | None = None


def _column_reference(reg: Regression, signals: Mapping[str, np.ndarray], h: float) -> np.ndarray:
    """The norm each regressor column would have if its signals kept their own RMS level (a derivative
    ``Dx``: the RMS of ``x`` per motion duration; sign(w): 1). A column far below it (1e-9) is rounding
    noise, e.g. the derivative of a constant speed. Unit-free: nothing refers to nominal parameters."""
    n = len(signals["w"])
    duration = n * h

    levels: dict[str, float] = {}

    def rms(name: str) -> float:  # once per signal: a derivative and its signal's own column read the same one
        if name not in levels:
            levels[name] = float(np.sqrt(np.mean(np.square(signals[name])))) or 1.0
        return levels[name]

    proxy = {}
    for name in reg.signals:
        if name == "sgn_w":
            proxy[name] = 1.0
        elif name.startswith("D") and signals.get(name[1:]) is not None:
            proxy[name] = rms(name[1:]) / duration
        else:
            proxy[name] = rms(name)
    # every sample is the same: the regression (elementwise) evaluated once; the norm of n equal values is
    # |value| sqrt(n) (the sum of the n squares rounded aside: within ~1e-15, tests/estimator/test_linear_fit_runs.py)
    y1, Phi1 = reg.evaluate({k: np.full(1, v) for k, v in proxy.items()})
    return np.abs(np.vstack([y1, Phi1.T])[1:, 0]) * np.sqrt(n)


#: most runs of used rows copied run by run (``_used_runs``); beyond, the rows are gathered by their indices
MAX_RUNS = 16


def _used_runs(r: np.ndarray) -> list[tuple[int, int]] | np.ndarray:
    """The runs ``[(start, stop), ...]`` of True in ``r`` (n,) bool, or its indices when there are more than
    ``MAX_RUNS``: a fit's usable rows are a few stretches of the motion (between its speed reversals), and a run
    is one block copy where a gather by index moves each row alone (the same rows, the same values)."""
    edges = np.flatnonzero(np.diff(np.concatenate([[False], r, [False]]).view(np.int8)))
    if edges.size > 2 * MAX_RUNS:
        return np.flatnonzero(r)
    return list(zip(edges[::2].tolist(), edges[1::2].tolist()))


def _solve(reg: Regression, parts: list[tuple], block: int, options: EstimationOptions,
           reference: np.ndarray | None = None, note: str = "", covariance: bool = True,
           memo: dict | None = None) -> _Fit:
    """LS or basic IV on the usable rows of one or more sample sets, column-scaled.

    Each part is ``(y (n,), Phi (n, p), Z (n, p) or None, rows (n,) bool)``. With ``Z`` None: LS
    (``lstsq``, not the normal equations), after the excitation check. Otherwise IV: ``theta = (sum Z^T Phi)^-1 sum Z^T y``. The parts are
    sample sets of the same time span (sample k of every part near the same time), so their score
    contributions are added sample by sample before the long-run covariance.

    ``memo`` (a dict the caller keeps, e.g. one per equation over the IV iterations): the usable rows, column
    scale and singular values of the regressors are kept in it and reused while the parts' ``y``, ``Phi``, rows
    and ``reference`` are the same objects (only the instruments change from one IV iteration to the next).
    """
    p = parts[0][1].shape[1]
    used = sum(np.count_nonzero(r) for *_, r in parts)  # counts: bit for bit r.sum(), a third of its time
    if used < 20 * p:
        raise NotEnoughExcitation(list(reg.names) + ([reg.normaliser] if reg.normaliser else []),
                                  f"motion too short: {used} usable samples in the {reg.equation} "
                                  f"equation, its {p} parameters ({', '.join(reg.names)}) need at least {20 * p}"
                                  + (f" ({note})" if note else ""))
    same = tuple(x for y, Phi, _, r in parts for x in (y, Phi, r)) + (reference,)
    kept = memo.get("regressors") if memo is not None else None
    hit = kept is not None and len(kept[0]) == len(same) and all(a is b for a, b in zip(kept[0], same))
    if hit:
        index, Xr, ys, scale, empty, Xs, eig, V = kept[1]
    else:
        index = {id(r): None if r.all() else _used_runs(r) for *_, r in parts}

    def rows(x, r):  # the same rows as x[r]: a few runs of used rows copied as blocks, else take() by index
        at = index[id(r)]
        if at is None:
            return x
        if isinstance(at, np.ndarray):
            return x.take(at, axis=0)
        out = np.empty((sum(b - a for a, b in at), *x.shape[1:]))  # C order, as take() gives (the products' order)
        # a regression's columns are contiguous (evaluate()): copied column by column, one strided write each,
        # rather than row by row into C order (a call of numpy's copy loop per row of 3-4 values)
        cols = x.ndim == 2 and not x.flags.c_contiguous
        k = 0
        for a, b in at:
            if cols:
                for j in range(x.shape[1]):
                    out[k:k + b - a, j] = x[a:b, j]
            else:
                out[k:k + b - a] = x[a:b]
            k += b - a
        return out

    def spread(x, r):  # rows x back in place of the used rows of r, zeros elsewhere: x[r] inverted
        at = index[id(r)]
        if at is None:
            return x
        if isinstance(at, np.ndarray):
            out = np.zeros((r.size, *x.shape[1:]))
            out[at] = x  # integer indices: a third of a boolean mask's time on (n, p) arrays
            return out
        out = np.empty((r.size, *x.shape[1:]))  # each row written once: the runs copied, the gaps between zeroed
        k = last = 0
        for a, b in at:
            out[last:a] = 0.0
            out[a:b] = x[k:k + b - a]
            k += b - a
            last = b
        out[last:] = 0.0
        return out

    if not hit:
        Xr = [rows(Phi, r) for _, Phi, _, r in parts]
        ys = [rows(y, r) for y, _, _, r in parts]
        scale = np.sqrt(sum(np.einsum("ij,ij->j", X, X) for X in Xr))
        # a column that is rounding noise (a derivative at constant speed) is empty, however well conditioned
        # column scaling makes it look; judged against the column's own scale (see _column_reference)
        empty = scale <= 1e-9 * reference if reference is not None else np.zeros(p, dtype=bool)
        scale[empty] = 1.0
        Xs = [divide_columns(X, scale) for X in Xr]
        # singular values of the scaled regressor from its p x p Gram matrix (cheap; fine up to cond ~1e7)
        gram = sum(X.T @ X for X in Xs)
        eig, V = np.linalg.eigh(gram[np.ix_(~empty, ~empty)])
        if memo is not None:  # the objects themselves kept: an id is only unique while its object lives
            memo["regressors"] = (same, (index, Xr, ys, scale, empty, Xs, eig, V))
    sv, Vt = np.sqrt(np.clip(eig[::-1], 0, None)), V[:, ::-1].T
    cond = sv[0] / sv[-1] if sv[-1] > 0 and not empty.any() else np.inf
    if parts[0][2] is None:
        if cond > options.max_condition:
            weak = np.zeros(p, dtype=bool)
            weak[~empty] = np.abs(Vt[sv < sv[0] / options.max_condition]).max(axis=0, initial=0) > 0.1
            bad = [n for n, b in zip(reg.names, weak | empty) if b]
            raise NotEnoughExcitation(bad, f"{reg.equation} regressor condition number {cond:.3g} > "
                                      f"{options.max_condition:.3g} (constant speed, no speed reversal?)", cond)
        Ws = Xs
        theta_s = ls_theta(Xs, ys, eig, V, cond)
    else:
        Zr = [rows(Z, r) for _, _, Z, r in parts]
        zscale = np.sqrt(sum(np.einsum("ij,ij->j", Z, Z) for Z in Zr)).clip(1e-300)
        Ws = [divide_columns(Z, zscale) for Z in Zr]
        theta_s = np.linalg.solve(sum(W.T @ X for W, X in zip(Ws, Xs)), sum(W.T @ y for W, y in zip(Ws, ys)))
    def complete() -> _Fit:
        """The fit with its covariance, from this solve's arrays."""
        # LS: the Gram matrix of the condition number (the same sum, the same bits)
        A = gram if Ws is Xs and not hit else sum(W.T @ X for W, X in zip(Ws, Xs))
        n = min(len(y) for y, *_ in parts)
        G = None  # the first set's scores themselves, not added to zeros (no (n, p) memset and pass)
        res2 = out2 = 0.0
        stationary = []  # (instruments, errors) with the unused rows zero, for the stationary-error floor
        for (y, _, _, r), W, X, yr in zip(parts, Ws, Xs, ys):
            e = yr - X @ theta_s
            res2 += e @ e
            out2 += yr @ yr
            Wf, ef = spread(W, r), spread(e, r)
            score = multiply_rows(Wf[:n], ef[:n])  # the scores, zero on the unused rows: W e on the used ones
            if G is None:
                G = score
            else:
                G += score
            stationary.append((Wf, ef))
        Ai = np.linalg.inv(A)
        cov, dof, nb = parameter_covariance(G, Ai, block, stationary_score_covariance(stationary, block))

        def lin(dys: list[np.ndarray]) -> np.ndarray:
            return Ai @ sum(W.T @ rows(dy, r) for W, dy, (*_, r) in zip(Ws, dys, parts)) / scale

        return _Fit(theta_s / scale, cov / np.outer(scale, scale), nb - p, float(cond),
                    float(np.sqrt(res2 / out2)), dof, lin)

    if not covariance:  # an IV iteration: its values, and the covariance on demand (for the last: 2/3 of IV)
        return _Fit(theta_s / scale, np.zeros((p, p)), 1, float(cond), float("nan"), np.ones(p), complete=complete)
    return complete()


def conditional_covariance(cov: np.ndarray, keep: list[int], given: list[int]) -> np.ndarray:
    """The covariance of the parameters ``keep`` given the values of ``given`` (the Schur complement: what a re-fit
    with them known gives for least squares), zero in every other row and column; ``cov`` is (p, p)."""
    C, kk, kr, rr = np.zeros_like(cov), np.ix_(keep, keep), np.ix_(keep, given), np.ix_(given, given)
    if keep:
        C[kk] = cov[kk] - cov[kr] @ np.linalg.pinv(cov[rr], hermitian=True) @ cov[kr].T if given else cov[kk]
    return C
