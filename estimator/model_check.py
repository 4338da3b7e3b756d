"""The paper's output-error model check on any drive model (paper IV.B.3, Fig. 13, 14; issue 25).

``mismatch.check_model`` is the DC drive's: the current from ``u, w`` by an exact Tustin recursion, the speed
from ``K i`` segment by segment. ``check_model_equations`` is the same check read from the model's equations
(``models.drives``), so a PMSM motion gets it too: every physical equation whose state and inputs are measured
is simulated alone, solved for its state's derivative (``simulation.simulate``: RK4, the inputs linearly
interpolated), driven by the other measured signals, filtered as the estimator's (eq. 8):

* an equation without the dry friction's sign (the DC electrical, the PMSM's q and d axes: ``u_q, w, i_d ->
  i_q``) over the whole motion less the filter's transients, from the measured state at the first sample;
* an equation with it (the mechanical: ``i_q, i_d -> w`` through the air-gap torque) on each segment where
  ``|w|`` stays above the speed threshold (``mismatch.speed_segments``), from the measured speed at the
  segment's start (sign(w) constant: no creep through the reversals).

Each residue ``measured - simulated`` goes through ``residue_tests`` as in ``check_model``: independence from
the inputs (or their ``instruments``, second sensors with independent noise: the residue carries the first
sensors' noise through the model), with the estimate's sensitivities (``mismatch.sensitivity_directions``)
and the free response to the start value (simulated: the start is one noisy sample) as nuisance regressors,
and the size test where a sensor noise is given. Bonferroni over every test, as ``check_model``.

Calibrated on healthy motions (benchmarks/bench_pmsm_model_check.py: the p-values of healthy PMSM motions
against the uniform): a current's independence test runs on the residue weighted by its null standard deviation
(``_weights``; the d axis's null variance follows the speed through ``p w L_q i_q``). Not yet calibrated: the
speed's independence test (7 % below 1 % at 40 dB), so on a PMSM the monitor keeps this check advisory.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from feeddrive.estimator.columnwise import multiply_rows
from feeddrive.estimator.errors import EstimatorInputError
from feeddrive.estimator.filtering import FilterSpec
from feeddrive.estimator.kernels import equation_parameters_of, label_slices, residual_symbols
from feeddrive.estimator.mismatch import (
    MIN_SEGMENT_S,
    MismatchResult,
    ResidueCheck,
    sensitivity_directions,
    speed_segments,
)
from feeddrive.estimator.residue_tests import block_samples, integrated_noise_covariance, residue_tests
from feeddrive.estimator.simulation import W_EPS, _ode, simulate
from feeddrive.models.drives import measured


def _inputs(model, equation: str) -> tuple[str, ...]:
    """Measured signals of the equation's residual other than its state (PMSM q axis: u_q, w, i_d)."""
    eq = model.equations[equation]
    syms = residual_symbols(model, equation)
    return tuple(x for x in measured(model) if x != eq.solves_for and model.variables[x].sym.name() in syms)


def _null_std(run, params: Mapping[str, float], f: Mapping[str, np.ndarray], ins: tuple[str, ...], state: str,
              noise: Mapping[str, float], h: float, filter: FilterSpec, k: np.ndarray
              ) -> tuple[float | None, np.ndarray | None]:
    """The size test's noise level of one residue: the state sensor's noise and, added in variance, the
    simulation's response to its inputs' noise (a white draw of each input's std, filtered, through the same
    simulation: two draws, seeded). DC: the current residue carries the voltage noise through ``1 / (L s + R)``;
    PMSM: 0.18 A of simulated i_q from a 40 dB u_q against a 0.06 A current sensor. ``(None, None)`` without
    every noise. Also returns that response's variance at each tested sample (the mean of the draws' squares),
    shape (k.sum(),): it follows the operating point (the d axis's ``p w L_q i_q`` carries the q current's noise
    in proportion to the speed)."""
    if state not in noise or any(x not in noise for x in ins):
        return None, None
    base = run(params, f)[k]
    rng = np.random.default_rng(0)
    var = []
    for _ in range(2):
        z = filter.apply({x: noise[x] * rng.standard_normal(f[x].size) for x in ins}, h)
        var.append((run(params, {**f, **{x: f[x] + z[x] for x in ins}})[k] - base) ** 2)
    profile = np.mean(var, axis=0)
    return float(np.sqrt(noise[state] ** 2 + np.mean(profile))), profile


def _weights(profile: np.ndarray, state_std: float, filter: FilterSpec, h: float, block: int) -> np.ndarray:
    """``1 / sigma`` of each sample of a residue whose null variance changes over the motion, constant over each
    of the test's blocks (``residue_tests`` averages blocks of ``block`` samples from the first): the filtered
    state sensor's noise variance plus ``profile`` (``_null_std``) averaged over the block and its two
    neighbours (the draws' scatter). Weighted so, the independence test's regression has one error variance (its
    F-test assumes it: on the PMSM's d axis, whose null variance follows the speed 50-fold, it rejected 16 % of
    healthy motions at 1 %, benchmarks/bench_pmsm_model_check.py)."""
    unit = filter.apply({"x": np.random.default_rng(1).standard_normal(max(20 * block, 4000))}, h)["x"]
    gain = float(np.var(unit[unit.size // 4:-unit.size // 4]))  # the filter's noise gain, away from its ends
    nb = -(-profile.size // block)
    per = np.nanmean(np.concatenate([profile, np.full(nb * block - profile.size, np.nan)]).reshape(nb, block), 1)
    per = np.convolve(np.pad(per, 1, mode="edge"), np.ones(3) / 3, mode="valid")
    return np.repeat(1.0 / np.sqrt(gain * state_std ** 2 + per).clip(1e-300), block)[:profile.size]


def _integrated_null(model, equation: str, ins: tuple[str, ...], params: Mapping[str, float],
                     f: Mapping[str, np.ndarray], k: np.ndarray, noise: Mapping[str, float], h: float,
                     rate_hz: float):
    """The null covariance of a segmented residue's blocks (``residue_tests.integrated_noise_covariance``): the
    state's sensor noise plus its inputs' noises integrated by the equation from each segment's start, an AR(1) at
    the block rate, ``rho = exp(-a tb)``, ``ratio = sum_j (b_j tb s_j)^2 / s_x^2`` with ``a = -df/dx`` and ``b_j
    = df/du_j`` of the equation's ODE at the motion's RMS point (DC: ``ft / Jt`` and ``K / Jt``: mismatch.py's;
    PMSM: ``K_t / Jt`` for i_q). None without every noise."""
    state = model.equations[equation].solves_for
    if state not in noise or any(x not in noise for x in ins) or not noise[state] > 0:
        return None
    names = tuple(sorted(ins))
    ode, _, phys, _ = _ode(model, (equation,), names)
    p = [float(params.get(v.name, v.nominal or 0.0)) for v in phys] + [W_EPS]
    x0 = float(np.sqrt(np.mean(f[state][k] ** 2)))
    s0 = np.array([float(np.sqrt(np.mean(f[x][k] ** 2))) for x in names])

    def rhs(x: float, s: np.ndarray) -> float:
        return float(ode(x, s, p))

    dx = 1e-6 * max(x0, 1.0)
    a = -(rhs(x0 + dx, s0) - rhs(x0 - dx, s0)) / (2 * dx)
    tb = block_samples(rate_hz, h) * h
    ratio = 0.0
    for j, x in enumerate(names):
        e = np.zeros(len(names))
        e[j] = 1e-6 * max(abs(s0[j]), 1.0)
        b = (rhs(x0, s0 + e) - rhs(x0, s0 - e)) / (2 * e[j])
        ratio += (b * tb * noise[x]) ** 2
    rho = float(np.exp(-max(a, 0.0) * tb))
    ratio /= noise[state] ** 2
    return lambda nb: integrated_noise_covariance(nb, rho, ratio)


def check_model_equations(signals: Mapping[str, np.ndarray], h: float, parameters: Mapping[str, float], model,
                          filter: FilterSpec, alpha: float = 0.01, covariance: np.ndarray | None = None,
                          names: Sequence[str] | None = None, noise: Mapping[str, float] | None = None,
                          noise_dof: float = np.inf, speed_threshold: float | None = None,
                          speed_fraction: float = 0.03, rate_hz: float = 50.0, lags: int = 10,
                          ar_order: int | None = None,
                          instruments: Mapping[str, np.ndarray] | None = None,
                          undetermined: Sequence[str] = ()) -> MismatchResult:
    """Simulate each equation of the fitted ``model`` from the measured signals and test the residues.

    Parameters
    ----------
    signals : mapping of str to ndarray, each shape (n,)
        The model's measured signals (``models.drives.measured``: PMSM ``i_q, i_d, w, u_d, u_q``), raw.
    h : float
        Sample time [s].
    parameters : mapping of str to float
        The estimated physical parameters (the model's design parameters are its nominal values:
        ``models.drives.with_design`` for known pole pairs).
    model : models.Model
    filter : FilterSpec
    alpha : float
        Family-wise level (the false-alarm rate on healthy motions).
    covariance, names
        The estimate's covariance and its parameters (nuisance directions); None: a relative step of 1e-3.
    noise : mapping of str to float, optional
        Sensor noise std of the raw measured signals: a residue's size test runs where its state's and its
        inputs' are given (``_null_std``).
    noise_dof : float
    speed_threshold, speed_fraction, rate_hz, lags, ar_order
        As ``mismatch.check_model``.
    instruments : mapping of str to ndarray, optional
        A second measurement of an input (same name), with noise independent of the first's.
    undetermined : sequence of str
        Parameters the fit held at a value because the motion could not determine them (as
        ``mismatch.check_model``): nuisance directions too.

    Returns
    -------
    MismatchResult
        ``checks`` keyed by the simulated state (``i_q``, ``i_d``, ``w``).

    Raises
    ------
    EstimatorInputError
        No equation can be simulated from ``signals``, a parameter is missing, or too few samples to test.
    """
    if not 0 < alpha < 1:
        raise EstimatorInputError(f"check_model: alpha must be in (0, 1), got {alpha}")
    params = {k: float(v) for k, v in parameters.items()}
    raw = {k: np.asarray(v, dtype=float) for k, v in signals.items() if v is not None}
    n = raw["w"].size if "w" in raw else 0
    equations = [e for e in model.equations.values()
                 if e.solves_for in raw and all(x in raw for x in _inputs(model, e.name))]
    if not equations:
        raise EstimatorInputError(f"check_model: no equation of {model.name} can be simulated from "
                                  f"{sorted(raw)}: expected {', '.join(measured(model))}")
    # with second sensors, an equation none of whose inputs has one is not tested: its residue would be regressed
    # on the inputs whose noise it carries (healthy PMSM recordings were rejected so)
    untested = [e.name for e in equations if instruments and not set(_inputs(model, e.name)) & set(instruments)]
    equations = [e for e in equations if e.name not in untested]
    if not equations:
        raise EstimatorInputError(f"check_model: no equation has an input with a second sensor (instruments "
                                  f"{sorted(instruments or {})})")
    optional = {v.name for v in model.of_kind("physical") if v.optional}  # T0: its nominal 0 unless estimated
    missing = sorted({p for e in equations for p in equation_parameters_of(model, e.name)} - set(params) - optional)
    if missing:
        raise EstimatorInputError(f"check_model: parameters {missing} are missing")
    names = tuple(params) if names is None else tuple(names)
    f = filter.apply(raw, h)
    fi = f if not instruments else {**f, **filter.apply({k: np.asarray(v, float) for k, v in instruments.items()}, h)}
    edge = int(round(5.0 / (filter.cutoff_hz * h)))  # the zero-phase filter's transients at both ends
    inner = np.zeros(n, dtype=bool)
    inner[edge:n - edge] = True
    if speed_threshold is None:
        speed_threshold = speed_fraction * float(np.abs(f["w"][inner]).max(initial=0.0))
    labels, _ = speed_segments(np.where(inner, f["w"], 0.0), speed_threshold, h, margin=edge)
    whole = inner.astype(int)
    checks = {}
    for eq in equations:
        state, ins = eq.solves_for, _inputs(model, eq.name)
        segmented = "sgn_w" in {x for x in residual_symbols(model, eq.name)}
        lab = labels if segmented else whole
        parts = label_slices(lab)

        def run(p: Mapping[str, float], s: Mapping[str, np.ndarray], start: float = 0.0, eq=eq, state=state,
                ins=ins, parts=parts) -> np.ndarray:
            out = np.full(n, np.nan)
            for (sl,) in parts:
                if sl is None:
                    continue
                x = simulate((eq.name,), {k: s[k][sl] for k in ins}, p, h, {state: f[state][sl][0] + start},
                             model=model)[state]
                out[sl] = x
            return out

        k = lab > 0
        if k.sum() < 2 / h * MIN_SEGMENT_S:
            raise EstimatorInputError(f"model check ({state}): only {k.sum()} samples to test")
        simulated = run(params, f)
        base = simulated if fi is f else run(params, fi)
        D = sensitivity_directions(lambda p: run(p, fi)[k], params, names, covariance,
                                   equation_parameters_of(model, eq.name), base[k], undetermined)
        # the start is one noisy (filtered) sample: its error's response, per segment, is a nuisance
        scale = max(float(np.std(f[state][k])), 1e-12) * 1e-3
        free = (run(params, fi, scale) - base) / scale
        cols = []
        for (sl,) in parts:
            col = np.zeros(n)
            col[sl] = free[sl]
            cols.append(col[k])
        D = np.column_stack([D, *cols]) if cols else D
        # with second sensors, the test's regressors are the instruments alone: an input without one (the PMSM's
        # i_d from the phases at the encoder's quantised angle) carries noise and cross-talk the residue shares
        reg = [x for x in ins if x in (instruments or {})] or list(ins)
        X = np.column_stack([fi[x] for x in reg])[k]
        sigma, profile = _null_std(run, params, f, ins, state, noise or {}, h, filter, k)
        # a segmented residue (the speed) integrates its inputs' noise from each segment's start: its null colour
        null = _integrated_null(model, eq.name, ins, params, f, k, noise or {}, h, rate_hz) if segmented else None
        tests, rms, corr, band = residue_tests(state, (f[state] - simulated)[k], D, X, h, alpha, rate_hz, lags,
                                               ar_order, sigma, noise_dof,
                                               labels[k] if segmented else None, constant=not segmented,
                                               segment_covariance=null)
        if profile is not None and not segmented:  # the independence test on the residue weighted by its null std
            wt = _weights(profile, noise[state], filter, h, block_samples(rate_hz, h))
            Dw = multiply_rows(np.column_stack([D, np.ones(len(wt))]), wt)  # the constant (an offset), weighted too
            wtests, _, corr, band = residue_tests(state, (f[state] - simulated)[k] * wt, Dw, multiply_rows(X, wt), h,
                                                  alpha, rate_hz, lags, ar_order, None, noise_dof, None,
                                                  constant=False)
            tests = {**tests, "independence": wtests["independence"]}  # its correlation figure too
        checks[state] = ResidueCheck(state, tests, rms, np.nan if sigma is None else sigma, simulated,
                                     np.where(k, f[state] - simulated, np.nan), corr, band)
    results = [(f"{name} {t}", r) for name, c in checks.items() for t, r in c.tests.items()]
    m = len(results)
    label, worst = min(results, key=lambda t: t[1].p_value)
    p = min(1.0, m * worst.p_value)
    rule = (f"Bonferroni over {m} tests ({', '.join(t for t, _ in results)}): mismatch when a p-value is below "
            f"alpha / {m}" + (f"; not tested: the {', '.join(untested)} equation (no second sensor of its inputs)"
                              if untested else ""))
    return MismatchResult(label, worst.statistic, p, alpha, bool(p >= alpha), rule, checks)
