"""IV whose instruments are the regressors themselves read a few filter periods away: the fall-back of the
split-sample IV (``estimate.instrumental_variables``) when that fails or does not settle, instead of plain LS.

Why not LS. The regressors are filtered noisy signals, and the derivative of the speed above all carries noise
that is also in the equation error: LS is biased towards zero on its coefficient (errors in variables), the more
the wider the filter's band. On a servo bench (HSM150, 1 kHz, torque and speed only) LS gave Jt 1.07e-4 kg.m2
at a 5 Hz cut-off, 8.5e-5 at 50 Hz and 2.7e-5 at 100 Hz, intervals that do not overlap; the split-sample IV did
not settle there, and the fall-back LS was printed with an interval that excluded the catalogue's 1.2e-4.

The instrument. Every signal passes the same low-pass of cut-off ``fc``: its filtered noise is correlated over
about ``1 / fc`` only, while the motion (well inside the band) changes little over a few filter periods. So a
differentiated signal read ``LAG = ceil(LAG_PERIODS / (fc h))`` samples before and after, averaged,
``z_t = (Dx_{t-LAG} + Dx_{t+LAG}) / 2``, is correlated with ``Dx_t`` through the motion and not with the equation
error through the noise (``adequacy``'s lack-of-fit test reads its regressors away for the same reason). The
regressors are evaluated on these instead of the derivatives (dw/dt, di/dt, and w itself when it is the
derivative of a position) for the instruments; every other signal is its own instrument: its filtered noise is a
fraction ``~1e-4`` of its variance at 30 dB, the derivative's is not, and read away it would only weaken the
instrument (the PMSM's 2 ms, 30 dB tool change of tests/estimator/test_pmsm_rates.py: every regressor read away
gave Jt in 29 of 40 noise draws and R in none; the derivatives alone Jt in 39 and R in 7, with the same coverage).

The estimate is the basic IV of ``linear_fit._solve`` on the regressions of ``estimate.prepare`` (any drive model,
the PMSM's d-axis partner included), equation by equation in model order as LS does, with its sandwich
covariance from batch means over blocks at least ``BLOCK_LAGS`` lags long: the scores ``z_t e_t`` are correlated
at a distance of about ``LAG`` (``z_{t+LAG}`` holds the noise of ``e_t``), which shorter blocks miss (Jt's standard
error 0.90 of its spread over 100 noise draws with blocks of 5 / fc, 1.00 with 4 lags).
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace

import casadi as ca
import numpy as np

from feeddrive.estimator.errors import FAILURES, NotEnoughExcitation, NumericalFailure
from feeddrive.estimator.estimate import _combine, _signals_for, fell_back, instrumental_variables, prepare
from feeddrive.estimator.linear_fit import _column_reference, _solve
from feeddrive.estimator.model_terms import constant_sensitivities, ls_parts, update_constants
from feeddrive.estimator.motion import EstimationOptions, MethodResult, MotionData, Prepared
from feeddrive.models.drives import differentiated

#: Filter periods ``1 / fc`` by which the instruments are read before and after each sample (the filtered
#: noise's correlation is negligible beyond ~1 / fc; ``adequacy.LAG_PERIODS`` for its own test).
LAG_PERIODS = 3.0
#: Fewest lags in a block of the batch-means covariance (the scores are correlated ~2 LAG apart).
BLOCK_LAGS = 4
#: ``MethodResult.ran`` of this method: its results are labelled ``iv`` (what was asked for), this says which ran.
LAGGED = "iv-lag"
#: The label of its result's message: which IV ran, and its instruments.
LABEL = f"IV (derivatives read {LAG_PERIODS:g} filter periods away as instruments)"


def lag_samples(cutoff_hz: float, h: float) -> int:
    """``ceil(LAG_PERIODS / (fc h))``: the instruments' distance [samples] from their row at period ``h`` [s]."""
    return int(np.ceil(LAG_PERIODS / (cutoff_hz * h)))


def read_around(x: np.ndarray, lag: int) -> np.ndarray:
    """``(x[t - lag] + x[t + lag]) / 2`` for each row ``t`` of ``x`` (shape (n,) or (n, p)); the first and last
    ``lag`` rows, which have no such neighbours, are the row itself (they are left out of the fit)."""
    out = np.array(x, dtype=float, copy=True)
    if 0 < lag < len(x) - lag:
        out[lag:len(x) - lag] = 0.5 * (x[:len(x) - 2 * lag] + x[2 * lag:])
    return out


def lagged_instruments_iv(p: Prepared, options: EstimationOptions, away: set[str]) -> MethodResult:
    """The lagged-regressor IV of every regression of ``p`` (module docstring).

    Parameters
    ----------
    p : Prepared
        Filtered signals and regressions (``estimate.prepare``); its ``constants`` are not changed.
    options : EstimationOptions
        Its filter's cut-off sets the lag; ``block_seconds`` the shortest block.
    away : set of str
        The signals read away for the instruments (``read_away``); the others are their own instruments.

    Returns
    -------
    MethodResult
        ``method`` ``iv``, ``ran`` ``LAGGED``; covariance and degrees of freedom as the other methods'.

    Raises
    ------
    NotEnoughExcitation
        An equation with fewer than 20 usable samples per parameter once ``LAG`` samples are kept from each end.
    numpy.linalg.LinAlgError
        A singular instrument-regressor product (instruments that do not follow the regressors).
    """
    p = replace(p, constants=dict(p.constants))  # each equation's estimates feed the later ones' outputs here
    lag = lag_samples(options.filter.cutoff_hz, p.h)
    block = max(p.block, BLOCK_LAGS * lag)
    z = {k: read_around(v, lag) for k, v in p.signals.items() if k in away}
    fits = {}
    for reg in p.regressions:
        parts = []
        for y, Phi, Z, rows in ls_parts(p, reg, z):  # Z: the regressors evaluated on z (the partner's too)
            rows = rows.copy()
            rows[:lag] = False
            rows[max(0, len(rows) - lag):] = False
            parts.append((y, Phi, Z, rows))
        fit = _solve(reg, parts, block, options, _column_reference(reg, _signals_for(p, reg), p.h),
                     p.notes.get(reg.equation, ""))
        if fit.dof < 0:  # fewer blocks than parameters: a singular covariance (LS's rule, ``partial._fit_ls``)
            raise NotEnoughExcitation(list(reg.names), f"{fit.dof + len(reg.names)} block(s) of {block * p.h:.3g} s "
                                      f"({BLOCK_LAGS} instrument lags of {lag * p.h:.3g} s) for the uncertainty of the "
                                      f"{reg.equation} equation; its {len(reg.names)} parameters need at least "
                                      f"{len(reg.names)}")
        fits[reg.equation] = fit
        update_constants(p, reg, fits[reg.equation].theta)
    res = _combine("iv", p, fits, sensitivities=constant_sensitivities(p.regressions, [p], fits))
    return replace(res, ran=LAGGED)


def read_away(data: MotionData, model) -> set[str]:
    """The differentiated signals of ``prepare``'s regressions (``D`` + each differentiated state of ``model``), and
    the speed when it is the derivative of the position (``data`` without a speed)."""
    return {"D" + x for x in differentiated(model)} | ({"w"} if data.w is None else set())


def lagged_iv(data: MotionData, options: EstimationOptions, equations: set[str]) -> MethodResult:
    """:func:`lagged_instruments_iv` of the regressions of ``equations`` that ``prepare(data, options)`` derives
    (``options.known`` holding what the LS re-fits fixed: the same regressions as that LS)."""
    p = prepare(data, options, strict=False)
    return lagged_instruments_iv(replace(p, regressions=[r for r in p.regressions if r.equation in equations]),
                                 options, read_away(data, options.model))


def fallback(data: MotionData, ls: MethodResult, options: EstimationOptions, equations: set[str],
             why: str) -> MethodResult:
    """The lagged IV standing in for the split-sample IV, which failed (``why``: its exception's text), labelled
    ``iv`` with the reason in ``message``; LS labelled ``iv`` (``estimate.fell_back``) when it fails too."""
    failed = why[3:] if why.startswith("IV ") else f"failed ({why})"
    try:
        res = lagged_iv(data, options, equations)
        if not (np.all(np.isfinite(res.values)) and np.all(np.isfinite(res.covariance))):
            raise NumericalFailure("non-finite estimate")
    except FAILURES as exc:  # NotEnoughExcitation, NumericalFailure, a singular matrix; never a coding error
        return fell_back(ls, "iv", f"IV fell back to LS: {why}; the {LABEL} failed too: {exc}")
    return replace(res, message=f"{LABEL}: the split-sample IV {failed}")


def iv_with_fallbacks(data: MotionData, ls: MethodResult, options: EstimationOptions, fixed: Mapping[str, float],
                      equations: set[str]) -> MethodResult:
    """IV from ``ls`` as every caller runs it (``partial.estimate_parameters``: the monitor, ``cosim estimate``;
    ``estimate.estimate_motion``: a campaign's per-method table), so the same motion gets the same method and label:
    the split-sample IV (``estimate.instrumental_variables``), else the lagged IV (:func:`fallback`), else ``ls``
    labelled ``iv`` with the reasons. Only the estimator's own failures (``errors.FAILURES``) fall back.

    Parameters
    ----------
    data : MotionData
    ls : MethodResult
        The LS estimate of the regressions of ``equations`` (the start of the iteration).
    options : EstimationOptions
        ``known`` holding what the LS re-fits fixed.
    fixed : mapping of str to float
        Parameters fixed in the re-fit of the others: a derivative coefficient (L, L_q, Jt) fixed at 0 leaves its
        equation without simulated instruments (its measured state is its own instrument).
    equations : set of str
        The equations ``ls`` holds.

    Returns
    -------
    MethodResult
        Labelled ``iv``; ``ran`` says which ran (``iv``, ``LAGGED`` or ``ls``), ``message`` why.
    """
    # an equation whose derivative coefficient is fixed at 0 cannot be simulated: its measured state is its own
    # instrument (IV = LS for it), the other equation still gets simulated instruments
    model = options.model
    dynamic = {}
    for eq in model.equations.values():  # the parameter that multiplies the equation's derivative (L, L_q, Jt)
        slope = ca.jacobian(eq.residual, model.derivative[eq.solves_for])
        n = next((v.name for v in model.of_kind("physical") if ca.depends_on(slope, v.sym)), None)
        if n is not None and fixed.get(n) == 0.0:
            dynamic[eq.name] = n
    if equations <= set(dynamic):
        return fell_back(ls, "iv", f"IV fell back to LS: {', '.join(dynamic.values())} fixed at 0, the instruments "
                                   f"cannot be simulated")
    try:
        res = instrumental_variables(data, ls, options, check=False, skip=tuple(dynamic))
        if dynamic:
            res = replace(res, message=f"IV without simulated instruments for the {', '.join(dynamic)} equation "
                                       f"({', '.join(n + ' fixed at 0' for n in dynamic.values())})")
    except FAILURES as exc:  # its own refusals and failures only: a coding error is not "IV failed"
        return fallback(data, ls, options, equations, str(exc))  # the lagged-regressor IV, or LS when it fails too
    missing = [n for n in ls.names if n not in res.names]  # a half short of fast samples for an equation
    if missing:  # the parameters would vanish from the result without a reason
        return fallback(data, ls, options, equations, f"the split-sample IV's halves (every second sample) cannot "
                                                      f"identify {', '.join(missing)}")
    finite = np.all(np.isfinite(res.values)) and np.all(np.isfinite(res.covariance))
    return res if finite else fallback(data, ls, options, equations, "non-finite IV estimate")
