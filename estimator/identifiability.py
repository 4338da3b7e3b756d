"""Is L the motor's? The current's second lag test (issue 22, REGBOT).

The electrical equation ``u = R i + L di/dt + K w`` is first order. When the recorded current reaches the
logger through a further first-order lag ``tau_f`` (a sensor's or an ADC's low-pass, an averaging current
measurement), the current obeys

    u = R i_m + (L + R tau_f) di_m/dt + L tau_f d2i_m/dt2 + K w

and the first-order fit gives ``L + R tau_f`` with a tight interval: on the REGBOT logs (course L/R 2 ms,
a current filtered over ~15 ms) it is 14 times the motor's L. The data determine only the two time
constants' sum ``a1`` and product ``a2`` (the roots of ``s^2 - a1 s + a2``): which one is the motor's
``L/R`` and which one the lag cannot be told from ``u, i, w`` alone, so L is refused, with both
candidates. R and K are still determined (the lag's ``L`` term is kept in the fit, as a lumped term).

The rule: the electrical regression augmented with ``d2i/dt2`` gives a coefficient whose Newey-West
t statistic exceeds the two-sided 5 % normal quantile, real time constants, and the smaller of them at least
``MIN_LAG_RATIO`` of the larger (below it the first-order L is within that fraction of one candidate,
the lag is negligible). The built-in plant (no sensor lag) gives |t| < 1 at 10 kHz, and so do the synthetic records at 1 kHz.

The other time-constant rule (``tau_rule``): a derivative parameter (L; L_q, L_d) whose equation's time constant
(``time_constants``, read from the model) is shorter than ``MIN_TAU_SAMPLES`` sample periods cannot be identified.
"""
from __future__ import annotations

from collections.abc import Mapping
from functools import lru_cache

import casadi as ca
import numpy as np

from feeddrive.estimator.columnwise import divide_columns, multiply_rows
from feeddrive.estimator.distributions import chi2_sf, norm_ppf, t_ppf
from feeddrive.estimator.kernels import columns, ls_theta

#: Smallest ratio of the two time constants for the second lag to matter to L.
MIN_LAG_RATIO = 0.1


def second_lag(y: np.ndarray, Phi: np.ndarray, names: tuple[str, ...], Di: np.ndarray, h: float, block: int,
               slope: str = "L", resistance: str = "R", extra: np.ndarray | None = None) -> dict | None:
    """The electrical fit with a ``d2i/dt2`` column, and the two time constants it implies.

    Parameters
    ----------
    y : ndarray, shape (n,)
        The electrical equation's output on its usable rows.
    Phi : ndarray, shape (n, p)
        Its regressors (columns ``names``; R and L among them).
    names : tuple of str
    Di : ndarray, shape (n,)
        The filtered current's derivative [A/s] on the same rows (contiguous samples).
    slope, resistance : str
        The columns of the derivative's coefficient and of the current's (DC: L, R; the PMSM's q axis: L_q, R).
    extra : ndarray, shape (n, k), optional
        Nuisance columns: the lag's terms on the equation's other currents (the PMSM's q axis: ``p w Di_d``, the
        lag of i_d in ``p w L_d i_d``, coefficient ``L_d tau_f``).
    h : float
        Sample period [s].
    block : int
        Lags of the Newey-West covariance [samples] (the estimator's block).

    Returns
    -------
    dict or None
        ``{"t": t statistic of the d2i/dt2 coefficient (Newey-West), "taus": (larger, smaller) [s] or None when
        complex, "R": R of the augmented fit [Ohm], "theta": its coefficients of ``names``}``; None when the test
        cannot run (too few batches,
        R or L not fitted, R not positive).
    """
    if not {resistance, slope} <= set(names):
        return None
    fit = _augmented(y, columns([Phi, *([] if extra is None else [extra]), np.gradient(Di, h)]), block)
    if fit is None:
        return None
    theta, cov = fit
    t = float(theta[-1] / np.sqrt(cov[-1, -1])) if cov[-1, -1] > 0 else float("nan")
    R, L, M = theta[names.index(resistance)], theta[names.index(slope)], theta[-1]
    if not (R > 0 and np.isfinite(M) and np.isfinite(t)):
        return None
    a1, a2 = L / R, M / R
    disc = a1 * a1 - 4 * a2
    taus = None if disc < 0 else ((a1 + np.sqrt(disc)) / 2, (a1 - np.sqrt(disc)) / 2)
    return {"t": t, "taus": taus, "R": float(R), "theta": theta[:Phi.shape[1]]}


def lag_reason(test: Mapping | None, R: float, slope: str = "L", state: str = "i") -> str | None:
    """The refusal of L when ``second_lag`` found a second lag that matters (module docstring), else None."""
    if test is None or test["taus"] is None:
        return None
    big, small = test["taus"]
    q = float(norm_ppf(0.975))
    if not (test["t"] > q and small > 0 and small >= MIN_LAG_RATIO * big):
        return None
    return (f"the current lags the voltage through two time constants, {big * 1e3:.3g} ms and {small * 1e3:.3g} ms "
            f"(d2{state}/dt2 term t = {test['t']:.3g} > {q:.3g}): one is {slope}/R, the other a lag of the current "
            f"measurement (a sensor filter) or of the amplifier, and the signals cannot tell which; {slope} is either "
            f"{R * small:.3g} or {R * big:.3g} H (R = {R:.3g}), the first-order fit's {R * (big + small):.3g} H is "
            f"neither (kept in the fit, as a lumped term, for the others)")


def lag_terms(y: np.ndarray, Phi: np.ndarray, extra: np.ndarray, block: int) -> dict | None:
    """An equation in a current whose measurement lags, fitted again with the lag's terms as nuisance columns.

    A measured current ``i_m`` that lags the motor's ``i`` by a first-order ``tau_f`` is ``i = i_m + tau_f
    di_m/dt``: an equation in ``i`` (the DC mechanical ``K i = Jt dw/dt + ft w + Cd sign(w)``) fitted on ``i_m``
    lumps ``tau_f di_m/dt`` into its parameters. Low-passed by 20 ms, the built-in axis's round trip gave ft
    2.2 times its value with a 95 % interval of [1.5, 2.9] times it, given as a number.

    Parameters
    ----------
    y : ndarray, shape (n,)
        The equation's output on its usable rows.
    Phi : ndarray, shape (n, p)
        Its regressors.
    extra : ndarray, shape (n, k)
        The lag's terms: the output's and the regressors' in the current, the current replaced by its derivative
        (their coefficients: ``-tau_f`` and ``tau_f`` times the parameter).
    block : int
        Lags of the Newey-West covariance [samples].

    Returns
    -------
    dict or None
        ``{"theta": the augmented fit's first p coefficients, "p_value": the Newey-West Wald test that the lag's
        terms are zero}``; None when the fit cannot be made (too few samples, non-finite values).
    """
    k = extra.shape[1] if extra.ndim == 2 else 1
    fit = _augmented(y, columns([Phi, extra]), block)
    if fit is None:
        return None
    theta, cov = fit
    b, C = theta[-k:], cov[-k:, -k:]
    try:
        wald = float(b @ np.linalg.solve(C, b))
    except np.linalg.LinAlgError:
        return None
    if not np.isfinite(wald):
        return None
    return {"theta": theta[:Phi.shape[1]], "p_value": float(chi2_sf(wald, k))}


def _augmented(y: np.ndarray, X: np.ndarray, block: int) -> tuple[np.ndarray, np.ndarray] | None:
    """Least squares of ``y`` on ``X`` (columns scaled to unit norm for the solve) with the Newey-West covariance
    over ``block`` lags: ``(theta (p,), covariance (p, p))`` in ``X``'s units; None with too few samples for the
    covariance or non-finite values."""
    if len(y) <= X.shape[1] + 2 * max(1, int(block)) or not np.all(np.isfinite(X)) or not np.all(np.isfinite(y)):
        return None
    scale = np.linalg.norm(X, axis=0)
    scale[scale == 0] = 1.0
    Xs = divide_columns(X, scale)
    gram = Xs.T @ Xs
    eig, V = np.linalg.eigh(gram)
    cond = float(np.sqrt(eig[-1] / eig[0])) if eig[0] > 0 else np.inf
    theta = ls_theta([Xs], [y], eig, V, cond)  # lstsq's solution (from the Gram matrix when well conditioned)
    cov = _newey_west_cov(Xs, y - Xs @ theta, max(1, int(block)), gram)
    return theta / scale, cov / np.outer(scale, scale)


def _newey_west_cov(X: np.ndarray, e: np.ndarray, lags: int, gram: np.ndarray | None = None) -> np.ndarray:
    """The coefficients' Newey-West (Bartlett) covariance over ``lags`` lags, shape (p, p) (see _newey_west_t);
    ``gram``: ``X.T @ X`` when the caller has it."""
    n, p = X.shape
    S = multiply_rows(X, e)
    m = lags + 1
    C = np.empty((n + 2 * m, p))  # each row written once: the zeros before the sums, the sums, the last repeated
    C[:m + 1] = 0.0
    np.cumsum(S, axis=0, out=C[m + 1:n + m + 1])
    C[n + m + 1:] = C[n + m]
    B = C[m:] - C[:-m]
    G = np.linalg.pinv(X.T @ X if gram is None else gram)
    return G @ (B.T @ B / m) @ G * n / (n - p)


def _newey_west_t(X: np.ndarray, e: np.ndarray, lags: int, theta: np.ndarray) -> float:
    """t statistic of the last coefficient with the Newey-West (Bartlett) covariance over ``lags`` lags.

    The filtered residue is correlated over the filter's memory, and a short record (REGBOT: 0.35 s) holds
    too few batches for batch means. The Bartlett-weighted sum of the score autocovariances,
    ``sum_k,j S_k S_j^T (1 - |k - j| / (lags + 1))+``, equals ``sum_m B_m B_m^T / (lags + 1)`` with ``B_m`` the
    sums of the scores over every window of ``lags + 1`` consecutive samples (those hanging over either end
    included): a window holds both k and j in ``lags + 1 - |k - j|`` positions. The window sums come from
    one cumulative sum, O(n p^2) (a transform of length 2 n of each column, then of each product, was 60 ms of
    a 10 kHz motion; tests/estimator/test_speed_shared.py compares it with the lag-by-lag sum).
    """
    var = float(_newey_west_cov(X, e, lags)[-1, -1])
    return float(theta[-1] / np.sqrt(var)) if var > 0 else float("nan")


#: Fewest sample periods in the electrical time constant L/R for L to be identifiable.
MIN_TAU_SAMPLES = 1.0


@lru_cache(maxsize=16)
def time_constants(model) -> list[tuple[str, str, str, str]]:
    """``(equation, state, slope, resistance)`` of each equation with a first-order time constant ``slope /
    resistance``: the physical parameter multiplying the state's derivative (DC: L; PMSM: L_q, L_d; Jt) and the
    one multiplying the state itself (R; R; ft), read from the residual's Jacobians, never from the motor."""
    out = []
    phys = model.of_kind("physical")
    for eq in model.equations.values():
        state = model.variables[eq.solves_for].sym
        slope = ca.jacobian(eq.residual, model.derivative[eq.solves_for])
        gain = ca.jacobian(ca.substitute(eq.residual, model.derivative[eq.solves_for], 0), state)
        a = next((v.name for v in phys if ca.depends_on(slope, v.sym)), None)
        r = next((v.name for v in phys if v.name != a and ca.depends_on(gain, v.sym)), None)
        if a and r:
            out.append((eq.name, eq.solves_for, a, r))
    return out


def tau_rule(fit, reg, h: float, fixed: dict, refused: dict, model) -> bool:
    """A derivative parameter refused when its equation's time constant (slope / resistance: L/R, L_q/R, L_d/R)
    is shorter than ``MIN_TAU_SAMPLES`` sample periods (True: it is fixed at 0, the others re-fitted)."""
    changed = False
    for eq, state, a, r in time_constants(model):
        if a in refused or not {a, r} <= set(reg.names):
            continue
        ja, jr = reg.names.index(a), reg.names.index(r)
        R, L = fit.theta[jr], fit.theta[ja]
        sl = float(np.sqrt(max(fit.cov[ja, ja], 0.0)))
        q = float(t_ppf(0.975, max(float(fit.theta_dof[ja]), 1.0)))
        if not R > 0:
            continue
        tau, tau_hi = L / R, (L + q * sl) / R
        if tau_hi < MIN_TAU_SAMPLES * h:
            refused[a] = (f"sample period {h:.3g} s too long for the {eq} time constant {a}/{r} = {tau:.3g} s (95 % "
                          f"upper bound {tau_hi:.3g} s): {a} cannot be identified; the others from the quasi-static "
                          f"{eq} equation (its {a} d{state}/dt term dropped)")
            fixed[a] = 0.0
            changed = True
    return changed
