"""The estimator at an NC's sample rate (1-4 ms): what IV's halves and LS's noise bias do to an interval.

``partial.estimate_parameters`` calls these when the filter's cut-off is high for the IV halves' period 2 h
(``2 pi fc 2h > MAX_HALF_PHASE``): a servo drive's 125 us trace with a 100 Hz filter is far from it (0.16 rad),
an NC's 2 ms trace with the default ``0.1 / h`` cut-off beyond it (1.26 rad).

* ``systematic``: the interval of the estimate holds the method's own systematic error. IV regresses each half
  (every other sample) on instruments from the other; at 2 h the content above ``1 / (4 h)`` (a servo's current
  transients) folds onto the filter's band. LS has no such aliasing but is biased by the noise of its
  regressors. Their difference bounds both: it is added (squared) to IV's variance. When IV fell back to LS,
  LS's noise bias is estimated by the halves' LS (the same cut-off at half the rate: twice the filtered noise's
  variance, twice the bias) and added the same way.
* ``rate_rule``: a parameter on which IV and LS disagree beyond what LS's noise bias explains is refused.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from feeddrive.estimator.errors import FAILURES
from feeddrive.estimator.estimate import split_halves
from feeddrive.estimator.lagged_iv import LAGGED
from feeddrive.estimator.motion import EstimationOptions, MethodResult, MotionData

#: Largest phase 2 pi f_c (2 h) of the filter's cut-off at the IV halves' sample period 2 h [rad] above which the
#: halves are checked against LS (a servo drive's 125 us trace with a 100 Hz filter: 0.16; an NC's 1-4 ms with
#: the default 0.1 / h cut-off: 1.26)
MAX_HALF_PHASE = 1.0
#: IV standard errors by which IV and LS may differ at such a rate.
MAX_DISAGREEMENT = 3.0


def _phase(data: MotionData, options: EstimationOptions) -> float:
    """``2 pi fc 2h`` [rad]: the filter's cut-off as a phase at the IV halves' sample period."""
    return 2 * np.pi * options.filter.cutoff_hz * 2 * data.h


def _halves_ls(data: MotionData, options: EstimationOptions, fixed: dict, fit_ls) -> list:
    """LS of the odd and of the even samples (None for a half that could not be fitted)."""
    out = []
    for half in split_halves(data):
        try:
            res = fit_ls(half, replace(options, known={**options.known, **fixed}))[1]
        except FAILURES:  # too short, or failed: no extrapolation (a coding error is raised)
            res = None
        out.append(res)
    return out


def systematic(data: MotionData, ls: MethodResult, result: MethodResult, options: EstimationOptions,
               fixed: dict, fit_ls) -> MethodResult:
    """``result`` (IV, or LS standing in for it) with its systematic error at an NC's rate in its covariance.

    Parameters
    ----------
    data : MotionData
    ls : MethodResult
        LS of the whole record.
    result : MethodResult
        IV, LS asked for (method ``ls``), or LS labelled ``iv`` when IV fell back (``result.ran == "ls"``); the lagged
        IV (``lagged_iv.LAGGED``) is returned unchanged.
    options : EstimationOptions
    fixed : dict
        Parameters fixed in the re-fit (they stay fixed in the halves' LS).
    fit_ls : callable
        ``partial._fit_ls``.

    Returns
    -------
    MethodResult
        ``result`` unchanged below ``MAX_HALF_PHASE``; else with ``d_j^2`` added to the variance of each
        parameter j (its row and column scaled: the correlations are kept), ``d = IV - LS`` (IV ran) or
        ``d = mean(LS_halves) - LS`` (LS's noise bias, IV fell back), and a note in ``message``. At 2 ms noise-free IV's L_d was -6.3 % +-6.1 % (LS -3.5 %); at 2 ms, 30 dB,
        the fall-back LS gave Jt -18 % +-17 % (the halves' LS -35 %: the bias of noisy Dw doubles).
    """
    if _phase(data, options) <= MAX_HALF_PHASE or result.method not in ("iv", "ls") or result.method_used == LAGGED:
        return result  # the lagged IV reads the whole record (no halves to alias), its instruments not the noise
    names = [n for n in result.names if n in ls.names]
    if result.method_used == "iv":
        d = {n: result.values[result.names.index(n)] - ls.values[ls.names.index(n)] for n in names}
        what = "IV - LS (IV's halves alias, LS's regressors are noisy)"
    else:
        halves = [r for r in _halves_ls(data, options, fixed, fit_ls) if r is not None]
        d = {n: float(np.mean([r.values[r.names.index(n)] for r in halves])) - ls.values[ls.names.index(n)]
             for n in names if halves and all(n in r.names for r in halves)}
        what = "the halves' LS - LS (LS's noise bias, doubled in the halves)"
    if not d:
        return result
    cov = np.array(result.covariance, dtype=float)
    scale = np.ones(len(result.names))
    for n, dn in d.items():
        j = result.names.index(n)
        var = cov[j, j]
        scale[j] = np.sqrt(1 + dn ** 2 / var) if var > 0 and np.isfinite(dn) else (1.0 if dn == 0 else np.inf)
    # each standard error scaled, so the correlations (the friction pair's, ``partial._rule``) are kept
    cov = cov * np.outer(scale, scale)
    note = (f"sample period {data.h:.3g} s (2 pi fc 2h = {_phase(data, options):.2f} rad > {MAX_HALF_PHASE:g}): "
            f"each variance holds the square of {what}")
    return replace(result, covariance=cov, message=f"{result.message}; {note}" if result.message else note)


def rate_rule(data: MotionData, ls: MethodResult, iv: MethodResult, options: EstimationOptions, fixed: dict,
              refused: dict, fit_ls) -> None:
    """Parameters refused when IV and LS disagree at a long sample period (``partial``'s docstring, ``sample period``).

    IV regresses each half of the record (every other sample, period 2 h) on instruments from the other. At an
    NC's 1-4 ms the signals' content between 1 / (4 h) and 1 / (2 h) (a servo's current transients) folds onto
    the filter's band in the halves but not in the whole record: the PMSM's R came out 3 % low by IV at 4 ms,
    its interval +-0.9 % excluding the truth, while LS gave it within 0.3 % (+-9 %). LS may differ from IV
    for the reason IV exists, too: the noise of the regressors biases LS in proportion to the filtered noise's
    variance, which is twice as large in the halves (the same cut-off, half the rate), so without aliasing IV
    is close to the extrapolation ``2 LS - LS_halves``. A parameter is refused when IV differs from LS and from
    that extrapolation by more than ``MAX_DISAGREEMENT`` of IV's standard errors (given the fixed parameters).
    ``fit_ls(data, options)`` is ``partial._fit_ls`` (LS with its refusals), passed in to avoid a cycle.
    """
    h, fc = data.h, options.filter.cutoff_hz
    phase = 2 * np.pi * fc * 2 * h
    if iv.method_used != "iv" or phase <= MAX_HALF_PHASE:
        return
    sd = np.sqrt(np.clip(np.diag(np.asarray(iv.covariance, dtype=float)), 0, None))
    far = {n: j for j, n in enumerate(iv.names) if n not in refused and n in ls.names
           and not abs(iv.values[j] - ls.values[ls.names.index(n)]) <= MAX_DISAGREEMENT * sd[j]}
    if not far:
        return
    halves = _halves_ls(data, options, fixed, fit_ls)
    for n, j in far.items():
        k = ls.names.index(n)
        lh = [r.values[r.names.index(n)] for r in halves if r is not None and n in r.names]
        extra = 2 * ls.values[k] - float(np.mean(lh)) if lh else np.nan
        if abs(iv.values[j] - extra) <= MAX_DISAGREEMENT * sd[j]:
            continue  # LS's noise bias explains the difference
        z = abs(iv.values[j] - ls.values[k]) / sd[j] if sd[j] > 0 else np.inf
        # without the halves' LS (too short or failed) there is no extrapolation to name
        towards = (f", extrapolated to noise-free {extra:.4g}" if np.isfinite(extra)
                   else ", no extrapolation: the halves' LS could not be fitted")
        refused[n] = (f"sample period {h:.3g} s: IV ({iv.values[j]:.4g}) and LS ({ls.values[k]:.4g}{towards}) differ by {z:.2g} of IV's standard errors (more than "
                      f"{MAX_DISAGREEMENT:g}); IV's halves are sampled every {2 * h:.3g} s, where the signals above "
                      f"{0.25 / h:.3g} Hz fold onto the {fc:.3g} Hz filter's band (2 pi fc 2h = {phase:.2f} rad > "
                      f"{MAX_HALF_PHASE:g}): neither is given (sample faster, or lower the cut-off)")
