"""The monitor's paper steps on what a servo drive (PMSM) measures (issue 25 item 4).

``MonitorPipeline`` calls ``identify_servo`` instead of its DC measurement validation when the axis's drive
is a PMSM (``MonitorConfig.drive``); the estimation (``estimate_parameters`` with the dq model), the model
check on the motion's own residue and the diagnosis (``MonitorPipeline.diagnose``, Table I of the drive)
are the same steps. Measurement validation of a servo drive:

* the q-axis pairs of the ``sensors`` component (two current sensors, tachometer against encoder; the
  terminal voltage against its reference only without the servo's dq voltages): the paper's residue test
  (eq. 10), detection only;
* the servo drive's redundancies (``estimator.redundancy_servo``): the three phase currents sum to zero
  (analytic), two sensors on phase U (material), the reported q current against the Park transform of the
  phase currents, the dq voltage references against the terminal voltages with the dead time modelled;

a failed check is a sensor fault, and the motion's parameters are then never validated. The motor encoder
against the linear scale measures the drive chain's lost motion (backlash): a plant finding, diagnosed as
``lost motion (backlash)`` when the test at ``alpha`` rejects zero, never a sensor fault.

The d current is the Park transform of the phase currents at the encoder's electrical angle; the q
current, q voltage and speed are the validated q-axis signals; the d voltage is the terminal voltage's.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict
from typing import Any

import numpy as np

from feeddrive.cosim import monitor_checks as checks
from feeddrive.cosim.model_check_servo import servo_model_check
from feeddrive.estimator import redundancy_servo as rs
from feeddrive.estimator.adequacy import check_motion
from feeddrive.estimator.errors import EstimatorInputError, NotEnoughExcitation
from feeddrive.estimator.estimate import MotionData
from feeddrive.estimator.partial import estimate_parameters

#: the monitor component's extra inputs on a PMSM axis, after ``state, motion`` (wired from the ``servo``
#: component: phase currents [A], second sensor on U [A], dq voltage references and terminal voltages [V],
#: table position from the motor encoder and from the linear scale [m])
SERVO_INPUTS = ("I_U", "I_V", "I_W", "I_2", "u_d_ref", "u_q_ref", "u_d", "u_q", "x_mot", "x_lin")
#: the lost-motion finding's name in ``result["diagnosis"]``
LOST_MOTION = "lost motion (backlash)"


def _json(x: Any) -> Any:
    """A check result as report.json values (tuples as lists, numpy scalars as floats)."""
    if isinstance(x, dict):
        return {k: _json(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_json(v) for v in x]
    if isinstance(x, np.generic):
        return x.item()
    return x


def servo_checks(signals: Mapping[str, np.ndarray], h: float, pole_pairs: int, i_q: np.ndarray | None,
                 alpha: float, gain_tol: float, offset_tol: float, u_loss: float,
                 options: Any) -> tuple[dict[str, dict], list[dict], dict[str, str]]:  # noqa: ANN401
    """Run the servo drive's redundancy checks on one motion.

    Parameters
    ----------
    signals : mapping of str to ndarray, shape (n,)
        ``SERVO_INPUTS`` and ``theta_enc`` [rad] (any subset; a check lacking a signal is not checked).
    h : float
        Sample time [s].
    pole_pairs : int
    i_q : ndarray, shape (n,), or None
        The q current the estimator uses [A].
    alpha, gain_tol, offset_tol : float
        Level and tolerances of the tests.
    u_loss : float
        Nominal per-leg dead-time loss [V].
    options : ValidationOptions

    Returns
    -------
    checks : dict of check name -> its result (``valid``: passed; report.json ``servo_checks``)
    faults : list of sensor-fault dicts (``sensor``, ``kind``, ``gain``, ``offset``)
    not_checked : dict of check name -> ``"not checked: <reason>"``
    """
    have = checks.present(signals)
    out: dict[str, dict] = {}
    faults: list[dict] = []
    skipped: dict[str, str] = {}
    phi = pole_pairs * np.asarray(signals["theta_enc"], float) if "theta_enc" in have else None

    def run(name: str, needs: set[str], fn) -> None:  # noqa: ANN001 - a closure computing one check
        missing = sorted(needs - have)
        if missing:
            skipped[name] = "not checked: no " + " and no ".join(missing)
            return
        try:
            fn()
        except EstimatorInputError as exc:
            skipped[name] = f"not checked: {exc}"

    def phase_sum() -> None:
        c = rs.phase_current_sum(signals["I_U"], signals["I_V"], signals["I_W"], alpha, gain_tol, offset_tol)
        out["phase_current_sum"] = _json(asdict(c)) | {"valid": not c.faulty}
        if c.faulty:
            faults.append({"sensor": f"I_{c.phase}" if c.phase else "I_U, I_V or I_W",
                           "kind": "gain" if c.phase else "offset", "gain": c.gain, "offset": c.offset,
                           "check": "phase_current_sum"})

    def pair() -> None:
        c = rs.phase_sensor_pair(signals["I_U"], signals["I_2"], h, options=options)
        r = c.residue
        out["phase_sensor_pair"] = {"kind": r.kind, "gain_diff": r.gain_diff, "gain_diff_ci95": list(r.gain_diff_ci95),
                                    "offset": r.offset, "p_gain": r.p_gain, "p_offset": r.p_offset,
                                    "gain_ratio": c.gain_ratio, "valid": not c.faulty}
        if c.faulty:
            faults.append({"sensor": "I_U or I_2", "kind": r.kind, "gain": 1.0 + r.gain_diff, "offset": r.offset,
                           "check": "phase_sensor_pair"})

    def dq() -> None:
        c = rs.dq_current_consistency(i_q, signals["I_U"], signals["I_V"], signals["I_W"], phi, alpha, gain_tol)
        out["dq_current_consistency"] = _json(asdict(c)) | {"valid": not c.faulty}
        if c.faulty:
            faults.append({"sensor": "i_q", "kind": "gain", "gain": c.gain, "offset": 0.0,
                           "check": "dq_current_consistency"})

    def voltage() -> None:
        c = rs.voltage_reference_check(signals["u_d_ref"], signals["u_q_ref"], signals["u_d"], signals["u_q"],
                                       signals["I_U"], signals["I_V"], signals["I_W"], phi, h, u_loss,
                                       options=options)
        out["voltage_reference_check"] = {
            "u_loss": c.u_loss, "u_loss_ci95": list(c.u_loss_ci95), "uncorrected_gap": c.uncorrected_gap,
            "residue": {a: {"kind": r.kind, "gain_diff": r.gain_diff, "offset": r.offset} for a, r in c.residue.items()},
            "valid": not c.faulty}
        for axis, r in c.residue.items():
            if r.kind != "none":
                faults.append({"sensor": f"u_{axis} or u_{axis}_ref", "kind": r.kind, "gain": 1.0 + r.gain_diff,
                               "offset": r.offset, "check": "voltage_reference_check"})

    run("phase_current_sum", {"I_U", "I_V", "I_W"}, phase_sum)
    run("phase_sensor_pair", {"I_U", "I_2"}, pair)
    if i_q is None:
        skipped["dq_current_consistency"] = "not checked: no q current"
    else:
        run("dq_current_consistency", {"I_U", "I_V", "I_W", "theta_enc"}, dq)
    run("voltage_reference_check", {"u_d_ref", "u_q_ref", "u_d", "u_q", "theta_enc", "I_U", "I_V", "I_W"}, voltage)
    return out, faults, skipped


def lost_motion_check(signals: Mapping[str, np.ndarray], h: float, alpha: float,
                      allowed_mm: float = 0.0) -> tuple[dict | None, str | None]:
    """Motor encoder against linear scale (``redundancy_servo.lost_motion`` in mm, tested against ``allowed_mm``):
    the result dict, or None and the reason it was not checked."""
    if not {"x_mot", "x_lin"} <= checks.present(signals):
        return None, "not checked: no " + " and no ".join(k for k in ("x_mot", "x_lin") if k not in signals)
    try:
        c = rs.lost_motion(1e3 * np.asarray(signals["x_mot"]), 1e3 * np.asarray(signals["x_lin"]), h, alpha,
                            allowed_mm)
    except EstimatorInputError as exc:
        return None, f"not checked: {exc}"
    return _json(asdict(c)), None


def identify_servo(pipe: Any, signals: Mapping[str, Any], h: float, start: float,  # noqa: ANN401
                   trace: Any) -> bool:  # noqa: ANN401 - the pipeline imports this module: no import back
    """Validation, estimation, model check and diagnosis of one motion of a PMSM axis; True on a model mismatch.

    ``pipe`` is the ``cosim.monitor_pipeline.MonitorPipeline``, ``trace`` its ``MotionTrace`` of the motion.

    ``signals``: the DC monitor's q-axis ``Im1, Im2, u, u_ref, w_tach, w_enc, theta_enc`` and ``SERVO_INPUTS``.
    """
    result, cfg = trace.result, pipe.config
    p = int(pipe.estimation_options.model.nominal(("design",))["p"])
    have = checks.present(signals)
    dc = {k: v for k, v in signals.items() if k in checks.SENSOR_NAMES}
    if {"u_d_ref", "u_q_ref", "u_d", "u_q"} <= have:  # the reference against the terminal voltage is the servo
        dc.pop("u_ref", None)  # check's, with the inverter's dead time modelled (the plain pair flags it)
    residues, faults, best, notes = checks.detect_subset(dc, h, pipe.validation_options, have & set(dc))
    result["notes"] += notes
    i_q = best.get("i")
    servo, servo_faults, skipped = servo_checks(signals, h, p, i_q, cfg.alpha, cfg.gain_tol, cfg.offset_tol,
                                                cfg.dead_time_loss_v, pipe.validation_options)
    faults += servo_faults
    lost, why = lost_motion_check(signals, h, cfg.alpha, cfg.lost_motion_allowed_mm)
    if lost is not None:
        servo["lost_motion"] = lost
    else:
        skipped["lost_motion"] = why
    valid = not faults
    result |= {"measurements_valid": valid, "sensor_faults": faults, "residues": residues, "servo_checks": servo}
    result["not_checked"] |= skipped
    # the dq signals the estimator needs: d current from the phase currents at the encoder's electrical angle
    dq: dict[str, np.ndarray] = {}
    if "i_d" in have:  # a recording's d current (``cosim monitor --drive pmsm --map i_d=...``)
        dq["i_d"] = np.asarray(signals["i_d"], float)
    elif {"I_U", "I_V", "I_W", "theta_enc"} <= have:
        dq["i_d"], _ = rs.park(np.vstack([signals["I_U"], signals["I_V"], signals["I_W"]]),
                               p * np.asarray(signals["theta_enc"], float))
    dq |= {k: v for k, v in (("i_q", i_q), ("u_q", best.get("u")), ("u_d", signals.get("u_d"))) if v is not None}
    missing = [k for k in ("i_q", "i_d", "u_q", "u_d") if k not in dq]
    if missing or "w" not in best:
        raise EstimatorInputError(f"a PMSM axis needs the dq currents and voltages and a speed; missing "
                                  f"{', '.join(missing + ['speed'] * ('w' not in best))}")
    options = pipe.estimation_options
    # interval means (an oversampled plant) aligned to the interval's middle, as the DC monitor's u, i, w
    delays = {{"u": "u_q", "i": "i_q"}.get(k, k): d for k, d in cfg.delays(h).items()}
    data = MotionData(h, w=best["w"], signals=dq, t0=start, delays=delays)
    adequacy = check_motion(data, options)  # before the estimation: a mismatch explains a refusal
    result["adequacy"] = adequacy.to_dict()
    try:
        est = estimate_parameters(data, options, dict(cfg.bounds))
    except (NotEnoughExcitation, ValueError, np.linalg.LinAlgError) as exc:
        result["error"] = str(exc)
        return adequacy.mismatch
    units = _units(cfg.drive)
    result["parameters"] = {k: {"value": q.value, "std": q.std, "ci95": list(q.ci95), "unit": units.get(k, "")}
                            for k, q in est.parameters.items()}
    result |= {"condition_number": float(est.condition_number), "fit_error": float(est.fit_error),
               "refused": dict(est.refused)}
    if est.result.message:
        result["notes"].append(est.result.message)
    flags = dict(est.flags)
    if flags:
        result["flags"] = flags
    # the paper's output-error check, simulated from the model's equations; the residue check reported beside it
    paper, why = servo_model_check(pipe, signals, dq, best, h, est, faults)
    if paper is None:
        result["not_checked"]["model (paper, output error)"] = why
    else:
        result["mismatch"] = paper.to_dict()  # (not trace.mismatch: Fig. 13-14's plots draw the DC residues)
    mismatch = adequacy.mismatch if paper is None else not paper.passed
    result["validated"] = bool(valid and not flags and not mismatch and (paper is not None
                                                                          or adequacy.verdict == "adequate"))
    checks.note_not_validated(result, flags, valid, mismatch, adequacy.verdict)
    if result["validated"]:
        pipe.diagnose(result)
    if valid and lost is not None and lost["detected"]:  # the drive chain, measured by the two encoders
        # the evidence in a drift's fields (report.html's table): against 0 mm, a change without a relative size
        lo, hi = lost["ci95_mm"]
        result["diagnosis"].append({"fault": LOST_MOTION, "parameters": ["lost_motion_mm"], "evidence": [
            {"parameter": "lost_motion_mm", "value": lost["value_mm"], "baseline": 0.0, "relative_change": None,
             "z_baseline": None, "z_last": None, "trend_per_motion": None, "significant": True,
             "std": (hi - lo) / 3.92, "unit": "mm", "ci95": [lo, hi], "p_value": lost["p_value"]}]})
    return mismatch


def _units(drive: str) -> dict[str, str]:
    from feeddrive.cosim.cli.estimate import model_units

    return model_units(drive)


def servo_line(servo: Mapping[str, Any]) -> str:
    """One console line of a motion's servo checks (report.json ``servo_checks``): each check ``ok`` or ``FAULT``
    with its number (the q current's gain against the Park transform, the dead time's per-leg loss [V], the
    lost motion [mm])."""
    def state(name: str) -> str:
        return "ok" if servo[name].get("valid", True) else "FAULT"

    parts = []
    if "phase_current_sum" in servo:
        parts.append(f"phase sum {state('phase_current_sum')}")
    if "phase_sensor_pair" in servo:
        parts.append(f"I_U/I_2 {state('phase_sensor_pair')} (ratio {servo['phase_sensor_pair']['gain_ratio']:.4f})")
    if "dq_current_consistency" in servo:
        parts.append(f"i_q/Park {state('dq_current_consistency')} (gain {servo['dq_current_consistency']['gain']:.4f})")
    if "voltage_reference_check" in servo:
        parts.append(f"u_ref/u {state('voltage_reference_check')} (dead time "
                     f"{servo['voltage_reference_check']['u_loss']:.2f} V per leg)")
    if "lost_motion" in servo:
        lost = servo["lost_motion"]
        parts.append(f"lost motion {lost['value_mm']:.4f} mm{' DETECTED' if lost['detected'] else ''}")
    return "servo checks: " + ", ".join(parts)
