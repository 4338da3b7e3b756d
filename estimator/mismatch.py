"""Model validation: does the estimated model explain the motion? (paper IV.B.3, Fig. 13, 14)

The estimated model is simulated from the measured inputs (output error, no feedback from the
measured output), on the filtered signals (eq. 8):

* current from the voltage and speed with the estimated R, L, K (electrical equation, exact Tustin
  recursion started in steady state, as the validation's Ir_hat);
* speed from the current with the estimated K, Jt, ft, Cd (T0), on each segment where ``|w|`` stays
  above the speed threshold, started from the measured speed at the segment's start. sign(w) is
  constant on a segment, so the mechanical equation is linear there and simulated exactly (Tustin).
  One simulation over the whole motion integrated every imperfection of the smoothed sign(w) through
  the reversals and dwells (creep): on healthy data its residue was coloured and correlated with the
  current, and any test rejected 25-40 % of healthy motions.

Each residue ``measured - simulated`` is judged by two tests whose null hypothesis holds on healthy
data, so that their level is their false-alarm rate:

* **independence** (Ljung's residual analysis, MATLAB ``resid``): is the residue explained by the
  past inputs (current residue: voltage and speed; speed residue: current) at lags 0..``lags`` of the
  residue decimated to ``rate_hz`` by block means? The residue's own colour is accounted for by
  prewhitening: feasible GLS with AR(``ar_order``) errors (statsmodels ``GLSAR``), F-test of the lag
  coefficients. The estimate's own error also leaves an input-correlated residue (theta_hat - theta
  is of the order of its standard error); it is not a mismatch, so the sensitivities of the simulation
  along the principal axes of the covariance (``sensitivity_directions``), a constant and, for the
  speed, one constant per segment (its start from a noisy speed) are nuisance regressors of the test;
* **size**: the residue, with those nuisance regressors removed, must be no larger than the noise of
  the sensors measured by the redundancy (``noise``: the standard deviation of the signal the
  estimator received, from the residue of the two sensors of each quantity). Statistic
  ``F = mean(e^2) / sigma^2``, one-sided F-test with (decimated blocks, noise samples) degrees of
  freedom. Filtering only lowers the noise, so a model that explains the motion leaves a residue well
  below one sensor noise (healthy: 0.06 to 0.64 sigma on the speed); a friction step of +10 % during
  the motion leaves 1.7 to 5.5 sigma.

The motion passes when no test rejects at the family-wise level ``alpha`` (Bonferroni: each of the m
tests at ``alpha / m``); ``p_value`` is the Bonferroni-adjusted ``min(1, m min p)`` and the result
names the test that decided. Without a noise level (recorded data without redundancy) only the
independence tests run. The former whiteness (Ljung-Box) test rejected every healthy motion (the
filtered open-loop residue is coloured by construction) and the decision then rested on a fixed size
rule (1 % of the signal's range); both are gone. A mismatch means the parameters are NOT validated;
they are still reported.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import casadi as ca
import numpy as np
import statsmodels.api as sm
from scipy import ndimage, signal, stats

from feeddrive.estimator.errors import EstimatorInputError
from feeddrive.estimator.filtering import FilterSpec
from feeddrive.estimator.simulation import MODEL
from feeddrive.estimator.validation import model_reference

#: physical parameters each simulated output depends on (from the model's equations)
USES = {signal_: tuple(v.name for v in MODEL.parameters
                       if v.kind == "physical" and ca.depends_on(MODEL.equations[eq].residual, v.sym))
        for signal_, eq in (("speed", "mechanical"), ("current", "electrical"))}
#: inputs of each simulation, the regressors of its independence test
INPUTS = {"current": ("u", "w"), "speed": ("i",)}
#: shortest speed segment simulated [s]: shorter ones (reversals) carry no test information
MIN_SEGMENT_S = 0.1


@dataclass(frozen=True)
class TestResult:
    """One test of one residue: ``statistic`` (F), its degrees of freedom and p-value."""

    __test__ = False  # not a pytest class

    name: str
    statistic: float
    df: tuple[float, float]
    p_value: float

    def to_dict(self) -> dict:
        return {"statistic": self.statistic, "df": list(self.df), "p_value": self.p_value}


@dataclass(frozen=True)
class ResidueCheck:
    """The tests of one output-error residue.

    Attributes
    ----------
    signal : str
        ``speed`` or ``current``.
    tests : dict of str to TestResult
        ``independence`` and, with a noise level, ``size``.
    rms, noise_std : float
        RMS of the residue without its nuisance part, and the sensor noise it is compared with (NaN
        without one), in the signal's unit.
    simulated, residue : ndarray, shape (n,)
        Simulated signal and ``measured - simulated`` (filtered; NaN on the samples not tested: the
        filter's transients at both ends and, for the speed, outside the segments).
    correlation : ndarray, shape (lags + 1, n_inputs)
        Correlation of the prewhitened residue with each prewhitened input at lags 0..lags (as ``resid``
        draws it); ``band``: its (1 - alpha) band ``z(1 - alpha / 2) / sqrt(blocks)`` under independence.
    band : float
    """

    signal: str
    tests: dict[str, TestResult]
    rms: float
    noise_std: float
    simulated: np.ndarray = field(repr=False)
    residue: np.ndarray = field(repr=False)
    correlation: np.ndarray = field(repr=False)
    band: float = 0.0


@dataclass(frozen=True)
class MismatchResult:
    """Model validation of one motion: the deciding test (smallest p-value), its statistic, the
    Bonferroni-adjusted p-value, the level, the verdict and the rule (see the module docstring)."""

    test: str
    statistic: float
    p_value: float
    alpha: float
    passed: bool
    rule: str
    checks: dict[str, ResidueCheck]

    def to_dict(self) -> dict:
        """``{test, statistic, p_value, alpha, passed, rule, checks: {signal: {test: {statistic, df,
        p_value}, rms, noise_std}}}`` (report.json)."""
        checks = {k: {**{t: r.to_dict() for t, r in c.tests.items()}, "rms": c.rms,
                      "noise_std": None if np.isnan(c.noise_std) else c.noise_std}
                  for k, c in self.checks.items()}
        return {"test": self.test, "statistic": self.statistic, "p_value": self.p_value, "alpha": self.alpha,
                "passed": self.passed, "rule": self.rule, "checks": checks}


def sensitivity_directions(simulate: Callable[[dict[str, float]], np.ndarray], parameters: Mapping[str, float],
                           names: Sequence[str], covariance: np.ndarray | None, uses: Sequence[str],
                           base: np.ndarray) -> np.ndarray:
    """Change of a simulated signal along each principal axis of the estimate's covariance.

    ``d_k = simulate(theta + sqrt(lambda_k) v_k) - simulate(theta)`` for the eigenpairs of the covariance
    restricted to the parameters the signal uses: one standard deviation along each axis. Without a
    covariance, one step of 1e-3 of each used parameter's value.

    Parameters
    ----------
    simulate : callable
        ``simulate(parameters) -> ndarray, shape (n,)``.
    parameters : mapping of str to float
    names : sequence of str, length p
        Rows of the covariance.
    covariance : ndarray, shape (p, p), or None
    uses : sequence of str
    base : ndarray, shape (n,)
        ``simulate(parameters)``.

    Returns
    -------
    ndarray, shape (n, k)
        One column per axis with a positive variance (signal's unit).
    """
    rows = [j for j, name in enumerate(names) if name in uses]
    if covariance is None:
        steps = [{names[j]: 1e-3 * (abs(parameters[names[j]]) or 1.0)} for j in rows]
    else:
        variances, axes = np.linalg.eigh(np.asarray(covariance, dtype=float)[np.ix_(rows, rows)])
        positive = variances > 1e-12 * max(variances.max(initial=0.0), np.finfo(float).tiny)
        steps = [{names[j]: d for j, d in zip(rows, np.sqrt(lam) * ax)}
                 for lam, ax in zip(variances[positive], axes.T[positive])]
    cols = []
    for step in steps:
        p = dict(parameters)
        for k, d in step.items():
            p[k] += d
        cols.append(simulate(p) - base)
    return np.column_stack(cols) if cols else np.zeros((base.size, 0))


def speed_segments(w: np.ndarray, threshold: float, h: float) -> tuple[np.ndarray, int]:
    """Labels 1..k of the runs of samples with ``|w| > threshold`` lasting at least ``MIN_SEGMENT_S``
    (0 elsewhere), and k."""
    labels, n = ndimage.label(np.abs(w) > threshold)
    sizes = np.bincount(labels.ravel(), minlength=n + 1)
    short = sizes < MIN_SEGMENT_S / h
    short[0] = True
    labels[short[labels]] = 0
    return ndimage.label(labels > 0)


def simulate_segments(i: np.ndarray, w: np.ndarray, labels: np.ndarray, params: Mapping[str, float],
                      h: float) -> np.ndarray:
    """Speed [rad/s] from the current [A] on each labelled segment (constant sign of w), NaN elsewhere.

    ``Jt dw/dt + ft w = K i - Cd sign(w) - T0``, Tustin, started at the measured speed ``w`` of each
    segment's first sample."""
    K, Jt, ft, Cd = (float(params[k]) for k in ("K", "Jt", "ft", "Cd"))
    T0 = float(params.get("T0", 0.0))
    b, a = signal.cont2discrete(([1.0], [Jt, ft]), h, method="bilinear")[:2]
    b = np.ravel(b)
    out = np.full(w.size, np.nan)
    for sl in ndimage.find_objects(labels):
        drive = K * i[sl] - Cd * np.sign(w[sl][0]) - T0
        # transposed direct form: y[0] = b0 x[0] + z[0], so z[0] = w0 - b0 x[0] starts the output at w0
        out[sl] = signal.lfilter(b, a, drive, zi=[w[sl][0] - b[0] * drive[0]])[0]
    return out


def _blocks(x: np.ndarray, block: int) -> np.ndarray:
    nb = x.shape[0] // block
    return x[:nb * block].reshape(nb, block, *x.shape[1:]).mean(axis=1)


def residue_tests(name: str, residue: np.ndarray, nuisance: np.ndarray, inputs: np.ndarray, h: float,
                  alpha: float, rate_hz: float = 50.0, lags: int = 10, ar_order: int = 2,
                  noise_std: float | None = None, noise_dof: float = np.inf,
                  groups: np.ndarray | None = None) -> tuple[dict[str, TestResult], float, np.ndarray, float]:
    """Independence and size tests of one residue; see the module docstring.

    Parameters
    ----------
    residue : ndarray, shape (n,)
        ``measured - simulated`` on the samples tested (signal's unit).
    nuisance : ndarray, shape (n, k)
        Columns whose effect is not a mismatch (sensitivities to the parameters).
    inputs : ndarray, shape (n, m)
        The simulation's inputs.
    h : float
        Sample time [s].
    alpha : float
        Level of the correlation band (the tests return p-values).
    rate_hz, lags, ar_order : float, int, int
        Decimated rate [Hz], input lags (at that rate) and order of the prewhitening AR model.
    noise_std : float or None
        Sensor noise standard deviation of the measured signal (None: no size test).
    noise_dof : float
        Degrees of freedom of ``noise_std`` (the samples it was estimated from).
    groups : ndarray of int, shape (n,), optional
        Segment labels: one nuisance constant per segment, and blocks never straddle two segments.

    Returns
    -------
    tests : dict of str to TestResult
    rms : float
        RMS of the residue without its least-squares nuisance part (signal's unit).
    correlation : ndarray, shape (lags + 1, m)
    band : float
    """
    block = max(1, int(round(1.0 / (rate_hz * h))))
    groups = np.ones(residue.size, dtype=int) if groups is None else np.asarray(groups)
    parts = [np.flatnonzero(groups == g) for g in np.unique(groups)]
    dummies = np.column_stack([groups == g for g in np.unique(groups)]).astype(float)
    Z = np.column_stack([nuisance, dummies])
    rb, Zb, Xb, lagged = [], [], [], []
    for idx in parts:
        nb = idx.size // block
        if nb <= lags + 1:
            continue
        take = idx[:nb * block]
        r_, Z_, X_ = _blocks(residue[take], block), _blocks(Z[take], block), _blocks(inputs[take], block)
        rb.append(r_[lags:])
        Zb.append(Z_[lags:])
        lagged.append(np.column_stack([X_[lags - k:nb - k, j] for j in range(X_.shape[1])
                                       for k in range(lags + 1)]))
        Xb.append(X_[lags:])
    if not rb or sum(len(r) for r in rb) < (lags + 1) * inputs.shape[1] + Z.shape[1] + 10:
        raise EstimatorInputError(f"model check ({name}): {residue.size} samples give too few {rate_hz:g} Hz blocks "
                                  f"for {lags} lags of {inputs.shape[1]} input(s)")
    y, N, L = np.concatenate(rb), np.vstack(Zb), np.vstack(lagged)
    L = (L - L.mean(axis=0)) / L.std(axis=0).clip(1e-300)
    N = N[:, np.abs(N).max(axis=0) > 0]
    N = N / np.abs(N).max(axis=0)
    # nuisance columns nearly collinear with others (a constant and a flat sensitivity) are dropped
    u_, s_, _ = np.linalg.svd(N, full_matrices=False)
    N = u_[:, s_ > 1e-9 * s_[0]]
    design = np.column_stack([N, L])
    fit = sm.GLSAR(y, design, rho=ar_order).iterative_fit(maxiter=6)
    q = L.shape[1]
    restriction = np.zeros((q, design.shape[1]))
    restriction[:, -q:] = np.eye(q)
    f = fit.f_test(restriction)
    tests = {"independence": TestResult("independence", float(np.squeeze(f.fvalue)),
                                        (float(f.df_num), float(f.df_denom)), float(np.squeeze(f.pvalue)))}
    # the correlation plot: residue and inputs prewhitened by the fitted AR model, after the nuisance
    rho = np.atleast_1d(fit.model.rho)
    white = fit.model.whiten(y - N @ np.linalg.lstsq(N, y, rcond=None)[0])
    wl = fit.model.whiten(L)
    corr = (wl.T @ white) / np.sqrt(np.sum(wl ** 2, axis=0) * (white @ white)).clip(1e-300)
    correlation = corr.reshape(inputs.shape[1], lags + 1).T
    band = float(stats.norm.isf(alpha / 2) / np.sqrt(white.size - rho.size))
    Zfull = Z[:, np.abs(Z).max(axis=0) > 0]
    e = residue - Zfull @ np.linalg.lstsq(Zfull, residue, rcond=None)[0]
    rms = float(np.sqrt(np.mean(e ** 2)))
    if noise_std is not None and noise_std > 0:
        dof = float(y.size)  # the residue is correlated over about a block: one degree of freedom per block
        ratio = rms ** 2 / noise_std ** 2
        tests["size"] = TestResult("size", ratio, (dof, float(noise_dof)), float(stats.f.sf(ratio, dof, noise_dof)))
    return tests, rms, correlation, band


def check_model(u: np.ndarray, i: np.ndarray, w: np.ndarray, h: float, parameters: Mapping[str, float],
                filter: FilterSpec, alpha: float = 0.01, covariance: np.ndarray | None = None,
                names: Sequence[str] | None = None, noise: Mapping[str, float] | None = None,
                noise_dof: float = np.inf, speed_threshold: float = 2.0, rate_hz: float = 50.0, lags: int = 10,
                ar_order: int = 2) -> MismatchResult:
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
        Family-wise level of the model check (its false-alarm rate on healthy motions).
    covariance : ndarray, shape (p, p), optional
        Covariance of the estimate (``MotionEstimate.covariance``); its principal axes give the
        nuisance directions. None: one relative step of 1e-3 per parameter.
    names : sequence of str, length p
        The covariance's parameters (``MotionEstimate.names``); required with ``covariance``.
    noise : mapping, optional
        Sensor noise standard deviation of the raw ``i`` [A] and ``w`` [rad/s] given (keys ``current``,
        ``speed``), from the redundant sensors; a missing key: no size test for that residue.
    noise_dof : float
        Degrees of freedom of those noise estimates (number of samples they come from).
    speed_threshold : float
        The speed is simulated on the segments where ``|w| >`` this [rad/s].
    rate_hz, lags, ar_order : float, int, int
        See ``residue_tests``.

    Returns
    -------
    MismatchResult
    """
    missing = [k for k in ("R", "L", "K", "Jt", "ft", "Cd") if k not in parameters]
    if missing:
        raise EstimatorInputError(f"check_model: parameters {missing} are missing")
    if not 0 < alpha < 1:
        raise EstimatorInputError(f"check_model: alpha must be in (0, 1), got {alpha}")
    if covariance is not None:
        covariance = np.asarray(covariance, dtype=float)
        if names is None or covariance.shape != (len(names), len(names)) or not np.all(np.isfinite(covariance)):
            raise EstimatorInputError(f"check_model: covariance must be a finite (p, p) matrix with p = len(names), "
                                      f"got shape {covariance.shape} for names {names}")
        unknown = [k for k in names if k not in parameters]
        if unknown:
            raise EstimatorInputError(f"check_model: covariance names {unknown} are not in the parameters")
    names = tuple(parameters) if names is None else tuple(names)
    f = filter.apply({"u": u, "i": i, "w": w}, h)
    params = {k: float(v) for k, v in parameters.items()}
    edge = int(round(5.0 / (filter.cutoff_hz * h)))  # the zero-phase filter's transients at both ends
    inner = np.zeros(f["w"].size, dtype=bool)
    inner[edge:f["w"].size - edge] = True
    labels, _ = speed_segments(np.where(inner, f["w"], 0.0), speed_threshold, h)
    keep = {"current": inner, "speed": labels > 0}
    simulators = {
        "current": ("i", lambda p: model_reference("current", f, h, p)),  # linear: exact Tustin recursion
        "speed": ("w", lambda p: simulate_segments(f["i"], f["w"], labels, p, h)),
    }
    noise = dict(noise or {})
    checks = {}
    for name, (x, simulate) in simulators.items():
        simulated = simulate(params)
        k = keep[name]
        if k.sum() < 2 / h * MIN_SEGMENT_S:
            raise EstimatorInputError(f"model check ({name}): only {k.sum()} samples to test")
        D = sensitivity_directions(lambda p, s=simulate, k=k: s(p)[k], params, names, covariance, USES[name],
                                   simulated[k])
        X = np.column_stack([f[s] for s in INPUTS[name]])[k]
        tests, rms, corr, band = residue_tests(name, (f[x] - simulated)[k], D, X, h, alpha, rate_hz, lags,
                                               ar_order, noise.get(name), noise_dof,
                                               labels[k] if name == "speed" else None)
        residue = np.where(k, f[x] - simulated, np.nan)  # the samples tested (filter edges out)
        checks[name] = ResidueCheck(name, tests, rms, float(noise.get(name, np.nan)), simulated, residue, corr, band)
    results = [(f"{name} {t}", r) for name, c in checks.items() for t, r in c.tests.items()]
    m = len(results)
    label, worst = min(results, key=lambda t: t[1].p_value)
    p = min(1.0, m * worst.p_value)
    rule = (f"Bonferroni over {m} tests ({', '.join(t for t, _ in results)}): mismatch when a p-value is below "
            f"alpha / {m}")
    return MismatchResult(label, worst.statistic, p, alpha, bool(p >= alpha), rule, checks)
