"""One verdict per motion, from report.json's keys: what a reader must see first.

Precedence (the first that applies decides):

1. ``sensor fault``: a measurement was not trusted (``sensor_faults`` non-empty or
   ``measurements_valid`` false). Even when the faulty sensor was isolated and the parameters were
   estimated from its healthy partner, the motion is never shown healthy;
2. ``not estimated``: no parameter could be estimated (``error``);
3. ``model mismatch``: the model check rejected the estimated model (parameters not validated);
4. ``diagnosis``: a Table I fault was diagnosed;
5. ``drifting``: a validated parameter lies beyond half the alarm band (``page.parameter_status``);
6. ``healthy``.

A motion may carry its own ``verdict`` (written by the monitor): a string or ``{"kind", "text"}``; it is
used as it is, and derived here the same way otherwise.

This module imports nothing heavy: the console summaries (``cosim run``, ``cosim monitor``) use it too.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from feeddrive.estimator.pvalue_text import p_text

#: verdict kinds in order of precedence, with the CSS class of their colour
KINDS = {"sensor fault": "bad", "not estimated": "not-judged", "model mismatch": "bad", "diagnosis": "diagnosed",
         "drifting": "drifting", "healthy": "healthy", "not validated": "not-judged"}
#: sensor -> (redundant pair, unit of its offset)
SENSORS = {"Im1": ("current", "A"), "Im2": ("current", "A"), "u": ("voltage", "V"), "u_ref": ("voltage", "V"),
           "w_tach": ("speed", "rad/s"), "w_enc": ("speed", "rad/s"), "torque": ("torque", "N.m"),
           "torque_ref": ("torque", "N.m")}


def finite(x: Any) -> bool:
    """True for a real, finite number (not None, not a bool, not nan or inf)."""
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def sensor_unit(sensor: Any) -> str:
    """The unit of a sensor fault's offset (``Im1``: A; ``torque or torque_ref``, not isolated: N.m; unknown: "")."""
    return SENSORS.get(str(sensor).split(" or ")[0], ("", ""))[1]


def fault_values(f: Mapping) -> str:
    """``gain 1.030, offset 0.200 A`` of an isolated sensor fault (report.json ``sensor_faults[k]``); what is not
    finite is left out (``kind`` when nothing is)."""
    unit = sensor_unit(f.get("sensor"))
    parts = []
    if finite(f.get("gain")):
        parts.append(f"gain {f['gain']:.4g}")
    if finite(f.get("offset")):
        parts.append(f"offset {f['offset']:.3g}{' ' + unit if unit else ''}")
    return ", ".join(parts) or str(f.get("kind", "fault"))


def fault_text(f: Mapping) -> str:
    """``Im1 gain 1.030, offset 0.200 A`` (the isolated sensor fault, report.json ``sensor_faults[k]``)."""
    return f"{f.get('sensor', '?')} {fault_values(f)}"


#: estimator.diagnosis.UNEXPLAINED, the fault of a drift no Table I row explains (not imported: numpy; a test
#: compares them)
UNEXPLAINED = "unexplained drift"
#: the monitor's own words for a kind (cosim/monitor_checks.motion_verdict writes ``diagnosed``)
_ALIASES = {"diagnosed": "diagnosis"}


def _kind_of(text: str) -> str:
    low = text.lower()
    words = [*_ALIASES.items(), *((k, k) for k in KINDS)]
    return next((kind for word, kind in words if low.startswith(word)), "not validated")


def motion_verdict(m: Mapping, statuses: Mapping[str, str] | None = None) -> dict[str, str]:
    """The verdict of one motion result (report.json ``motions[k]`` or a history row).

    Parameters
    ----------
    m : mapping
        The motion result.
    statuses : mapping name -> str, optional
        Each parameter's colour against the alarm band (``page.parameter_status``); without it a motion
        cannot be called drifting.

    Returns
    -------
    dict
        ``kind`` (a key of ``KINDS``), ``text`` (one line, starting with the kind) and ``css``.
    """
    own = m.get("verdict")
    if isinstance(own, str) and own:
        kind = _kind_of(own)
        # the monitor's own verdict decides the kind; the keys give the detail when they agree with it
        derived_kind, derived = _derive(m, statuses or {})
        text = derived if derived_kind == kind and len(derived) > len(own) else own
        return {"kind": kind, "text": text, "css": KINDS[kind]}
    if isinstance(own, Mapping) and own.get("text"):
        kind = own.get("kind") if own.get("kind") in KINDS else _kind_of(own["text"])
        return {"kind": kind, "text": str(own["text"]), "css": KINDS[kind]}
    kind, text = _derive(m, statuses or {})
    return {"kind": kind, "text": text, "css": KINDS[kind]}


def _derive(m: Mapping, statuses: Mapping[str, str]) -> tuple[str, str]:
    faults = m.get("sensor_faults") or []
    estimated = bool(m.get("parameters"))
    if faults or m.get("measurements_valid") is False:
        what = "; ".join(fault_text(f) for f in faults) or "a redundant pair disagrees and the faulty sensor is unknown"
        trusted = sorted({r.get("trusted") for r in (m.get("residues") or {}).values()
                          if isinstance(r, Mapping) and r.get("trusted")})
        if not estimated:
            tail = f"; not estimated: {m.get('error') or 'no parameters'}"
        elif m.get("validated"):
            tail = f"; parameters estimated from {', '.join(trusted)}" if trusted else "; parameters estimated"
        else:
            tail = "; parameters not validated"
        return "sensor fault", f"sensor fault: {what}{tail}"
    if not estimated:
        return "not estimated", f"not estimated: {m.get('error') or 'no parameters in this result'}"
    mm = m.get("mismatch")
    if isinstance(mm, Mapping) and mm.get("passed") is False:
        p = f", adjusted {p_text(mm['p_value'])} < alpha = {mm['alpha']:g}" if finite(mm.get("p_value")) and \
            finite(mm.get("alpha")) else ""
        return "model mismatch", f"model mismatch: the {mm.get('test', 'model check')} test rejects{p}; " \
                                 "parameters not validated"
    a = m.get("adequacy")
    if isinstance(a, Mapping) and a.get("verdict") == "model mismatch" and not m.get("validated"):
        # the motion's own residue check decided (no redundant pair for the paper's): its p-value and reason too
        p = f", adjusted {p_text(a['p_value'])} < alpha = {a['alpha']:g}" if finite(a.get("p_value")) and \
            finite(a.get("alpha")) else ""
        why = f": {a['reason']}" if a.get("reason") else ""
        return "model mismatch", f"model mismatch: the residue check rejects{p}{why}; parameters not validated"
    if not m.get("validated"):
        reasons = [n.removeprefix("not validated: ") for n in m.get("notes") or () if n.startswith("not validated")]
        return "not validated", "not validated: " + ("; ".join(reasons) or "no model check")
    diagnosis = m.get("diagnosis") or []
    if diagnosis:
        params = ", ".join(dict.fromkeys(p for d in diagnosis for p in d.get("parameters", ())))
        if all(d.get("fault") == UNEXPLAINED for d in diagnosis):  # no Table I fault: the monitor calls it drifting
            return "drifting", f"drifting: {UNEXPLAINED} of {params} (no Table I fault matches)"
        faults = "; ".join(dict.fromkeys(d.get("fault", "?") for d in diagnosis))
        return "diagnosis", f"diagnosis: {faults} ({params})"
    drifting = [k for k, s in statuses.items() if s == "drifting"]
    if drifting:
        return "drifting", f"drifting: {', '.join(drifting)} beyond half the alarm band (no fault diagnosed)"
    learning = next((n for n in m.get("notes") or () if n.startswith("healthy baseline")), None)
    return "healthy", "healthy: validated, no drift" + (f" ({learning})" if learning else "")


def verdict_line(m: Mapping, statuses: Mapping[str, str] | None = None) -> str:
    """The verdict as one console line (``cosim run``, ``cosim monitor``)."""
    return motion_verdict(m, statuses)["text"]
