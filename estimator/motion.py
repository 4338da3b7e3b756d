"""The estimator's data types: one motion's signals, the options, and the results (no computation).

Kept apart from ``estimate`` so that the method modules (``estimate``, ``oe``) share them without a cycle.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from feeddrive.estimator.blocks_c import row_block_sums
from feeddrive.estimator.distributions import t_ppf
from feeddrive.estimator.errors import EstimatorInputError, NotEnoughExcitation
from feeddrive.estimator.filtering import FilterSpec, check_decimation
from feeddrive.estimator.regression import Regression
from feeddrive.estimator.simulation import MODEL
from feeddrive.models import Model
from feeddrive.models.drives import DRIVES, drive_model, parameter_order, with_design

METHODS = ("ls", "iv", "oe")
#: fraction of the sampling period by which a sampling mode's samples lag their time stamps: an interval
#: mean over [t - h, t] belongs to the middle of its interval, t - h / 2
SAMPLING_DELAY = {"instant": 0.0, "mean": 0.5}

#: Physical parameters of the model in model order (T0 and other optional terms on request).
PHYSICAL = [v for v in MODEL.parameters if v.kind == "physical"]
#: physical parameter names of every drive kind (the order of pooled results and of the bounds' names)
ORDER = parameter_order()
#: MotionData's own signal fields (the DC drive's names; other models' signals go in ``signals``)
FIELDS = ("u", "i", "w", "position", "torque")


def physical(model: Model) -> list:
    """Physical parameters (``Variable``) of a model, in model order (``PHYSICAL`` for the DC drive)."""
    return PHYSICAL if model is MODEL else [v for v in model.parameters if v.kind == "physical"]


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
    delays : mapping of str to float
        Signal name -> how long [s] its samples lag their time stamps: ``h / 2`` for a sample that is the
        mean over the interval before its time stamp (``SAMPLING_DELAY``); default 0 (instantaneous).
        The estimator aligns every signal to its time stamp before the regression.
    signals : mapping of str to ndarray, each shape (n,)
        Other models' measured signals by model signal name (PMSM: ``u_d, u_q`` [V], ``i_d, i_q`` [A];
        the speed stays in ``w``), checked like the fields above.
    """

    h: float
    u: np.ndarray | None = None
    i: np.ndarray | None = None
    w: np.ndarray | None = None
    position: np.ndarray | None = None
    torque: np.ndarray | None = None
    t0: float = 0.0
    delays: Mapping[str, float] = field(default_factory=dict)
    signals: Mapping[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not (np.isfinite(self.h) and self.h > 0):
            raise EstimatorInputError(f"MotionData: h must be a positive sampling period [s], got {self.h}")
        n = None
        extra = dict(self.signals)
        clash = sorted(set(extra) & set(FIELDS))
        if clash:
            raise EstimatorInputError(f"MotionData: signals: {clash[0]!r} is a field of its own, give it as {clash[0]}=")
        for name in FIELDS + tuple(extra):
            x = extra[name] if name in extra else getattr(self, name)
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
            if name in extra:
                extra[name] = x
            else:
                object.__setattr__(self, name, x)
        if n is None:
            raise EstimatorInputError("MotionData: no signal given")
        object.__setattr__(self, "signals", extra)
        for name, d in dict(self.delays).items():
            if name not in FIELDS + tuple(extra) or not (np.isfinite(d) and 0 <= d <= 10 * self.h):
                raise EstimatorInputError(f"MotionData: delays: expected u, i, w, position, torque or a name of "
                                          f"signals -> a delay in [0, 10 h] s, got {name!r}: {d!r}")
        object.__setattr__(self, "delays", dict(self.delays))

    @property
    def n(self) -> int:
        return next(len(x) for x in (self.u, self.i, self.w, self.position, self.torque, *self.signals.values())
                    if x is not None)

    def raw(self) -> dict[str, np.ndarray]:
        """Every given signal by name: the fields that are not None, then ``signals``."""
        return {k: getattr(self, k) for k in FIELDS if getattr(self, k) is not None} | dict(self.signals)


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
    speed_threshold : float or None
        Samples with ``|w| <`` this (in the speed's own unit, rad/s or m/s) are excluded from the
        equations that use sign(w) ... None (default): ``speed_fraction`` of the motion's largest
        ``|w|``, so the threshold follows the data's scale (a linear axis at 0.13 m/s as well as a
        motor at 70 rad/s) ...
    speed_fraction : float
        ... the relative threshold used when ``speed_threshold`` is None (0.03: 2.1 rad/s at the
        built-in plant's 70 rad/s, close to the absolute 2 rad/s used before) ...
    speed_unit : str
        Unit of the speed, for messages only.
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
    model : Model or str
        The drive's model, or a kind of ``models.drives.DRIVES`` (``"dc"``, ``"pmsm"``, ``"pmsm-spm"``);
        default the DC feed drive. Known design parameters in ``known`` (the PMSM's pole pairs ``p``)
        replace the model's nominal values (``models.drives.with_design``) and leave ``known``.
    decimation : int or "auto"
        Every how many filtered samples the regressions use: "auto" (default) the largest factor the
        cut-off allows at the record's rate (``filtering.decimation_factor``), or a factor (1: every one).
    """

    method: str = "iv"
    filter: FilterSpec = FilterSpec(50.0)
    known: Mapping[str, float] = field(default_factory=dict)
    offset: bool = False
    speed_threshold: float | None = None
    speed_fraction: float = 0.03
    speed_unit: str = "rad/s"
    sign_guard: float = 2.0
    edge_guard: float = 3.0
    iv_iterations: int = 10
    iv_tolerance: float = 1e-4
    max_condition: float = 1e4
    max_relative_std: float = 0.3
    block_seconds: float | None = None
    oe_rate_hz: float = 1000.0
    model: Model | str = MODEL
    decimation: int | str = "auto"

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise EstimatorInputError(f"method must be one of {METHODS}, got {self.method!r}")
        model = self.model
        if isinstance(model, str):
            if model not in DRIVES:
                raise EstimatorInputError(f"drive must be one of {sorted(DRIVES)}, got {model!r}")
            model = drive_model(model)
        names = {v.name for v in physical(model)}
        design = {v.name for v in model.of_kind("design")}
        for k, v in self.known.items():
            if k not in names and k not in design:
                raise EstimatorInputError(f"known parameter {k!r} is not one of {sorted(names)} "
                                          f"(or a design parameter of {model.name})")
            if not np.isfinite(v):
                raise EstimatorInputError(f"known parameter {k!r} must be finite, got {v}")
        model = with_design(model, {k: v for k, v in self.known.items() if k in design})
        object.__setattr__(self, "model", model)
        object.__setattr__(self, "known", {k: v for k, v in self.known.items() if k not in design})
        if self.speed_threshold is not None and not self.speed_threshold >= 0:
            raise EstimatorInputError(f"speed_threshold must be >= 0 {self.speed_unit}, got {self.speed_threshold}")
        if not 0 <= self.speed_fraction < 1:
            raise EstimatorInputError(f"speed_fraction must be in [0, 1), got {self.speed_fraction}")
        check_decimation(self.decimation)

    @property
    def physical(self) -> list:
        """The model's physical parameters (``Variable``), in model order."""
        return physical(self.model)

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
        Degrees of freedom of the batch-means covariance (blocks less parameters).
    condition_number : float
        Of the column-scaled regressor (largest over the equations; OE: of the scaled jacobian).
    fit_error : float
        Relative fit error ``||y - Phi theta|| / ||y||`` (largest over the equations; OE: outputs).
    iterations : int
    message : str
        Why OE fell back, or "".
    parameter_dof : ndarray, shape (p,), optional
        Effective degrees of freedom of each parameter's variance (see :func:`parameter_covariance`), for
        the t quantile of its interval; ``dof`` for every parameter when absent.
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
    parameter_dof: np.ndarray | None = None
    ran: str = ""  # the method that actually produced the numbers when it fell back ("" = ``method``)

    @property
    def method_used(self) -> str:
        return self.ran or self.method

    @property
    def parameters(self) -> dict[str, ParameterEstimate]:
        dof = np.full(len(self.names), float(self.dof)) if self.parameter_dof is None else self.parameter_dof
        t = t_ppf(0.975, np.maximum(dof, 1))
        std = np.sqrt(np.clip(np.diag(self.covariance), 0, None))
        return {n: ParameterEstimate(float(v), float(s), (float(v - q * s), float(v + q * s)))
                for n, v, s, q in zip(self.names, self.values, std, t)}

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
    #: refused parameter -> the rule and its numbers (``estimator.partial``; empty from ``estimate_motion``)
    refused: Mapping[str, str] = field(default_factory=dict)
    #: quantities derived from the parameters (PMSM: K_t, K_e) with their standard errors, by the delta method
    derived: Mapping[str, ParameterEstimate] = field(default_factory=dict)
    #: given parameter outside its physical range or the user's bounds -> why (never validated)
    flags: Mapping[str, str] = field(default_factory=dict)
    #: parameter -> value of the bounded least squares fit, offered when something is flagged
    bounded: Mapping[str, float] = field(default_factory=dict)
    hint: str | None = None  #: the flags' cause when one quantity's sign convention explains them
    #: parameter -> the value it was fixed at in the re-fit of the others (L = 0: quasi-static equation)
    fixed: Mapping[str, float] = field(default_factory=dict)
    #: refused parameter kept in the fit as a lumped term -> its value there (Cd holding Cd + T0 or the
    #: friction at the motion's speed; L with a second lag): with ``fixed``, the model as fitted
    lumped: Mapping[str, float] = field(default_factory=dict)
    #: the given parameters with their covariance before a refused one was fixed at its estimate (the
    #: intervals not conditional on it): what several motions or files are pooled and compared with
    joint: MethodResult | None = None
    #: rate of the samples the regressions used [Hz] (the record's or, ``EstimationOptions.decimation``, less)
    rate_hz: float | None = None

    @property
    def undetermined(self) -> tuple[str, ...]:
        """The parameters the fit held at a value because the motion could not determine them (``fixed``,
        ``lumped``): the model checks take them as free (``mismatch.check_model``'s ``undetermined``)."""
        return (*self.fixed, *self.lumped)

    @property
    def method_used(self) -> str:
        """The method whose numbers are given (``iv`` when ``oe`` fell back, ``ls`` when IV did)."""
        return self.result.method_used

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
        """``{"start","end","method","parameters": {name: {"value","ci95"}},"condition_number","fit_error","rate_hz"}``."""
        out = {
            "start": self.start, "end": self.end, "method": self.method_used,
            "parameters": {n: {"value": p.value, "ci95": list(p.ci95)} for n, p in self.parameters.items()},
            "condition_number": float(self.condition_number), "fit_error": float(self.fit_error),
        }
        # the keys below appear only when they have something to say
        if self.method_used != self.method:
            out |= {"method_requested": self.method, "fallback": self.result.message}
        if self.derived:
            out["derived"] = {n: {"value": p.value, "ci95": list(p.ci95)} for n, p in self.derived.items()}
        if self.refused:
            out["refused"] = dict(self.refused)
        if self.fixed:
            out["fixed"] = {k: float(v) for k, v in self.fixed.items()}
        if self.flags:
            out["flags"] = dict(self.flags)
        if self.bounded:
            out["bounded"] = {n: {"value": float(v), "bounded": True} for n, v in self.bounded.items()}
        if self.hint:
            out["hint"] = self.hint
        if self.rate_hz is not None:
            out["rate_hz"] = float(self.rate_hz)
        return out


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
    #: parameter -> reason, for the regressions ``prepare(..., strict=False)`` left out
    refused: dict[str, str] = field(default_factory=dict)
    #: equation -> how many samples are usable and why the others are not (for the messages)
    notes: dict[str, str] = field(default_factory=dict)
    #: parameter -> its current value, for the regressions that take it as a constant (``Regression.constants``:
    #: estimated by another equation; the nominal value until that equation's estimate is known)
    constants: dict[str, float] = field(default_factory=dict)
    #: the model's physical parameters in model order (empty: the DC drive's ``PHYSICAL``)
    order: tuple[str, ...] = ()
    #: equation -> the regression of an equation that estimates nothing of its own (the PMSM's d axis: R, L_d, L_q
    #: are the q axis's), fitted jointly with it as a second sample set of the same parameters
    partners: dict[str, Regression] = field(default_factory=dict)
    decimation: int = 1  # every how many filtered samples ``signals`` keeps (``h``: the record's period times it)


def stationary_score_covariance(parts: list[tuple[np.ndarray, np.ndarray]], lags: int) -> np.ndarray:
    """Covariance of the summed score ``sum_t w_t e_t`` when the equation error is stationary.

    Parameters
    ----------
    parts : list of (W (n, p), e (n,))
        Instruments (or regressors) and equation errors of each independent sample set; rows left out of
        the fit are zero in both.
    lags : int
        Largest lag of the error's autocovariance kept [samples] (the filter's memory, ``block``).

    Returns
    -------
    ndarray, shape (p, p)
        ``sum_parts W^T Gamma W`` with ``Gamma`` the Toeplitz matrix of the error's autocovariance, each
        ``gamma(l)`` the mean of ``e_t e_(t+l)`` over every pair of used rows.

    Notes
    -----
    Measurement noise through the identical filter is stationary, so its autocovariance can be estimated
    from every sample of the motion, while the batch-means estimate of a parameter excited in a few places
    (L: the current transients) rests on the few blocks that carry it and scatters by a factor of 3 from
    one noise draw to the next. The regressor's own structure is known exactly here.
    """
    from feeddrive.estimator.toeplitz import score_covariance_sum  # the sets' transforms batched

    S = score_covariance_sum(parts, lags)
    return 0.5 * (S + S.T)


def parameter_covariance(G: np.ndarray, Ai: np.ndarray, block: int,
                         stationary: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, int]:
    """Batch-means covariance of ``Ai @ sum(G)`` with each parameter's own degrees of freedom.

    Parameters
    ----------
    G : ndarray, shape (n, p)
        Score rows (regressor times residual), one per sample.
    Ai : ndarray, shape (q, p)
        Maps the summed score to the parameters (the inverse information).
    block : int
        Samples per block.

    Returns
    -------
    cov : ndarray, shape (q, q)
    dof : ndarray, shape (q,)
        Degrees of freedom of each parameter's variance, for the t quantile of its interval.
    nb : int
        Blocks count.

    Notes
    -----
    Parameter ``j`` moves with ``c_t = (Ai g_t)_j``. A block's share of its variance is estimated by
    ``v_b = sum c_t^2`` over the block (less noisy than the squared block sum). When a few blocks
    carry the parameter (L: only the current transients), the variance rests on about
    ``k = (sum v_b)^2 / sum v_b^2`` blocks (Kish), not on all of them, and the parameter's own
    estimate took one of those: as for the mean of ``k`` samples, the variance is scaled by
    ``k / (k - 1)`` (instead of the all-blocks ``nb / (nb - p)`` when that is larger) and the t
    quantile has ``k - 1`` degrees of freedom (at most ``nb - p``). Checked by Monte Carlo in
    tests/estimator/test_parameter_covariance.py.

    ``stationary`` (p, p), the score covariance under a stationary equation error
    (:func:`stationary_score_covariance`), is a floor: a parameter whose batch-means variance falls below
    its stationary-error variance takes the latter, with ``nb - p`` degrees of freedom (its error
    autocovariance rests on every block). Over 40 white-noise draws on examples/tool_change.yaml (the
    sensors' default noise, 50 Hz filter), batch means alone gave L a standard error of 0.46 to 2.0 times
    its Monte-Carlo value 5.05e-6 H; with the floor 0.96 to 2.0 (coverage of the 95 % interval 95 -> 100 %;
    R and K unchanged). Issue 23's run had a half-width of 7.4e-6 H where 1.96 x 5.05e-6 = 9.9e-6.
    """
    S, nb = long_run_covariance(G, block)
    p = G.shape[1]
    cov = Ai @ S @ Ai.T
    block = min(block, len(G))
    v = row_block_sums((G[:nb * block] @ Ai.T) ** 2, block)  # numpy's reshape(nb, block, p).sum(axis=1)
    total = v.sum(axis=0)
    k = np.where(total > 0, total ** 2 / np.maximum((v ** 2).sum(axis=0), np.finfo(float).tiny), nb)
    # one block (a short record) leaves k = 1: its k / (k - 1) is capped rather than divided by zero
    k = np.clip(k, 1.0 + 1.0 / max(nb, 2), max(nb, 2))
    scale = np.sqrt(np.maximum(k / (k - 1) * max(nb - p, 1) / max(nb, 1), 1.0))
    cov, dof = cov * np.outer(scale, scale), np.clip(k - 1, 1.0, max(nb - p, 1))
    if stationary is not None:
        floor = np.diag(Ai @ stationary @ Ai.T) * (len(G) / max(len(G) - p, 1))
        var = np.diag(cov)
        low = floor > var
        lift = np.sqrt(np.where(low, floor / np.maximum(var, np.finfo(float).tiny), 1.0))
        cov, dof = cov * np.outer(lift, lift), np.where(low, max(nb - p, 1), dof)
    return cov, dof, nb


def long_run_covariance(G: np.ndarray, block: int) -> tuple[np.ndarray, int]:
    """Batch-means long-run covariance of the sum of the rows of G (n, p), and its blocks count."""
    block = min(block, len(G))
    nb = len(G) // block
    B = row_block_sums(G, block)  # G[:nb * block].reshape(nb, block, p).sum(axis=1), bit for bit
    # scaled up for the samples of the incomplete last block and for the p estimated parameters
    return B.T @ B * (len(G) / (nb * block)) * nb / max(nb - G.shape[1], 1), nb


def check_result(result: MethodResult, options: EstimationOptions) -> None:
    """Refuse parameters that must be positive but whose relative standard error is too large."""
    std = np.sqrt(np.clip(np.diag(result.covariance), 0, None))
    strict = {v.name for v in options.physical if v.lower_strict}
    bad = [n for n, v, s in zip(result.names, result.values, std)
           if n in strict and not (v > 0 and s / v <= options.max_relative_std)]
    if bad:
        raise NotEnoughExcitation(bad, f"relative standard error above {options.max_relative_std:.0%} or "
                                  f"non-positive estimate ({result.method.upper()})", result.condition_number)
