"""Model validation: does the estimated model explain the motion? (paper IV.B.3, Fig. 13, 14)

The estimated model is simulated from the measured inputs (output error, no feedback from the
measured output):

* speed from the filtered current with the estimated K, Jt, ft, Cd (mechanical equation), and
* current from the filtered voltage and speed with the estimated R, L, K (electrical equation,
  the same first-order recursion as the validation's Ir_hat, started in steady state),

and each residue ``measured - simulated`` (filtered signals, eq. 8) is judged twice:

* whiteness: Ljung-Box test (statsmodels ``acorr_ljungbox``) at level ``alpha`` on the residue
  decimated to ``rate_hz`` by block means (at 10 kHz the filtered residue is correlated over about
  1/cutoff and the test would reject every motion for that reason alone);
* size: RMS of the residue relative to the range of the measured signal.

A residue counts as a mismatch only when it is both coloured (p < alpha) and larger than
``rms_tol`` of the range. The size rule is needed: an open-loop speed simulation integrates every
small model imperfection (the filtered sign(w) at reversals, estimation error), so even the true
model gives a coloured speed residue (about 2e-4 of the range on the plant at 10 kHz), which does not
matter; a white residue is noise. A mismatch means the parameters are NOT validated; they are still
reported.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping

import numpy as np
from statsmodels.stats.diagnostic import acorr_ljungbox

from estimator.errors import EstimatorInputError
from estimator.filtering import FilterSpec
from estimator.simulation import simulate_speed
from estimator.validation import model_reference


@dataclass(frozen=True)
class ResidueCheck:
    """Whiteness and size of one output-error residue.

    Attributes
    ----------
    signal : str
        ``speed`` or ``current``.
    statistic, p_value : float
        Ljung-Box Q statistic and its p-value.
    lags : int
    rms_relative : float
        RMS residue / range of the measured signal.
    passed : bool
    simulated, residue : ndarray, shape (n,)
        Simulated signal and ``measured - simulated`` (filtered), in the signal's unit.
    """

    signal: str
    statistic: float
    p_value: float
    lags: int
    rms_relative: float
    passed: bool
    simulated: np.ndarray = field(repr=False)
    residue: np.ndarray = field(repr=False)


@dataclass(frozen=True)
class MismatchResult:
    """Model validation of one motion; ``statistic``/``p_value`` are those of the failing (or worst) check."""

    test: str
    statistic: float
    p_value: float
    passed: bool
    checks: dict[str, ResidueCheck]
    alpha: float
    rms_tol: float

    def to_dict(self) -> dict:
        return {"test": self.test, "statistic": self.statistic, "p_value": self.p_value, "passed": self.passed,
                "rms_relative": {k: c.rms_relative for k, c in self.checks.items()}}


def residue_check(name: str, measured: np.ndarray, simulated: np.ndarray, h: float, alpha: float, rate_hz: float,
                  lags: int, rms_tol: float) -> ResidueCheck:
    """Judge one output-error residue; see the module docstring. Arrays have shape (n,); h [s]."""
    r = measured - simulated
    block = max(1, int(round(1.0 / (rate_hz * h))))
    nb = r.size // block
    if nb < 2 * lags + 2:
        raise EstimatorInputError(
            f"model check: {r.size} samples give {nb} blocks at {rate_hz} Hz; need {2 * lags + 2} for {lags} lags")
    decimated = r[:nb * block].reshape(nb, block).mean(axis=1)
    lb = acorr_ljungbox(decimated, lags=[lags])
    stat, p = float(lb["lb_stat"].iloc[0]), float(lb["lb_pvalue"].iloc[0])
    span = float(np.ptp(measured)) or 1.0
    rms = float(np.sqrt(np.mean(r**2))) / span
    return ResidueCheck(name, stat, p, lags, rms, bool(p >= alpha or rms <= rms_tol), simulated, r)


def check_model(u: np.ndarray, i: np.ndarray, w: np.ndarray, h: float, parameters: Mapping[str, float],
                filter: FilterSpec, alpha: float = 1e-3, rate_hz: float = 50.0, lags: int = 10,
                rms_tol: float = 0.01) -> MismatchResult:
    """Simulate the estimated model from the measured inputs and test the residues.

    Parameters
    ----------
    u, i, w : ndarray, shape (n,)
        Validated raw voltage [V], current [A] and speed [rad/s] of the motion.
    h : float
        Sample time [s].
    parameters : mapping
        Estimated ``R, L, K, Jt, ft, Cd`` (and optional ``T0``).
    filter : FilterSpec
        The monitor's filter (eq. 8).
    alpha : float
        Level of the Ljung-Box test.
    rate_hz : float
        Rate of the decimated residue the test sees [Hz].
    lags : int
        Ljung-Box lags.
    rms_tol : float
        RMS residue, as a fraction of the measured signal's range, below which the model is accepted.

    Returns
    -------
    MismatchResult
    """
    missing = [k for k in ("R", "L", "K", "Jt", "ft", "Cd") if k not in parameters]
    if missing:
        raise EstimatorInputError(f"check_model: parameters {missing} are missing")
    f = filter.apply({"u": u, "i": i, "w": w}, h)
    params = {k: float(v) for k, v in parameters.items()}
    decimate = max(h, 1.0 / (20.0 * filter.cutoff_hz))  # integration step: 20 per filter cut-off period
    w_sim = simulate_speed(f["i"], params, h, w0=float(f["w"][0]), step=decimate)
    i_sim = model_reference("current", f, h, params)  # linear: exact Tustin recursion, no ODE solver needed
    checks = {
        "speed": residue_check("speed", f["w"], w_sim, h, alpha, rate_hz, lags, rms_tol),
        "current": residue_check("current", f["i"], i_sim, h, alpha, rate_hz, lags, rms_tol),
    }
    worst = min(checks.values(), key=lambda c: (c.passed, c.p_value))
    return MismatchResult("ljung-box", worst.statistic, worst.p_value, all(c.passed for c in checks.values()),
                          checks, alpha, rms_tol)
