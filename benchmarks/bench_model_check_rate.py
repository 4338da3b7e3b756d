"""The model checks at several decimations on the same motions: does a coarser rate change their verdicts?

The first ``--runs`` runs of an issue-12 campaign (examples/campaign_check_<name>.yaml: healthy motions, the
vendor-style FMU's, the dry-friction step or the backlash the model lacks) are co-simulated once each; the
monitor's processing of each motion then runs one check on the same inputs at each decimation asked for (every
D-th filtered sample simulated and tested; ``auto``: the checks' rule, ``filtering.check_rate_factor``):
``--check model``, the paper's output-error check (``estimator.mismatch.check_model``, on the same estimate), or
``--check residue``, the recording's own residue check (``estimator.adequacy.check_adequacy``). Prints, per
decimation: how many motions it rejects at the campaign's alpha, the verdicts that differ from the first
decimation's, and the check's CPU time per motion.

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_model_check_rate.py [--check model|residue]
        [--campaign healthy|vendor|cd_step|backlash] [--runs 40] [--decimation 2,auto]
        [--fmu VendorDrive.fmu (--campaign vendor: python examples/vendor_fmu/build_vendor_fmu.py --out PATH)]
        [--json FILE]
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import feeddrive.cosim.monitor_pipeline as pipeline
from feeddrive.cosim.campaign import load_campaign
from feeddrive.cosim.campaign.schema import expand
from feeddrive.cosim.monitor import MEASUREMENTS, MonitorConfig, MonitorPipeline, centred_speed
from feeddrive.cosim.run import run_scenario
from feeddrive.cosim.scenario import scenario_from_dict
from feeddrive.estimator.history import History

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--campaign", default="healthy", help="examples/campaign_check_<NAME>.yaml")
    ap.add_argument("--runs", type=int, default=40)
    ap.add_argument("--decimation", default="2,auto")
    ap.add_argument("--fmu", help="the plant FMU of the vendor campaign (python examples/vendor_fmu/build_vendor_fmu.py "
                                  "--out PATH)")
    ap.add_argument("--check", choices=("model", "residue"), default="model",
                    help="model: the paper's output-error check (check_model); residue: the recording's own residue "
                         "check (estimator.adequacy.check_adequacy)")
    ap.add_argument("--json", help="write the per-motion p-values to this file")
    args = ap.parse_args()
    factors = [d if d == "auto" else int(d) for d in args.decimation.split(",")]
    campaign = load_campaign(ROOT / "examples" / f"campaign_check_{args.campaign}.yaml")
    specs = expand(campaign)[:args.runs]
    stage = "check_model" if args.check == "model" else "check_adequacy"
    original = getattr(pipeline, stage)
    rows, spent = [], {d: 0.0 for d in factors}

    def every_rate(*a, **k):
        out = {}
        for d in factors:
            cpu = time.process_time()
            out[d] = original(*a, **(k | {"decimation": d}))
            spent[d] += time.process_time() - cpu
        if args.check == "model":
            rows[-1].append({str(d): (r.p_value, r.passed, r.test, {f"{n} {t}": x.p_value for n, c in r.checks.items()
                                                                   for t, x in c.tests.items()}) for d, r in out.items()})
        else:  # the residue check's verdict: mismatch, not enough excitation or adequate
            rows[-1].append({str(d): (1.0 if r.p_value is None else r.p_value, not r.mismatch, r.verdict,
                                      {e: c.p_value for e, c in r.equations.items()}) for d, r in out.items()})
        return out[factors[0]]

    for spec in specs:
        if args.fmu:
            spec.scenario["plant"]["fmu"] = str(Path(args.fmu).resolve())
        scenario = scenario_from_dict(spec.scenario, source="scenario", base_dir=spec.base_dir)
        with tempfile.TemporaryDirectory() as tmp:
            run = run_scenario(scenario, tmp, overwrite=True, plots=False)
        h = run.report["step_s"]
        state = run.signals["nc.state"]
        edges = np.flatnonzero(np.diff(np.r_[0, (state == 1).astype(int), 0]))
        config = MonitorConfig(**(spec.scenario.get("monitor") or {}))
        for a, b in zip(edges[::2], edges[1::2]):
            signals = {k: run.signals[f"sensors.{k}"][a:b] for k in MEASUREMENTS}
            signals["w_enc"] = centred_speed(signals["theta_enc"], signals["w_enc"], h, config.encoder_window_s)
            rows.append([spec.index])
            setattr(pipeline, stage, every_rate)
            try:
                with History(":memory:") as history:
                    MonitorPipeline(config, history, "X").process(signals, h, a * h, 1, 0.0)
            finally:
                setattr(pipeline, stage, original)
            print(spec.index, {d: f"{v[0]:.3g} {v[2]}" for d, v in rows[-1][1].items()}, flush=True)
    done = [r for r in rows if len(r) > 1]
    first = str(factors[0])
    print(f"\n{args.campaign}: {len(done)} motions of {len(specs)} runs")
    for d in factors:
        rejected = sum(not r[1][str(d)][1] for r in done)
        differ = sum(r[1][str(d)][1] != r[1][first][1] for r in done)
        print(f"decimation {d!s:>5}: {rejected} rejected, {differ} verdicts differ from {first}'s; "
              f"{stage} {1e3 * spent[d] / max(len(done), 1):.1f} ms CPU per motion")
    if args.json:
        Path(args.json).write_text(json.dumps(done))
    return 0


if __name__ == "__main__":
    sys.exit(main())
