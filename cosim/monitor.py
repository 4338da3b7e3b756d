"""The monitor: the paper's Fig. 4 as a co-simulation component (and as a pipeline on recorded data).

For every high-speed motion without machining (NC ``state == 1``, one ``motion`` index), the
monitor buffers the redundant measurements and, when the motion ends, runs in order:

    filtering (eq. 8) -> measurement validation (Fig. 5, 6) -> estimation (eq. 4, 5)
    -> model validation (IV.B.3) -> diagnosis (Table I) -> history (SQLite)

and measures its own processing time against the paper's budget (1-2 s between the end of the rapid
motion and the tool engaging the work-piece). theta_{j-1} (``last_validated``) and the healthy
baseline are read from the history at setup, so a second run on the same axis and database
continues where the first stopped. The output ``request`` is 1.0 while the identification is too old
(no validated identification for more than ``max_motions`` motions or ``max_age_s`` seconds of
machine time); the NC then inserts an identification motion.

Machine time is the wall-clock time at setup plus the simulated time, so ages are comparable across
runs. ``MonitorPipeline`` is the same treatment without the component (``cosim monitor`` on CSVs).
"""
from __future__ import annotations

import math
import time as _time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from feeddrive.cosim import monitor_checks as checks
from feeddrive.cosim.axis import parameter_units
from feeddrive.cosim.component import Component
from feeddrive.cosim.errors import InputError, ScenarioError
from feeddrive.cosim.monitor_checks import _drift_reference, _residue_dict, centred_speed, interval_mean_speed
from feeddrive.cosim.nc import describe_validation_error
from feeddrive.estimator.adequacy import check_adequacy
from feeddrive.estimator.diagnosis import DiagnosisOptions, diagnose, make_baseline
from feeddrive.estimator.errors import EstimatorInputError, HistoryError, NotEnoughExcitation
from feeddrive.estimator.estimate import EstimationOptions, MotionData, estimate_motion
from feeddrive.estimator.filtering import FilterSpec
from feeddrive.estimator.history import History
from feeddrive.estimator.mismatch import MismatchResult, check_model, check_signals
from feeddrive.estimator.motion import SAMPLING_DELAY
from feeddrive.estimator.physical import physical_flags
from feeddrive.estimator.validation import MeasurementValidation, ValidationOptions, validate_measurements

#: NC state of a high-speed motion without machining
RAPID = 1
#: measurement inputs, in the order the buffer stores them
MEASUREMENTS = ("Im1", "Im2", "u", "u_ref", "w_tach", "w_enc", "theta_enc")


class MonitorConfig(BaseModel):
    """The scenario's ``monitor:`` section (all keys optional).

    Attributes
    ----------
    axis : str or None
        Machine/axis id in the history; None: the scenario's ``axis`` (set by the loader), else ``X``.
    scenario : str
        Scenario name stored with each motion.
    db : str or None
        SQLite history file; None keeps the history in memory (nothing persists between runs).
    method : {"ls", "iv", "oe"}
        Estimation method whose parameters are validated and stored.
    filter_cutoff_hz, filter_order : float, int
        The identical low-pass of every signal (eq. 8), used by validation and estimation.
    speed_threshold : float or None
        Samples with ``|w|`` below it [rad/s] are excluded from the sign(w) term; None (default):
        ``speed_fraction`` of each motion's largest speed (relative to the data, not to a nominal plant).
    speed_fraction : float
        The relative threshold used when ``speed_threshold`` is None.
    alpha : float
        Level of every statistical test (residues, model whiteness, drifts).
    window_s, gain_tol, offset_tol : float
        Residue windows [s]; sensor gain error [relative] and offset [fraction of range] that count as faults.
    mismatch_alpha : float
        Family-wise level of the model check (independence and size tests of the output-error residues,
        estimator/mismatch.py): its false-alarm rate on healthy motions.
    baseline : {"motions", "nominal"}
        Healthy baseline: the first ``baseline_motions`` validated motions without a diagnosis, or the
        model's nominal values. While it is incomplete, each validated motion is diagnosed against the
        healthy motions accepted so far (from the second validated motion on; the same test), and a
        motion with a diagnosis is not added to it.
    baseline_motions : int
    nominal : dict of str to float
        The axis's design values of ``R, L, K, Jt, ft, Cd`` (motor side, SI) where they differ from the
        built-in model's: the first motion's sensor isolation and ``baseline: nominal`` use them.
    known : dict of str to float
        Parameters known in advance (motor side, SI), fixed in the estimation and the model checks, e.g.
        ``{R: 8.4, K: 0.042}`` (``cosim monitor --known R=8.4 K=0.042``); K is needed to estimate Jt, ft,
        Cd from a current without a voltage.
    min_relative_drift : float
        Smallest relative parameter change diagnosed.
    min_motion_s, max_motion_s : float
        Shorter motions are recorded as not identified; longer ones are cut to this length [s].
    max_motions, max_age_s : int, float
        Identification too old: more motions than this, or more seconds, since the last validated one.
    budget_s : float
        Processing time allowed per motion [s] (paper: 1-2 s).
    keep_traces : int
        Motions whose signals are kept for the monitor plots (the last ones).
    encoder_window_s : float
        The component's encoder speed is the centred difference of ``theta_enc`` over this window [s].
        The sensors' ``w_enc`` is a backward difference, i.e. the speed half a window earlier: averaged
        with the tachometer it delayed the speed by a quarter window (0.25 ms), which biased R by
        +0.45 % and ft by -1 % on the built-in plant.
    sampling : mapping of {"voltage", "current", "speed"} to {"instant", "mean"}
        What a sample of each quantity is: ``mean``, the mean over the sampling interval before its
        time stamp, which the estimator aligns to the interval's middle (h/2 earlier); default
        instant. In a scenario it defaults to the sensors' sampling when ``plant.oversample`` > 1.
    """

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    axis: str | None = Field(None, min_length=1)
    scenario: str = ""
    db: str | None = None
    method: Literal["ls", "iv", "oe"] = "iv"
    filter_cutoff_hz: float = Field(100.0, gt=0)
    filter_order: int = Field(4, ge=1)
    speed_threshold: float | None = Field(None, ge=0)
    speed_fraction: float = Field(0.03, ge=0, lt=1)
    alpha: float = Field(1e-3, gt=0, lt=0.5)
    window_s: float = Field(0.05, gt=0)
    gain_tol: float = Field(0.005, gt=0)
    offset_tol: float = Field(0.005, gt=0)
    mismatch_alpha: float = Field(0.01, gt=0, lt=0.5)
    baseline: Literal["motions", "nominal"] = "motions"
    baseline_motions: int = Field(3, ge=1)
    nominal: dict[Literal["R", "L", "K", "Jt", "ft", "Cd"], float] = {}
    known: dict[Literal["R", "L", "K", "Jt", "ft", "Cd"], float] = {}
    bounds: dict[Literal["R", "L", "K", "Jt", "ft", "Cd"], tuple[float | None, float | None]] = {}
    min_relative_drift: float = Field(0.05, gt=0)
    min_motion_s: float = Field(1.0, gt=0)
    max_motion_s: float = Field(30.0, gt=0)
    max_motions: int = Field(10, ge=0)
    max_age_s: float = Field(7 * 86400.0, gt=0)
    budget_s: float = Field(2.0, gt=0)
    keep_traces: int = Field(5, ge=0)
    encoder_window_s: float = Field(1.0e-3, gt=0)
    sampling: dict[Literal["voltage", "current", "speed"], Literal["instant", "mean"]] = {}


    @field_validator("bounds", mode="before")
    @classmethod
    def _bounds(cls, raw: object) -> object:
        """``{Jt: "4e-6:", ft: [0, 1]}`` (the scenario's and ``--bounds``' forms) -> (low, high) pairs."""
        from feeddrive.estimator.physical import bounds_mapping

        if isinstance(raw, dict):
            try:
                return bounds_mapping(raw, "")
            except ValueError as exc:
                raise ValueError(str(exc).lstrip(": ")) from None
        return raw

    def delays(self, h: float) -> dict[str, float]:
        """Estimator signal -> delay [s] of its samples (see ``sampling``), for sampling period ``h``."""
        symbol = {"voltage": "u", "current": "i", "speed": "w"}
        return {symbol[q]: SAMPLING_DELAY[mode] * h for q, mode in self.sampling.items() if SAMPLING_DELAY[mode]}

    @property
    def filter(self) -> FilterSpec:
        return FilterSpec(self.filter_cutoff_hz, self.filter_order)


@dataclass
class MotionTrace:
    """Signals of one processed motion, for the monitor plots (paper Fig. 9-14)."""

    motion: int
    t: np.ndarray
    signals: dict[str, np.ndarray]
    validation: MeasurementValidation | None = None
    mismatch: MismatchResult | None = None
    result: dict = field(default_factory=dict)


class MonitorPipeline:
    """The monitor's treatment of one motion at a time, with its memory (theta_{j-1}, baseline).

    Parameters
    ----------
    config : MonitorConfig
    history : History
        The store; theta_{j-1}, the baseline and the recent validated sets are read from it now.
    axis : str
    """

    def __init__(self, config: MonitorConfig, history: History, axis: str) -> None:
        from feeddrive.models import feed_drive

        self.config, self.history, self.axis = config, history, axis
        # the axis's own design values when given (a vendor motor), else the built-in model's
        self.nominal = feed_drive().nominal(("physical",)) | dict(config.nominal) | dict(config.known)
        self.validation_options = ValidationOptions(config.alpha, config.window_s, config.gain_tol, config.offset_tol)
        self.estimation_options = EstimationOptions(method=config.method, filter=config.filter,
                                                    speed_threshold=config.speed_threshold,
                                                    speed_fraction=config.speed_fraction, known=dict(config.known))
        self.diagnosis_options = DiagnosisOptions(config.alpha, config.min_relative_drift)
        last = history.last_validated(axis)
        self.last_validated: dict | None = last["parameters"] if last else None
        self.baseline_sets = [b["parameters"] for b in history.baseline(axis, config.baseline_motions)]
        self.recent = [r["parameters"] for r in history.recent_validated(axis, self.diagnosis_options.trend_motions)]

    @property
    def building(self) -> bool:
        """True while the healthy baseline has fewer than ``baseline_motions`` motions."""
        return self.config.baseline == "motions" and len(self.baseline_sets) < self.config.baseline_motions

    def baseline(self) -> dict | None:
        """The healthy reference (name -> (value, std)) a validated motion is diagnosed against.

        The nominal values, or the mean of the healthy baseline motions; while that baseline is being
        built, the mean of the healthy motions accepted so far (None before the first one).
        """
        if self.config.baseline == "nominal":
            return {k: (v, 0.0) for k, v in self.nominal.items()}
        return make_baseline(self.baseline_sets) if self.baseline_sets else None

    def thresholds(self) -> dict:
        """The diagnosis' thresholds and the healthy baseline now (report.json ``diagnosis_thresholds``).

        ``{"alpha", "z_crit", "min_relative": {name: fraction}, "baseline_motions", "baseline":
        {name: {"value", "std"}} or None}``: what the alarm bands of the trend plots are drawn from.
        """
        return _drift_reference(self.baseline(), self.diagnosis_options, list(self.nominal)) | {
            "alpha": self.diagnosis_options.alpha, "baseline_mode": self.config.baseline,
            "baseline_motions": self.config.baseline_motions,
            "baseline_learnt": len(self.baseline_sets)}

    def process(self, signals: Mapping[str, np.ndarray | None], h: float, start: float, motion: int,
                time: float, scenario: str = "") -> MotionTrace:
        """Validate, estimate, check, diagnose and store one motion.

        Parameters
        ----------
        signals : mapping of str to ndarray, shape (n,)
            ``Im1, Im2`` [A], ``u, u_ref`` [V], ``w_tach, w_enc`` [rad/s], ``torque`` [N.m]: any subset with a
            speed (cosim/monitor_checks.py); a missing or None sensor leaves its pair not checked.
        h : float
            Sample time [s].
        start : float
            Time of the first sample in the run or recording [s].
        motion : int
            Motion index.
        time : float
            Machine clock at the end of the motion [s since the epoch], for the history.
        scenario : str
            Stored with the motion.

        Returns
        -------
        MotionTrace
            ``result`` is the per-motion dict stored in the history and in report.json.
        """
        tic, cpu = _time.perf_counter(), _time.process_time()
        signals = {k: v for k, v in signals.items() if v is not None}
        n = len(next(iter(signals.values())))
        result: dict[str, Any] = {"motion": int(motion), "start": start, "end": start + (n - 1) * h,
                                  "method": self.config.method, "validated": False, "measurements_valid": None,
                                  "reference": None, "parameters": {}, "sensor_faults": [], "gain_ratio": None,
                                  "residues": {}, "mismatch": None, "adequacy": None, "diagnosis": [], "notes": [],
                                  "error": None, "verdict": None,
                                  "not_checked": checks.not_checked(checks.present(signals), "torque" in signals)}
        if self.config.known:
            result["known"] = dict(self.config.known)
        trace = MotionTrace(int(motion), start + h * np.arange(n), dict(signals), result=result)
        mismatch = False
        if (n - 1) * h < self.config.min_motion_s:
            result["error"] = (f"motion of {(n - 1) * h:.3g} s is shorter than "
                               f"min_motion_s = {self.config.min_motion_s} s (set it with --min-motion)")
        else:
            try:
                mismatch = self._identify(signals, h, start, trace)
            except (NotEnoughExcitation, EstimatorInputError) as exc:  # this motion cannot be used; the next may
                result["error"] = str(exc)
            except (np.linalg.LinAlgError, FloatingPointError) as exc:  # ill-conditioned data: a refusal, not a crash
                result["error"] = f"numerical failure on this motion's data ({exc})"
        result["verdict"] = checks.motion_verdict(result, mismatch)
        result["processing_s"] = _time.perf_counter() - tic
        # judged on CPU time: the wall time also counts whatever else the host runs meanwhile
        result["processing_cpu_s"] = _time.process_time() - cpu
        result["within_budget"] = result["processing_cpu_s"] <= self.config.budget_s
        self.history.record(self.axis, result, scenario=scenario, time=time)
        return trace

    def _identify(self, signals: Mapping[str, Any], h: float, start: float, trace: MotionTrace) -> bool:
        """Validation, estimation, model check and diagnosis of one motion; True when the model check that
        decided found a mismatch."""
        result, cfg = trace.result, self.config
        have = checks.present(signals)
        known = dict(cfg.known)
        if "w_tach" not in have and "w_enc" in have:
            signals, have = {**signals, "w_tach": signals["w_enc"]}, have | {"w_tach"}
            signals.pop("w_enc")
            have.discard("w_enc")
        full = {"Im1", "u", "w_tach"} <= have
        v, mismatch_result = None, None
        if full:
            electrical = checks.electrical_reference(self.last_validated, self.nominal, known)
            if cfg.sampling.get("speed") == "mean" and signals.get("w_enc") is not None:
                signals = {**signals, "w_enc": interval_mean_speed(signals["w_enc"])}
            v = validate_measurements(signals, h, electrical, cfg.filter, self.validation_options,
                                      nominal=self.nominal)
            trace.validation = v
            faults = [f.to_dict() for f in v.sensor_faults]
            ratio = v.pairs["current"].gain_ratio if v.pairs["current"].residue is not None else None
            result |= {"measurements_valid": bool(v.valid and not faults), "reference": v.reference,
                       "gain_ratio": ratio, "relative_gain_error": None if ratio is None else 1.0 - ratio,
                       "sensor_faults": faults,
                       "residues": {q: _residue_dict(p) for q, p in v.pairs.items() if p.residue is not None}}
            result["notes"] += list(v.notes) + [n for p in v.pairs.values() for n in p.notes if p.residue is not None]
            valid, u, i, w = v.valid, v.u, v.i, v.w
        else:
            residues, faults, best, notes = checks.detect_subset(signals, h, self.validation_options, have)
            result |= {"measurements_valid": not faults, "sensor_faults": faults, "residues": residues}
            result["notes"] += notes
            valid, u, i, w = not faults, best.get("u"), best.get("i"), best["w"]
        torque = signals.get("torque")
        # a torque's offset T0 needs both directions: in one, sign(w) is a constant and Cd absorbs it
        peak = float(np.max(np.abs(w))) if np.size(w) else 0.0
        both = bool(np.max(w) > cfg.speed_fraction * peak and np.min(w) < -cfg.speed_fraction * peak)
        offset = torque is not None and both
        if torque is not None and not both:
            result["notes"].append("one direction only: Cd and a torque offset cannot be told apart (Cd holds both)")
        adequacy = None
        try:  # before the estimation: a mismatch explains a refusal (gravity hides Jt on a robot axis)
            adequacy = check_adequacy(h, u=u, i=i, w=w, torque=torque, alpha=cfg.mismatch_alpha, filter=cfg.filter,
                                      speed_fraction=cfg.speed_fraction, known=known, offset=offset)
            result["adequacy"] = adequacy.to_dict()
        except EstimatorInputError as exc:
            result["not_checked"]["model (own residue)"] = f"not checked: {exc}"
        try:
            est = estimate_motion(MotionData(h, u=u, i=i, w=w, torque=torque, t0=start, delays=cfg.delays(h)),
                                  replace(self.estimation_options, offset=offset))
        except (NotEnoughExcitation, ValueError, np.linalg.LinAlgError) as exc:
            # this motion cannot be used (the next may); ValueError: a non-finite simulation of the instruments
            result["error"] = str(exc) if isinstance(exc, NotEnoughExcitation | EstimatorInputError) else \
                f"estimation failed on this motion's data ({exc})"
            if adequacy is not None and adequacy.mismatch:
                result["notes"].append("not validated: model mismatch (the residue check), which may be why the "
                                       "estimation was refused")
            return adequacy is not None and adequacy.mismatch
        params = est.parameters
        units = parameter_units("motor")  # the monitor's signals are the motor's: u, i, w [rad/s]
        result["parameters"] = {k: {"value": p.value, "std": p.std, "ci95": list(p.ci95), "unit": units.get(k, "")}
                                for k, p in params.items()}
        result |= {"condition_number": float(est.condition_number), "fit_error": float(est.fit_error)}
        flags = physical_flags(est, dict(cfg.bounds))
        if flags:  # outside the physical range or the user's bounds: reported, never validated
            result["flags"] = flags
        values = {k: p.value for k, p in params.items()} | known
        if full and all(k in values for k in ("R", "L", "K", "Jt", "ft", "Cd")):
            inputs, instruments, noise = check_signals(v, signals)
            mismatch_result = check_model(inputs["u"], inputs["i"], inputs["w"], h, values, cfg.filter,
                                          cfg.mismatch_alpha, covariance=est.covariance, names=est.names,
                                          noise=noise, noise_dof=len(v.i), speed_threshold=cfg.speed_threshold,
                                          speed_fraction=cfg.speed_fraction, instruments=instruments)
            trace.mismatch = mismatch_result
            result["mismatch"] = mismatch_result.to_dict()
        else:
            result["not_checked"]["model (paper, output error)"] = (
                "not checked: needs the current, the voltage and the speed" if not full
                else "not checked: needs every parameter estimated or known")
        if mismatch_result is not None:  # the paper's check decides; the residue check is reported beside it
            mismatch = not mismatch_result.passed
        else:
            mismatch = adequacy is not None and adequacy.mismatch
        result["validated"] = bool(valid and not mismatch and (mismatch_result is not None or (
            adequacy is not None and adequacy.verdict == "adequate")))
        if flags:
            result["validated"] = False
            result["notes"].append("not validated: physically impossible estimate: " + "; ".join(flags.values()))
        if not valid:
            result["notes"].append("not validated: a measurement could not be trusted (no diagnosis)")
        if mismatch:
            result["notes"].append("not validated: model mismatch (no diagnosis; parameters reported)")
        elif valid and not result["validated"]:
            why = adequacy.verdict if adequacy is not None else "model not checked"
            result["notes"].append(f"not validated: {why} (the model check has no power; parameters reported)")
        if not result["validated"]:
            return mismatch
        current = result["parameters"]
        reference = self.baseline()
        if reference is not None:
            # the reference and thresholds this motion was judged against: the trend plots' alarm band
            result["drift_reference"] = _drift_reference(reference, self.diagnosis_options, list(self.nominal))
            result["diagnosis"] = [d.to_dict() for d in diagnose(current, reference, self.last_validated, self.recent,
                                                                 self.diagnosis_options)]
        if self.building:
            k, n = len(self.baseline_sets), self.config.baseline_motions
            if result["diagnosis"]:  # a worn axis must not become the healthy reference
                result["notes"].append(f"healthy baseline incomplete ({k} of {n}): drift diagnosed against the "
                                       f"{k} healthy motion(s) so far; not added to the baseline")
            else:
                self.baseline_sets.append(current)
                result["notes"].append(f"healthy baseline: motion {k + 1} of {n}")
        self.last_validated = current
        self.recent = (self.recent + [current])[-self.diagnosis_options.trend_motions:]
        return False


class Monitor(Component):
    """Co-simulation component of the monitor; see the module docstring.

    Inputs: ``Im1, Im2, u, u_ref, w_tach, w_enc, theta_enc`` (sensors), ``state, motion`` (NC).
    Output: ``request`` (1.0 while the identification is too old).
    """

    input_names = MEASUREMENTS + ("state", "motion")
    output_names = ("request",)
    output_units = ("1",)

    def __init__(self, name: str, config: MonitorConfig | Mapping | None = None) -> None:
        if not isinstance(config, MonitorConfig):
            try:
                config = MonitorConfig.model_validate(config or {})
            except ValidationError as exc:
                raise ScenarioError(describe_validation_error(exc, name)) from None
        super().__init__(name, config)
        self.axis = config.axis or "X"
        self.history: History | None = None
        self.pipeline: MonitorPipeline | None = None
        self.traces: list[MotionTrace] = []
        self.results: list[dict] = []

    def setup(self, t0: float, h: float, n_steps: int) -> None:
        cfg = self.config
        self.t0, self.h = t0, h
        try:
            self.history = History(cfg.db or ":memory:")
        except HistoryError as exc:  # an unusable monitor.db is bad input (exit 2), found before the run
            raise InputError(f"monitor.db: {exc}") from None
        self.pipeline = MonitorPipeline(cfg, self.history, self.axis)
        self.clock0 = _time.time() - t0  # machine time of simulated time 0
        capacity = min(n_steps + 1, int(round(cfg.max_motion_s / h)) + 1)
        self._rows: list = [None] * capacity
        self._k = 0  # samples buffered in the current motion
        self._motion = None  # index of the motion being buffered
        self._start = 0
        self._in: tuple = (0.0,) * len(self.input_names)
        self._update_request(t0)

    def _update_request(self, t: float) -> None:
        age = self.history.age(self.axis, self.clock0 + t)
        self._request = 1.0 if age.too_old(self.config.max_motions, self.config.max_age_s) else 0.0
        # the step from which the age in seconds exceeds max_age_s: one integer compare per step
        remaining = self.config.max_age_s - age.seconds
        self._age_step = math.inf if self._request else math.floor((t - self.t0 + remaining) / self.h) + 1

    def set_inputs(self, values: Sequence[float]) -> None:
        self._in = values if type(values) is tuple else tuple(values)

    def step(self, n: int) -> None:
        values = self._in
        if values[7] == RAPID:
            if self._motion is None:
                self._motion, self._start, self._k = values[8], n + 1, 0
            elif values[8] != self._motion:
                self._end_motion()
                self._motion, self._start, self._k = values[8], n + 1, 0
            if self._k < len(self._rows):
                self._rows[self._k] = values
                self._k += 1
        elif self._motion is not None:
            self._end_motion()
        if n >= self._age_step:
            self._request, self._age_step = 1.0, math.inf

    def _end_motion(self) -> None:
        rows = np.array(self._rows[:self._k], dtype=float)
        motion, self._motion = int(self._motion), None
        if rows.shape[0] < 2:
            return
        signals = dict(zip(MEASUREMENTS, rows[:, :len(MEASUREMENTS)].T))
        signals["w_enc"] = centred_speed(signals["theta_enc"], signals["w_enc"], self.h, self.config.encoder_window_s)
        start = self.t0 + self._start * self.h
        end = start + (rows.shape[0] - 1) * self.h
        trace = self.pipeline.process(signals, self.h, start, motion, self.clock0 + end, self.config.scenario)
        if self._k == len(self._rows):
            trace.result["notes"].append(f"motion longer than max_motion_s = {self.config.max_motion_s} s: cut")
        self.results.append(trace.result)
        if self.config.keep_traces:
            self.traces = (self.traces + [trace])[-self.config.keep_traces:]
        self._update_request(end)

    def get_outputs(self) -> list[float]:
        return [self._request]

    def report(self) -> dict:
        times = [r["processing_s"] for r in self.results]
        return {"axis": self.axis, "db": self.config.db, "budget_s": self.config.budget_s,
                "max_processing_s": max(times, default=None),
                "max_processing_cpu_s": max((r["processing_cpu_s"] for r in self.results), default=None),
                "within_budget": all(r["within_budget"] for r in self.results),
                "request": self._request, "unfinished_motion": self._motion,
                "diagnosis_thresholds": self.pipeline.thresholds() if self.pipeline else None,
                "motions": self.results}

    def write_plots(self, folder: str | Path) -> list[Path]:
        """Monitor plots of the kept motions and the parameter trends of the axis into ``folder``."""
        from feeddrive.cosim.monitor_plots import plot_monitor

        if self.config.db:
            with History(self.config.db) as history:
                motions = history.motions(self.axis)
        else:
            motions = self.results
        return plot_monitor(self.traces, motions, Path(folder), self.pipeline.thresholds() if self.pipeline else None)

    def terminate(self) -> None:
        if self.history is not None:
            self.history.close()
            self.history = None
