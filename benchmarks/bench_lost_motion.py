"""Lost motion seen by the two encoders (motor encoder against the linear scale) on the vendor PMSM FMU.

Random out-and-back motions (300..1500 rpm, 0.1..0.25 s each way, held speed commands) of the hand-written
vendor PMSM FMU (tests/plants/vendor_pmsm) with an elastic drive chain (``ELASTIC``: 150 kg table, 120 N guide
friction, 200 N/um screw: a healthy axis has 2 Fc / k = 1.2 um of lost motion), healthy (no backlash) and with
``--lost-motion`` mm of backlash, each measured by the servo sensors (cosim.sensors_servo: 2500-line motor
encoder, 0.1 um linear scale with 0.2 um noise; sensor noise seeded per motion) and tested by
estimator.redundancy_servo.lost_motion at ``--alpha`` against the acceptance value ``--allowed`` (5 um). Prints
the detection rate, the healthy false-alarm rate, the estimates' spread and the intervals' coverage; and the
test's size: the healthy axis tested against its own true lost motion (false alarms should be about alpha).
Issue 25's figure asks at least 90 % detected at 0.02 mm and at most 2 % false alarms at alpha = 1 %.

    python benchmarks/bench_lost_motion.py [--motions 100] [--lost-motion 0.02] [--alpha 0.01] [--allowed 0.005]
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "plants"))
from vendor_pmsm import ELASTIC, build_vendor_pmsm  # noqa: E402
from vendor_pmsm.motions import campaign  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--motions", type=int, default=100, help="motions per case (healthy, worn)")
    parser.add_argument("--lost-motion", type=float, default=0.02, help="the worn axis's lost motion [mm]")
    parser.add_argument("--alpha", type=float, default=0.01, help="level of the lost-motion test")
    parser.add_argument("--allowed", type=float, default=0.005, help="acceptance value of the lost motion [mm]")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    elastic = 2 * ELASTIC["Fc_table"] / ELASTIC["k_axial"] * 1e-3
    with tempfile.TemporaryDirectory() as tmp:
        fmu = build_vendor_pmsm(tmp)
        healthy = campaign(fmu, args.motions, 0.0, seed=1, alpha=args.alpha, parameters=ELASTIC,
                           allowed_mm=args.allowed)
        worn = campaign(fmu, args.motions, args.lost_motion, seed=2, alpha=args.alpha, parameters=ELASTIC,
                        allowed_mm=args.allowed)
        size = campaign(fmu, args.motions, 0.0, seed=1, alpha=args.alpha, parameters=ELASTIC, allowed_mm=elastic)
    print(f"lost motion tested against {args.allowed * 1e3:g} um at alpha = {args.alpha:g}; the healthy chain's "
          f"elastic lost motion is {elastic * 1e3:.2f} um")
    for name, runs, truth in (("healthy", healthy, elastic), (f"backlash {args.lost_motion:g} mm", worn,
                                                              args.lost_motion + elastic),
                              (f"healthy tested against its true {elastic * 1e3:.2f} um (the test's size)", size,
                               elastic)):
        values = np.array([r.value_mm for r in runs])
        covered = np.mean([r.ci95_mm[0] <= truth <= r.ci95_mm[1] for r in runs])
        rate = np.mean([r.detected for r in runs])
        print(f"{name}: {rate:.1%} detected at alpha = {args.alpha:g} ({len(runs)} motions); estimate "
              f"{values.mean() * 1e3:.4f} um mean, {values.std(ddof=1) * 1e3:.4f} um std; 95 % intervals cover the "
              f"truth in {covered:.0%}")
    print(f"{3 * args.motions} motions in {time.perf_counter() - start:.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
