"""Measurement validation (paper section IV.B, Fig. 4-6; EQUATIONS.md section 6).

Three redundant pairs are checked on each high-speed motion:

* current: two current sensors ``Im1``, ``Im2`` (eq. 9: ``Imi = ai Ir + bi + ni``);
* voltage: terminal voltage ``u`` and the regulator's reference ``u_ref``;
* speed: tachometer ``w_tach`` and the differentiated encoder ``w_enc``.

Detection (eq. 10). The residue ``r = x1 - x2`` is cut into consecutive, non-overlapping windows
(``window_s``). On the window means ``r_k`` and the window levels ``l_k = mean((x1 + x2) / 2)`` the
regression ``r_k = c l_k + d`` is fitted: for eq. 9, ``c = a1 - a2`` (differential gain) and
``d = b1 - b2`` (differential offset). The variance of a window mean is the larger of

* the high-frequency noise prediction ``sigma^2 / m`` (``sigma`` from the first differences of ``r``,
  robust MAD estimate; ``m`` samples per window; exact for white noise), and
* the scatter of the window means about the fit (covers coloured noise and unmodelled structure),

and ``c`` and ``d`` get t-tests with ``n_windows - 2`` degrees of freedom at level ``alpha``
(default 1e-3). A fault is declared only when it is statistically significant AND larger than a
stated tolerance (``gain_tol`` relative, ``offset_tol`` as a fraction of the signal's range), so
a tiny but significant bias on a long motion is not a fault. A chi-square test of the fit residuals
against ``sigma^2 / m`` tells whether the residue has structure beyond gain and offset
(``p_structure``; for example a delay between the sensors).

Gain ratio (eq. 12, 11) on the filtered signals: ``a1/a2 = mean[(x1f - mean x1f) / (x2f - mean x2f)]``,
averaged over the samples whose denominator exceeds 20 % of its largest magnitude (the ratio is
meaningless near the zero crossings of the denominator); ``Er = 1 - a1/a2``.

Isolation by analytical redundancy (Fig. 6). When a pair's residue shows a fault, a third,
model-based value of the quantity is computed from the other two quantities and the electrical
equation (eq. 1) with the LAST VALIDATED ``L, R, K`` (or nominal values for the first motion)::

    current  Ir_hat(s) = (uf(s) - K wf(s)) / (L s + R)      (Tustin discretisation, steady-state start)
    voltage  u_hat     = R if + L d(if)/dt + K wf
    speed    w_hat     = (uf - R if - L d(if)/dt) / K

and each sensor is fitted as ``xkf = ak x_hat + bk`` (eq. 13, 14) by OLS with heteroscedasticity-
and-autocorrelation-consistent (Newey-West) standard errors, because the residuals of filtered
signals are coloured. A sensor is faulty when its gain CI excludes 1 (and ``|ak - 1| > gain_tol``) or
its offset CI excludes 0 (and ``|bk| > offset_tol * range``). The sensor with the smaller error
``rms((ak - 1) x_hat + bk)`` is trusted; if it is itself faulty the pair's signal is the corrected
``(x - bk) / ak`` and the pair is not valid (parameters estimated from it must not be diagnosed).
Without a fault the pair's signal is the mean of the two sensors.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from feeddrive.estimator.distributions import chi2_sf, t_ppf, t_sf
from feeddrive.estimator.errors import EstimatorInputError
from feeddrive.estimator.filtering import FilterSpec, decimation_factor, share_filtered

# the isolation (Fig. 6) lives in its own module; its names stay importable from here
from feeddrive.estimator.isolation import KINDS, SensorFit, isolate, model_reference  # noqa: F401
from feeddrive.estimator.kernels import line_fit
from feeddrive.estimator.medians import median_in_place

#: the redundant pairs: quantity -> (sensor 1, sensor 2)
PAIRS: dict[str, tuple[str, str]] = {
    "current": ("Im1", "Im2"),
    "voltage": ("u", "u_ref"),
    "speed": ("w_tach", "w_enc"),
}


@dataclass(frozen=True)
class ValidationOptions:
    """Settings of the measurement validation.

    Attributes
    ----------
    alpha : float
        Level of every statistical test (probability of a false alarm per test).
    window_s : float
        Length of the residue windows [s].
    gain_tol : float
        Smallest relative gain error that counts as a fault (0.005 = 0.5 %).
    offset_tol : float
        Smallest offset that counts as a fault, as a fraction of the largest absolute value of the
        signal over the motion (0.005 = 0.5 % of the range; 0.1 A at 20 A).
    edge_s : float
        Samples dropped at each end of the motion for the isolation fits [s] (filter transients).
    """

    alpha: float = 1e-3
    window_s: float = 0.05
    gain_tol: float = 0.005
    offset_tol: float = 0.005
    edge_s: float = 0.02

    def __post_init__(self) -> None:
        for name in ("alpha", "window_s", "gain_tol", "offset_tol"):
            if not getattr(self, name) > 0:
                raise EstimatorInputError(f"ValidationOptions.{name}: must be > 0, got {getattr(self, name)!r}")
        if not self.alpha < 0.5:
            raise EstimatorInputError(f"ValidationOptions.alpha: must be < 0.5, got {self.alpha!r}")
        if self.edge_s < 0:
            raise EstimatorInputError(f"ValidationOptions.edge_s: must be >= 0, got {self.edge_s!r}")


@dataclass(frozen=True)
class ResidueTest:
    """Detection on the residue ``r = x1 - x2`` (eq. 10).

    Attributes
    ----------
    kind : str
        ``none``, ``offset``, ``gain`` or ``gain+offset``.
    noise_std : float
        High-frequency noise std of ``r`` from its first differences [signal unit].
    window : int
        Samples per window.
    gain_diff, gain_diff_ci95, p_gain : float, tuple, float
        Slope ``a1 - a2`` of the window means on the level, its 95 % CI and the test's p-value.
    offset, offset_ci95, p_offset : float, tuple, float
        ``b1 - b2`` [signal unit], its 95 % CI and p-value.
    p_structure : float
        p-value of the chi-square lack-of-fit test (small: structure beyond gain and offset).
    centers, means, levels : ndarray, shape (n_windows,)
        Window centre sample indices, window means of ``r`` and window levels.
    anti : bool
        The level is ``x2`` (the sensors read opposite signs), not the pair's mean: ``a1 / a2`` is then
        ``1 + gain_diff``, else ``(2 + gain_diff) / (2 - gain_diff)`` (``gain_ratio_of``).
    """

    kind: str
    noise_std: float
    window: int
    gain_diff: float
    gain_diff_ci95: tuple[float, float]
    p_gain: float
    offset: float
    offset_ci95: tuple[float, float]
    p_offset: float
    p_structure: float
    centers: np.ndarray = field(repr=False)
    means: np.ndarray = field(repr=False)
    levels: np.ndarray = field(repr=False)
    anti: bool = False

    def gain_ratio_of(self, c: float) -> float:
        """``a1 / a2`` for a slope ``c`` of the residue on this test's level (``gain_diff`` or a bound of its CI)."""
        if self.anti:
            return 1.0 + c
        return (2.0 + c) / (2.0 - c) if c < 2.0 else float("inf")


@dataclass(frozen=True)
class PairValidation:
    """Validation of one redundant pair.

    Attributes
    ----------
    quantity : str
        ``current``, ``voltage`` or ``speed``.
    sensors : tuple of str
        The two sensor names (the second is None without redundancy).
    residue : ResidueTest or None
        None without redundancy.
    gain_ratio, relative_gain_error : float
        ``a1/a2`` (eq. 12) and ``Er = 1 - a1/a2`` (eq. 11); NaN without redundancy.
    fits : tuple of SensorFit
        Isolation fits (empty when the residue shows no fault).
    trusted : str or None
        Sensor whose signal (or corrected signal) is passed on; None when the mean of both is.
    signal : ndarray, shape (n,)
        The validated (or corrected) raw signal for the estimator.
    valid : bool
        False when no sensor of the pair can be trusted.
    notes : tuple of str
    """

    quantity: str
    sensors: tuple
    residue: ResidueTest | None
    gain_ratio: float
    relative_gain_error: float
    fits: tuple[SensorFit, ...]
    trusted: str | None
    signal: np.ndarray = field(repr=False)
    valid: bool
    notes: tuple[str, ...] = ()

    @property
    def faults(self) -> list[SensorFit]:
        return [f for f in self.fits if f.faulty]


@dataclass(frozen=True)
class MeasurementValidation:
    """Result of ``validate_measurements``: one ``PairValidation`` per quantity and the signals to use."""

    pairs: dict[str, PairValidation]
    reference: str
    u: np.ndarray = field(repr=False)
    i: np.ndarray = field(repr=False)
    w: np.ndarray = field(repr=False)
    notes: tuple[str, ...] = ()

    @property
    def valid(self) -> bool:
        return all(p.valid for p in self.pairs.values())

    @property
    def sensor_faults(self) -> list[SensorFit]:
        return [f for p in self.pairs.values() for f in p.faults]

    @property
    def gain_ratio(self) -> float:
        return self.pairs["current"].gain_ratio if "current" in self.pairs else float("nan")


#: the MAD of a standard normal variable, scipy.special.ndtri(0.75) (median_abs_deviation's scale="normal")
NORMAL_MAD = 0.6744897501960817


def noise_std(x: np.ndarray) -> float:
    """High-frequency noise std of ``x`` from its first differences (robust, MAD based).

    For white noise of std ``s`` on a slowly varying signal, ``diff(x)`` has std ``s sqrt(2)``.
    """
    d = np.diff(np.asarray(x, dtype=float))
    if d.size < 2:
        return float(np.median(np.abs(d - np.median(d))) / NORMAL_MAD / np.sqrt(2.0))
    # scipy.stats.median_abs_deviation(d, scale="normal")'s arithmetic without its axis/NaN-policy wrapper
    # (a third of its time on 35000 samples; the same bits, tests/estimator/test_speed.py)
    med = median_in_place(d)
    if np.isnan(d[d.size // 2:].max()):  # a NaN sorts into the upper part: numpy's median is then NaN
        return float("nan")
    return float(median_in_place(np.abs(d - med, out=d)) / NORMAL_MAD / np.sqrt(2.0))


def residue_test(x1: np.ndarray, x2: np.ndarray, h: float,
                 options: ValidationOptions = ValidationOptions(), mean: np.ndarray | None = None) -> ResidueTest:
    """Detect and classify a disagreement between two sensors of one quantity (eq. 10).

    Parameters
    ----------
    x1, x2 : ndarray, shape (n,)
        Raw (unfiltered) measurements of the same quantity, same samples.
    h : float
        Sample time [s].
    options : ValidationOptions
    mean : ndarray, shape (n,), optional
        ``0.5 * (x1 + x2)`` when the caller has it (validate_measurements passes the pair's mean on).

    Returns
    -------
    ResidueTest
    """
    x1, x2 = _same_shape(x1, x2, "x1", "x2")
    m = max(int(round(options.window_s / h)), 2)
    n_win = x1.size // m
    if n_win < 8:
        raise EstimatorInputError(
            f"residue_test: {x1.size} samples give {n_win} windows of {options.window_s} s; need at least 8")
    r = x1 - x2
    sigma = noise_std(r)
    cut = n_win * m
    means = r[:cut].reshape(n_win, m).mean(axis=1)
    # the level is the pair's mean, unless one sensor reads the quantity with the opposite sign (a tachometer
    # or a current probe mounted the other way round): the mean then cancels, the residue 2 x has no level to
    # regress on and a pair that disagrees by 200 % passed as "none". Strongly anti-correlated sensors (a
    # correlation below -0.5: never noise alone, ~1/sqrt(n)) take the second sensor's reading as the level, and
    # the residue is a gain difference near -2 (sensor 1 reads about -1 times sensor 2)
    anti = float(x1 @ x2) < -0.5 * float(np.sqrt(float(x1 @ x1) * float(x2 @ x2)))
    level = x2 if anti else (0.5 * (x1 + x2) if mean is None else mean)  # the caller's mean when it has one
    levels = level[:cut].reshape(n_win, m).mean(axis=1)
    centers = np.arange(n_win) * m + (m - 1) / 2
    coef, resid, gram_inv = line_fit(levels, means)
    dof = n_win - 2
    var_hf = sigma**2 / m
    scale = max(float(resid @ resid) / dof, var_hf, np.finfo(float).tiny)
    cov = scale * gram_inv
    se = np.sqrt(np.diag(cov))
    tq = t_ppf(0.975, dof)
    p = 2 * t_sf(np.abs(coef) / np.where(se > 0, se, np.inf), dof)
    p_structure = float(chi2_sf(float(resid @ resid) / var_hf, dof)) if var_hf > 0 else 0.0
    span = float(np.max(np.abs(levels)))
    gain = p[0] < options.alpha and abs(coef[0]) > options.gain_tol
    offset = p[1] < options.alpha and abs(coef[1]) > options.offset_tol * span
    kind = KINDS[int(offset) + 2 * int(gain)]
    ci = [(float(c - tq * s), float(c + tq * s)) for c, s in zip(coef, se)]
    return ResidueTest(kind, sigma, m, float(coef[0]), ci[0], float(p[0]), float(coef[1]), ci[1], float(p[1]),
                       p_structure, centers, means, levels, anti)


def gain_ratio(x1f: np.ndarray, x2f: np.ndarray, step: int = 1) -> float:
    """Gain ratio ``a1/a2`` of two filtered sensors (eq. 12).

    Parameters
    ----------
    x1f, x2f : ndarray, shape (n,)
        Filtered measurements of the same quantity.
    step : int
        Every how many samples are averaged: the low-passed signals carry nothing above a few cut-offs, so
        the estimator's decimation (``filtering.decimation_factor``) keeps the ratio (validate_measurements
        passes it: 0.29 -> 0.11 ms a pair at 10 kHz; on the tool change the ratio moves by 8e-8 of itself).

    Returns
    -------
    float
        ``mean[(x1f - mean x1f) / (x2f - mean x2f)]`` over the samples where
        ``|x2f - mean x2f|`` exceeds 20 % of its maximum. ``Er = 1 - a1/a2`` (eq. 11).
    """
    x1f, x2f = _same_shape(x1f, x2f, "x1f", "x2f")
    if step > 1:
        x1f, x2f = x1f[::step], x2f[::step]
    d1, d2 = x1f - x1f.mean(), x2f - x2f.mean()
    a2 = np.abs(d2)
    keep = a2 > 0.2 * np.max(a2)
    if not keep.any():
        raise EstimatorInputError("gain_ratio: the second signal is constant; no gain ratio")
    with np.errstate(divide="ignore", invalid="ignore"):  # the samples left out may divide by 0
        ratio = np.divide(d1, d2, out=d1)  # every quotient, then those kept: one gather instead of two
    return float(np.mean(ratio[keep]))


def validate_measurements(signals: Mapping[str, np.ndarray], h: float, electrical: Mapping[str, float] | None,
                          filter: FilterSpec, options: ValidationOptions = ValidationOptions(),
                          nominal: Mapping[str, float] | None = None,
                          decimation: int | str = "auto") -> MeasurementValidation:
    """Validate the redundant measurements of one high-speed motion (paper Fig. 4-6).

    Parameters
    ----------
    signals : mapping of str to ndarray, shape (n,)
        Raw measurements: ``Im1`` (required) and ``Im2`` [A], ``u`` (required) and ``u_ref`` [V],
        ``w_tach`` (required) and ``w_enc`` [rad/s]. A missing or None second sensor means no
        redundancy for that quantity: its first sensor is passed on unchecked (with a note).
    h : float
        Sample time [s].
    electrical : mapping with ``R``, ``L``, ``K``, or None
        Last validated electrical parameters (theta_{j-1}). None on the first motion: ``nominal`` is used.
    filter : estimator.filtering.FilterSpec
        The monitor's low-pass filter (eq. 8), the same as the estimator's.
    options : ValidationOptions
    nominal : mapping with ``R``, ``L``, ``K``, optional
        The axis's stated values, used when ``electrical`` is None; None: the feed-drive model's. Without
        all three a disagreeing pair is not isolated (``reference`` "none").
    decimation : int or "auto"
        ``EstimationOptions.decimation``: the gain ratios (eq. 12) average every D-th filtered sample, as the
        estimator's regressions (``filtering.decimation_factor``); the residue tests (eq. 10) read every raw one.

    Returns
    -------
    MeasurementValidation
    """
    if h <= 0:
        raise EstimatorInputError(f"validate_measurements: sample time h must be > 0, got {h!r}")
    notes = []
    if electrical is None:
        if nominal is None:
            from feeddrive.models.drives import drive_model
            nominal = drive_model("dc").nominal()  # the feed drive's model built once (feed_drive(): 3 ms a call)
        # another machine's R, L, K taken for this one's would blame the wrong sensor (gains of 0.004 on both)
        electrical, reference = (nominal, "nominal") if all(k in nominal for k in "RLK") else (None, "none")
        notes.append("no validated parameters yet (first motion): isolation uses nominal R, L, K" if electrical else
                     "no validated or stated R, L, K for this axis yet: a disagreeing pair cannot be isolated")
    else:
        reference = "last validated"
    raw = {}
    for q, (s1, s2) in PAIRS.items():
        if signals.get(s1) is None:
            raise EstimatorInputError(f"validate_measurements: signal {s1!r} is required")
        raw[s1] = np.asarray(signals[s1], dtype=float)
        if signals.get(s2) is not None:
            raw[s2] = _same_shape(raw[s1], signals[s2], s1, s2)[1]
    n = raw["Im1"].size
    for name, x in raw.items():
        if x.shape != (n,) or not np.all(np.isfinite(x)):
            raise EstimatorInputError(f"validate_measurements: signal {name!r} must be finite with shape ({n},)")
    filt = filter.apply(raw, h)
    symbol = {"current": "i", "voltage": "u", "speed": "w"}
    residues, best = {}, {}  # best: quantity symbol -> (raw, filtered) signal to pass on
    for q, (s1, s2) in PAIRS.items():
        if s2 in raw:
            mean = 0.5 * (raw[s1] + raw[s2])
            residues[q] = residue_test(raw[s1], raw[s2], h, options, mean)
            best[symbol[q]] = (mean, 0.5 * (filt[s1] + filt[s2]))
        else:
            best[symbol[q]] = (raw[s1], filt[s1])
    pairs = {}
    for q, (s1, s2) in PAIRS.items():
        if s2 not in raw:
            pairs[q] = PairValidation(q, (s1, None), None, float("nan"), float("nan"), (), s1, raw[s1], True,
                                      (f"{q}: no redundant sensor, {s1} passed on unchecked",))
            continue
        res = residues[q]
        ratio = gain_ratio(filt[s1], filt[s2], decimation_factor(filter.cutoff_hz, h, n, decimation))
        if res.kind == "none":
            pairs[q] = PairValidation(q, (s1, s2), res, ratio, 1.0 - ratio, (), None, best[symbol[q]][0], True)
            continue
        if electrical is None:  # Fig. 6 needs R, L, K: the pair is reported, neither sensor trusted
            pairs[q] = PairValidation(q, (s1, s2), res, ratio, 1.0 - ratio, (), None, best[symbol[q]][0], False, (
                f"{q}: {s1} and {s2} disagree ({res.kind}); not isolated: the isolation (Fig. 6) needs the axis's "
                f"R, L, K: state them (monitor.nominal, --nominal R=... L=... K=...) or validate a healthy motion",))
            continue
        others = {k: v[1] for k, v in best.items()}
        ref = model_reference(q, others, h, electrical)
        fits = isolate(filt[s1], filt[s2], ref, (s1, s2), h, filter.cutoff_hz, options)
        chosen = min(fits, key=lambda f: f.error_rms)
        pair_notes = []
        if chosen.faulty:
            x = (raw[chosen.sensor] - chosen.offset) / chosen.gain
            xf = (filt[chosen.sensor] - chosen.offset) / chosen.gain
            pair_notes.append(f"{q}: both sensors faulty; {chosen.sensor} corrected with its isolation fit")
        else:
            x, xf = raw[chosen.sensor], filt[chosen.sensor]
        valid = not chosen.faulty and any(f.faulty for f in fits)
        if not any(f.faulty for f in fits):
            pair_notes.append(f"{q}: the residue shows a {res.kind} fault that isolation cannot attribute")
        best[symbol[q]] = (x, xf)
        pairs[q] = PairValidation(q, (s1, s2), res, ratio, 1.0 - ratio, fits, chosen.sensor, x, valid,
                                  tuple(pair_notes))
    for q, (s1, _) in PAIRS.items():  # the signals passed on, filtered already: the estimator's and model checks'
        x, xf = best[symbol[q]]  # low-pass of them is this one (a mean or a correction of filtered rows)
        if x is not raw[s1]:  # the pair's mean or a corrected sensor, made here: kept itself, read-only
            share_filtered(filter, h, x, xf, own=not any(x is r for r in raw.values()))
    faulty_pairs = [q for q, p in pairs.items() if p.residue is not None and p.residue.kind != "none"]
    if len(faulty_pairs) > 1:
        notes.append(f"faults on several quantities ({', '.join(faulty_pairs)}): each isolation used the "
                     "others' best signals, which may themselves be corrected")
    return MeasurementValidation(pairs, reference, best["u"][0], best["i"][0], best["w"][0], tuple(notes))


def _same_shape(x1, x2, n1: str, n2: str) -> tuple[np.ndarray, np.ndarray]:
    x1, x2 = np.asarray(x1, dtype=float), np.asarray(x2, dtype=float)
    if x1.ndim != 1 or x1.shape != x2.shape:
        raise EstimatorInputError(f"{n1} and {n2} must be 1-D arrays of the same length, got {x1.shape} and {x2.shape}")
    return x1, x2
