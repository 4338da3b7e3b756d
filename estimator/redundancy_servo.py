"""Measurement validation of a servo drive (PMSM): its analytical and material redundancies (issue 25 item 4).

The DC drive's pairs (paper section IV.B, ``estimator.validation``) become, on a three-phase servo drive:

* **phase-current sum** (analytical redundancy): the winding is star-connected without a neutral, so the
  true phase currents sum to zero; the measured sum ``r = I_U + I_V + I_W`` is noise unless a phase sensor
  has a gain or offset fault (``phase_current_sum``);
* **two sensors on one phase** (material redundancy, as the paper's two current sensors): the paper's
  residue test and gain ratio (``validation.residue_test``, ``validation.gain_ratio``) on an AC signal
  (``phase_sensor_pair``);
* **dq current consistency**: the q and d currents a drive reports against the Park transform of its phase
  currents; this catches a mis-scaled current output, such as an rms value taken for a peak
  (``dq_current_consistency``);
* **voltage reference against terminal voltage**: the inverter's dead time costs each leg
  ``t_dead f_pwm u_dc`` against its current's sign. That loss is modelled (``dead_time_loss``), not flagged:
  the test is on ``u_ref - loss - u`` (``voltage_reference_check``), and the loss is also estimated; without
  a voltage sensor ``u`` is observed from the dq equations (``observed_terminal_voltage``);
* **motor encoder against the linear scale**: their difference is constant while the axis moves in one
  direction and jumps by the lost motion (backlash) at each reversal; ``lost_motion`` estimates it with an
  interval and tests it at ``alpha`` (the commercial "fingerprint" test with two encoders).

Conventions: amplitude-invariant Park transform (dq values are phase peak values, as in
``models.pmsm``), electrical angle ``phi_el = p theta``; ``i_a = i_d cos(phi) - i_q sin(phi)`` and the
phases B, C lag by 120 and 240 degrees. All arrays are 1-D of the same length ``n``, sampled every ``h``
seconds. These functions take arrays and return frozen results; the monitor wiring is the caller's.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from feeddrive.estimator.distributions import chi2_sf, t_ppf, t_sf
from feeddrive.estimator.errors import EstimatorInputError
from feeddrive.estimator.hac import ols_hac
from feeddrive.estimator.validation import ResidueTest, ValidationOptions, gain_ratio, noise_std, residue_test

PHASES = ("U", "V", "W")
_DEFAULT = ValidationOptions()


def _arrays(*xs: np.ndarray, names: Sequence[str]) -> list[np.ndarray]:
    out = [np.asarray(x, dtype=float) for x in xs]
    for x, name in zip(out, names):
        if x.ndim != 1 or x.size != out[0].size:
            raise EstimatorInputError(f"{name}: expected a 1-D array of {out[0].size} samples, got shape {x.shape}")
        if not np.all(np.isfinite(x)):
            raise EstimatorInputError(f"{name}: contains NaN or inf")
    return out


def inverse_park(d: np.ndarray, q: np.ndarray, phi_el: np.ndarray) -> np.ndarray:
    """Phase values from dq values (amplitude invariant): shape (3, n), rows U, V, W, in the unit of ``d, q``."""
    d, q, phi = np.asarray(d, float), np.asarray(q, float), np.asarray(phi_el, float)
    shifts = np.array([0.0, 2 * math.pi / 3, 4 * math.pi / 3])[:, None]
    return d * np.cos(phi - shifts) - q * np.sin(phi - shifts)


def park(abc: np.ndarray, phi_el: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(d, q)`` of phase values ``abc`` (shape (3, n)); the zero sequence is ignored."""
    abc, phi = np.asarray(abc, float), np.asarray(phi_el, float)
    shifts = np.array([0.0, 2 * math.pi / 3, 4 * math.pi / 3])[:, None]
    return 2 / 3 * np.sum(abc * np.cos(phi - shifts), axis=0), -2 / 3 * np.sum(abc * np.sin(phi - shifts), axis=0)


# -- currents ---------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class PhaseSumCheck:
    """Result of ``phase_current_sum``.

    Attributes
    ----------
    faulty : bool
        The sum's residue is significant at ``alpha`` and larger than the tolerances.
    phase : str or None
        The isolated phase (``U``, ``V``, ``W``) under the single-fault hypothesis; None when healthy or when
        only an offset is seen (an offset on the sum cannot be attributed to one phase).
    gain : float
        Estimated gain [1] of ``phase`` (``I_meas = gain I_true + offset``); 1.0 when healthy.
    offset : float
        Offset of the sum [A] (the faulty phase's offset under the single-fault hypothesis).
    offset_ci95 : (float, float)
    p_value : float
        p-value of the joint Wald test that the sum is noise only.
    noise_std : float
        High-frequency std of the sum [A] (about sqrt(3) x one sensor's noise).
    """

    faulty: bool
    phase: str | None
    gain: float
    offset: float
    offset_ci95: tuple[float, float]
    p_value: float
    noise_std: float


def phase_current_sum(i_u: np.ndarray, i_v: np.ndarray, i_w: np.ndarray, alpha: float = 1e-3,
                      gain_tol: float = 0.005, offset_tol: float = 0.005) -> PhaseSumCheck:
    """Test the analytical redundancy ``I_U + I_V + I_W = 0`` of a star-connected winding.

    With sensors ``I_k = a_k i_k + b_k + noise`` and ``sum_k i_k = 0``, the measured sum is
    ``r = (a_U - a_W) i_U + (a_V - a_W) i_V + sum_k b_k + noise``: it is regressed on ``[I_U, I_V, 1]``
    (OLS, Newey-West errors) and the three coefficients are tested jointly (Wald, chi-square with 3 degrees
    of freedom). A fault is declared when ``p < alpha`` and its size passes a tolerance (a relative gain
    difference above ``gain_tol``, or an offset above ``offset_tol`` times the largest phase current).
    Isolation assumes one faulty phase: ``r = e I_k + b`` is fitted for each k and the best fit names the
    phase, with ``gain = 1 / (1 - e)``.

    Parameters
    ----------
    i_u, i_v, i_w : ndarray, shape (n,)
        Measured phase currents [A], n >= 50, covering at least a few electrical periods.
    alpha, gain_tol, offset_tol : float
        Test level; tolerances (relative gain; offset as a fraction of the largest |I|).

    Returns
    -------
    PhaseSumCheck
    """
    i_u, i_v, i_w = _arrays(i_u, i_v, i_w, names=("i_u", "i_v", "i_w"))
    if i_u.size < 50:
        raise EstimatorInputError(f"phase_current_sum: {i_u.size} samples; need at least 50")
    r = i_u + i_v + i_w
    X = np.column_stack([i_u, i_v, np.ones_like(i_u)])
    res = ols_hac(r, X, maxlags=16)
    beta, cov = res.params, res.cov
    p = float(chi2_sf(float(beta @ np.linalg.solve(cov, beta)), 3))
    span = float(np.max(np.abs([i_u, i_v, i_w])))
    # single fault: the best of r = e I_k + b
    fits = []
    for k, x in enumerate((i_u, i_v, i_w)):
        A = np.column_stack([x, np.ones_like(x)])
        coef, *_ = np.linalg.lstsq(A, r, rcond=None)
        fits.append((float(np.sum((r - A @ coef) ** 2)), k, coef))
    _, k, (e, b) = min(fits)
    gain = 1.0 / (1.0 - e)
    off_ci = tuple(float(v) for v in res.conf_int(0.05)[2])
    big_gain = abs(gain - 1.0) > gain_tol
    big_offset = abs(beta[2]) > offset_tol * span
    faulty = p < alpha and (big_gain or big_offset)
    phase = PHASES[k] if faulty and big_gain else None
    return PhaseSumCheck(bool(faulty), phase, float(gain) if faulty and big_gain else 1.0, float(beta[2]),
                         off_ci, p, noise_std(r))


@dataclass(frozen=True)
class PhasePairCheck:
    """The paper's two sensors on one phase: ``residue`` (eq. 10 on short windows) and ``gain_ratio`` (eq. 12)."""

    residue: ResidueTest
    gain_ratio: float

    @property
    def faulty(self) -> bool:
        return self.residue.kind != "none"


def phase_sensor_pair(x1: np.ndarray, x2: np.ndarray, h: float, window_s: float = 5e-4,
                      options: ValidationOptions = _DEFAULT) -> PhasePairCheck:
    """Two current sensors on one phase (material redundancy), by ``validation``'s residue test and gain ratio.

    The phase current is AC, so the residue's windows must be short against the electrical period (the
    window means carry the level the gain is regressed on): ``window_s`` (default 0.5 ms, a sixteenth of the
    period at 120 Hz) replaces ``options.window_s``.

    Parameters
    ----------
    x1, x2 : ndarray, shape (n,)
        The two sensors' samples [A].
    h : float
        Sample time [s].
    window_s : float
        Residue window [s].
    options : ValidationOptions
        Level and tolerances (``alpha``, ``gain_tol``, ``offset_tol``).

    Returns
    -------
    PhasePairCheck
    """
    x1, x2 = _arrays(x1, x2, names=("x1", "x2"))
    opts = ValidationOptions(alpha=options.alpha, window_s=window_s, gain_tol=options.gain_tol,
                             offset_tol=options.offset_tol, edge_s=options.edge_s)
    return PhasePairCheck(residue_test(x1, x2, h, opts), gain_ratio(x1, x2))


@dataclass(frozen=True)
class DQConsistency:
    """``dq_current_consistency``: the reported q current's gain against the phase currents' Park transform."""

    gain: float
    gain_ci95: tuple[float, float]
    faulty: bool


def dq_current_consistency(i_q: np.ndarray, i_u: np.ndarray, i_v: np.ndarray, i_w: np.ndarray,
                           phi_el: np.ndarray, alpha: float = 1e-3, gain_tol: float = 0.005) -> DQConsistency:
    """Fit ``i_q_reported = gain * q(Park(I_U, I_V, I_W)) + b`` (OLS, Newey-West); faulty when the gain's
    ``1 - alpha`` interval excludes 1 and ``|gain - 1| > gain_tol``. An rms value mapped as a peak without its
    factor gives ``gain = 1 / sqrt(2)``.

    Parameters
    ----------
    i_q : ndarray, shape (n,)
        The q current as read from the drive [A, peak expected].
    i_u, i_v, i_w : ndarray, shape (n,)
        Phase currents [A].
    phi_el : ndarray, shape (n,)
        Electrical angle [rad].
    """
    i_q, i_u, i_v, i_w, phi = _arrays(i_q, i_u, i_v, i_w, phi_el, names=("i_q", "i_u", "i_v", "i_w", "phi_el"))
    _, q = park(np.vstack([i_u, i_v, i_w]), phi)
    res = ols_hac(i_q, np.column_stack([q, np.ones_like(q)]), maxlags=16)
    lo, hi = res.conf_int(alpha)[0]
    g = float(res.params[0])
    lo95, hi95 = res.conf_int(0.05)[0]
    return DQConsistency(g, (float(lo95), float(hi95)), bool(not lo <= 1.0 <= hi and abs(g - 1) > gain_tol))


# -- voltages ---------------------------------------------------------------------------------------------------


def dead_time_loss(i_u: np.ndarray, i_v: np.ndarray, i_w: np.ndarray, phi_el: np.ndarray, u_loss: float,
                   i_eps: float = 0.2) -> tuple[np.ndarray, np.ndarray]:
    """The inverter's dead-time loss in the dq frame [V], shape (n,) each.

    Each leg loses ``u_loss = t_dead f_pwm u_dc`` against the smoothed sign of its current,
    ``i / sqrt(i^2 + i_eps^2)``; the common mode does not reach a star-connected winding (removed), the rest
    is Park-transformed. Its fundamental is ``(4 / pi) u_loss`` along the current vector.
    """
    abc = np.vstack([i_u, i_v, i_w])
    loss = u_loss * abc / np.sqrt(abc**2 + i_eps**2)
    loss -= loss.mean(axis=0)
    return park(loss, phi_el)


def observed_terminal_voltage(i_d: np.ndarray, i_q: np.ndarray, theta: np.ndarray, h: float, R: float, L_d: float,
                              L_q: float, psi_f: float, p: float) -> tuple[np.ndarray, np.ndarray]:
    """The terminal voltages the dq equations give for measured currents and motor angle, for a drive without
    a voltage sensor: ``u_d = R i_d + L_d di_d/dt - p w L_q i_q``, ``u_q = R i_q + L_q di_q/dt + p w (psi_f +
    L_d i_d)``, with ``w = dtheta/dt`` and the derivatives by central differences (``numpy.gradient``).

    Parameters
    ----------
    i_d, i_q : ndarray, shape (n,)
        dq currents [A, peak] (e.g. the Park transform of the phase currents).
    theta : ndarray, shape (n,)
        Motor angle [rad] (the encoder's).
    h : float
        Sample time [s].
    R, L_d, L_q, psi_f, p : float
        The motor's resistance [Ohm], inductances [H], magnet flux [Wb] and pole pairs (the last validated
        values, as the paper's isolation uses).

    Returns
    -------
    (ndarray, ndarray)
        ``u_d, u_q`` [V], shape (n,) each. The current noise is amplified by ``L / h`` (a few V at 10 kHz); the
        residue test's window means average it out.
    """
    i_d, i_q, theta = _arrays(i_d, i_q, theta, names=("i_d", "i_q", "theta"))
    w = np.gradient(theta, h)
    u_d = R * i_d + L_d * np.gradient(i_d, h) - p * w * L_q * i_q
    u_q = R * i_q + L_q * np.gradient(i_q, h) + p * w * (psi_f + L_d * i_d)
    return u_d, u_q


@dataclass(frozen=True)
class VoltageCheck:
    """``voltage_reference_check``: per axis (``d``, ``q``) the residue test of ``u`` against ``u_ref - loss``,
    the estimated per-leg loss ``u_loss`` [V] with its 95 % interval, and the mean gap [V] that an
    unmodelled dead time would leave (what a naive comparison would flag)."""

    residue: dict[str, ResidueTest]
    u_loss: float
    u_loss_ci95: tuple[float, float]
    uncorrected_gap: dict[str, float]

    @property
    def faulty(self) -> bool:
        return any(r.kind != "none" for r in self.residue.values())


def voltage_reference_check(u_d_ref: np.ndarray, u_q_ref: np.ndarray, u_d: np.ndarray, u_q: np.ndarray,
                            i_u: np.ndarray, i_v: np.ndarray, i_w: np.ndarray, phi_el: np.ndarray, h: float,
                            u_loss: float, i_eps: float = 0.2,
                            options: ValidationOptions = _DEFAULT) -> VoltageCheck:
    """The drive's voltage references against the measured (or observed) terminal voltages, the dead time modelled.

    Parameters
    ----------
    u_d_ref, u_q_ref : ndarray, shape (n,)
        Voltage references of the current regulator [V] (dq, phase peak).
    u_d, u_q : ndarray, shape (n,)
        Terminal voltages [V].
    i_u, i_v, i_w, phi_el : ndarray, shape (n,)
        Phase currents [A] and electrical angle [rad] (the loss's sign pattern).
    h : float
        Sample time [s].
    u_loss : float
        The drive's nominal per-leg loss ``t_dead f_pwm u_dc`` [V] (0 for an ideal inverter).
    i_eps : float
        Current scale of the loss's smooth sign [A].
    options : ValidationOptions
        Level, tolerances and residue windows of ``validation.residue_test``.

    Returns
    -------
    VoltageCheck
        A residue test per axis of ``u`` against ``u_ref - loss(u_loss)``; ``u_loss`` re-estimated by least
        squares of ``u_ref - u`` on the unit loss (both axes stacked) with a 95 % interval.
    """
    arrays = _arrays(u_d_ref, u_q_ref, u_d, u_q, i_u, i_v, i_w, phi_el,
                     names=("u_d_ref", "u_q_ref", "u_d", "u_q", "i_u", "i_v", "i_w", "phi_el"))
    u_d_ref, u_q_ref, u_d, u_q, i_u, i_v, i_w, phi = arrays
    unit_d, unit_q = dead_time_loss(i_u, i_v, i_w, phi, 1.0, i_eps)
    residue = {"d": residue_test(u_d, u_d_ref - u_loss * unit_d, h, options),
               "q": residue_test(u_q, u_q_ref - u_loss * unit_q, h, options)}
    y = np.concatenate([u_d_ref - u_d, u_q_ref - u_q])
    x = np.concatenate([unit_d, unit_q])
    est = float(x @ y / (x @ x))
    # the error of the estimate: white noise of the gap (first differences), stacked samples
    sigma = noise_std(y)
    se = sigma / math.sqrt(float(x @ x))
    gap = {"d": float(np.mean(u_d_ref - u_d)), "q": float(np.mean(u_q_ref - u_q))}
    return VoltageCheck(residue, est, (est - 1.96 * se, est + 1.96 * se), gap)


# -- positions --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class LostMotion:
    """``lost_motion``: the estimate [mm] with its 95 % interval, the one-sided test's p-value and decision.

    Attributes
    ----------
    value_mm : float
        Mean of ``s_mot - s_lin`` moving forward minus its mean moving backward [mm].
    ci95_mm : (float, float)
    p_value : float
        One-sided Welch test of ``lost motion <= allowed_mm`` on the batch means.
    detected : bool
        ``p_value < alpha``.
    batches : (int, int)
        Number of batch means forward and backward.
    """

    value_mm: float
    ci95_mm: tuple[float, float]
    p_value: float
    detected: bool
    batches: tuple[int, int]


def lost_motion(s_mot_mm: np.ndarray, s_lin_mm: np.ndarray, h: float, alpha: float = 0.01,
                allowed_mm: float = 0.0, settle_mm: float = 0.2, v_min_mm_s: float = 1.0,
                a_max_mm_s2: float = 200.0, batches: int = 6) -> LostMotion:
    """Lost motion (backlash) of the drive chain from the motor encoder and the linear scale on one motion.

    While the axis moves in one direction the difference ``d = s_mot - s_lin`` is constant (plus the
    encoders' noise); at a reversal the motor turns through the lost motion before the table follows, so
    ``d`` moving forward minus ``d`` moving backward is the lost motion: the backlash plus the deflection of
    the drive chain under the table's friction, twice (what a reversal test with two encoders measures). The
    deflection under acceleration is not lost motion: samples where the motor side accelerates faster than
    ``a_max_mm_s2`` (second difference over 5 ms, ~30 mm/s^2 of encoder noise) are left out. The samples moving faster than
    ``v_min_mm_s`` are kept, except those within ``settle_mm`` of motor travel after the last reversal (the
    play being taken up). Each direction's kept samples are cut into ``batches`` consecutive parts, whose
    means are close to independent even for coloured encoder errors; Welch's t-test on the batch means gives
    the interval and the one-sided test of ``H0: lost motion <= allowed_mm`` at ``alpha``.

    Parameters
    ----------
    s_mot_mm : ndarray, shape (n,)
        Table position from the motor encoder (motor angle x pitch / 2 pi) [mm].
    s_lin_mm : ndarray, shape (n,)
        Table position on the linear scale [mm].
    h : float
        Sample time [s].
    alpha : float
        Level of the test.
    allowed_mm : float
        The lost motion tolerated (the test's null) [mm].
    settle_mm, v_min_mm_s, a_max_mm_s2 : float
        Travel skipped after a reversal [mm]; slowest kept speed [mm/s]; largest kept acceleration [mm/s^2].
    batches : int
        Batch means per direction (consecutive kept samples, in time order, cut into equal parts).

    Returns
    -------
    LostMotion

    Raises
    ------
    EstimatorInputError
        The motion does not move at least two batches in each direction.
    """
    s_mot, s_lin = _arrays(s_mot_mm, s_lin_mm, names=("s_mot_mm", "s_lin_mm"))
    if not h > 0:
        raise EstimatorInputError(f"lost_motion: h must be > 0, got {h!r}")
    # direction from the motor side, smoothed over ~1 ms so the encoder's counts do not flip it
    k = max(1, int(round(1e-3 / h)))
    v = np.empty_like(s_mot)
    v[k:] = (s_mot[k:] - s_mot[:-k]) / (k * h)
    v[:k] = v[k] if s_mot.size > k else 0.0
    direction = np.where(v > v_min_mm_s, 1, np.where(v < -v_min_mm_s, -1, 0))
    # travel since the last reversal (the last sample where the motor's motion changed sign)
    keep = np.zeros(s_mot.size, dtype=bool)
    anchor, current = s_mot[0], 0
    for j in range(s_mot.size):
        dj = direction[j]
        if dj != 0 and dj != current:
            anchor = s_mot[max(j - k, 0)]
            current = dj
        keep[j] = dj != 0 and abs(s_mot[j] - anchor) > settle_mm
    K = max(1, int(round(5e-3 / h)))
    accel = np.full(s_mot.size, np.inf)
    accel[K:-K] = (s_mot[2 * K:] - 2 * s_mot[K:-K] + s_mot[:-2 * K]) / (K * h) ** 2
    keep &= np.abs(accel) <= a_max_mm_s2
    d = s_mot - s_lin
    means = []
    for sign in (1, -1):
        idx = np.flatnonzero(keep & (direction == sign))
        means.append(np.array([d[part].mean() for part in np.array_split(idx, batches)]) if idx.size >= 20 * batches
                     else np.array([]))
    fwd, bwd = means
    if fwd.size < 2 or bwd.size < 2:
        raise EstimatorInputError(f"lost_motion: {np.count_nonzero(keep & (direction == 1))} forward and "
                                  f"{np.count_nonzero(keep & (direction == -1))} backward samples at constant speed "
                                  f"beyond {settle_mm} mm of travel; need {20 * batches} each (a motion out and back)")
    value = float(fwd.mean() - bwd.mean())
    v1, v2 = fwd.var(ddof=1) / fwd.size, bwd.var(ddof=1) / bwd.size
    se = math.sqrt(v1 + v2) or np.finfo(float).tiny
    dof = (v1 + v2) ** 2 / ((v1**2 / (fwd.size - 1) if v1 else 0) + (v2**2 / (bwd.size - 1) if v2 else 0) or 1e-300)
    dof = float(min(dof, fwd.size + bwd.size - 2))
    tq = float(t_ppf(0.975, dof))
    p = float(t_sf((value - allowed_mm) / se, dof))
    return LostMotion(value, (value - tq * se, value + tq * se), p, p < alpha, (int(fwd.size), int(bwd.size)))
