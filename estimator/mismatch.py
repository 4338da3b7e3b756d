"""Model validation: does the estimated model explain the motion? (paper IV.B.3, Fig. 13, 14)

The estimated model is simulated from the measured inputs (output error, no feedback from the
measured output), on the filtered signals (eq. 8):

* current from the voltage and speed with the estimated R, L, K (electrical equation, exact Tustin
  recursion started in steady state, as the validation's Ir_hat);
* speed from the current with the estimated K, Jt, ft, Cd (T0), on each segment where ``|w|`` stays
  above the speed threshold, less the filter's smear of the dry-friction jump at each end, started from
  the measured speed at the segment's start. sign(w) is constant on a segment, so the mechanical
  equation is linear there and simulated exactly (Tustin). One simulation over the whole motion
  integrated every imperfection of the smoothed sign(w) through the reversals and dwells (creep): on
  healthy data its residue was coloured and correlated with the current.

The simulation runs on the first sensor of each healthy redundant pair (``Im1``, ``u``, ``w_tach``)
and the second one (``Im2``, ``u_ref``, ``w_enc``) is the instrument (``check_signals``): the residue
carries the first sensors' noise through the model, so regressors or nuisance directions computed from
the same signals correlate with it on a healthy motion (with the mean of both sensors the test rejected
every healthy motion at high signal-to-noise ratio), and the differentiated encoder's quantisation,
aliased into the filter's band at slow speeds, is a structured error the speed residue must not carry.

Each residue ``measured - simulated`` is judged by two tests whose null hypothesis holds on healthy
data, so that their level is their false-alarm rate:

* **independence** (Ljung's residual analysis, MATLAB ``resid``): is the residue explained by the
  instruments (current residue: voltage and speed; speed residue: current) at lags 0..``lags`` of the
  residue decimated to ``rate_hz`` by block means? The residue's own colour is accounted for in two
  stages. First the colour the model itself implies: the speed residue integrates the current sensor's
  noise from each segment's start (a near-unit root at the block rate, seconds of ``Jt / ft``), so each
  segment is whitened by that null covariance (``integrated_noise_covariance``, from both sensors' noise
  and the estimated K, Jt, ft). Then what remains: feasible GLS with AR errors of an order chosen by BIC
  (estimator.glsar: statsmodels' ``GLSAR``), F-test of the lag coefficients. After the first stage the AR
  stage runs only if a Ljung-Box test finds the whitened residue coloured (``WHITE_ALPHA``): on a fast motion (a few
  dozen blocks) BIC overfits and the feasible GLS F-test is oversized. With the AR stage alone the
  speed test rejected 5 % of healthy motions at alpha / 4; the current residue, whose noises all pass
  the electrical time constant (shorter than a block), has the AR stage only. The estimate's own error also leaves an input-correlated residue (theta_hat -
  theta is of the order of its standard error); it is not a mismatch, so the sensitivities of the
  simulation along the principal axes of the covariance (``sensitivity_directions``), a constant
  (current) and, for the speed, each segment's free response (its start from one noisy sample,
  ``free_responses``) are nuisance regressors of the test;
* **size**: the residue, with those nuisance regressors removed, must be no larger than the noise of
  the sensor (``noise``: from its first differences, for a sensor the redundancy confirmed). Statistic
  ``F = mean(e^2) / sigma^2``, one-sided F-test with (decimated blocks, noise samples) degrees of
  freedom. Filtering lowers the sensor's own noise, so a model that explains the motion leaves a residue
  below it; a friction step of +10 % during the motion leaves several times it. The current residue also
  carries the voltage's and the speed's noise through the simulation (``1 / (L s + R)``, filtered): its
  sigma^2 adds that variance (``input_noise_variance``, where the voltage's noise is known). At 10 kHz the
  filter leaves little of it; at 1 kHz (a 100 Hz cut-off is a fifth of the band) it was 1.4 times the
  current sensor's own noise, and the size test rejected the healthy built-in plant (F = 2.1, p = 1e-13).

* **peak** (speed residue only, where both sensor pairs confirmed their noise): is one block far
  outside the others? ``residue_tests.peak_test``:
  the largest block of the whitened, nuisance-free residue against its MAD scale, Bonferroni over the
  blocks. The two tests above average over the motion, and a fault acting for a few blocks (backlash
  crossed at the start or the reversal of a slow motion: ~0.1 s in 10 s, 50 times the residue's noise)
  moved neither (backlash 0.02 rad: 0 of the 6 motions slower than 0.05 m/s detected). Not the current
  residue: on the vendor FMU its acceleration transients (held inputs, analog loops) stood 4.9 MAD out
  on 1 of 40 healthy motions.

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
from functools import lru_cache

import casadi as ca
import numpy as np

from feeddrive.estimator import lti
from feeddrive.estimator.errors import EstimatorInputError, NumericalFailure
from feeddrive.estimator.filtering import FilterSpec, check_rate_factor
from feeddrive.estimator.kernels import bilinear_first_order, columns, erode, label_runs, label_slices
from feeddrive.estimator.residue_tests import TestResult, block_samples, integrated_noise_covariance, residue_tests
from feeddrive.estimator.simulation import MODEL
from feeddrive.estimator.validation import MeasurementValidation, model_reference, noise_std

#: physical parameters each simulated output depends on (from the model's equations)
USES = {signal_: tuple(v.name for v in MODEL.parameters
                       if v.kind == "physical" and ca.depends_on(MODEL.equations[eq].residual, v.sym))
        for signal_, eq in (("speed", "mechanical"), ("current", "electrical"))}
#: inputs of each simulation, the regressors of its independence test
INPUTS = {"current": ("u", "w"), "speed": ("i",)}
#: shortest speed segment simulated [s]: shorter ones (reversals) carry no test information
MIN_SEGMENT_S = 0.1


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
        RMS of the residue without its nuisance part, and the noise it is compared with (NaN without one),
        in the signal's unit: the sensor's, and for the current also what the simulation passes of the
        voltage's and the speed's noise.
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
                           base: np.ndarray, undetermined: Sequence[str] = ()) -> np.ndarray:
    """Change of a simulated signal along each principal axis of the estimate's covariance.

    ``d_k = simulate(theta + sqrt(lambda_k) v_k) - simulate(theta)`` for the eigenpairs of the covariance
    restricted to the parameters the signal uses: one standard deviation along each axis. Without a
    covariance, one step of 1e-3 of each used parameter's value. Each ``undetermined`` parameter the signal
    uses (and the covariance does not hold) adds one step of 1e-3 of its value (1e-3 of its unit at 0).

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
    undetermined : sequence of str
        Parameters the fit held at a value because the motion could not determine them (``MotionEstimate``'s
        ``fixed`` and ``lumped``): no covariance, but free under the null all the same.

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
    steps += [{k: 1e-3 * (abs(parameters[k]) or 1.0)} for k in undetermined if k in uses and k not in names]
    cols = []
    with np.errstate(all="ignore"):  # a diverging perturbed simulation is a refusal below, not a warning
        for step in steps:  # (one floating-point state for all the steps: numpy's context set once)
            p = dict(parameters)
            for k, d in step.items():
                p[k] += d
            col = simulate(p) - base
            if not np.all(np.isfinite(col)):
                raise NumericalFailure(f"the model check's simulation diverges when {', '.join(step)} moves by one "
                                       "standard deviation: the estimate is too uncertain to check")
            cols.append(col)
    return np.column_stack(cols) if cols else np.zeros((base.size, 0))


def speed_segments(w: np.ndarray, threshold: float, h: float, margin: int = 0) -> tuple[np.ndarray, int]:
    """Labels 1..k of the runs of samples with ``|w| > threshold``, less ``margin`` samples at each end,
    lasting at least ``MIN_SEGMENT_S`` (0 elsewhere), and k.

    The margin keeps the filter's smear of the dry-friction jump at a reversal or a start out of the
    segments: there the filtered current carries part of the torque step of the other sign, which the
    constant-sign simulation does not have (a model error of up to 4e-3 rad/s at 0.02 m/s, as large as
    the noise's)."""
    fast = np.abs(w) > threshold
    if margin > 0:
        fast = erode(fast, margin, border=False)
    labels, n = label_runs(fast)
    sizes = np.bincount(labels.ravel(), minlength=n + 1)
    short = sizes < MIN_SEGMENT_S / h
    short[0] = True
    labels[short[labels]] = 0
    return label_runs(labels > 0)


def simulate_segments(i: np.ndarray, w: np.ndarray, labels: np.ndarray, params: Mapping[str, float],
                      h: float) -> np.ndarray:
    """Speed [rad/s] from the current [A] on each labelled segment (constant sign of w), NaN elsewhere.

    ``Jt dw/dt + ft w = K i - Cd sign(w) - T0``, Tustin, started at the measured speed ``w`` of each
    segment's first sample."""
    K, Jt, ft, Cd = (float(params[k]) for k in ("K", "Jt", "ft", "Cd"))
    T0 = float(params.get("T0", 0.0))
    b, a = bilinear_first_order(Jt, ft, h)
    slices = label_slices(labels)
    spans = [(sl[0].start, sl[0].stop) if sl is not None else (-1, -1) for sl in slices]
    out = np.empty(w.size)
    last = 0
    for first, stop in spans:  # NaN between the segments only (each sample written once), when they are in order
        if first < last or first < 0:
            out.fill(np.nan)
            break
        out[last:first] = np.nan
        last = stop
    else:
        out[last:] = np.nan
    for sl in slices:
        drive = K * i[sl]  # (K i - Cd sign(w0)) - T0, in place: the same two subtractions, no temporaries
        drive -= Cd * np.sign(w[sl][0])
        drive -= T0
        # transposed direct form: y[0] = b0 x[0] + z[0], so z[0] = w0 - b0 x[0] starts the output at w0
        out[sl] = lti.lfilter(b, a, drive, zi=[w[sl][0] - b[0] * drive[0]])[0]
    return out


def free_responses(labels: np.ndarray, params: Mapping[str, float], h: float) -> np.ndarray:
    """Free response of ``simulate_segments`` to a unit error of each segment's start speed, shape (n, k).

    The start is one noisy measured sample: its error decays as ``exp(-ft t / Jt)`` through the segment
    (seconds), so it is not a constant; it is a nuisance of the speed residue's tests."""
    b, a = bilinear_first_order(float(params["Jt"]), float(params["ft"]), h)
    pole = -float(np.ravel(a)[1])
    slices = label_slices(labels)
    out = np.zeros((labels.size, len(slices)))  # np.column_stack of the columns, written in place
    for j, sl in enumerate(slices):
        # float exponents: the int64 ones were cast to float64 through the ufunc's buffers (the same values)
        np.power(pole, np.arange(sl[0].stop - sl[0].start, dtype=float), out=out[sl[0], j])
    return out


def check_signals(v: MeasurementValidation, signals: Mapping[str, np.ndarray | None]
                  ) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray], dict[str, float]]:
    """Signals of the model check (estimator/mismatch.py): simulation inputs and measured outputs, instruments
    and sensor noise, per quantity.

    Where both sensors of a pair are healthy, the check simulates from and compares with the first sensor
    alone and takes the second as the instrument (the regressors of its independence test and the inputs
    of its nuisance directions): their noises are independent, so the residue, which carries the first
    sensor's noise through the model, is uncorrelated with them on a healthy motion. With the mean of both
    the residue and the regressors shared the noise, and the test rejected healthy motions. Elsewhere (no
    redundancy, a faulty or corrected sensor) the validated signal is used and has no instrument. The noise
    [V, A, rad/s] is that of the first sensor, from its first differences (``validation.noise_std``), only where
    the redundancy confirmed it.

    Returns
    -------
    inputs : dict with ``u``, ``i``, ``w`` of ndarray, shape (n,)
    instruments : dict of str to ndarray, shape (n,)
    noise : dict with ``voltage``, ``current``, ``speed`` (those confirmed)
    """
    symbol = {"voltage": "u", "current": "i", "speed": "w"}
    inputs = {"u": v.u, "i": v.i, "w": v.w}
    instruments, noise = {}, {}
    for quantity, pair in v.pairs.items():
        s1, s2 = pair.sensors
        healthy = (s2 is not None and pair.residue is not None and pair.residue.kind == "none"
                   and signals.get(s2) is not None)
        if not healthy:
            continue
        x = np.asarray(signals[s1], dtype=float)
        inputs[symbol[quantity]] = x
        instruments[symbol[quantity]] = np.asarray(signals[s2], dtype=float)
        noise[quantity] = noise_std(x)
    return inputs, instruments, noise


def input_noise_variance(filter: FilterSpec, h: float, step: int, L: float, R: float, sigma_v: float,
                         points: int = 2048) -> float:
    """Variance [A^2] that a white noise of std ``sigma_v`` [V] on ``v = u - K w`` at the record's period ``h``
    [s] leaves in the simulated current: through the monitor's filter at ``h``, every ``step``-th sample kept,
    then the Tustin ``1 / (L s + R)`` at ``h step`` (``isolation.model_reference``). The power gain is
    integrated over the record's band (midpoint rule, ``points`` frequencies); the filter's cut-off is far
    below the decimated Nyquist frequency (``check_rate_factor``), so what the decimation folds is neglected.
    ``sigma_v^2 = sigma_u^2 + K^2 sigma_w^2`` for independent voltage and speed sensor noises."""
    filtered, zd = _filter_power(filter, h, step, points)
    b, a = bilinear_first_order(L, R, h * step)
    gain = filtered * np.abs((b[0] + b[1] * zd) / (a[0] + a[1] * zd)) ** 2
    return float(sigma_v ** 2 * np.mean(gain))


@lru_cache(maxsize=16)
def _filter_power(filter: FilterSpec, h: float, step: int, points: int) -> tuple[np.ndarray, np.ndarray]:
    """The filter's power gain at ``input_noise_variance``'s frequencies and ``exp(-i w step)`` there, both (points,)
    and read-only: the same for every motion of an axis (its filter, period and decimation), so formed once."""
    w = (np.arange(points) + 0.5) * (np.pi / points)  # rad per record sample
    z1, z2 = np.exp(-1j * w), np.exp(-2j * w)
    gain = np.ones(points)
    for b0, b1, b2, _, a1, a2 in filter.sos(h):
        gain *= np.abs((b0 + b1 * z1 + b2 * z2) / (1 + a1 * z1 + a2 * z2)) ** 2
    if filter.zero_phase:  # forward and backward: the magnitude squared twice
        gain *= gain
    return _read_only(gain), _read_only(np.exp(-1j * w * step))


def _one_run(mask: np.ndarray) -> slice | np.ndarray:
    """``mask`` (n,) bool as the slice of its one run of True (indexing by it gives the same values as views), or
    itself when its True samples are not one run."""
    idx = np.flatnonzero(mask)
    return slice(int(idx[0]), int(idx[-1]) + 1) if idx.size and idx[-1] - idx[0] + 1 == idx.size else mask


def _read_only(x: np.ndarray) -> np.ndarray:
    x.setflags(write=False)
    return x


def _upsample(y: np.ndarray, step: int, n: int) -> np.ndarray:
    """``np.interp(arange(n), arange(0, n, step), y)`` with numpy's own arithmetic (``slope (x - xp) + fp``,
    the samples past the last one held), by strides instead of a search per sample (4 ms of a motion)."""
    out = np.empty(n)
    out[::step] = y
    slope = (y[1:] - y[:-1]) / float(step)
    last = (y.size - 1) * step  # the last sample with a value; after it np.interp holds y[-1]
    for j in range(1, step):
        out[j:last:step] = slope * float(j) + y[:-1]
    out[last + 1:] = y[-1]
    return out


def _instrument_signals(instruments: Mapping[str, np.ndarray], n: int) -> dict[str, np.ndarray]:
    out = {}
    for key, x in instruments.items():
        if key not in ("u", "i", "w"):
            raise EstimatorInputError(f"check_model: instrument {key!r} is not one of u, i, w")
        x = np.asarray(x, dtype=float)
        if x.shape != (n,) or not np.all(np.isfinite(x)):
            raise EstimatorInputError(f"check_model: instrument {key!r} must be finite with shape ({n},)")
        out[key] = x
    return out


def check_model(u: np.ndarray, i: np.ndarray, w: np.ndarray, h: float, parameters: Mapping[str, float],
                filter: FilterSpec, alpha: float = 0.01, covariance: np.ndarray | None = None,
                names: Sequence[str] | None = None, noise: Mapping[str, float] | None = None,
                noise_dof: float = np.inf, speed_threshold: float | None = None,
                speed_fraction: float = 0.03, rate_hz: float = 50.0, lags: int = 10,
                ar_order: int | None = None,
                instruments: Mapping[str, np.ndarray] | None = None,
                decimation: int | str = "auto", undetermined: Sequence[str] = ()) -> MismatchResult:
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
        ``speed``), from the redundant sensors; a missing key: no size test for that residue. With
        ``voltage`` [V] too, the current's size test counts the voltage's and the speed's noise that the
        simulation passes into its residue (``input_noise_variance``).
    noise_dof : float
        Degrees of freedom of those noise estimates (number of samples they come from).
    speed_threshold : float or None
        The speed is simulated on the segments where ``|w| >`` this [rad/s]; None: ``speed_fraction`` of
        the motion's peak filtered speed (as the estimator).
    rate_hz, lags, ar_order : float, int, int
        See ``residue_tests``.
    decimation : int or "auto"
        Every how many filtered samples are simulated and tested (``EstimationOptions.decimation``; "auto":
        the checks' rule, ``filtering.check_rate_factor``); the residues are given back on every sample (linear
        interpolation, for the plots).
    undetermined : sequence of str
        Parameters in ``parameters`` that the fit held at a value because the motion could not determine them
        (``MotionEstimate.fixed`` and ``lumped``: a viscous friction fixed at 0 and the dry friction lumped at
        the motion's one speed). Their sensitivities are nuisance directions like the covariance's axes, so
        the check does not reject what the motion cannot tell: the lumped friction is right at the cruise
        speed and wrong on the ramps, and on a healthy vendor FMU that alone rejected 9 of 100 motions.

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
    n, record_h = len(f["w"]), h
    # the filtered signals carry the model on every D-th sample: simulated and tested there
    step = check_rate_factor(filter.cutoff_hz, h, n, decimation, rate_hz)
    if step > 1:
        f = {k: np.ascontiguousarray(x[::step]) for k, x in f.items()}
        h = h * step
    params = {k: float(v) for k, v in parameters.items()}
    edge = int(round(5.0 / (filter.cutoff_hz * h)))  # the zero-phase filter's transients at both ends
    inner = np.zeros(f["w"].size, dtype=bool)
    inner[edge:f["w"].size - edge] = True
    if speed_threshold is None:
        speed_threshold = speed_fraction * float(np.abs(f["w"][inner]).max(initial=0.0))
    labels, _ = speed_segments(np.where(inner, f["w"], 0.0), speed_threshold, h, margin=edge)
    keep = {"current": inner, "speed": labels > 0}
    # instruments: second sensors whose noise is independent of the residue's (the simulation's inputs'
    # noise passes into the residue; regressors or nuisance directions carrying the same noise correlate
    # with it under the null, and the test rejected every healthy motion)
    fi = f if instruments is None else {**f, **{k: np.ascontiguousarray(x[::step]) for k, x in filter.apply(
        _instrument_signals(instruments, u.size), record_h).items()}}
    simulators = {
        "current": ("i", lambda p, s: model_reference("current", s, h, p)),  # linear: exact Tustin recursion
        "speed": ("w", lambda p, s: simulate_segments(s["i"], f["w"], labels, p, h)),
    }
    noise = dict(noise or {})
    null_covariance = None
    if noise.get("speed", 0) > 0 and noise.get("current", 0) > 0:
        # the speed residue integrates the current sensor's noise through the model (see
        # integrated_noise_covariance): its share per block from the sensor noises and the parameters
        tb = block_samples(rate_hz, h) * h
        rho = float(np.exp(-params["ft"] / params["Jt"] * tb))
        ratio = (params["K"] * tb / params["Jt"] * noise["current"] / noise["speed"]) ** 2
        # the independence and the peak tests whiten the same segments: each size built once
        null_covariance = lru_cache(maxsize=None)(lambda nb: _read_only(integrated_noise_covariance(nb, rho, ratio)))
    if noise.get("current", 0) > 0 and noise.get("voltage", 0) > 0:
        # the simulated current carries the filtered voltage and speed noise: the residue's null is both
        sigma_v2 = noise["voltage"] ** 2 + (params["K"] * noise.get("speed", 0.0)) ** 2
        noise["current"] = float(np.sqrt(noise["current"] ** 2 + input_noise_variance(
            filter, record_h, step, params["L"], params["R"], np.sqrt(sigma_v2))))
    checks = {}
    for name, (x, simulate) in simulators.items():
        simulated = simulate(params, f)
        k = keep[name]
        sel = _one_run(k)  # the current's samples are one run: read as views (a slice), not gathered by the mask
        if np.count_nonzero(k) < 2 / h * MIN_SEGMENT_S:
            raise EstimatorInputError(f"model check ({name}): only {np.count_nonzero(k)} samples to test")
        base = simulated if fi is f else simulate(params, fi)
        D = sensitivity_directions(lambda p, s=simulate, k=sel: s(p, fi)[k], params, names, covariance, USES[name],
                                   base[sel], undetermined)
        # (n, k) blocks gathered a column at a time (a 2-D gather by a mask copies each row of a few values alone):
        # the same C-ordered rows as np.column_stack(...)[sel]
        if name == "speed":
            D = columns([D, *(c[sel] for c in free_responses(labels, params, h).T)])
        X = columns([fi[s][sel] for s in INPUTS[name]])
        tests, rms, corr, band = residue_tests(name, (f[x] - simulated)[sel], D, X, h, alpha, rate_hz, lags,
                                               ar_order, noise.get(name), noise_dof,
                                               labels[sel] if name == "speed" else None, constant=name == "current",
                                               # with a null covariance the peak test runs too: the speed
                                               # only (on the vendor FMU the current residue's acceleration
                                               # transients stood 4.9 MAD out on 1 of 40 healthy motions), and
                                               # only with both pairs confirmed (a differentiated encoder's
                                               # quantisation has peaks of its own)
                                               segment_covariance=null_covariance if name == "speed" else None)
        residue = np.where(k, f[x] - simulated, np.nan)  # the samples tested (filter edges out)
        if step > 1:  # back on every sample of the record (the plots' time axis)
            simulated, residue = (_upsample(y, step, n) for y in (simulated, residue))
        checks[name] = ResidueCheck(name, tests, rms, float(noise.get(name, np.nan)), simulated, residue, corr, band)
    results = [(f"{name} {t}", r) for name, c in checks.items() for t, r in c.tests.items()]
    m = len(results)
    label, worst = min(results, key=lambda t: t[1].p_value)
    p = min(1.0, m * worst.p_value)
    rule = (f"Bonferroni over {m} tests ({', '.join(t for t, _ in results)}): mismatch when a p-value is below "
            f"alpha / {m}")
    free = [k for k in undetermined if k in params and k not in names]
    if free:  # say why a check passes where the parameters are refused: they were not taken as known
        rule += f"; {', '.join(free)} (not determined by this motion) are free in the tests, like the estimate's uncertainty"
    return MismatchResult(label, worst.statistic, p, alpha, bool(p >= alpha), rule, checks)
