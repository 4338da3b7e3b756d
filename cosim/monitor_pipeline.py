"""The monitor's treatment of one motion (``MonitorPipeline``), without the co-simulation component.

    filtering (eq. 8) -> measurement validation (Fig. 5, 6) -> estimation (eq. 4, 5)
    -> model validation (IV.B.3) -> diagnosis (Table I) -> history (SQLite)

Used by the component (cosim/monitor.py) and by ``cosim monitor`` on recorded data.
"""
from __future__ import annotations

import time as _time
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from feeddrive.cosim import monitor_checks as checks
from feeddrive.cosim.axis import parameter_units
from feeddrive.cosim.monitor_checks import _drift_reference, _residue_dict, interval_mean_speed
from feeddrive.cosim.monitor_config import MonitorConfig
from feeddrive.estimator.adequacy import check_adequacy
from feeddrive.estimator.diagnosis import TABLES, DiagnosisOptions, diagnose, make_baseline
from feeddrive.estimator.errors import FAILURES, EstimatorInputError, NotEnoughExcitation
from feeddrive.estimator.estimate import EstimationOptions, MotionData
from feeddrive.estimator.history import History
from feeddrive.estimator.mismatch import MismatchResult, check_model, check_signals
from feeddrive.estimator.partial import NOT_ASSUMED, estimate_parameters
from feeddrive.estimator.segmentation import at_rest
from feeddrive.estimator.validation import MeasurementValidation, ValidationOptions, validate_measurements


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
        from feeddrive.models.drives import drive_model

        self.config, self.history, self.axis = config, history, axis
        # the axis's stated design values only (a scenario states its built-in plant's; a vendor FMU's or a
        # recorded machine's are the user's): another motor's would blame the wrong sensor or diagnose a healthy axis
        self.nominal = dict(config.nominal) | dict(config.known)
        self.names = [v.name for v in drive_model(config.drive).of_kind("physical")]
        self.validation_options = ValidationOptions(config.alpha, config.window_s, config.gain_tol, config.offset_tol)
        # a PMSM's pole pairs are known, not estimated (as ``cosim estimate --pole-pairs``)
        design = {"p": float(config.pole_pairs)} if config.pole_pairs and config.drive != "dc" else {}
        self.estimation_options = EstimationOptions(method=config.method, filter=config.filter,
                                                    speed_threshold=config.speed_threshold,
                                                    speed_fraction=config.speed_fraction,
                                                    known=dict(config.known) | design, model=config.drive,
                                                    decimation=config.decimation)
        self.diagnosis_options = DiagnosisOptions(config.alpha, config.min_relative_drift)
        self.table = TABLES[config.drive]  # Table I of the axis's drive kind
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
        if self.config.stated_baseline is not None:  # a stated baseline FILE
            return self.config.stated_baseline
        return make_baseline(self.baseline_sets) if self.baseline_sets else None

    def thresholds(self) -> dict:
        """The diagnosis' thresholds and the healthy baseline now (report.json ``diagnosis_thresholds``).

        ``{"alpha", "z_crit", "min_relative": {name: fraction}, "baseline_motions", "baseline":
        {name: {"value", "std"}} or None}``: what the alarm bands of the trend plots are drawn from.
        """
        return _drift_reference(self.baseline(), self.diagnosis_options, self.names) | {
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
                                  "residues": {}, "refused": {}, "mismatch": None, "adequacy": None, "diagnosis": [], "notes": [],
                                  "error": None, "verdict": None,
                                  "not_checked": checks.not_checked(checks.present(signals), "torque" in signals)}
        if self.config.known:
            result["known"] = dict(self.config.known)
        trace = MotionTrace(int(motion), start + h * np.arange(n), dict(signals), result=result)
        mismatch = False
        if (n - 1) * h < self.config.min_motion_s:
            result["error"] = (f"motion of {(n - 1) * h:.3g} s is shorter than "
                               f"min_motion_s = {self.config.min_motion_s} s (a scenario's monitor.min_motion_s, "
                               "cosim monitor's --min-motion)")
        elif (rest := self._at_rest(signals)) is not None:  # no motion: its sensor noise is nothing to estimate from
            result["error"] = rest
        else:
            try:
                mismatch = self._identify(signals, h, start, trace)
            except FAILURES as exc:  # this motion cannot be used (the next may); a coding error is raised
                # numpy's singular matrix (a LinAlgError) on ill-conditioned data: a refusal, not a crash
                result["error"] = str(exc) if isinstance(exc, NotEnoughExcitation | EstimatorInputError) else \
                    f"numerical failure on this motion's data ({exc})"
        result["verdict"] = checks.motion_verdict(result, mismatch)
        result["processing_s"] = _time.perf_counter() - tic
        # judged on CPU time: the wall time also counts whatever else the host runs meanwhile
        result["processing_cpu_s"] = _time.process_time() - cpu
        result["within_budget"] = result["processing_cpu_s"] <= self.config.budget_s
        self.history.record(self.axis, result, scenario=scenario, time=time)
        return trace

    def _at_rest(self, signals: Mapping[str, np.ndarray]) -> str | None:
        """``segmentation.at_rest`` of the motion's speed (the tachometer's, else the encoder's): an axis that did
        not move (a plant held still, a recording at rest) is said so with its threshold, not refused parameter by
        parameter."""
        w = signals.get("w_tach", signals.get("w_enc"))
        return None if w is None else at_rest(w, "rad/s", self.config.speed_threshold)

    def _identify(self, signals: Mapping[str, Any], h: float, start: float, trace: MotionTrace) -> bool:
        """Validation, estimation, model check and diagnosis of one motion; True when the model check that
        decided found a mismatch."""
        result, cfg = trace.result, self.config
        if cfg.drive != "dc":  # a servo drive's redundancies and dq model; estimation to diagnosis as below
            from feeddrive.cosim.monitor_servo import identify_servo

            return identify_servo(self, signals, h, start, trace)
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
                                      nominal=self.nominal, decimation=self.estimation_options.decimation)
            trace.validation = v
            faults = [f.to_dict() for f in v.sensor_faults] + [
                checks.unisolated_fault(*p.sensors, p.residue) for p in v.pairs.values()
                if p.residue is not None and p.residue.kind != "none" and not p.fits]  # no R, L, K to isolate with
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
        # the torque pair (measurement, command) is checked like u and u_ref (monitor_checks.torque_pair)
        if full and "torque" in have:  # (detect_subset checks it otherwise)
            best = {}
            checks.torque_pair(signals, h, self.validation_options, have, result["residues"], result["sensor_faults"],
                               best, result["notes"])
            valid = bool(valid and result["residues"].get("torque", {}).get("valid", True))
            result["measurements_valid"] = bool(result["measurements_valid"] and valid)
        torque = best.get("torque") if "torque" in have else None
        # a torque's offset T0 needs both directions: in one, sign(w) is a constant and Cd absorbs it
        peak = float(np.max(np.abs(w))) if np.size(w) else 0.0
        both = bool(np.max(w) > cfg.speed_fraction * peak and np.min(w) < -cfg.speed_fraction * peak)
        offset = torque is not None and both
        if torque is not None and not both:
            result["notes"].append("one direction only: Cd and a torque offset cannot be told apart (Cd holds both)")
        adequacy = None
        try:  # before the estimation: a mismatch explains a refusal (gravity hides Jt on a robot axis)
            adequacy = check_adequacy(h, u=u, i=i, w=w, torque=torque, alpha=cfg.mismatch_alpha, filter=cfg.filter,
                                      speed_fraction=cfg.speed_fraction, known=known, offset=offset,
                                      decimation=self.estimation_options.decimation)
            result["adequacy"] = adequacy.to_dict()
        except EstimatorInputError as exc:
            result["not_checked"]["model (own residue)"] = f"not checked: {exc}"
        try:
            est = estimate_parameters(  # one parameter at a time: the refused ones named with their reason
                MotionData(h, u=u, i=i, w=w, torque=torque, t0=start, delays=cfg.delays(h)),
                replace(self.estimation_options, offset=offset), dict(cfg.bounds))
        except FAILURES as exc:  # the estimator's own refusals and failures only (a coding error is raised)
            # this motion cannot be used (the next may); a NumericalFailure: a non-finite simulation of the instruments
            result["error"] = str(exc) if isinstance(exc, NotEnoughExcitation | EstimatorInputError) else \
                f"estimation failed on this motion's data ({exc})"
            if adequacy is not None and adequacy.mismatch:
                result["notes"].append("not validated: model mismatch (the residue check), which may be why the "
                                       "estimation was refused")
            return adequacy is not None and adequacy.mismatch
        params = est.parameters
        units = parameter_units("motor")  # the monitor's signals are the motor's: u, i, w [rad/s]
        # judged against other motions (drift, baseline, trends): the intervals not conditional on a refused parameter
        # fixed at its own estimate, as several files are compared (cosim estimate A B C); the conditional ones were
        # 5 times narrower on an HSM150 repeat and made the same machine "drifting"
        joint = est.joint.parameters if est.joint is not None else {}
        entries = {k: checks.parameter_entry(p, joint.get(k), units.get(k, "")) for k, p in params.items()}
        # the interval shown is that wider one: judged by the estimator's rule too, or a parameter passed on its
        # interval given a refused one would be shown with one the rule refuses (REGBOT: K +-170 %, from -0.0085)
        wide = checks.wide_intervals(entries, self.estimation_options.max_relative_std,
                                     [n for n, why in est.refused.items() if est.fixed.get(n, 0.0) != 0.0
                                      and NOT_ASSUMED not in why])  # not an impossible one (R < 0)
        params = {k: p for k, p in params.items() if k not in wide}
        result["parameters"] = {k: e for k, e in entries.items() if k not in wide}
        result |= {"condition_number": float(est.condition_number), "fit_error": float(est.fit_error),
                   "estimation_rate_hz": est.rate_hz}  # the record's rate, or its decimated one
        refused = dict(est.refused) | wide
        result["refused"] = {n: refused[n] for n in sorted(refused, key=lambda n: (n not in self.names,
                                                                                   self.names.index(n) if n in self.names else 0))}
        if est.result.message:  # a fallback (IV -> LS) is stated with its reason
            result["notes"].append(est.result.message)
        if est.method_used != result["method"]:  # which method gave the numbers: iv-lag or ls standing in for iv
            result["method_used"] = est.method_used
        if not params:  # every parameter refused: nothing to validate, to diagnose or to add to the baseline
            result["error"] = (f"every parameter refused ({', '.join(result['refused']) or 'none given'}), each with its "
                               "reason: nothing to validate")
            return adequacy is not None and adequacy.mismatch
        flags = dict(est.flags)
        if flags:  # outside the physical range or the user's bounds: reported, never validated
            result["flags"] = flags
        # the model checks simulate the model as fitted: a refused parameter at the value the fit held it at
        # (its own estimate, 0, or the lumped term); only the given parameters are validated and stored
        fitted = {k: float(v) for k, v in {**est.fixed, **est.lumped}.items()} | {k: entries[k]["value"] for k in wide}
        if fitted:
            result["fitted"] = fitted
        values = {k: p.value for k, p in params.items()} | fitted | known
        # the output-error simulation integrates both equations: it needs L > 0 and Jt > 0 (a fixed 0 has no
        # dynamics, a negative one diverges)
        derivative = [k for k in ("L", "Jt") if k in values and not values[k] > 0]
        if full and derivative:
            result["not_checked"]["model (paper, output error)"] = (
                "not checked: the model check could not be run: its simulation needs "
                + "; ".join(f"{k} > 0, the fit holds {k} = {values[k]:.4g} ({est.refused.get(k, 'given')})"
                            for k in derivative))
        elif full and all(k in values for k in ("R", "L", "K", "Jt", "ft", "Cd")):
            try:  # an overflow ends as the NumericalFailure below, never a warning on the console
                with np.errstate(all="ignore"):
                    inputs, instruments, noise = check_signals(v, signals)
                    mismatch_result = check_model(inputs["u"], inputs["i"], inputs["w"], h, values, cfg.filter,
                                                  cfg.mismatch_alpha, covariance=est.covariance, names=est.names,
                                                  noise=noise, noise_dof=len(v.i), instruments=instruments,
                                                  speed_threshold=cfg.speed_threshold,
                                                  speed_fraction=cfg.speed_fraction,
                                                  decimation=self.estimation_options.decimation,
                                                  undetermined=est.undetermined)
            except FAILURES as exc:  # NumericalFailure: it diverged (a coding error, a bare ValueError, is raised)
                # the check could not be run; the estimates stand, the residue check decides
                result["not_checked"]["model (paper, output error)"] = (
                    f"not checked: the model check could not be run: {exc}")
            else:
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
        checks.note_not_validated(result, flags, valid, mismatch,
                                  adequacy.verdict if adequacy is not None else "model not checked", est.hint)
        if not result["validated"]:
            return mismatch
        self.diagnose(result)
        return False

    def diagnose(self, result: dict) -> None:
        """Diagnosis (Table I of the axis's drive) of a validated motion's ``result["parameters"]`` against
        the baseline, which it may join; theta_{j-1} and the trend's sets move on."""
        current = result["parameters"]
        reference = self.baseline()
        if reference is not None:
            # the reference and thresholds this motion was judged against: the trend plots' alarm band
            # with the baseline's size, so that the history page states the baseline this axis's monitor used
            result["drift_reference"] = _drift_reference(reference, self.diagnosis_options, self.names) | {
                "baseline_mode": self.config.baseline, "baseline_motions": self.config.baseline_motions}
            result["diagnosis"] = [d.to_dict() for d in diagnose(current, reference, self.last_validated, self.recent,
                                                                 self.diagnosis_options, self.table)]
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
