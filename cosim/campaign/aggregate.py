"""Campaign aggregates (detection and estimation tables) and their plots."""
from __future__ import annotations

import csv
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from feeddrive.cosim.campaign.schema import PHYSICAL
from feeddrive.estimator.diagnosis import TABLE_I
from feeddrive.estimator.estimate import METHODS


# -- aggregates ------------------------------------------------------------------------------------------
def fault_class(injected: Mapping[str, Any]) -> str:
    """``healthy``, ``plant:Cd+ft``, ``sensor:Im1`` or a combination joined by ``&``."""
    parts = []
    if injected.get("plant"):
        parts.append("plant:" + "+".join(sorted(injected["plant"])))
    if injected.get("sensors"):
        parts.append("sensor:" + "+".join(sorted(injected["sensors"])))
    return " & ".join(parts) or "healthy"


def _isolates(diagnoses: list[Mapping[str, Any]], changed: set[str]) -> bool:
    """The plant diagnoses of one motion isolate the fault when the Table I faults they name cover every
    changed parameter and none of them is foreign (sensitive to no changed parameter)."""
    named = [set(TABLE_I[d["fault"]]) for d in diagnoses if d.get("fault") in TABLE_I]
    return bool(changed and named) and changed <= set().union(*named) and all(s & changed for s in named)


def _truths(result: Mapping[str, Any]) -> list[dict[str, float]]:
    return [m.get("truth") or result.get("truth") or {} for m in result.get("motions", [])]


def _onset(truths: list[dict[str, float]]) -> tuple[int, set[str]]:
    """First motion whose truth differs from motion 0 and the parameters that change (drifts); 0 and the
    empty set when the truth is constant."""
    if not truths:
        return 0, set()
    changed = {p for t in truths for p, v in t.items() if not math.isclose(v, truths[0].get(p, v), rel_tol=1e-9)}
    onset = next((k for k, t in enumerate(truths)
                  if any(not math.isclose(t[p], truths[0][p], rel_tol=1e-9) for p in changed)), 0)
    return onset, changed


def _mismatch(motion: Mapping[str, Any]) -> bool:
    """The motion's model check rejected the model (its verdict, or the check's own record)."""
    return motion.get("verdict") == "model mismatch" or (motion.get("mismatch") or {}).get("passed") is False


def _run_outcome(result: Mapping[str, Any]) -> dict[str, Any]:
    """Per-run detection facts; see ``aggregate`` for the definitions."""
    injected = result.get("injected") or {}
    motions = result.get("motions", [])
    onset, drifting = _onset(_truths(result))
    plant = set(injected.get("plant") or ()) | drifting
    sensors = set(injected.get("sensors") or ())
    # a model mismatch is an alarm too: the motion is red on the report and its parameters are not validated
    alarms = [bool(m.get("diagnosis")) or bool(m.get("sensor_faults")) or _mismatch(m) for m in motions]
    hits = [_isolates(m.get("diagnosis") or [], plant) for m in motions]
    sensor_hits = [{f.get("sensor") for f in m.get("sensor_faults") or ()} == sensors if sensors else False
                   for m in motions]
    cls = fault_class({"plant": plant, "sensors": sensors})
    if cls == "healthy":
        return {"class": cls, "false_alarm": any(alarms)}
    detected_at = next((k for k in range(onset, len(motions))
                        if (plant and (motions[k].get("diagnosis") or _mismatch(motions[k])))
                        or (sensors and motions[k].get("sensor_faults"))), None)
    return {"class": cls, "detected": detected_at is not None,
            "isolated": any(h or s for h, s in zip(hits[onset:], sensor_hits[onset:])),
            "delay": None if detected_at is None else detected_at - onset,
            "false_alarm": any(alarms[:onset])}


@dataclass
class Aggregates:
    """``detection``: one row per fault class; ``estimation``: one row per (parameter, method)."""

    detection: list[dict[str, Any]]
    estimation: list[dict[str, Any]]

    def write(self, out: Path) -> None:
        for name, rows in (("detection", self.detection), ("estimation", self.estimation)):
            if rows:
                with open(out / f"{name}.csv", "w", newline="") as f:
                    w = csv.DictWriter(f, fieldnames=list(rows[0]))
                    w.writeheader()
                    w.writerows(rows)

    def table(self) -> str:
        """Both tables as aligned text."""
        def fmt(v: Any) -> str:
            return "-" if v is None else f"{v:.3g}" if isinstance(v, float) else str(v)

        blocks = []
        for rows in (self.detection, self.estimation):
            if not rows:
                continue
            cells = [list(rows[0])] + [[fmt(v) for v in r.values()] for r in rows]
            widths = [max(len(c[j]) for c in cells) for j in range(len(cells[0]))]
            blocks.append("\n".join("  ".join(c.ljust(w) for c, w in zip(row, widths)) for row in cells))
        return "\n\n".join(blocks)


def _rate(num: int, den: int) -> float | None:
    return num / den if den else None


#: the detection table's row of the runs whose axis did not follow its NC (report.json ``following``)
UNFOLLOWED = "(did not follow its NC)"
#: ... and of the runs whose model checks rejected a held-input plant sampled once per step (``held_inputs``)
UNAVERAGED = "(held inputs sampled per step)"
#: report.json keys that say a run's verdicts judge its set-up, not the drive -> the run's own row
SET_APART = {"following": UNFOLLOWED, "held_inputs": UNAVERAGED}


def set_apart(result: dict) -> str | None:
    """The row of a run whose verdicts judge its set-up (``SET_APART``), or None."""
    return next((row for key, row in SET_APART.items() if result.get(key)), None)


def aggregate(records: list[dict]) -> Aggregates:
    """Detection and estimation statistics of a campaign.

    Detection (per fault class, ``fault_class`` of the injected faults and of the parameters that
    drift over the motions):

    * a run detects its fault when a motion at or after the fault's onset has a diagnosis or a model
      mismatch (plant fault: backlash is seen by the model check only) or a sensor fault (sensor fault);
    * it isolates it when such a motion names the right faults: Table I faults whose sensitive
      parameters together hold every faulty parameter, none of them foreign to the faulty parameters
      (several faults of one drift, e.g. wear and brush wear, need several diagnoses), or exactly the
      faulty sensors;
    * ``false_alarm_rate``: on healthy runs, the fraction with any diagnosis, sensor fault or model
      mismatch (a red motion); on drifting runs, the fraction with such an alarm before the onset;
    * ``mean_delay_motions``: motions from the onset to the first detection (0 for a fault present
      from the first motion), over the detecting runs.

    Estimation (per physical parameter and method, over every motion not marked ``validated: false``
    of the finished runs without an injected sensor fault; method ``monitor``: the parameters of the
    motions the monitor validated):
    relative error ``e = (value - truth) / truth``; ``bias_pct`` = 100 mean(e), ``rms_pct`` =
    100 sqrt(mean(e^2)), ``coverage`` = fraction of motions whose ``ci95`` holds the truth.

    Failed runs are counted in ``failed`` and left out of every rate, and so are the runs whose axis did not
    follow its NC (``following``: a sign or a loop the map got wrong) and those whose model checks rejected a
    held-input plant sampled once per step (``held_inputs``, cosim/held_inputs.py): their verdicts judge the
    set-up, not the drive; each in its own row. Runs without a monitor (no motion has a ``validated`` verdict) are left out of
    the detection table.
    """
    classes: dict[str, list[dict]] = {}
    failed: dict[str, int] = {}
    errors: dict[tuple[str, str], list[tuple[float, bool]]] = {}
    for record in records:
        if record["status"] != "ok":
            failed["(failed)"] = failed.get("(failed)", 0) + 1
            continue
        result = record["result"]
        apart = set_apart(result)  # the axis did not follow its NC (a sign or a loop the map got wrong), or its
        if apart:                  # held-input plant was sampled once per step: its verdicts judge the set-up
            failed[apart] = failed.get(apart, 0) + 1
            continue
        if any(m.get("validated") is not None for m in result.get("motions", [])):  # runs without a monitor
            outcome = _run_outcome(result)                                           # detect nothing
            classes.setdefault(outcome["class"], []).append(outcome)
        if (result.get("injected") or {}).get("sensors"):
            continue  # estimates from a faulty sensor say nothing about the estimator
        for motion, truth in zip(result.get("motions", []), _truths(result)):
            if motion.get("validated") is False:
                continue
            # the methods scored on the recorded signals, and the parameters the monitor validated
            methods = dict(motion.get("methods") or {})
            if motion.get("validated") and motion.get("parameters"):
                methods["monitor"] = motion["parameters"]
            for method, params in methods.items():
                for name, est in (params or {}).items():
                    if name in truth and truth[name] != 0 and est.get("value") is not None:
                        lo, hi = est.get("ci95") or (math.nan, math.nan)
                        errors.setdefault((name, method), []).append(
                            ((est["value"] - truth[name]) / truth[name], lo <= truth[name] <= hi))
    detection = []
    for cls in sorted(classes, key=lambda c: (c != "healthy", c)):
        runs = classes[cls]
        n = len(runs)
        row = {"fault_class": cls, "runs": n}
        if cls == "healthy":
            row |= {"detected": None, "isolated": None, "detection_rate": None, "isolation_rate": None,
                    "false_alarm_rate": _rate(sum(r["false_alarm"] for r in runs), n), "mean_delay_motions": None}
        else:
            det = [r for r in runs if r["detected"]]
            row |= {"detected": len(det), "isolated": sum(r["isolated"] for r in runs),
                    "detection_rate": _rate(len(det), n), "isolation_rate": _rate(sum(r["isolated"] for r in runs), n),
                    "false_alarm_rate": _rate(sum(r["false_alarm"] for r in runs), n),
                    "mean_delay_motions": float(np.mean([r["delay"] for r in det])) if det else None}
        detection.append(row)
    for cls, n in sorted(failed.items()):
        detection.append({"fault_class": cls, "runs": n} | dict.fromkeys(
            ("detected", "isolated", "detection_rate", "isolation_rate", "false_alarm_rate", "mean_delay_motions")))
    order = {p: n for n, p in enumerate(PHYSICAL)}
    estimation = []
    for (name, method), values in sorted(errors.items(), key=lambda kv: (order.get(kv[0][0], 99), kv[0][0],
                                                                         METHODS.index(kv[0][1]) if kv[0][1] in METHODS else 9)):
        e = np.array([v for v, _ in values])
        estimation.append({"parameter": name, "method": method, "n": len(e), "bias_pct": float(100 * e.mean()),
                           "rms_pct": float(100 * np.sqrt(np.mean(e ** 2))),
                           "coverage": float(np.mean([c for _, c in values]))})
    return Aggregates(detection, estimation)


# -- plots -----------------------------------------------------------------------------------------------
#: units of swept keys, by the key's last part and its quantity (the campaign files' own comments)
_UNITS = {("current", "offset"): "A", ("current", "noise"): "A", ("voltage", "offset"): "V",
          ("voltage", "noise"): "V", ("speed", "offset"): "rad/s", ("speed", "noise"): "rad/s",
          ("position", "offset"): "rad", ("position", "noise"): "rad"}
_PLANT_UNITS = {"R": "Ohm", "L": "H", "K": "N.m/A", "Jt": "kg.m2", "ft": "N.m.s/rad", "Cd": "N.m", "backlash": "rad"}


def sweep_unit(key: str, base: Mapping[str, Any] | None = None) -> str:
    """The unit of a swept key (``sensors.current[0].offset`` -> ``A``, a gain -> ``1``), or ``""``; an event's
    value (``events[0].value``) has its target's unit, read from the campaign's ``base`` scenario."""
    target = event_target(key, base)
    last = (target or key).rsplit(".", 1)[-1]
    if last == "gain":
        return "1"
    quantity = next((q for q in ("current", "voltage", "speed", "position") if f"sensors.{q}" in (target or key)), None)
    return _UNITS.get((quantity, last), _PLANT_UNITS.get(last, ""))


def event_target(key: str, base: Mapping[str, Any] | None) -> str | None:
    """The target of the event whose value ``key`` sweeps (``events[0].value`` -> ``plant.Cd``), from ``base``."""
    import re

    match = re.fullmatch(r"events\[(\d+)\]\.value", key)
    events = (base or {}).get("events")
    if match is None or not isinstance(events, list) or int(match[1]) >= len(events):
        return None
    event = events[int(match[1])]
    return str(event["target"]) if isinstance(event, Mapping) and "target" in event else None


def sweep_label(key: str, base: Mapping[str, Any] | None = None) -> str:
    """An axis label for a swept key: ``events[0].value (plant.Cd) [N.m]``, ``sensors.current[0].offset [A]``."""
    target, unit = event_target(key, base), sweep_unit(key, base)
    return f"{key}{f' ({target})' if target else ''}{f' [{unit}]' if unit else ''}"


def detection_curves(records: list[dict], keys: list[str]) -> dict[str, dict]:
    """Per swept key, its detection, isolation and false-alarm rates with the other swept keys fault-free.

    A point of key ``k`` at value ``x`` counts only the runs where ``k == x`` and every other swept key holds
    its fault-free value: the value with the largest share of healthy runs (an offset of 0, a gain of 1).
    Pooling the other keys' faults into each point showed a detection of 1 at offset 0.

    Returns
    -------
    dict key -> dict
        ``x`` (sorted values), ``detection``, ``isolation`` (over the faulty runs at x, None where none),
        ``false_alarm`` (over the fault-free runs at x, None where none), ``runs`` (counted at x) and
        ``others`` (the other keys' fault-free values).
    """
    outcomes = [(r["overrides"], _run_outcome(r["result"])) for r in records if not set_apart(r["result"])]
    neutral = {}
    for key in keys:
        values = sorted({o[key] for o, _ in outcomes if key in o})
        share = {x: np.mean([out["class"] == "healthy" for o, out in outcomes if o.get(key) == x]) for x in values}
        neutral[key] = max(values, key=lambda x: share[x])
    curves = {}
    for key in keys:
        others = {k: neutral[k] for k in keys if k != key}
        xs = sorted({o[key] for o, _ in outcomes if key in o})
        c = {"x": xs, "detection": [], "isolation": [], "false_alarm": [], "runs": [], "faulty": [], "healthy": [],
             "others": others}
        for x in xs:
            at = [out for o, out in outcomes if o.get(key) == x and all(o.get(k) == v for k, v in others.items())]
            faulty = [out for out in at if out["class"] != "healthy"]
            healthy = [out for out in at if out["class"] == "healthy"]
            c["detection"].append(_rate(sum(out["detected"] for out in faulty), len(faulty)))
            c["isolation"].append(_rate(sum(out["isolated"] for out in faulty), len(faulty)))
            c["false_alarm"].append(_rate(sum(out["false_alarm"] for out in healthy), len(healthy)))
            c["runs"].append(len(at))
            c["faulty"].append(len(faulty))
            c["healthy"].append(len(healthy))
        curves[key] = c
    return curves


def plot_campaign(records: list[dict], aggregates: Aggregates, out: Path,
                  base: Mapping[str, Any] | None = None) -> list[Path]:
    """Detection rate against each swept key, parameter error against the noise key, one drift with its alarm.

    ``base`` (the campaign's base scenario) names what a swept event value sets, with its unit. Returns the
    written PNG paths (plots that have no data in this campaign are skipped).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ok = [r for r in records if r["status"] == "ok"]
    out.mkdir(parents=True, exist_ok=True)
    written = []
    keys = sorted({k for r in ok for k, v in r["overrides"].items() if isinstance(v, (int, float))})
    sweep_keys = [k for k in keys if len({r["overrides"].get(k) for r in ok}) <= max(10, len(ok) // 3)]
    if sweep_keys and any(row["fault_class"] not in ("healthy", "(failed)", *SET_APART.values()) for row in aggregates.detection):
        curves = detection_curves(ok, sweep_keys)
        fig, axes = plt.subplots(1, len(sweep_keys), figsize=(5.2 * len(sweep_keys), 4.2), squeeze=False)
        for ax, key in zip(axes[0], sweep_keys):
            c = curves[key]
            xs = np.asarray(c["x"], dtype=float)
            # each rate with its 95 % (Wilson) interval and its count: a campaign of a few runs a point says little,
            # and the figure showed 1.0 for 2 of 2 as it would for 200 of 200
            for name, style, n_key in (("detection", "o-", "faulty"), ("false_alarm", "x", "healthy"),
                                       ("isolation", "s--", "faulty")):  # isolation over detection: both seen
                y = np.array([np.nan if v is None else v for v in c[name]], dtype=float)
                lo, hi = np.transpose([_wilson(v, n) for v, n in zip(c[name], c[n_key])]).reshape(2, -1)
                label = ("false-alarm rate (fault-free runs)" if name == "false_alarm"
                         else f"{name} rate (faulty runs)") + (", 95 % interval" if name != "isolation" else "")
                kw = {"color": "C3", "ms": 9, "mew": 2} if name == "false_alarm" else {}
                if name == "isolation":
                    ax.plot(xs, y, style, mfc="none", label=label)
                else:
                    ax.errorbar(xs, y, yerr=[y - lo, hi - y], fmt=style, capsize=3, label=label, **kw)
                if name != "isolation":
                    for x, v, n in zip(xs, c[name], c[n_key]):
                        if v is not None:
                            ax.annotate(f"{round(v * n)}/{n}", (x, v), textcoords="offset points", fontsize=7,
                                        xytext=(-6, -12) if v > 0.9 else (5, 5), ha="right" if v > 0.9 else "left")
            others = ", ".join(f"{k} = {v:g}" for k, v in c["others"].items())
            target = event_target(key, base)
            ax.set(xlabel=sweep_label(key, base), ylabel="rate [fraction of runs]", ylim=(-0.05, 1.05),
                   title=f"detection against {key}{f' ({target})' if target else ''}"
                         + (f"\n(other swept keys fault-free: {others})" if others else ""))
            ax.title.set_fontsize(8)
            ax.grid(True)
            ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.22), fontsize=7, frameon=False)
        fig.tight_layout()
        written.append(out / "detection_rate.png")
        fig.savefig(written[-1], dpi=110)
        plt.close(fig)
    noise = next((k for k in sweep_keys if "noise" in k), next((k for k in keys if "noise" in k), None))
    if noise:
        fig, ax = plt.subplots(figsize=(6, 5.2))
        xs = np.array([r["overrides"].get(noise, np.nan) for r in ok], dtype=float)
        values = np.unique(xs[np.isfinite(xs)])
        # a swept key: one point per value; a drawn one: up to 6 quantile bins
        edges = np.c_[values, values] if noise in sweep_keys else np.c_[
            np.quantile(xs, np.linspace(0, 1, 7))[:-1], np.quantile(xs, np.linspace(0, 1, 7))[1:]]
        colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
        for c, name in enumerate(PHYSICAL):
            for method, style in zip(METHODS + ("monitor",), ("o-", "s--", "^:", "d-.")):
                centres, rms = [], []
                for lo, hi in edges:
                    rows = aggregate([r for r, x in zip(ok, xs) if lo <= x <= hi]).estimation
                    row = next((row for row in rows if row["parameter"] == name and row["method"] == method), None)
                    if row:
                        centres.append((lo + hi) / 2)
                        rms.append(row["rms_pct"])
                if centres:
                    ax.plot(centres, rms, style, color=colours[c % len(colours)], label=f"{name} {method}")
        counts = sorted({sum(lo <= x <= hi for x in xs) for lo, hi in edges})  # an RMS of a few runs is rough
        runs = f"{counts[0]}" if counts[0] == counts[-1] else f"{counts[0]}-{counts[-1]}"
        ax.set(xlabel=sweep_label(noise, base), ylabel="RMS relative error [%]", yscale="log",
               title=f"parameter error against noise ({runs} runs a point)")
        ax.grid(True, which="both")
        ax.legend(fontsize=7, ncol=4, loc="upper center", bbox_to_anchor=(0.5, -0.16), frameon=False)  # off the lines
        fig.tight_layout()
        written.append(out / "error_vs_noise.png")
        fig.savefig(written[-1], dpi=110)
        plt.close(fig)
    drift = drift_run(ok)
    if drift is not None:
        changes = ", ".join(_change_text(k, v) for k, v in drift["overrides"].items())
        written.append(plot_drift(drift["result"], out / "drift.png",
                                  f"run {drift['id']}" + (f" ({changes})" if changes else "")))
    return written


def _wilson(rate: float | None, n: int) -> tuple[float, float]:
    """The 95 % Wilson interval of a rate of ``n`` runs (NaN when there is none)."""
    if rate is None or n == 0:
        return math.nan, math.nan
    from feeddrive.estimator.distributions import norm_ppf  # not scipy.stats (tests/cosim/test_run_imports.py)

    z = float(norm_ppf(0.975))
    p = round(rate * n) / n
    centre, half = (p + z * z / (2 * n)), z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    return max(0.0, (centre - half) / (1 + z * z / n)), min(1.0, (centre + half) / (1 + z * z / n))


def _change_text(key: str, value: Any) -> str:
    """A run's change for a figure's title: ``events[0].value = 1.32``; a swept events list as its events
    (``plant.R = 0.77 at 3.24 s``), where its repr ran off the figure."""
    if isinstance(value, list) and all(isinstance(e, Mapping) and {"target", "value"} <= set(e) for e in value):
        return ", ".join(f"{e['target']} = {e['value']:g}" + (f" at {e['time']:g} s" if "time" in e else "")
                         for e in value) or f"{key}: none"
    text = f"{value:g}" if isinstance(value, float) else str(value)
    return f"{key} = {text if len(text) <= 40 else text[:37] + '...'}"


def drift_run(records: list[dict]) -> dict | None:
    """The run the drift figure shows: of the runs whose parameters drift, a diagnosed one with the largest change,
    else the largest change (the first drifting run was shown: the smallest fault, often missed, unsaid)."""
    drifts = [r for r in records if _onset(_truths(r["result"]))[1]]
    return max(drifts, key=lambda r: (_run_outcome(r["result"]).get("delay") is not None, _drift_size(r["result"])),
               default=None)


def drift_outcome(result: Mapping[str, Any]) -> str:
    """``diagnosed at motion 12 (the drift starts at motion 6)`` or ``not diagnosed (...)``, by the motions' numbers."""
    motions, (onset, _), outcome = result["motions"], _onset(_truths(result)), _run_outcome(result)
    number = [m.get("motion", i + 1) for i, m in enumerate(motions)]
    start = f"(the drift starts at motion {number[onset]})"
    return (f"diagnosed at motion {number[onset + outcome['delay']]} {start}" if outcome.get("delay") is not None
            else f"not diagnosed {start}")


def _drift_size(result: Mapping[str, Any]) -> float:
    """The largest relative change of a parameter over the run's motions."""
    truths = _truths(result)
    return max((abs(t[p] / truths[0][p] - 1) for t in truths for p in t if truths[0].get(p)), default=0.0)


def plot_drift(result: Mapping[str, Any], path: Path, title: str = "") -> Path:
    """Estimated and true drifting parameters against the motion index, with the first alarm marked and the run's
    outcome in the title (after ``title``, which names the run)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    motions = result["motions"]
    truths = _truths(result)
    onset, drifting = _onset(truths)
    outcome = _run_outcome(result)
    # the DC drive's order, then another model's own names (a PMSM's psi_f, L_q)
    names = [p for p in PHYSICAL if p in drifting] + sorted(p for p in drifting if p not in PHYSICAL)
    fig, axes = plt.subplots(len(names), 1, figsize=(7, 2.4 * len(names)), sharex=True, squeeze=False)
    # each motion's own number (the NC's, as the run's report gives it)
    k = np.array([m.get("motion", i + 1) for i, m in enumerate(motions)], dtype=float)
    for ax, name in zip(axes[:, 0], names):
        est = [m.get("parameters", {}).get(name, {}) for m in motions]
        # the truth holds over each motion (a step between motions, not a ramp); the estimate with its 95 % interval
        ax.step(k, [t[name] for t in truths], "k-", where="mid", label="truth")
        values = np.array([e.get("value", np.nan) for e in est], dtype=float)
        ci = np.array([e.get("ci95") or (np.nan, np.nan) for e in est], dtype=float).reshape(-1, 2)
        ax.errorbar(k, values, yerr=np.abs(ci.T - values), fmt="o", ms=3, capsize=2, label="estimate, 95 % CI")
        unit = _PLANT_UNITS.get(name, "")
        ax.set_ylabel(f"{name} [{unit}]" if unit else name)
        if outcome.get("delay") is not None:
            ax.axvline(k[onset + outcome["delay"]], color="r", ls="--", label="first diagnosis")
        ax.grid(True)
    axes[0, 0].legend(fontsize=8)
    axes[-1, 0].set_xlabel("motion")
    axes[-1, 0].xaxis.set_major_locator(matplotlib.ticker.MaxNLocator(integer=True))
    import textwrap

    said = drift_outcome(result)
    axes[0, 0].set_title(textwrap.fill(f"{title}: {said}" if title else said, 110), fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
