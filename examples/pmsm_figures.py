"""Figures of the PMSM monitor campaign (examples/campaign_pmsm.yaml): detection rate per fault, false alarms.

    python examples/pmsm_figures.py runs/campaign-pmsm [MORE_OUT_DIRS ...] [--json]

Each run's last motion is scored (the one after the parameter step; the earlier ones build the healthy
baseline). A case is the run's injected plant change: none (healthy), ``psi_f`` (demagnetisation) or ``R``
(winding heating). On a faulty case a motion is *detected* when its diagnosis names the expected fault; on
the healthy case a *false alarm* is any alarm: a diagnosis, a sensor fault or a model mismatch. Motions
not validated (no alarm, no diagnosis) are counted apart. Rates come with their 95 % Clopper-Pearson interval.
Several out dirs (campaigns of other seeds, or one per case) are counted together.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from statsmodels.stats.proportion import proportion_confint

#: injected plant parameter -> (case name, the Table I fault expected)
EXPECTED = {"psi_f": ("psi_f -3 %", "demagnetisation"), "R": ("R +10 %", "winding heating")}
ALARMS = ("diagnosed", "drifting", "sensor fault", "model mismatch")


def figures(out: Path) -> dict:
    """``case -> {motions, hits, rate, ci95, not_validated}`` of one campaign out dir (hits: detections or
    false alarms)."""
    cases: dict[str, dict] = {}
    for path in sorted((out / "runs").glob("*.json")):
        record = json.loads(path.read_text(encoding="utf-8"))
        if record.get("status") != "ok":
            continue
        result = record["result"]
        motion = result["motions"][-1]
        plant = result["injected"]["plant"]
        name, fault = EXPECTED[next(iter(plant))] if plant else ("healthy", None)
        faults = [d["fault"] for d in motion.get("diagnosis", ())]
        verdict = motion.get("verdict") or ""
        hit = fault in faults if fault else verdict in ALARMS
        case = cases.setdefault(name, {"fault": fault, "motions": 0, "hits": 0, "not_validated": 0})
        case["motions"] += 1
        case["hits"] += int(hit)
        case["not_validated"] += int(not motion.get("validated"))
    if not cases:
        raise SystemExit(f"{out}: no finished run")
    return _rates(cases)


def _rates(cases: dict[str, dict]) -> dict[str, dict]:
    for case in cases.values():
        lo, hi = proportion_confint(case["hits"], case["motions"], alpha=0.05, method="beta")
        case |= {"rate": case["hits"] / case["motions"], "ci95": [float(lo), float(hi)]}
    return cases


def merged(outs: list[Path]) -> dict[str, dict]:
    """``figures`` of several out dirs, the counts of each case added."""
    total: dict[str, dict] = {}
    for out in outs:
        for name, c in figures(out).items():
            t = total.setdefault(name, {"fault": c["fault"], "motions": 0, "hits": 0, "not_validated": 0})
            for key in ("motions", "hits", "not_validated"):
                t[key] += c[key]
    return _rates(total)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path, nargs="+")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    cases = merged(args.out)
    if args.json:
        print(json.dumps(cases, indent=2))
        return 0
    for name, c in cases.items():
        what = f"detected as {c['fault']}" if c["fault"] else "false alarms"
        print(f"{name}: {c['hits']} of {c['motions']} {what} ({100 * c['rate']:.1f} %, 95 % CI "
              f"{100 * c['ci95'][0]:.1f}-{100 * c['ci95'][1]:.1f} %); {c['not_validated']} not validated")
    return 0


if __name__ == "__main__":
    sys.exit(main())
