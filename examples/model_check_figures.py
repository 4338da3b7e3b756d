"""Figures of the model check and the parameter covariances from campaign out dirs (issue 12).

    python examples/model_check_figures.py runs/check-healthy runs/check-vendor runs/check-backlash \\
        runs/check-cd-step

For each out dir (one ``cosim campaign`` of examples/campaign_check_*.yaml): the motions processed,
the share the model check rejects (``mismatch.passed`` false: the false-alarm rate on healthy
campaigns, the detection rate on faulty ones), with its 95 % Clopper-Pearson interval (statsmodels),
the coverage of each parameter's 95 % CI by the plant's value (campaigns whose truth is constant over
each motion), and the monitor's mean processing time per motion. ``--json`` prints the same as JSON.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from statsmodels.stats.proportion import proportion_confint

PARAMETERS = ("R", "L", "K", "Jt", "ft", "Cd")


def figures(out: Path) -> dict:
    """Rejection rate, CI coverage and processing time of one campaign out dir."""
    motions = []
    for path in sorted((out / "runs").glob("*.json")):
        record = json.loads(path.read_text(encoding="utf-8"))
        if record.get("status") != "ok":
            continue
        result = record["result"]
        changing = bool(result["injected"]["plant"]) and result["injected"]["plant"] != {}
        for m in result["motions"]:
            if m.get("mismatch"):
                motions.append((m, result["truth"], changing))
    if not motions:
        raise SystemExit(f"{out}: no finished run with a model check")
    rejected = np.array([not m["mismatch"]["passed"] for m, _, _ in motions])
    lo, hi = proportion_confint(int(rejected.sum()), rejected.size, alpha=0.05, method="beta")
    coverage = {}
    for name in PARAMETERS:
        hits = [m["parameters"][name]["ci95"][0] <= (m.get("truth") or truth)[name] <= m["parameters"][name]["ci95"][1]
                for m, truth, changing in motions if not changing and name in m["parameters"]]
        if hits:
            coverage[name] = float(np.mean(hits))
    return {"campaign": str(out), "motions": int(rejected.size), "rejected": int(rejected.sum()),
            "rejection_rate": float(rejected.mean()), "rejection_ci95": [float(lo), float(hi)],
            "alpha": motions[0][0]["mismatch"]["alpha"], "coverage": coverage,
            "processing_s": float(np.mean([m["processing_s"] for m, _, _ in motions]))}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", nargs="+", type=Path)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    rows = [figures(o) for o in args.out]
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    for r in rows:
        cov = " ".join(f"{k} {100 * v:.0f} %" for k, v in r["coverage"].items()) or "-"
        print(f"{r['campaign']}: {r['rejected']} of {r['motions']} motions rejected "
              f"({100 * r['rejection_rate']:.1f} %, 95 % CI {100 * r['rejection_ci95'][0]:.1f}-"
              f"{100 * r['rejection_ci95'][1]:.1f} %) at alpha = {r['alpha']:g}; CI coverage {cov}; "
              f"processing {r['processing_s']:.2f} s per motion")
    return 0


if __name__ == "__main__":
    sys.exit(main())
