"""Excitation design: the slope of the rapid move's trapezoid that minimises the parameters' variance.

The paper (section II.C) allows the monitor to adapt only the slope (acceleration) of the NC's
trapezoidal speed profile: no PRBS, which would age the drive and does not fit in a tool change.
For a move of given distance and top speed, each candidate acceleration ``a`` is scored by the
Fisher information of the estimator's own regressions:

1. simulate the noise-free closed-loop plant (``models.feed_drive()``, speed and current PI loops,
   RK4 with ``substeps`` per sample) driven by the speed reference of the move at ``a``;
2. build the regressions exactly as the estimator does (``estimator.estimate.prepare``: filter,
   zero-forcing derivatives, samples with ``|w|`` below the speed threshold left out of the
   equations with sign(w));
3. predicted covariance of each equation's least-squares estimate, ``A^-1 Phi^T R Phi A^-1`` with
   ``A = Phi^T Phi`` (the Fisher information of the regression) and ``R`` the autocovariance of the
   equation error that the white sensor noises (voltage, current, speed) produce after the
   estimator's filter and derivative; with white noise on the output only this is the textbook
   ``sigma^2 (Phi^T Phi)^-1``, which underestimates the friction parameters' variance several times
   because the tachometer noise enters eq. 5 differentiated. Jt, ft, Cd = theta_m K: relative
   variances add (delta method, independent equations);
4. criterion ``J(a) = sum_p (std_p / p)^2`` over R, L, K, Jt, ft, Cd (sum of squared relative
   standard errors); candidates whose noise-free current or voltage reaches the drive's limits
   (``i_max``, ``u_max``) are infeasible.

The prediction is first order: it ignores the bias that noise in the regressors gives LS (IV
removes it) and the noise of sign(w) near the excluded low speeds. ``cosim design --verify`` checks
it with a small campaign.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np

from feeddrive.estimator.compiled import compiled_step
from feeddrive.estimator.derivative import zero_forcing_derivative
from feeddrive.estimator.errors import EstimatorInputError
from feeddrive.estimator.estimate import EstimationOptions, MotionData, prepare
from feeddrive.estimator.model_terms import ls_parts, signals_for
from feeddrive.estimator.motion import FIELDS
from feeddrive.estimator.simulation import rk4_step
from feeddrive.models.drives import drive_model, measured

MODEL = drive_model("dc")
PHYSICAL = tuple(v.name for v in MODEL.parameters if v.kind == "physical" and not v.optional)


def physical(model) -> tuple[str, ...]:
    """The model's physical parameters the design scores (not the optional offset)."""
    return tuple(v.name for v in model.parameters if v.kind == "physical" and not v.optional)


def motion_data(signals: Mapping[str, np.ndarray], h: float, model) -> MotionData:
    """The model's measured signals of ``signals`` as a motion (DC ``u, i, w``; PMSM ``u_q, u_d, i_q, i_d, w``)."""
    names = [k for k in (*measured(model), "w") if k in signals]
    fields = {k: signals[k] for k in names if k in FIELDS}
    return MotionData(h, **fields, signals={k: signals[k] for k in names if k not in FIELDS})


def peaks(signals: Mapping[str, np.ndarray], model) -> tuple[float, float]:
    """Peak current and voltage amplitudes [A, V] of the measured signals: the vector sum of those in A (in V)
    at each sample (DC: |i|, |u|; PMSM: the dq current and voltage vectors' amplitudes)."""
    out = []
    for unit in ("A", "V"):
        xs = [np.asarray(signals[k], dtype=float) for k in measured(model)
              if k in signals and model.variables[k].unit == unit]
        out.append(float(np.max(np.sqrt(sum(x ** 2 for x in xs)))) if xs else 0.0)
    return out[0], out[1]


@lru_cache(maxsize=8)
def _closed_loop_step(model, substeps: int):
    """The closed-loop plant's RK4 step and its compiled rollout (None without a C compiler): built once per
    model, not once per simulation (CasADi's ``mapaccum`` over a 4 s motion took ~1 s to build and as long
    to run; the compiled loop does the same operations in the same order, ``estimator.compiled``)."""
    step = rk4_step(model.rhs_function(), substeps)
    return step, compiled_step(step, f"{model.name}: closed loop, {substeps} RK4 substeps")


_CHUNK = 4096  # samples per call of the outputs' map: built once per model, not once per record length


@lru_cache(maxsize=8)
def _output_map(model):
    return model.output_function().map(_CHUNK)


def _outputs(model, X: np.ndarray, U: np.ndarray, p: np.ndarray) -> np.ndarray:
    """The model outputs (ny, m) at the states X (nx, m) and inputs U (nu, m), in chunks of one cached
    CasADi map (each column is computed as by a map over all m: the same operations)."""
    m = X.shape[1]
    pad = -m % _CHUNK
    X, U = (np.pad(A, ((0, 0), (0, pad)), mode="edge") for A in (X, U))
    P = np.tile(p, (_CHUNK, 1)).T
    F = _output_map(model)
    return np.hstack([np.asarray(F(X[:, j:j + _CHUNK], U[:, j:j + _CHUNK], P))
                      for j in range(0, m + pad, _CHUNK)])[:, :m]


def simulate_closed_loop(w_ref: np.ndarray, h: float, params: Mapping[str, float] | None = None,
                         substeps: int = 10, model=MODEL) -> dict[str, np.ndarray]:
    """Noise-free closed-loop plant driven by a speed reference, no load torque.

    Parameters
    ----------
    w_ref : ndarray, shape (n,)
        Speed reference [rad/s] at ``t_k = k h``, linearly interpolated in between. (Held constant,
        a ramp would become a staircase whose steps the cascade's proportional gains, Kp_i Kp_w ~
        150 V per rad/s, turn into a 10 kHz voltage sawtooth of ~3 V that biases R and L.)
    h : float
        Sampling period [s].
    params : mapping or None
        Model parameters overriding the nominal ones.
    substeps : int
        RK4 substeps per sample.
    model : models.Model
        The drive (default the DC feed drive; ``models.drives.drive_model("pmsm")`` for the PMSM).

    Returns
    -------
    dict of str to ndarray, each shape (n + 1,)
        The model outputs (``u``, ``u_ref``, ``i``, ``w``, ``theta``, ``x``, ``i_ref``) at
        ``t_k = k h``, k = 0..n, from rest (the last reference value held over the final period).
    """
    w_ref = np.asarray(w_ref, dtype=float)
    if w_ref.ndim != 1 or not np.all(np.isfinite(w_ref)):
        raise EstimatorInputError(f"w_ref must be a finite 1-D array, got shape {w_ref.shape}")
    nominal = model.nominal()
    unknown = sorted(set(params or {}) - set(nominal))
    if unknown:
        raise EstimatorInputError(f"unknown model parameters {unknown}")
    p = np.array([(dict(nominal) | dict(params or {}))[v.name] for v in model.parameters])
    n = len(w_ref)
    U = np.zeros((len(model.inputs), n + 1))
    U[[v.name for v in model.inputs].index("w_ref")] = np.append(w_ref, w_ref[-1])
    step, run = _closed_loop_step(model, substeps)
    S = np.vstack([U[:, :-1], U[:, 1:]])
    if run is not None:
        X = run(np.zeros(len(model.states)), S, p, h)
    else:
        X = np.asarray(step.mapaccum("rollout", n, [0], [0])(np.zeros(len(model.states)), S, p, h))
    X = np.hstack([np.zeros((len(model.states), 1)), X])
    Y = _outputs(model, X, U, p)
    return {v.name: Y[k] for k, v in enumerate(model.outputs)}


def _error_gains(reg, theta: np.ndarray, at: Mapping[str, float] | None = None) -> dict[str, float]:
    """Equation error ``y - Phi theta`` per unit of each signal, at the operating point ``at`` (signal -> value;
    default 0). The DC regressions are linear in the signals (except sign(w), whose noise is negligible away from
    the excluded low speeds), so the point does not matter; the PMSM's ``p w L_d i_d`` is bilinear, and its
    gains are taken at the motion's RMS speed and currents."""
    base = {name: np.full(1, float((at or {}).get(name, 0.0))) for name in reg.signals}
    y0, P0 = reg.evaluate(base)
    gains = {}
    for name in reg.signals:
        if name != "sgn_w" and name not in reg.constants:
            y1, P1 = reg.evaluate(base | {name: base[name] + 1.0})
            gains[name] = float((y1[0] - P1[0] @ theta) - (y0[0] - P0[0] @ theta))
    return gains


def _pipeline_responses(h: float, options: EstimationOptions) -> tuple[np.ndarray, np.ndarray]:
    """Impulse responses of the estimator's treatment of one signal: filtered, and filtered then
    differentiated (zero-forcing), aligned as in ``estimator.estimate.prepare``."""
    half = max(64, int(round(4.0 / (options.filter.cutoff_hz * h))))
    x = np.zeros(2 * half + 1)
    x[half] = 1.0
    f = options.filter.apply({"x": x}, h)["x"]
    d, valid = zero_forcing_derivative(f, h)
    return f[valid], d


def _toeplitz_times(acov: np.ndarray, Phi: np.ndarray) -> np.ndarray:
    """``R Phi`` with ``R[t, s] = acov[mid + t - s]`` (zero beyond the kernel), the equation error's
    autocovariance as a Toeplitz matrix, by FFT convolution of each column.

    Parameters
    ----------
    acov : ndarray, shape (2 mid + 1,)
        Symmetric autocovariance, lag 0 at ``mid``.
    Phi : ndarray, shape (n, p)

    Returns
    -------
    ndarray, shape (n, p)
        So that ``Phi.T @ R Phi = acov[mid] Phi^T Phi + sum_k acov[mid + k] (C_k + C_k^T)``,
        ``C_k = Phi[:-k]^T Phi[k:]`` (the sum over lags, in O(n log n) instead of O(mid n p^2)).
    """
    mid, n = len(acov) // 2, len(Phi)
    size = 1 << int(np.ceil(np.log2(n + len(acov) - 1)))
    full = np.fft.irfft(np.fft.rfft(Phi, size, axis=0) * np.fft.rfft(acov, size)[:, None], size, axis=0)
    return full[mid:mid + n]


def predicted_std(signals: Mapping[str, np.ndarray], h: float, noise: Mapping[str, float],
                  options: EstimationOptions = EstimationOptions(),
                  params: Mapping[str, float] | None = None) -> dict[str, float]:
    """Predicted relative standard error of each physical parameter from one motion.

    The least-squares estimate of each regression ``y = Phi theta`` (the estimator's own, on the
    noise-free signals) has the covariance ``A^-1 Phi^T R Phi A^-1``, ``A = Phi^T Phi``, where ``R`` is
    the autocovariance of the equation error that white sensor noise produces once it has gone
    through the estimator's filter and zero-forcing derivative (voltage noise enters eq. 4 through u;
    current noise through i and Di; speed noise through w and Dw, which dominates eq. 5). With white
    noise on the output alone and no filter it is the textbook ``sigma^2 (Phi^T Phi)^-1``.

    Parameters
    ----------
    signals : mapping of str to ndarray, each shape (n,)
        Noise-free measured signals of the motion (``options.model``'s: DC ``u`` [V], ``i`` [A], ``w``
        [rad/s]; PMSM ``u_q, u_d, i_q, i_d, w``).
    h : float
        Sampling period [s].
    noise : mapping of str to float
        White noise std of each measured signal at the sampling rate (DC ``u``, ``i`` and optionally ``w``);
        a signal not given is noise-free.
    options : EstimationOptions
        The estimator's options (model, filter, speed threshold).
    params : mapping or None
        True parameters (nominal by default), to turn theta_m = p / K into relative errors.

    Returns
    -------
    dict of str to float
        ``std_p / p`` for the model's physical parameters (DC: R, L, K, Jt, ft, Cd). An equation fitted jointly
        with a partner (the PMSM's d axis with the q axis) is predicted from its own samples only.
    """
    model = options.model
    truth = model.nominal() | dict(params or {})
    # on every sample: the noise's responses below are at the rate h (the decimated fit's spread is the same)
    prep = prepare(motion_data(signals, h, model), replace(options, decimation=1))
    g_f, g_d = _pipeline_responses(h, options)
    rel_var: dict[str, float] = {}
    for reg in prep.regressions:
        scale = truth[reg.normaliser] if reg.normaliser else 1.0
        theta = np.array([truth[name] / scale for name in reg.names])
        A, B = 0.0, 0.0
        # its own samples, and its partner's (the PMSM's d axis, whose p w L_q i_q carries most of L_q)
        for r, (_, Phi, _, rows) in zip((reg, prep.partners.get(reg.equation)), ls_parts(prep, reg)):
            sig = signals_for(prep, r)
            at = {k: (float(np.sqrt(np.mean(sig[k][rows] ** 2))) if k not in r.constants else float(sig[k][0]))
                  for k in r.signals}
            gains = _error_gains(r, np.array([truth[n] / scale for n in r.names]), at | {"sgn_w": 1.0})
            acov = sum(noise.get(x, 0.0) ** 2 * np.correlate(g, g, "full")
                       for x in dict.fromkeys((*measured(model), "w"))
                       if (g := gains.get(x, 0.0) * g_f + gains.get("D" + x, 0.0) * g_d).any())
            Phi = Phi * rows[:, None]  # excluded samples contribute nothing
            A = A + Phi.T @ Phi
            if np.ndim(acov) == 0:  # no noise reaches this equation
                continue
            B = B + Phi.T @ _toeplitz_times(acov, Phi)
        A_inv = np.linalg.pinv(A)
        cov = A_inv @ B @ A_inv
        for j, name in enumerate(reg.names):
            rel_var[name] = cov[j, j] / theta[j] ** 2
    for reg in prep.regressions:  # p = theta K: the relative variances add (independent equations)
        if reg.normaliser:
            for name in reg.names:
                rel_var[name] += rel_var[reg.normaliser]
    return {name: float(np.sqrt(rel_var[name])) for name in physical(model) if name in rel_var}


@dataclass(frozen=True)
class Candidate:
    """One acceleration: ``rel_std`` per parameter, ``criterion`` = sum of squares, feasibility."""

    accel: float
    duration: float
    rel_std: dict[str, float]
    criterion: float
    peak_current: float
    peak_voltage: float
    feasible: bool


def design_acceleration(reference: Callable[[float], np.ndarray], accels: Sequence[float], h: float,
                        noise: Mapping[str, float], options: EstimationOptions = EstimationOptions(),
                        params: Mapping[str, float] | None = None) -> tuple[Candidate, list[Candidate]]:
    """Score candidate accelerations and pick the feasible one with the smallest criterion.

    Parameters
    ----------
    reference : callable
        ``reference(accel) -> w_ref`` (ndarray (n,) [rad/s]): the motor speed reference of the
        motion at that acceleration [m/s^2], sampled every ``h``.
    accels : sequence of float
        Candidate accelerations [m/s^2].
    h : float
        Sampling period [s].
    noise : mapping of str to float
        Measurement noise std of each measured signal (as for ``predicted_std``).
    options, params
        As for ``predicted_std`` (``options.model``: the drive simulated and scored).

    Returns
    -------
    best : Candidate
    candidates : list of Candidate
        In the order of ``accels``.

    Raises
    ------
    EstimatorInputError
        When no candidate is feasible.
    """
    model = options.model
    limits = model.nominal() | dict(params or {})
    candidates = []
    for a in accels:
        w_ref = reference(float(a))
        sig = simulate_closed_loop(w_ref, h, params, model=model)
        peak_i, peak_u = peaks(sig, model)
        rel = predicted_std(sig, h, noise, options, params)
        feasible = peak_i < 0.99 * limits["i_max"] and peak_u < 0.99 * limits["u_max"]
        candidates.append(Candidate(float(a), len(w_ref) * h, rel, float(sum(v ** 2 for v in rel.values())),
                                    peak_i, peak_u, feasible))
    ok = [c for c in candidates if c.feasible]
    if not ok:
        raise EstimatorInputError(f"no candidate acceleration keeps the drive below i_max = {limits['i_max']} A "
                                  f"and u_max = {limits['u_max']} V: try smaller accelerations")
    return min(ok, key=lambda c: c.criterion), candidates
