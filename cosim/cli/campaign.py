"""``cosim campaign CAMPAIGN.yaml [--workers N] [--scheduler tcp://HOST:PORT] [--out DIR]``.

Runs (or resumes) a campaign: every run's record in OUT/runs/, the detection and estimation tables
printed and written to OUT/detection.csv and OUT/estimation.csv, plots in OUT/plots/. The default out
dir, ``campaigns/<name>``, is stable so that running the same command again resumes.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("campaign", type=Path, help="campaign YAML file")
    parser.add_argument("--workers", type=int, default=1, help="local worker processes (default 1: this process)")
    parser.add_argument("--scheduler", metavar="ADDRESS", help="run on an existing Dask cluster (tcp://host:port)")
    parser.add_argument("--out", type=Path, help="out dir (default campaigns/<name>; reused to resume)")
    parser.add_argument("--overwrite", action="store_true", help="discard another campaign's results in --out")
    parser.add_argument("--retry-failed", action="store_true", help="run the failed runs again")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--no-plots", action="store_true", help="do not draw the plots")
    parser.add_argument("--timeout", type=float, metavar="SECONDS",
                        help="wall-time limit of each run (default: the campaign's timeout, else none)")


def main(args: argparse.Namespace) -> int:
    import os

    # the runs use every CPU already: each draws its figures in turn, not in forked processes of its own (the
    # workers inherit the environment); restored afterwards, for a caller that goes on in this process
    before = os.environ.get("FEEDDRIVE_PLOT_PROCESSES")
    os.environ.setdefault("FEEDDRIVE_PLOT_PROCESSES", "1")
    try:
        return _run(args)
    finally:
        if before is None:
            os.environ.pop("FEEDDRIVE_PLOT_PROCESSES", None)


def _run(args: argparse.Namespace) -> int:
    from feeddrive.cosim.campaign import load_campaign, run_campaign
    from feeddrive.cosim.progress import enabled

    campaign = load_campaign(args.campaign)
    out = args.out or Path("campaigns", campaign.name)
    result = run_campaign(campaign, out, workers=args.workers, scheduler=args.scheduler,
                          progress=enabled(not args.no_progress), overwrite=args.overwrite,
                          retry_failed=args.retry_failed, plots=not args.no_plots,
                          timeout=args.timeout)
    print(result.aggregates.table())
    failed = result.failed
    print(f"\n{campaign.name}: {len(result.records)} runs ({result.executed} run now, {len(failed)} failed) -> {out}")
    for record in failed:
        print(f"  failed {record['id']}: {record['reason']}")
    if failed and len(failed) == len(result.records):
        print(f"cosim campaign: failed: every run failed (first: {failed[0]['reason']})", file=sys.stderr)
        return 1
    return 0
