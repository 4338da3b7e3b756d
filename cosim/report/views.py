"""What the page shows of a motion's model check, measurement validation and processing time.

Every quantity that could not be computed is shown with the reason, never as ``nan``.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from feeddrive.cosim.report.verdict import SENSORS, fault_text, finite

#: (signal, test) -> what the test asks, and its statistic (estimator/mismatch.py)
TESTS = {
    "independence": ("independent of past inputs", "F"),
    "size": ("no larger than its noise σ", "F = mean(e²) / σ²"),
    "peak": ("no block far outside the others", "max |z| (MAD units)"),
}
SIGNAL_UNITS = {"current": "A", "speed": "rad/s", "voltage": "V", "torque": "N.m"}


def _n(x: Any, digits: int = 4) -> str:
    return f"{x:.{digits}g}" if finite(x) else "not computed"


def _dof(d: Any) -> str:
    """Degrees of freedom: an integer count in full (34879, not 3.488e+04), a fractional one to 4 digits."""
    return f"{d:.0f}" if finite(d) and float(d).is_integer() else _n(d, 4)


def model_check(mm: Mapping | None) -> dict | None:
    """The model check (report.json ``motions[k].mismatch``) as a table of its tests.

    Returns
    -------
    dict or None
        ``rows``: one per test ``{test, statistic, df, p_value, threshold, decision, reject}``;
        ``sizes``: per residue its RMS against the sensor noise (or why the noise is unknown);
        ``level``: the adjusted level named (``alpha/m = 0.01/5 = 0.002, Bonferroni``); ``summary``: the
        deciding test with its adjusted p-value. None when the check did not run.
    """
    if not isinstance(mm, Mapping):
        return None
    checks = mm.get("checks") or {}
    tests = [(sig, name, t) for sig, c in checks.items() if isinstance(c, Mapping)
             for name, t in c.items() if isinstance(t, Mapping) and "p_value" in t]
    m = len(tests)
    alpha = mm.get("alpha")
    each = alpha / m if finite(alpha) and m else None
    rows = []
    for sig, name, t in tests:
        what, symbol = TESTS.get(name, (name, "statistic"))
        df = t.get("df")
        p = t.get("p_value")
        reject = finite(p) and each is not None and p < each
        rows.append({"test": f"{sig} residue {what}", "key": f"{sig} {name}", "symbol": symbol,
                     "statistic": _n(t.get("statistic")),
                     "df": ", ".join(_dof(d) for d in df) if isinstance(df, Sequence) and df else "-",
                     "p_value": _n(p, 3), "threshold": "-" if each is None else f"{each:.3g}",
                     "decision": "not computed" if not finite(p) else ("reject: mismatch" if reject else "pass"),
                     "reject": bool(reject)})
    sizes = []
    for sig, c in checks.items():
        if not isinstance(c, Mapping):
            continue
        unit = SIGNAL_UNITS.get(sig, "")
        noise = c.get("noise_std")
        sizes.append({"signal": sig, "rms": f"{c['rms']:.3g} {unit}" if finite(c.get("rms")) else "not computed",
                      "noise": f"{noise:.3g} {unit}" if finite(noise) else
                      f"not checked: no confirmed redundant {'current' if sig == 'current' else 'speed'} sensor pair "
                      "(one sensor, or the pair disagrees)"})
    level = (f"alpha/m = {alpha:g}/{m} = {each:.3g} per test (Bonferroni: family-wise level {alpha:g} over the "
             f"{m} tests)") if each is not None else "level not recorded"
    p_adj = mm.get("p_value")
    summary = (f"deciding test: {mm.get('test', '?')}, smallest p-value; Bonferroni-adjusted p = min(1, {m} p) = "
               f"{_n(p_adj, 3)} {'<' if mm.get('passed') is False else '>='} alpha = {alpha:g}"
               if finite(alpha) else f"deciding test: {mm.get('test', '?')}")
    free = str(mm.get("rule") or "").partition("; ")[2]  # the parameters the motion did not determine
    if free:
        summary += f"; {free}"
    return {"rows": rows, "sizes": sizes, "level": level, "summary": summary, "passed": mm.get("passed")}


def residue_rows(m: Mapping) -> list[dict]:
    """Each redundant pair's residue; a pair holding a faulty sensor is not valid, whatever its residue says.

    report.json's ``residues[q].valid`` is the validity of the pair after isolation (the fault was
    attributed and the partner trusted); the page shows the pair's sensors as valid only without a fault.
    """
    faulty: dict[str, list[Mapping]] = {}
    for f in m.get("sensor_faults") or ():
        faulty.setdefault(SENSORS.get(f.get("sensor"), ("?", ""))[0], []).append(f)
    rows = []
    for q, r in (m.get("residues") or {}).items():
        if not isinstance(r, Mapping):
            continue
        faults = faulty.get(q, [])
        valid = bool(r.get("valid")) and not faults
        unit = SIGNAL_UNITS.get(q, "")
        rows.append({"pair": q, "kind": r.get("kind", "-"),
                     "gain_diff": _ci(r.get("gain_diff"), r.get("gain_diff_ci95"), ""),
                     "offset": _ci(r.get("offset"), r.get("offset_ci95"), unit),
                     "noise": f"{r['noise_std']:.3g} {unit}" if finite(r.get("noise_std")) else "not computed",
                     "trusted": r.get("trusted") or "-", "valid": "yes" if valid else "no",
                     "faults": "; ".join(fault_text(f) for f in faults) or ("-" if valid else "not isolated")})
    return rows


def _ci(x: Any, ci: Any, unit: str) -> str:
    if not finite(x):
        return "not computed"
    text = f"{x:.4g}"
    if isinstance(ci, Sequence) and len(ci) == 2 and all(finite(v) for v in ci):
        text += f" [{ci[0]:.4g}, {ci[1]:.4g}]"
    return f"{text} {unit}".rstrip()


def residue_check(m: Mapping) -> dict | None:
    """The model check on the motion's own residue (report.json ``adequacy``: estimator/adequacy.py), one row per
    equation: the nuisance terms tested, F statistic, degrees of freedom, p-value and the decision at the
    Bonferroni-adjusted level. None when it did not run."""
    a = m.get("adequacy")
    if not isinstance(a, Mapping) or not a.get("verdict"):
        return None
    eqs = a.get("equations") or {}
    alpha = a.get("alpha")
    level = alpha / max(len(eqs), 1) if finite(alpha) else None
    rows = []
    for name, e in eqs.items():
        p = e.get("p_value")
        if e.get("reason"):
            decision = e["reason"]
        elif not finite(p):
            decision = "not computed"
        elif level is not None and p < level:  # significant; a mismatch only when it is material (adequacy.py)
            from feeddrive.estimator.adequacy import MIN_EFFECT

            effect = e.get("effect")
            decision = (f"significant but immaterial: {100 * effect:.2g} % of the {e.get('output')} signal "
                        f"unexplained (< {100 * MIN_EFFECT:g} %)" if finite(effect) and effect < MIN_EFFECT
                        else "reject: mismatch")
        else:
            decision = "pass"
        rows.append({"equation": f"{name} ({e.get('output')})", "terms": ", ".join(e.get("terms") or []) or "-",
                     "statistic": _n(e.get("statistic")), "p": _n(p),
                     "df": ", ".join(_dof(x) for x in e["df"]) if isinstance(e.get("df"), Sequence) else _dof(e.get("df")),
                     "strongest": e.get("strongest") or "-", "decision": decision, "bad": decision.startswith("reject")})
    return {"verdict": a["verdict"], "p": _n(a.get("p_value")), "reason": a.get("reason") or "",
            "level": f"alpha {alpha:g} / {max(len(eqs), 1)} equations = {level:.3g} (Bonferroni)" if level else "",
            "bad": a["verdict"] != "adequate", "rows": rows}


def servo_rows(m: Mapping) -> list[dict]:
    """The servo drive's redundancy checks of a PMSM motion (report.json ``servo_checks``), one row each:
    what was checked, its figure with its 95 % interval, and the decision."""
    checks = m.get("servo_checks") or {}
    rows = []

    def row(name: str, what: str, figure: str, bad: bool, decision: str) -> None:
        rows.append({"check": name, "what": what, "figure": figure, "bad": bad, "decision": decision, "skipped": False})

    if (c := checks.get("phase_current_sum")) is not None:
        bad = bool(c.get("faulty"))
        row("phase currents", "I_U + I_V + I_W = 0 (analytic)", "offset " + _ci(c.get("offset"), c.get("offset_ci95"), "A"),
            bad, f"fault on phase {c.get('phase')}" if bad and c.get("phase") else ("fault" if bad else "valid"))
    if (c := checks.get("phase_sensor_pair")) is not None:
        bad, phase = c.get("valid") is False, c.get("phase", "U")
        row(f"second sensor on phase {phase}", f"I_{phase} against I_2: material redundancy (paper eq. 12)",
            "gain ratio " + _ci(c.get("gain_ratio"), None, ""), bad, "not valid" if bad else "valid")
    if (c := checks.get("dq_current_consistency")) is not None:
        bad = bool(c.get("faulty"))
        row("i_q against Park(I_U, I_V, I_W)", "analytic", "gain " + _ci(c.get("gain"), c.get("gain_ci95"), ""),
            bad, "mis-scaled current" if bad else "valid")
    if (c := checks.get("voltage_reference_check")) is not None:
        bad = c.get("valid") is False
        # the loss the data give when it is not the one stated: valid, with what to state (monitor_servo.servo_checks)
        unstated = "u_loss_stated" in c and not bad
        row("voltage references against terminal voltages", "dead time modelled",
            "dead-time loss " + _ci(c.get("u_loss"), c.get("u_loss_ci95"), "V per leg"), bad,
            "not valid" if bad else f"valid with the measured loss: {c.get('note')}" if unstated else "valid")
    if (c := checks.get("lost_motion")) is not None:
        bad = bool(c.get("detected"))
        row("motor encoder against linear scale", "lost motion of the drive chain",
            _ci(c.get("value_mm"), c.get("ci95_mm"), "mm"), bad, "lost motion detected" if bad else "within the allowed lost motion")
    if checks:  # a PMSM motion: the checks that did not run, each with its reason (report.json ``not_checked``)
        skipped = m.get("not_checked") or {}
        rows += [{"check": label, "what": "-", "figure": "-", "bad": False, "decision": str(skipped[name]),
                  "skipped": True} for name, label in SERVO_CHECKS.items() if name not in checks and name in skipped]
    return rows


#: the servo checks' report.json names and the page's labels
SERVO_CHECKS = {"phase_current_sum": "phase currents", "phase_sensor_pair": "second sensor on one phase",
                "dq_current_consistency": "i_q against Park(I_U, I_V, I_W)",
                "voltage_reference_check": "voltage references against terminal voltages",
                "lost_motion": "motor encoder against linear scale"}


def gain_ratio(m: Mapping) -> tuple[str, str]:
    """(a1/a2, relative gain error) of the current sensors, or why they were not computed."""
    if not finite(m.get("gain_ratio")):
        why = m.get("gain_ratio_reason") or (m.get("not_checked") or {}).get("current") or (
            "not checked: one current sensor" if "current" not in (m.get("residues") or {}) else
            "not computed: the current pair's residue test did not run to its gain (see the residues)")
        return why, why
    rel = m.get("relative_gain_error")
    return f"{m['gain_ratio']:.5g}", f"{100 * rel:+.3g} %" if finite(rel) else "not computed"


def processing(m: Mapping, budget_s: float | None) -> dict:
    """The motion's processing time against the budget: judged on CPU time; wall time only labelled as such.

    Returns ``{text, css, within}``: ``within`` None when it cannot be judged.
    """
    cpu, wall = m.get("processing_cpu_s"), m.get("processing_s")
    paper = "paper: 1–2 s between the end of the rapid motion and the tool engaging the work-piece"
    if finite(cpu):
        text = f"{cpu:.3g} s CPU time" + (f" ({wall:.3g} s wall time)" if finite(wall) else "")
        if budget_s is None:
            return {"text": text, "css": "", "within": None}
        within = cpu <= budget_s
        verdict = "within budget" if within else "over budget (CPU time)"
        return {"text": f"{text} against the budget of {budget_s:.3g} s ({paper}): {verdict}",
                "css": "healthy" if within else "diagnosed", "within": within}
    if not finite(wall):
        return {"text": "not measured", "css": "", "within": None}
    text = f"{wall:.3g} s wall time (CPU time not recorded; wall time grows with the host's load)"
    if budget_s is None:
        return {"text": text, "css": "", "within": None}
    if wall <= budget_s:
        return {"text": f"{text} against the budget of {budget_s:.3g} s ({paper}): within budget",
                "css": "healthy", "within": True}
    return {"text": f"{text}, above the budget of {budget_s:.3g} s: not judged, the wall time may be the host's load",
            "css": "", "within": None}
