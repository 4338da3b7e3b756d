"""Model validation: does the estimated model explain the motion? (paper IV.B.3, Fig. 13, 14)

The estimated model is simulated from the measured inputs (output error, no feedback from the
measured output):

* speed from the filtered current with the estimated K, Jt, ft, Cd (mechanical equation), and
* current from the filtered voltage and speed with the estimated R, L, K (electrical equation,
  the same first-order recursion as the validation's Ir_hat, started in steady state),

and each residue ``measured - simulated`` (filtered signals, eq. 8) is judged on its shape and size:

* whiteness: Ljung-Box test (statsmodels ``acorr_ljungbox``) at level ``alpha`` on the residue
  decimated to ``rate_hz`` by block means (at 10 kHz the filtered residue is correlated over about
  1/cutoff and the test would reject every motion for that reason alone);
* bursts: the largest block mean against the robust (MAD) scale of all of them, ``burst_z``, with the
  Sidak-corrected p-value ``1 - (1 - 2 Phi(-burst_z))^n_blocks`` of the largest of n Gaussian block
  means (filter transients at both ends excluded). Ljung-Box sums autocorrelations over the motion and
  misses a few short bursts; this test does not;
* size: RMS of the residue relative to the range of the measured signal, over the whole motion
  (``rms_relative``) and over every ``window_s`` window (the filter's transients at both ends excluded;
  the largest is ``peak_rms_relative``).

A residue counts as a mismatch only when it is not white Gaussian noise (Ljung-Box or burst
p < alpha) and it is too large for the estimate's uncertainty: in some window its RMS exceeds

    rms_tol * range + c * (RMS of the band sigma(t) over that same window),

``excess_relative`` being the largest ``(residue RMS - c band RMS) / range`` over the windows and
``band_relative`` the band's RMS / range in that window. sigma(t) = sqrt(diag(S Sigma S^T)) is the
standard deviation of the simulated signal due to the parameters' uncertainty: Sigma the estimate's
covariance restricted to the parameters the signal uses (speed: K, Jt, ft, Cd and T0 when estimated;
current: R, L, K), S the sensitivity of the simulation to them, by finite differences of the same
simulation along the principal axes of Sigma (``uncertainty_band``). c = sqrt(chi2_p^-1(1 - alpha)),
p = rank of Sigma (4.30 for speed, 4.03 for current at alpha = 1e-3), is a simultaneous bound for every
window: with delta = theta_hat - theta, Cauchy-Schwarz gives |S_t delta| <= sigma(t) sqrt(delta^T
Sigma^-1 delta) at each t, so the windowed RMS of the parameter error's effect is at most its band's RMS
times sqrt(delta^T Sigma^-1 delta), below c with probability 1 - alpha. Without a covariance the band is
0 and the rule is ``peak_rms_relative <= rms_tol``. The result names the test that decided:
``ljung-box`` or ``burst`` (with its statistic and p-value) for a mismatch or a white residue, ``size``
(statistic: the largest ``excess_relative``; p-value: the rejecting whiteness test's) when the residue is
coloured but within the rule, which is the usual case on healthy data (see below): on healthy plant data
the whiteness tests alone cannot accept a model, and ``rms_tol`` is a stated engineering threshold, not
one derived from the noise.

The worst window, not the whole motion, and the burst test, because an unmodelled effect can be local:
backlash in the drive chain disturbs the current only around the torque reversals. With the whole-motion
RMS and Ljung-Box alone, a 0.06 rad gap (0.19 mm at the table) passed with L estimated 6.6 % high (and
was diagnosed as motor heating); its current residue was white by Ljung-Box (p = 1.4e-3) but had bursts
(p < 1e-80) and a worst window of 1.8 % of the range (1.3 % beyond the band).

The band, because a slow motion determines friction poorly. A tool change at 0.02 m/s (6.3 rad/s,
10.5 s; the standard one runs at 70 rad/s for 3.5 s) gave ft 0.032 [0.017, 0.048] and Cd 1.12
[1.02, 1.22] N m for a plant with 0.02 and 1.2, and the open-loop speed simulation integrates that
torque error over seconds: 0.6 to 1.3 % of the range in the worst window over 9 noise seeds, all
healthy; the band brings the largest excess down to 0.06 to 0.34 %. Measured on those 9 motions, the
windowed RMS of the actual parameter error's effect stayed within 1.1 to 5.0 times the band's (above
c = 4.30 in three: the estimator's covariance is optimistic on this motion, delta^T Sigma^-1 delta
reached 27 for the 4 speed parameters), within 0.7 to 1.6 times on 4 standard tool changes. A
friction step during the motion (Cd 1.2 -> 2.4 N m) still leaves 2.1 % beyond the band.

The size rule is needed: an open-loop speed simulation integrates every small model imperfection (the
filtered sign(w) at reversals, estimation error), so even the true model gives a coloured speed residue,
and the true model's current residue has small bursts at the torque steps (the plant's sampled signals
do not satisfy eq. 1 exactly there: burst p down to 6e-4, worst window 1e-3 of the range); neither
matters. The simulation smooths sign(w) as tanh(w / w_eps) with the smallest w_eps its step allows
(friction stiffness Cd / (Jt w_eps) times the 0.5 ms step at most 1: 6e-3 rad/s, the plant's 1e-3 is
too stiff for it): with 0.1 rad/s the true model's worst speed window was 1.5 % of the range on the slow
motion (it creeps through the dwell at the tool-change position), with 6e-3 rad/s it is 0.2 %
(0.02 % on the standard motion). A white Gaussian residue is noise, however large. A mismatch means
the parameters are NOT validated; they are still reported.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import casadi as ca
import numpy as np
from scipy import stats
from statsmodels.stats.diagnostic import acorr_ljungbox

from feeddrive.estimator.errors import EstimatorInputError
from feeddrive.estimator.filtering import FilterSpec
from feeddrive.estimator.simulation import MODEL, simulate_speed
from feeddrive.estimator.validation import model_reference

#: physical parameters each simulated output depends on (from the model's equations)
USES = {signal: tuple(v.name for v in MODEL.parameters
                      if v.kind == "physical" and ca.depends_on(MODEL.equations[eq].residual, v.sym))
        for signal, eq in (("speed", "mechanical"), ("current", "electrical"))}


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
    peak_rms_relative : float
        Largest RMS over a sliding window / range of the measured signal.
    excess_relative : float
        Largest over the windows of ``residue RMS - band_factor * band RMS``, / range (the size the rule
        compares with ``rms_tol``; ``peak_rms_relative`` without a band).
    band_relative : float
        RMS of the band over the window of ``excess_relative``, / range (0 without a band).
    band_factor : float
        c of the module docstring (0 without a band).
    burst_z, burst_p : float
        Largest robust z-score of the block means and its Sidak-corrected p-value.
    passed : bool
    simulated, residue : ndarray, shape (n,)
        Simulated signal and ``measured - simulated`` (filtered), in the signal's unit.
    band : ndarray, shape (n,) or None
        sigma(t), the standard deviation of the simulated signal due to the parameters' uncertainty
        (signal's unit); None without a covariance.
    """

    signal: str
    statistic: float
    p_value: float
    lags: int
    rms_relative: float
    peak_rms_relative: float
    excess_relative: float
    band_relative: float
    band_factor: float
    burst_z: float
    burst_p: float
    passed: bool
    simulated: np.ndarray = field(repr=False)
    residue: np.ndarray = field(repr=False)
    band: np.ndarray | None = field(repr=False)


@dataclass(frozen=True)
class MismatchResult:
    """Model validation of one motion; ``test``, ``statistic`` and ``p_value`` are those of the smaller
    p-value (``ljung-box`` or ``burst``) of the failing (or worst) check, or ``size`` (see the module
    docstring)."""

    test: str
    statistic: float
    p_value: float
    passed: bool
    checks: dict[str, ResidueCheck]
    alpha: float
    rms_tol: float

    def to_dict(self) -> dict:
        """``test, statistic, p_value, passed`` and, per signal, ``rms_relative, peak_rms_relative,
        excess_relative, band_relative, band_factor, burst_p``."""
        per = {key: {k: getattr(c, key) for k, c in self.checks.items()}
               for key in ("rms_relative", "peak_rms_relative", "excess_relative", "band_relative", "band_factor",
                           "burst_p")}
        return {"test": self.test, "statistic": self.statistic, "p_value": self.p_value, "passed": self.passed,
                **per}


def residue_check(name: str, measured: np.ndarray, simulated: np.ndarray, h: float, alpha: float, rate_hz: float,
                  lags: int, rms_tol: float, window_s: float = 0.05, edge_s: float = 0.0,
                  band: np.ndarray | None = None, band_factor: float = 0.0) -> ResidueCheck:
    """Judge one output-error residue; see the module docstring. Arrays have shape (n,); h, window_s and
    edge_s (time left out of the windows and burst blocks at each end) in seconds; ``band`` is sigma(t)
    (signal's unit) and a window's RMS residue may exceed ``rms_tol`` of the range by ``band_factor``
    times the band's RMS over that window."""
    r = measured - simulated
    if band is not None and np.shape(band) != r.shape:
        raise EstimatorInputError(f"model check ({name}): band has shape {np.shape(band)}, the residue {r.shape}")
    block = max(1, int(round(1.0 / (rate_hz * h))))
    nb = r.size // block
    if nb < 2 * lags + 2:
        raise EstimatorInputError(
            f"model check: {r.size} samples give {nb} blocks at {rate_hz} Hz; need {2 * lags + 2} for {lags} lags")
    decimated = r[:nb * block].reshape(nb, block).mean(axis=1)
    lb = acorr_ljungbox(decimated, lags=[lags])
    stat, p = float(lb["lb_stat"].iloc[0]), float(lb["lb_pvalue"].iloc[0])
    eb = int(np.ceil(edge_s / (block * h)))
    inner_blocks = decimated[eb:nb - eb] if nb > 2 * eb + 2 else decimated
    deviation = float(np.max(np.abs(inner_blocks - np.median(inner_blocks))))
    scale = float(stats.median_abs_deviation(inner_blocks, scale="normal"))
    burst_z = deviation / scale if scale > 0 else (np.inf if deviation > 0 else 0.0)
    burst_p = float(-np.expm1(inner_blocks.size * np.log1p(-2 * stats.norm.sf(burst_z))))
    span = float(np.ptp(measured)) or 1.0
    rms = float(np.sqrt(np.mean(r**2))) / span
    edge, m = int(round(edge_s / h)), max(1, int(round(window_s / h)))
    keep = slice(edge, r.size - edge) if r.size - 2 * edge >= m else slice(None)
    m = min(m, r[keep].size)
    size, spread = (window_rms(x[keep], m) / span for x in (r, np.zeros_like(r) if band is None else band))
    excess = size - band_factor * spread
    worst = int(np.argmax(excess))
    white = p >= alpha and burst_p >= alpha
    return ResidueCheck(name, stat, p, lags, rms, float(size.max()), float(excess[worst]),
                        float(spread[worst]), float(band_factor), float(burst_z), burst_p,
                        bool(white or excess[worst] <= rms_tol), simulated, r, band)


def window_rms(x: np.ndarray, m: int) -> np.ndarray:
    """RMS over every window of ``m`` consecutive samples.

    Parameters
    ----------
    x : ndarray, shape (n,)
    m : int
        Window length in samples, ``1 <= m <= n``.

    Returns
    -------
    ndarray, shape (n - m + 1,)
        Element k is the RMS of ``x[k:k + m]`` (unit of x).
    """
    energy = np.concatenate(([0.0], np.cumsum(x**2)))
    return np.sqrt(np.maximum(energy[m:] - energy[:-m], 0.0) / m)


def uncertainty_band(simulate: Callable[[dict[str, float]], np.ndarray], parameters: Mapping[str, float],
                     names: Sequence[str], covariance: np.ndarray, uses: Sequence[str],
                     base: np.ndarray | None = None) -> tuple[np.ndarray, int]:
    """Standard deviation of a simulated signal due to the parameters' uncertainty.

    ``sigma(t) = sqrt(diag(S Sigma S^T))`` with S the sensitivity of the signal to the parameters it uses
    and Sigma their covariance. Writing ``Sigma = sum_k lambda_k v_k v_k^T`` (principal axes),
    ``S Sigma S^T = sum_k d_k d_k^T`` with ``d_k = S sqrt(lambda_k) v_k``, taken as the finite difference
    ``simulate(theta + sqrt(lambda_k) v_k) - simulate(theta)``: one simulation per axis, each step one
    standard deviation along it, so also the curvature at the scale of the uncertainty is in the band.

    Parameters
    ----------
    simulate : callable
        ``simulate(parameters) -> ndarray, shape (n,)``.
    parameters : mapping of str to float
        The estimate theta.
    names : sequence of str, length p
        Names of the covariance's rows.
    covariance : ndarray, shape (p, p)
        Covariance of the estimate (unit of each parameter squared).
    uses : sequence of str
        Parameters the signal depends on; the others' rows are left out.
    base : ndarray, shape (n,), optional
        ``simulate(parameters)`` when already computed.

    Returns
    -------
    band : ndarray, shape (n,)
        sigma(t), in the signal's unit.
    rank : int
        Number of principal axes with a positive variance (the degrees of freedom of the parameter error).
    """
    rows = [j for j, name in enumerate(names) if name in uses]
    variances, axes = np.linalg.eigh(np.asarray(covariance, dtype=float)[np.ix_(rows, rows)])
    base = simulate(dict(parameters)) if base is None else base
    positive = variances > 1e-12 * max(variances.max(initial=0.0), np.finfo(float).tiny)
    power = np.zeros_like(base)
    for variance, axis in zip(variances[positive], axes.T[positive]):
        step = dict(parameters)
        for j, delta in zip(rows, np.sqrt(variance) * axis):
            step[names[j]] += delta
        power += (simulate(step) - base) ** 2
    return np.sqrt(power), int(positive.sum())


def check_model(u: np.ndarray, i: np.ndarray, w: np.ndarray, h: float, parameters: Mapping[str, float],
                filter: FilterSpec, alpha: float = 1e-3, rate_hz: float = 50.0, lags: int = 10,
                rms_tol: float = 0.01, window_s: float = 0.05, covariance: np.ndarray | None = None,
                names: Sequence[str] | None = None) -> MismatchResult:
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
        Level of the Ljung-Box test (and of the uncertainty band).
    rate_hz : float
        Rate of the decimated residue the test sees [Hz].
    lags : int
        Ljung-Box lags.
    rms_tol : float
        RMS residue over the worst window, as a fraction of the measured signal's range, below which the
        model is accepted (beyond the uncertainty band, when ``covariance`` is given).
    window_s : float
        Length of the sliding window of that RMS [s]; ``5 / cutoff`` seconds at each end are left out
        (the zero-phase filter's transients, the simulations' start).
    covariance : ndarray, shape (p, p), optional
        Covariance of the estimated parameters (``MotionEstimate.covariance``); None: no uncertainty
        band, only ``rms_tol``.
    names : sequence of str, length p
        The covariance's parameters (``MotionEstimate.names``); required with ``covariance``.

    Returns
    -------
    MismatchResult
    """
    missing = [k for k in ("R", "L", "K", "Jt", "ft", "Cd") if k not in parameters]
    if missing:
        raise EstimatorInputError(f"check_model: parameters {missing} are missing")
    if covariance is not None:
        covariance = np.asarray(covariance, dtype=float)
        if names is None or covariance.shape != (len(names), len(names)) or not np.all(np.isfinite(covariance)):
            raise EstimatorInputError(f"check_model: covariance must be a finite (p, p) matrix with p = len(names), "
                                      f"got shape {covariance.shape} for names {names}")
        unknown = [k for k in names if k not in parameters]
        if unknown:
            raise EstimatorInputError(f"check_model: covariance names {unknown} are not in the parameters")
    f = filter.apply({"u": u, "i": i, "w": w}, h)
    params = {k: float(v) for k, v in parameters.items()}
    decimate = max(h, 1.0 / (20.0 * filter.cutoff_hz))  # integration step: 20 per filter cut-off period
    # the sharpest sign(w) the step allows: friction stiffness Cd / (Jt w_eps) times the step at most 1
    w_eps = max(float(MODEL.variables["w_eps"].nominal), abs(params["Cd"]) * decimate / max(abs(params["Jt"]), 1e-12))
    simulators = {
        "speed": ("w", lambda p: simulate_speed(f["i"], p, h, w0=float(f["w"][0]), step=decimate, w_eps=w_eps)),
        "current": ("i", lambda p: model_reference("current", f, h, p)),  # linear: exact Tustin recursion
    }
    edge_s = 5.0 / filter.cutoff_hz
    checks = {}
    for name, (x, simulate) in simulators.items():
        simulated, band, factor = simulate(params), None, 0.0
        if covariance is not None:
            band, rank = uncertainty_band(simulate, params, names, covariance, USES[name], simulated)
            factor = float(np.sqrt(stats.chi2.isf(alpha, rank))) if rank else 0.0
        checks[name] = residue_check(name, f[x], simulated, h, alpha, rate_hz, lags, rms_tol, window_s, edge_s,
                                     band, factor)
    worst = min(checks.values(), key=lambda c: (c.passed, min(c.p_value, c.burst_p)))
    test, statistic, p = min((("ljung-box", worst.statistic, worst.p_value), ("burst", worst.burst_z, worst.burst_p)),
                             key=lambda t: t[2])
    passed = all(c.passed for c in checks.values())
    if passed and p < alpha:
        # coloured but small: the size rule decided; say so, with its statistic (worst window beyond the band)
        test, statistic = "size", max(c.excess_relative for c in checks.values())
    return MismatchResult(test, statistic, p, passed, checks, alpha, rms_tol)
