"""The monitor on whatever sensors a machine has (issue 22 item 7), and each motion's verdict.

The paper's monitor needs the full redundancy: two current sensors, the terminal voltage and its
reference, the tachometer and the encoder. A machine may have one current sensor, no voltage, or only
a torque signal. Then:

* each redundant pair that lacks a sensor is **not checked**, with the missing sensor named (in the
  console, report.json ``not_checked`` and ``residues``; never a NaN gain ratio);
* a pair whose two sensors are both there but whose isolation needs a quantity that is missing is
  checked for a disagreement (residue test, eq. 10) but not isolated;
* the estimator uses what is there (``torque``: only the mechanical equation, Jt, ft, Cd and an offset
  T0; no voltage: the mechanical equation with a known K), with the known parameters fixed;
* the paper's model check (output-error residues, estimator/mismatch.py) needs the redundancy for its
  noise levels and instruments; without it the recording's own residue decides (estimator/adequacy.py);
* a torque measurement and the drive's torque command (``torque_ref``, ``TORQUE_PAIR``) are a redundant pair
  like ``u`` and ``u_ref``: their residue test (eq. 10) finds a gain or offset between them (not isolated: no
  third torque to tell which), and a healthy pair's mean is the torque the estimator uses.

``motion_verdict`` gives the one-word verdict of a motion, in the precedence ``sensor fault``,
``model mismatch``, ``not estimated: <reason>``, ``not validated: <reason>``, ``diagnosed``,
``drifting``, ``healthy``. A mismatch wins over a refusal: it is often why the estimation was refused.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from feeddrive.estimator.diagnosis import UNEXPLAINED, DiagnosisOptions
from feeddrive.estimator.validation import PAIRS, ValidationOptions, residue_test

#: what each sensor is, for the "not checked" lines
SENSOR_NAMES = {"Im1": "current sensor 1 (Im1)", "Im2": "second current sensor (Im2)",
                "u": "terminal voltage (u)", "u_ref": "voltage reference (u_ref)",
                "w_tach": "tachometer (w_tach)", "w_enc": "encoder speed (w_enc)",
                "torque": "torque measurement (torque)", "torque_ref": "torque command (torque_ref)"}
#: the redundant torque pair of a recording with a torque signal: the measurement and the drive's command
TORQUE_PAIR = ("torque", "torque_ref")


def present(signals: Mapping[str, np.ndarray | None]) -> set[str]:
    """Names of the signals given (not None)."""
    return {k for k, v in signals.items() if v is not None}


def not_checked(have: set[str], torque: bool) -> dict[str, str]:
    """Quantity -> ``"not checked: <which sensor is missing>"`` for each pair that lacks a sensor."""
    out = {}
    for quantity, (s1, s2) in PAIRS.items():
        missing = [s for s in (s1, s2) if s not in have]
        if quantity == "current" and torque and s1 not in have:
            out[quantity] = "not checked: a torque signal replaces the current sensors"
        elif missing:
            out[quantity] = "not checked: no " + " and no ".join(SENSOR_NAMES[s] for s in missing)
    if torque and TORQUE_PAIR[1] not in have:
        out["torque"] = f"not checked: no {SENSOR_NAMES[TORQUE_PAIR[1]]}"
    return out


def detect_subset(signals: Mapping[str, np.ndarray | None], h: float, options: ValidationOptions,
                  have: set[str]) -> tuple[dict[str, dict], list[dict], dict[str, np.ndarray], list[str]]:
    """The redundant pairs of a machine without the full redundancy: detection only (eq. 10).

    Returns
    -------
    residues : dict of quantity -> residue dict (report.json ``residues``)
    faults : list of sensor-fault dicts (the pair named, not isolated)
    best : dict of ``u``, ``i``, ``w`` -> the signal passed on (the mean of a healthy pair, else sensor 1)
    notes : list of str
    """
    residues, faults, best, notes = {}, [], {}, []
    symbol = {"current": "i", "voltage": "u", "speed": "w"}
    for quantity, (s1, s2) in PAIRS.items():
        first = s1 if s1 in have else s2 if s2 in have else None
        if first is None:
            continue
        x1 = np.asarray(signals[first], dtype=float)
        best[symbol[quantity]] = x1
        if not {s1, s2} <= have:
            continue
        x2 = np.asarray(signals[s2], dtype=float)
        res = residue_test(x1, x2, h, options)
        residues[quantity] = {"kind": res.kind, "gain_diff": res.gain_diff, "gain_diff_ci95": list(res.gain_diff_ci95),
                              "p_gain": res.p_gain, "offset": res.offset, "offset_ci95": list(res.offset_ci95),
                              "p_offset": res.p_offset, "noise_std": res.noise_std, "trusted": None,
                              "valid": res.kind == "none"}
        if res.kind == "none":
            best[symbol[quantity]] = 0.5 * (x1 + x2)
            continue
        faults.append(unisolated_fault(s1, s2, res))
        notes.append(f"{quantity}: {s1} and {s2} disagree ({res.kind}); not isolated: the isolation (Fig. 6) needs "
                     "the current, the voltage and the speed")
    torque_pair(signals, h, options, have, residues, faults, best, notes)
    return residues, faults, best, notes


def torque_pair(signals: Mapping[str, np.ndarray | None], h: float, options: ValidationOptions, have: set[str],
                residues: dict, faults: list, best: dict, notes: list) -> None:
    """The torque measurement against the drive's torque command (``TORQUE_PAIR``), added to ``detect_subset``'s
    outputs: the residue test (eq. 10), the pair's mean as ``best["torque"]`` when they agree, else the measurement;
    a disagreement is a sensor fault of the pair, not isolated (the model gives no third torque without the
    current and K)."""
    s1, s2 = TORQUE_PAIR
    if s1 not in have:
        return
    x1 = np.asarray(signals[s1], dtype=float)
    best["torque"] = x1
    if s2 not in have:
        return
    res = residue_test(x1, np.asarray(signals[s2], dtype=float), h, options)
    residues["torque"] = {"kind": res.kind, "gain_diff": res.gain_diff, "gain_diff_ci95": list(res.gain_diff_ci95),
                          "p_gain": res.p_gain, "offset": res.offset, "offset_ci95": list(res.offset_ci95),
                          "p_offset": res.p_offset, "noise_std": res.noise_std, "trusted": None,
                          "valid": res.kind == "none"}
    if res.kind == "none":
        best["torque"] = 0.5 * (x1 + np.asarray(signals[s2], dtype=float))
        return
    faults.append(unisolated_fault(s1, s2, res))
    # the sensor fault's own gain (gain_ratio_of), not 1 + gain_diff: the note said 0.8053 beside the fault's 0.8226
    notes.append(f"torque: the measurement and the command disagree ({res.kind} fault: gain "
                 f"{res.gain_ratio_of(res.gain_diff):.4g}, offset {res.offset:.3g} N.m); not isolated: the measured "
                 "torque is used")


def unisolated_fault(s1: str, s2: str, res) -> dict:  # noqa: ANN001 - estimator.validation.ResidueTest
    """A disagreeing pair's sensor-fault dict when the faulty one cannot be told: ``"Im1 or Im2"``, the
    pair's relative gain and offset (residue test, eq. 10)."""
    # the residue's slope c is on the pair's mean level (a1 + a2) / 2, not on x2: a1 / a2 = (2 + c) / (2 - c)
    # (1 + c was 1.0488 for a 5 % torque-sensor gain, its interval [1.0487, 1.0489] excluding it); monotonic in c,
    # so the interval maps through it
    lo, hi = res.gain_diff_ci95
    return {"sensor": f"{s1} or {s2}", "kind": res.kind, "gain": res.gain_ratio_of(res.gain_diff),
            "gain_ci95": [res.gain_ratio_of(lo), res.gain_ratio_of(hi)], "offset": res.offset,
            "offset_ci95": list(res.offset_ci95)}


def motion_verdict(result: Mapping, mismatch: bool) -> str:
    """One motion's verdict (report.json ``verdict``); see the module docstring for the precedence.

    Parameters
    ----------
    result : mapping
        The motion's result (``sensor_faults``, ``measurements_valid``, ``error``, ``validated``,
        ``diagnosis``, ``notes``).
    mismatch : bool
        The model check that decided found a mismatch.
    """
    if result.get("sensor_faults") or result.get("measurements_valid") is False:
        return "sensor fault"
    if mismatch:
        return "model mismatch"
    if result.get("error"):
        return f"not estimated: {result['error']}"
    if not result.get("validated"):
        reasons = [n.removeprefix("not validated: ") for n in result.get("notes", ()) if n.startswith("not validated")]
        return "not validated: " + (reasons[0] if reasons else "no model check")
    faults = [d["fault"] for d in result.get("diagnosis", ())]
    if any(f != UNEXPLAINED for f in faults):
        return "diagnosed"
    if faults:
        return "drifting"
    return "healthy"


def parameter_entry(p, joint, unit: str) -> dict:  # noqa: ANN001 - estimator ParameterEstimate (joint: or None)
    """A given parameter's report.json entry: its value, with the wider of its interval and its interval not
    conditional on a refused parameter fixed at its own estimate (``MotionEstimate.joint``)."""
    if joint is not None and joint.std > p.std:
        half = joint.ci95[1] - joint.value
        return {"value": p.value, "std": joint.std, "ci95": [p.value - half, p.value + half], "unit": unit}
    return {"value": p.value, "std": p.std, "ci95": list(p.ci95), "unit": unit}


def wide_intervals(entries: Mapping[str, dict], max_relative_std: float, conditioned: Sequence[str]) -> dict[str, str]:
    """The given parameters whose shown 95 % interval (``parameter_entry``: the wider of the estimator's and the one
    not conditional on ``conditioned``, refused parameters fixed at their estimates) is wider than the estimator's
    rule allows (``+-1.96 max_relative_std`` of the value, ``partial._rule``): name -> the refusal's reason."""
    limit = 1.959963984540054 * max_relative_std
    out = {}
    for name, e in entries.items():
        rel = (e["ci95"][1] - e["value"]) / abs(e["value"]) if e["value"] else float("inf")
        if not rel <= limit:
            given = f" (its interval given {', '.join(conditioned)} at their estimates passed)" if conditioned else ""
            out[name] = (f"95 % interval +-{rel:.0%} of the value when the refused parameters are not taken as known, "
                         f"more than +-{limit:.0%}{given}: {e['value']:.4g}")
    return out


def known_parameters(known: Mapping[str, float], units: Mapping[str, str]) -> dict[str, dict]:
    """Known parameters as report.json parameter entries (``known: true``, no interval)."""
    return {k: {"value": float(v), "std": 0.0, "ci95": [float(v), float(v)], "unit": units.get(k, ""), "known": True}
            for k, v in known.items()}


def electrical_reference(last: Mapping | None, nominal: Mapping[str, float],
                         known: Mapping[str, float]) -> dict[str, float] | None:
    """R, L, K of the isolation: the known values over the last validated ones; None (nominal) when the
    last validated set lacks one (a motion estimated without voltage)."""
    if last is None or not all(k in last or k in known for k in "RLK"):
        return None
    return {k: float(known[k]) if k in known else float(last[k]["value"]) for k in "RLK"}


def names_with(names: Sequence[str], extra: Mapping[str, float]) -> list[str]:
    """``names`` followed by the keys of ``extra`` not already in it."""
    return list(names) + [k for k in extra if k not in names]


# -- helpers of cosim/monitor.py (moved here to keep that module short) --------------------------


def interval_mean_speed(w_enc: np.ndarray) -> np.ndarray:
    """The latched encoder's speed at the sample times -> its mean over each sampling interval (trapezoid).

    With a tachometer sampled as an interval mean, the average of the two speeds would otherwise lag the
    tachometer by a quarter sample (R -0.04 % on the vendor-style drive at 10 kHz).
    """
    w_enc = np.asarray(w_enc, dtype=float)
    return np.r_[w_enc[:1], 0.5 * (w_enc[1:] + w_enc[:-1])]


def centred_speed(theta: np.ndarray, fallback: np.ndarray, h: float, window_s: float) -> np.ndarray:
    """Encoder speed at the sample times: ``(theta(t + k h) - theta(t - k h)) / (2 k h)``, ``2 k h ~ window_s``.

    Parameters
    ----------
    theta : ndarray, shape (n,)
        Encoder angle [rad].
    fallback : ndarray, shape (n,)
        Speed [rad/s] kept on the ``k`` samples at each end, where the centred window does not fit.
    h, window_s : float
        Sample time and differencing window [s].

    Returns
    -------
    ndarray, shape (n,)
        Speed [rad/s], without the half-window delay of a backward difference.
    """
    k = max(1, int(round(window_s / (2 * h))))
    w = np.array(fallback, dtype=float)
    if theta.size > 2 * k:
        w[k:-k] = (theta[2 * k:] - theta[:-2 * k]) / (2 * k * h)
    return w


def _drift_reference(reference: Mapping | None, options: DiagnosisOptions, names: Sequence[str]) -> dict:
    """``{"z_crit", "min_relative": {name}, "baseline": {name: {"value", "std"}} or None}`` of a drift test."""
    base = None if reference is None else {k: {"value": float(v), "std": float(s)} for k, (v, s) in reference.items()}
    return {"z_crit": options.z_crit, "min_relative": {n: options.min_rel(n) for n in names}, "baseline": base}


def _residue_dict(pair) -> dict:
    r = pair.residue
    return {"kind": r.kind, "gain_diff": r.gain_diff, "gain_diff_ci95": list(r.gain_diff_ci95), "p_gain": r.p_gain,
            "offset": r.offset, "offset_ci95": list(r.offset_ci95), "p_offset": r.p_offset,
            "noise_std": r.noise_std, "trusted": pair.trusted, "valid": pair.valid}


# -- the monitor's thresholds on the command line ---------------------------------------------------

#: MonitorConfig field -> (command-line option, metavar, help). The defaults are MonitorConfig's only:
#: an option not given leaves the field to the config (``config_with_options``), so a scenario's
#: ``monitor:`` section and ``cosim monitor`` build the same frozen object with the same defaults.
CLI_OPTIONS = {
    "known": ("--known", "NAME=VALUE", "parameters known in advance, motor side, SI, e.g. R=8.4 K=0.042 "
              "(fixed in the estimation and the model checks; K is needed without a voltage)"),
    "bounds": ("--bounds", "NAME=LOW:HIGH", "bounds beyond the physical range, either side may be empty, e.g. "
               "Jt=4e-6: (the rotor's own inertia); an estimate outside is flagged and never validated"),
    "min_motion_s": ("--min-motion", "SECONDS", "shorter motions are not identified"),
    "max_motion_s": ("--max-motion", "SECONDS", "longer motions are cut to this length"),
    "alpha": ("--alpha", "P", "level of the sensor residue tests and the drift tests"),
    "window_s": ("--window", "SECONDS", "length of the sensor residue windows"),
    "gain_tol": ("--gain-tol", "FRACTION", "smallest relative sensor gain error that is a fault"),
    "offset_tol": ("--offset-tol", "FRACTION", "smallest sensor offset that is a fault, as a fraction of the range"),
    "mismatch_alpha": ("--mismatch-alpha", "P", "family-wise level of the model checks (false-alarm rate)"),
    "speed_fraction": ("--speed-fraction", "FRACTION", "relative speed threshold of the sign(w) term, when "
                       "--speed-threshold is not given"),
    "filter_order": ("--filter-order", "N", "order of the identical low-pass filter"),
    "baseline": ("--baseline", "{motions,nominal}", "healthy baseline: the first validated motions, or the "
                 "nominal values"),
    "baseline_motions": ("--baseline-motions", "N", "motions of the healthy baseline"),
    "nominal": ("--nominal", "NAME=VALUE", "design values of the axis (first motion's isolation, --baseline "
                "nominal)"),
    "min_relative_drift": ("--min-drift", "FRACTION", "smallest relative parameter change diagnosed"),
    "max_motions": ("--max-motions", "N", "identification too old after this many motions"),
    "max_age_s": ("--max-age", "SECONDS", "identification too old after this long"),
    "budget_s": ("--budget", "SECONDS", "processing time allowed per motion"),
    "keep_traces": ("--keep-traces", "N", "motions whose signals are kept for the plots (the last ones)"),
    "dead_time_loss_v": ("--dead-time-loss", "VOLTS", "a PMSM inverter's per-leg dead-time loss t_dead f_pwm u_dc "
                         "(modelled in the voltage check and taken off the voltage references)"),
    "lost_motion_allowed_mm": ("--lost-motion-allowed", "MM", "a PMSM axis's acceptance value of the lost motion "
                               "between the motor encoder and the linear scale"),
}


def add_config_arguments(parser, config_class) -> None:  # noqa: ANN001 - argparse parser, pydantic model class
    """One option per ``CLI_OPTIONS`` entry, its default shown from ``config_class`` (never duplicated)."""
    defaults = config_class()
    for name, (flag, metavar, text) in CLI_OPTIONS.items():
        default = getattr(defaults, name)
        shown = f" (default {default})" if default not in ({}, None) else ""
        if isinstance(default, dict):
            parser.add_argument(flag, dest=f"cfg_{name}", action="extend", nargs="+", default=None, metavar=metavar,
                                help=text + shown)
        else:
            parser.add_argument(flag, dest=f"cfg_{name}", default=None, metavar=metavar, help=text + shown)


def config_with_options(args, config_class, **fixed):  # noqa: ANN001, ANN201 - argparse namespace, pydantic model
    """``config_class`` from ``fixed`` and the ``CLI_OPTIONS`` given on the command line (validated by the
    config itself: a bad value is one line naming the option, exit 2)."""
    from pydantic import ValidationError

    from feeddrive.cosim.errors import InputError
    from feeddrive.cosim.recorded import pairs

    values = dict(fixed)
    for name, (flag, _, _) in CLI_OPTIONS.items():
        given = getattr(args, f"cfg_{name}", None)
        if given is None:
            continue
        if isinstance(config_class.model_fields[name].default, dict):
            given = pairs(given, flag)
            for key, text in given.items():
                if name == "bounds":  # LOW:HIGH, parsed by the config itself
                    continue
                try:
                    given[key] = float(text)
                except ValueError:
                    raise InputError(f"{flag} {key}={text}: expected a number") from None
        values[name] = given
    try:
        return config_class.model_validate(values)
    except ValidationError as exc:
        err = exc.errors()[0]
        if not err["loc"]:  # a rule across fields (baseline: nominal and the nominal values): its own words
            raise InputError(err["msg"].removeprefix("Value error, ")) from None
        field = str(err["loc"][0])
        flag = CLI_OPTIONS.get(field, (field,))[0]
        detail = ".".join(str(x) for x in err["loc"][1:])
        msg = err["msg"].removeprefix("Value error, ")
        raise InputError(f"{flag}{' ' + detail if detail else ''}: {msg} (got {err.get('input')!r})") from None


def note_not_validated(result: dict, flags: dict, valid: bool, mismatch: bool, why: str,
                       hint: str | None = None) -> None:
    """Append to ``result["notes"]`` each reason why the motion's parameters were not validated (``why``: the
    model check's verdict when it had no power; ``hint``: the flags' likely cause, ``MotionEstimate.hint``).
    Shared by the DC and the servo drive's paths."""
    if flags and hint:  # the cause first: it says what to do; the impossible values after it
        result["notes"].append(f"not validated: {hint}; the estimate is physically impossible: "
                               + "; ".join(flags.values()))
        result["hint"] = hint
    elif flags:
        result["notes"].append("not validated: physically impossible estimate: " + "; ".join(flags.values()))
    if not valid:
        result["notes"].append("not validated: a measurement could not be trusted (no diagnosis)")
    if mismatch:
        result["notes"].append("not validated: model mismatch (no diagnosis; parameters reported)")
    elif valid and not flags and not result["validated"]:  # the model check alone withheld it
        result["notes"].append(f"not validated: {why} (the model check has no power; parameters reported)")
