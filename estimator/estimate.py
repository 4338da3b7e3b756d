"""One high-speed motion -> R, L, K, Jt, ft, Cd with uncertainties (paper sections 3-5).

Pipeline: identical low-pass of every signal (eq. 8) -> zero-forcing derivatives (eq. 3) ->
regressions derived from the model (eq. 4, 5) -> least squares, then instrumental variables with
instruments simulated from the model (IDIM-IV), then optionally output error (``estimator.oe``).

Uncertainty. The filtered equation errors are correlated over about 1/cutoff, so the textbook
``sigma^2 (Phi^T Phi)^-1`` would be far too optimistic. Covariances are sandwich estimates whose
middle term is a batch-means long-run variance (blocks of ``block_seconds``); confidence intervals
use Student's t with (blocks - parameters) degrees of freedom. Jt, ft, Cd (and T0) come from
theta_m = p / K and K by the delta method, K's uncertainty included; the two equations are treated
as independent.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping

import numpy as np
from scipy import stats
from scipy.ndimage import binary_erosion

from estimator.derivative import FUTURE, PAST, zero_forcing_derivative
from estimator.errors import EstimatorInputError, NotEnoughExcitation
from estimator.filtering import FilterSpec
from estimator.regression import Regression, derive_regression
from estimator.simulation import MODEL, simulate

METHODS = ("ls", "iv", "oe")
#: Signals measured on the drive (the others are derivatives and sign(w), computed from them).
MEASURED = ("u", "i", "w")
#: Physical parameters of the model in model order (T0 and other optional terms on request).
PHYSICAL = [v for v in MODEL.parameters if v.kind == "physical"]
_NOMINAL = {v.name: float(v.nominal) for v in PHYSICAL}


@dataclass(frozen=True)
class MotionData:
    """One high-speed motion, sampled every ``h`` seconds from ``t0``.

    Attributes
    ----------
    h : float
        Sampling period [s].
    u, i, w : ndarray, shape (n,), or None
        Armature voltage [V], armature current [A], motor speed [rad/s].
    position : ndarray, shape (n,), or None
        Motor angle [rad] (encoder); differentiated for the speed when ``w`` is None.
    torque : ndarray, shape (n,), or None
        Motor torque [N.m], used in place of ``K i`` in the mechanical equation.
    t0 : float
        Time of the first sample [s].
    """

    h: float
    u: np.ndarray | None = None
    i: np.ndarray | None = None
    w: np.ndarray | None = None
    position: np.ndarray | None = None
    torque: np.ndarray | None = None
    t0: float = 0.0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.h) and self.h > 0):
            raise EstimatorInputError(f"MotionData: h must be a positive sampling period [s], got {self.h}")
        n = None
        for name in ("u", "i", "w", "position", "torque"):
            x = getattr(self, name)
            if x is None:
                continue
            x = np.asarray(x, dtype=float)
            if x.ndim != 1:
                raise EstimatorInputError(f"MotionData: {name} must be 1-D, got shape {x.shape}")
            if not np.all(np.isfinite(x)):
                raise EstimatorInputError(f"MotionData: {name} contains NaN or infinite values")
            if n is not None and x.size != n:
                raise EstimatorInputError(f"MotionData: {name} has {x.size} samples, the other signals {n}")
            n = x.size
            object.__setattr__(self, name, x)
        if n is None:
            raise EstimatorInputError("MotionData: no signal given")

    @property
    def n(self) -> int:
        return next(len(x) for x in (self.u, self.i, self.w, self.position, self.torque) if x is not None)


@dataclass(frozen=True)
class EstimationOptions:
    """Options of ``estimate_motion``; the defaults suit 10 kHz data from the plant.

    Attributes
    ----------
    method : str
        ``ls``, ``iv`` (default) or ``oe``: the method whose numbers ``parameters`` holds.
    filter : FilterSpec
        The identical low-pass of every signal (cut-off below 0.1125 / h for IV and OE).
    known : mapping of str to float
        Parameters known in advance (e.g. ``{"K": 1.05}`` for the mechanical equation alone).
    offset : bool
        Also estimate the optional constant torque offset ``T0`` (needs a speed reversal).
    speed_threshold : float
        Samples with ``|w| <`` this [rad/s] are excluded from the equations that use sign(w) ...
    sign_guard : float
        ... and so are ``sign_guard / cutoff_hz`` seconds on either side of them (filter smearing).
    edge_guard : float
        ``edge_guard / cutoff_hz`` seconds at each end of the filtered motion (at its start only for a
        causal filter) are dropped: the filter's start-up transient does not obey the model.
    iv_iterations, iv_tolerance : int, float
        IV iterations at most, and the relative parameter change that ends them.
    max_condition : float
        Largest condition number of the column-scaled regressor accepted.
    max_relative_std : float
        Largest relative standard error accepted for the strictly positive parameters (R, L, K, Jt).
    block_seconds : float or None
        Block length of the long-run covariance [s]; None: ``max(0.05, 5 / cutoff)``.
    oe_rate_hz : float
        Sampling rate the output-error refinement decimates to [Hz].
    """

    method: str = "iv"
    filter: FilterSpec = FilterSpec(50.0)
    known: Mapping[str, float] = field(default_factory=dict)
    offset: bool = False
    speed_threshold: float = 2.0
    sign_guard: float = 2.0
    edge_guard: float = 3.0
    iv_iterations: int = 10
    iv_tolerance: float = 1e-4
    max_condition: float = 1e4
    max_relative_std: float = 0.3
    block_seconds: float | None = None
    oe_rate_hz: float = 1000.0

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise EstimatorInputError(f"method must be one of {METHODS}, got {self.method!r}")
        names = {v.name for v in PHYSICAL}
        for k, v in self.known.items():
            if k not in names:
                raise EstimatorInputError(f"known parameter {k!r} is not one of {sorted(names)}")
            if not np.isfinite(v):
                raise EstimatorInputError(f"known parameter {k!r} must be finite, got {v}")
        if not self.speed_threshold >= 0:
            raise EstimatorInputError(f"speed_threshold must be >= 0 rad/s, got {self.speed_threshold}")
        object.__setattr__(self, "known", dict(self.known))

    def block(self) -> float:
        return self.block_seconds or max(0.05, 5.0 / self.filter.cutoff_hz)


@dataclass(frozen=True)
class ParameterEstimate:
    """Estimate of one parameter: value, standard error and 95 % confidence interval (same unit)."""

    value: float
    std: float
    ci95: tuple[float, float]


@dataclass(frozen=True)
class MethodResult:
    """Result of one method (LS, IV or OE).

    Attributes
    ----------
    method : str
    names : tuple of str
        Estimated physical parameters.
    values : ndarray, shape (p,)
    covariance : ndarray, shape (p, p)
    dof : int
        Degrees of freedom of the t quantile of the intervals.
    condition_number : float
        Of the column-scaled regressor (largest over the equations; OE: of the scaled jacobian).
    fit_error : float
        Relative fit error ``||y - Phi theta|| / ||y||`` (largest over the equations; OE: outputs).
    iterations : int
    message : str
        Why OE fell back, or "".
    """

    method: str
    names: tuple[str, ...]
    values: np.ndarray
    covariance: np.ndarray
    dof: int
    condition_number: float
    fit_error: float
    iterations: int = 1
    message: str = ""

    @property
    def parameters(self) -> dict[str, ParameterEstimate]:
        t = stats.t.ppf(0.975, max(self.dof, 1))
        std = np.sqrt(np.clip(np.diag(self.covariance), 0, None))
        return {n: ParameterEstimate(float(v), float(s), (float(v - t * s), float(v + t * s)))
                for n, v, s in zip(self.names, self.values, std)}

    def as_dict(self) -> dict[str, float]:
        return dict(zip(self.names, map(float, self.values)))


@dataclass(frozen=True)
class MotionEstimate:
    """Estimates of one motion.

    ``parameters``, ``names``, ``covariance``, ``condition_number`` and ``fit_error`` are those of the
    requested ``method``; ``ls``, ``iv`` and ``oe`` hold each method's result (None if not run).
    ``start`` and ``end`` are the times of the motion's first and last samples [s].
    """

    method: str
    start: float
    end: float
    ls: MethodResult
    iv: MethodResult | None
    oe: MethodResult | None

    @property
    def result(self) -> MethodResult:
        return getattr(self, self.method)

    @property
    def names(self) -> tuple[str, ...]:
        return self.result.names

    @property
    def parameters(self) -> dict[str, ParameterEstimate]:
        return self.result.parameters

    @property
    def covariance(self) -> np.ndarray:
        return self.result.covariance

    @property
    def condition_number(self) -> float:
        return self.result.condition_number

    @property
    def fit_error(self) -> float:
        return self.result.fit_error

    def to_dict(self) -> dict:
        """``{"start","end","method","parameters": {name: {"value","ci95"}},"condition_number","fit_error"}``."""
        return {
            "start": self.start, "end": self.end, "method": self.method,
            "parameters": {n: {"value": p.value, "ci95": list(p.ci95)} for n, p in self.parameters.items()},
            "condition_number": float(self.condition_number), "fit_error": float(self.fit_error),
        }


@dataclass
class Prepared:
    """Filtered, differentiated, aligned signals of one motion and the regressions they allow.

    ``signals`` holds ``u, i, w, Di, Dw, sgn_w`` (and ``torque``) on the samples where every
    derivative exists; ``rows[equation]`` marks the usable samples (the sign term excludes speeds
    near zero); ``overrides[equation]`` replaces signals (a torque signal for ``K i``); ``block`` is
    the block length of the long-run covariance in samples.
    """

    h: float
    signals: dict[str, np.ndarray]  # u, i, w, Di, Dw, sgn_w on the aligned samples
    regressions: list[Regression]
    rows: dict[str, np.ndarray]  # equation -> boolean mask of usable samples
    overrides: dict[str, dict[str, np.ndarray]]  # equation -> signals replaced (torque for K i)
    known: dict[str, float]
    block: int


def prepare(data: MotionData, options: EstimationOptions) -> Prepared:
    """Filter, differentiate and align the signals; derive the regressions the data allow.

    Returns
    -------
    Prepared
    """
    h = data.h
    raw = {k: getattr(data, k) for k in ("u", "i", "w", "position", "torque") if getattr(data, k) is not None}
    if data.w is not None:
        raw.pop("position", None)  # a tachometer is preferred to the differentiated encoder
    f = options.filter.apply(raw, h)
    if "position" in f:
        w, valid = zero_forcing_derivative(f.pop("position"), h)
        f = {k: v[valid] for k, v in f.items()} | {"w": w}
    if "w" not in f:
        raise EstimatorInputError("the motion has neither a speed nor a position signal")
    sig = {}
    for state in ("i", "w"):
        if state in f:
            sig["D" + state], valid = zero_forcing_derivative(f[state], h)
    sig.update({k: v[PAST:len(v) - FUTURE] for k, v in f.items()})
    # the filter's start-up (both ends for zero phase: sosfiltfilt pads with a mirror image that does
    # not obey the model) would bias the fits: those samples are dropped, like the derivative's edges
    edge = max(0, int(np.ceil(options.edge_guard / (options.filter.cutoff_hz * h))) - min(PAST, FUTURE))
    if edge:
        keep = slice(edge, -edge if options.filter.zero_phase else None)
        if len(sig["w"][keep]) < 10:
            raise NotEnoughExcitation([v.name for v in PHYSICAL if not v.optional],
                                      f"motion too short: {len(sig['w'])} samples, the filter's start-up "
                                      f"needs {edge} at each end")
        sig = {k: v[keep] for k, v in sig.items()}
    sig["sgn_w"] = np.sign(sig["w"])
    free = [v.name for v in PHYSICAL if (options.offset or not v.optional) and v.name not in options.known]
    regressions, overrides = [], {}
    for eq in MODEL.equations.values():
        known, over = dict(options.known), {}
        if eq.normaliser and "torque" in sig:
            known[eq.normaliser] = 1.0  # the torque signal is the normaliser times the output (K i)
            over[eq.output] = sig["torque"]
        reg = derive_regression(MODEL, eq.name, free, known)
        if reg.names and all({**sig, **over}.get(x) is not None for x in reg.signals):
            regressions.append(reg)
            overrides[eq.name] = over
    if not regressions:
        raise EstimatorInputError(f"no model equation can be used with the signals {sorted(raw)}")
    rows = {}
    for reg in regressions:
        r = np.ones(len(sig["w"]), dtype=bool)
        if "sgn_w" in reg.signals:
            # the filter smears sign(w) over about 1/cutoff around each zero crossing: widen the gap
            r &= binary_erosion(np.abs(sig["w"]) >= options.speed_threshold,
                                iterations=int(np.ceil(options.sign_guard / (options.filter.cutoff_hz * h))),
                                border_value=True)
        rows[reg.equation] = r
    block = max(1, int(round(options.block() / h)))
    return Prepared(h, sig, regressions, rows, overrides, dict(options.known), block)


def _signals_for(p: Prepared, reg: Regression, instruments: Mapping[str, np.ndarray] | None = None) -> dict:
    return {**p.signals, **(instruments or {}), **p.overrides[reg.equation]}


def _long_run(G: np.ndarray, block: int) -> tuple[np.ndarray, int]:
    """Batch-means long-run covariance of the sum of the rows of G (n, p), and its blocks count."""
    block = min(block, len(G))
    nb = len(G) // block
    B = G[:nb * block].reshape(nb, block, -1).sum(axis=1)
    # scaled up for the samples of the incomplete last block and for the p estimated parameters
    return B.T @ B * (len(G) / (nb * block)) * nb / max(nb - G.shape[1], 1), nb


@dataclass
class _Fit:
    theta: np.ndarray
    cov: np.ndarray
    dof: int
    cond: float
    fit: float


def _solve(reg: Regression, parts: list[tuple], block: int, options: EstimationOptions) -> _Fit:
    """LS or basic IV on the usable rows of one or more sample sets, column-scaled.

    Each part is ``(y (n,), Phi (n, p), Z (n, p) or None, rows (n,) bool)``. With ``Z`` None: LS
    (``lstsq``, not the normal equations), after the excitation check. Otherwise IV: ``theta = (sum Z^T Phi)^-1 sum Z^T y``. The parts are
    sample sets of the same time span (sample k of every part near the same time), so their score
    contributions are added sample by sample before the long-run covariance.
    """
    p = parts[0][1].shape[1]
    used = sum(int(r.sum()) for *_, r in parts)
    if used < 20 * p:
        raise NotEnoughExcitation(list(reg.names) + ([reg.normaliser] if reg.normaliser else []),
                                  f"motion too short: {used} usable samples in the {reg.equation} "
                                  f"equation, need at least {20 * p}")
    def rows(x, r):
        return x if r.all() else x[r]

    Xr = [rows(Phi, r) for _, Phi, _, r in parts]
    ys = [rows(y, r) for y, _, _, r in parts]
    scale = np.sqrt(sum(np.einsum("ij,ij->j", X, X) for X in Xr))
    # a column whose contribution at the nominal parameter is rounding noise (a derivative at constant
    # speed) is empty, however well conditioned column scaling makes it look
    nominal = np.array([abs(_NOMINAL[n] / (_NOMINAL[reg.normaliser] if reg.normaliser else 1.0)) or 1.0
                        for n in reg.names])
    empty = scale * nominal <= 1e-9 * np.sqrt(sum(y @ y for y in ys))
    scale[empty] = 1.0
    Xs = [X / scale for X in Xr]
    # singular values of the scaled regressor from its p x p Gram matrix (cheap; fine up to cond ~1e7)
    eig, V = np.linalg.eigh(sum(X.T @ X for X in Xs)[np.ix_(~empty, ~empty)])
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
        theta_s = np.linalg.lstsq(np.vstack(Xs), np.concatenate(ys), rcond=None)[0]
    else:
        Zr = [rows(Z, r) for _, _, Z, r in parts]
        zscale = np.sqrt(sum(np.einsum("ij,ij->j", Z, Z) for Z in Zr)).clip(1e-300)
        Ws = [Z / zscale for Z in Zr]
        theta_s = np.linalg.solve(sum(W.T @ X for W, X in zip(Ws, Xs)), sum(W.T @ y for W, y in zip(Ws, ys)))
    A = sum(W.T @ X for W, X in zip(Ws, Xs))
    n = min(len(y) for y, *_ in parts)
    G = np.zeros((n, p))
    res2 = out2 = 0.0
    for (y, _, _, r), W, X, yr in zip(parts, Ws, Xs, ys):
        e = yr - X @ theta_s
        g = np.zeros((len(y), p))
        g[r] = W * e[:, None]
        G += g[:n]
        res2 += e @ e
        out2 += yr @ yr
    S, nb = _long_run(G, block)
    Ai = np.linalg.inv(A)
    return _Fit(theta_s / scale, Ai @ S @ Ai.T / np.outer(scale, scale), nb - p, float(cond),
                float(np.sqrt(res2 / out2)))


def _combine(method: str, p: Prepared, fits: dict[str, _Fit], iterations: int = 1) -> MethodResult:
    """Physical parameters from the per-equation theta: p_j = theta_j n for a normalised equation (delta method)."""
    theta, cov_blocks, names_t = [], [], []
    for reg in p.regressions:
        theta.extend(fits[reg.equation].theta)
        cov_blocks.append(fits[reg.equation].cov)
        names_t.extend((reg.equation, n) for n in reg.names)
    C = np.zeros((len(theta), len(theta)))
    k = 0
    for c in cov_blocks:
        C[k:k + len(c), k:k + len(c)] = c
        k += len(c)
    theta = np.array(theta)
    where = {n: j for j, (_, n) in enumerate(names_t)}
    names = [v.name for v in PHYSICAL if v.name in where]
    values = np.array([theta[where[n]] for n in names])
    J = np.zeros((len(names), len(theta)))
    for a, n in enumerate(names):
        J[a, where[n]] = 1.0
    for reg in p.regressions:
        if reg.normaliser is None:
            continue
        if reg.normaliser not in where:
            raise EstimatorInputError(
                f"{reg.normaliser} is needed to scale the {reg.equation} equation: give a voltage signal, "
                f"a known {reg.normaliser} or a torque signal")
        jn = where[reg.normaliser]
        for a, n in enumerate(names):
            if (reg.equation, n) in names_t and n in reg.names:
                jt = names_t.index((reg.equation, n))
                values[a] = theta[jt] * theta[jn]
                J[a] = 0.0
                J[a, jt], J[a, jn] = theta[jn], theta[jt]
    cov = J @ C @ J.T
    return MethodResult(method, tuple(names), values, cov, min(f.dof for f in fits.values()),
                        max(f.cond for f in fits.values()), max(f.fit for f in fits.values()), iterations)


def _check(result: MethodResult, options: EstimationOptions) -> None:
    """Refuse parameters that must be positive but whose relative standard error is too large."""
    std = np.sqrt(np.clip(np.diag(result.covariance), 0, None))
    strict = {v.name for v in PHYSICAL if v.lower_strict}
    bad = [n for n, v, s in zip(result.names, result.values, std)
           if n in strict and not (v > 0 and s / v <= options.max_relative_std)]
    if bad:
        raise NotEnoughExcitation(bad, f"relative standard error above {options.max_relative_std:.0%} or "
                                  f"non-positive estimate ({result.method.upper()})", result.condition_number)


def least_squares(p: Prepared, options: EstimationOptions) -> MethodResult:
    """Ordinary least squares of every regression (eq. 4, 5)."""
    fits, refused = {}, []
    for reg in p.regressions:  # every equation is checked, so a refusal names all it cannot identify
        y, Phi = reg.evaluate(_signals_for(p, reg))
        try:
            fits[reg.equation] = _solve(reg, [(y, Phi, None, p.rows[reg.equation])], p.block, options)
        except NotEnoughExcitation as exc:
            refused.append(exc)
    if refused:
        raise NotEnoughExcitation([n for exc in refused for n in exc.unidentifiable],
                                  "; ".join(exc.reason for exc in refused),
                                  max(exc.condition_number for exc in refused))
    res = _combine("ls", p, fits)
    _check(res, options)
    return res


def instruments(source: Prepared, params: Mapping[str, float], options: EstimationOptions, shift: float = 0.0,
                n: int | None = None) -> dict[str, np.ndarray]:
    """Noise-free copies of the signals, simulated from the model and ``params`` (IDIM-IV instruments).

    Each equation is simulated alone, solved for its derivative and driven by the measured filtered
    signals of ``source``; the instruments are the simulated states, their zero-forcing derivatives
    and sign, evaluated ``shift`` samples after the source's samples (cubic interpolation).

    Returns
    -------
    dict of str to ndarray, shape (n,)
        ``i``, ``w``, ``Di``, ``Dw``, ``sgn_w`` (those that can be simulated).
    """
    s, h = source.signals, source.h
    par = {**{v.name: v.nominal for v in PHYSICAL if v.optional}, **params, **source.known}
    step = max(h, 0.125 / options.filter.cutoff_hz)
    n = n or len(s["w"])
    at = np.arange(n) + shift
    out = {}
    for reg in source.regressions:
        eq = MODEL.equations[reg.equation]
        sig = _signals_for(source, reg)
        inputs = {x: sig[x] for x in reg.signals if x in MEASURED and x != eq.solves_for}
        # a torque signal replaces normaliser * output: simulate with the normaliser at 1
        values = dict(par, **{eq.normaliser: 1.0}) if source.overrides[reg.equation] else par
        out[eq.solves_for] = simulate((reg.equation,), inputs, values, h, {eq.solves_for: sig[eq.solves_for][0]},
                                      step, at=at)[eq.solves_for]
    for k in list(out):
        d, valid = zero_forcing_derivative(out[k], h)
        out["D" + k] = np.concatenate([np.full(valid.start, d[0]), d, np.full(n - valid.stop, d[-1])])
    if "w" in out:
        out["sgn_w"] = np.sign(out["w"])
    return out


def split_halves(data: MotionData) -> tuple[MotionData, MotionData]:
    """Odd and even samples of a motion: two records of the same motion with independent white noise."""
    def half(k: int) -> MotionData:
        return MotionData(2 * data.h, *(None if x is None else x[k::2] for x in
                                        (data.u, data.i, data.w, data.position, data.torque)), data.t0 + k * data.h)
    return half(1), half(0)


def instrumental_variables(data: MotionData, start: MethodResult, options: EstimationOptions) -> MethodResult:
    """Split-sample IDIM-IV, iterated to convergence from ``start``.

    The regression of the odd samples uses instruments simulated from the even samples, and the
    other way round. With white measurement noise the two halves carry independent noise, so the
    instruments are uncorrelated with the equation error even for the derivative of the current,
    whose only noise-free information is in the (noisy) voltage; instruments simulated from the
    same samples would bias L (about +15 % at 30 dB SNR here). Noise correlated from one sample to
    the next (not white) brings part of that bias back. The halves are sampled every 2 h, so the
    filter cut-off must stay below 0.45 of their Nyquist frequency (0.1125 / h).
    """
    odd, even = split_halves(data)
    halves = (prepare(odd, options), prepare(even, options))
    measured = {(reg.equation, k): reg.evaluate(_signals_for(half, reg))
                for k, half in enumerate(halves) for reg in half.regressions}
    cur = start
    for it in range(1, options.iv_iterations + 1):
        params = cur.as_dict()
        z = (instruments(halves[1], params, options, +0.5, len(halves[0].signals["w"])),
             instruments(halves[0], params, options, -0.5, len(halves[1].signals["w"])))
        fits = {}
        for reg in halves[0].regressions:
            parts = [(*measured[reg.equation, k], reg.evaluate(_signals_for(half, reg, zh))[1],
                      half.rows[reg.equation]) for k, (half, zh) in enumerate(zip(halves, z))]
            fits[reg.equation] = _solve(reg, parts, halves[0].block, options)
        new = _combine("iv", halves[0], fits, it)
        change = np.max(np.abs(new.values - cur.values) / np.maximum(np.abs(cur.values), 1e-12))
        cur = new
        if change < options.iv_tolerance:
            break
    _check(cur, options)
    return cur


def estimate_motion(data: MotionData, options: EstimationOptions = EstimationOptions()) -> MotionEstimate:
    """Estimate the physical parameters of one high-speed motion.

    Parameters
    ----------
    data : MotionData
        Voltage, current and speed (or position, or torque) of one motion, sampled every ``data.h``.
    options : EstimationOptions

    Returns
    -------
    MotionEstimate
        LS always; IV for methods ``iv`` and ``oe``; OE for ``oe`` (falls back to IV with a message).

    Raises
    ------
    NotEnoughExcitation
        The data cannot determine some parameters (they are named); no numbers are returned.
    EstimatorInputError
        Unusable signals or options.
    """
    p = prepare(data, options)
    ls = least_squares(p, options)
    iv = oe = None
    if options.method in ("iv", "oe"):
        iv = instrumental_variables(data, ls, options)
    if options.method == "oe":
        from estimator.oe import output_error

        oe = output_error(p, iv, options)
    return MotionEstimate(options.method, float(data.t0), float(data.t0 + (data.n - 1) * data.h), ls, iv, oe)
