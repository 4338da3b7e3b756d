"""Calibration of the paper's output-error model check on the PMSM (issue 25): are healthy p-values uniform?

The closed-loop PMSM motion of tests/estimator/pmsm_data.py (nine speed levels of both signs, field weakening
above 150 rad/s, 8 kHz), 40 dB white noise on each measured signal and a second sensor of each (independent
noise) as the instrument, estimated by IV, then ``estimator.model_check.check_model_equations`` at alpha 1 %
(tests/estimator/test_model_check_pmsm.py's ``check``), over ``--motions`` noise draws. Prints per test (the
q and d currents' and the speed's independence, size and peak tests): the Kolmogorov-Smirnov p-value of its
healthy p-values against the uniform, the fractions below 1 % and 5 % and the median; then the check's
false-alarm rate (Bonferroni over its tests) and, over ``--loaded`` draws, how often it flags the 0.5 N.m load
torque the model lacks. (A size test's p-values near 1 are conservative: its null level counts the state
sensor's noise unfiltered.)

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_pmsm_model_check.py [--motions 200] [--loaded 20]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from scipy import stats

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "estimator"))
from pmsm_data import closed_loop  # noqa: E402
from test_model_check_pmsm import ALPHA, check  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--motions", type=int, default=200)
    ap.add_argument("--loaded", type=int, default=20)
    args = ap.parse_args()
    healthy = closed_loop()
    p: dict[str, list[float]] = {}
    cpu = time.process_time()
    for seed in range(args.motions):
        r = check(healthy, 1000 + seed)
        for name, c in r.checks.items():
            for test, res in c.tests.items():
                p.setdefault(f"{name} {test}", []).append(res.p_value)
        p.setdefault("the check (Bonferroni)", []).append(r.p_value)
    cpu = (time.process_time() - cpu) / max(args.motions, 1)
    print(f"{args.motions} healthy motions ({cpu:.2f} s CPU each)")
    print(f"{'test':24s} {'KS p (uniform)':>14s} {'< 1 %':>7s} {'< 5 %':>7s} {'median':>7s}")
    for name, v in p.items():
        v = np.asarray(v)
        print(f"{name:24s} {stats.kstest(v, 'uniform').pvalue:14.3g} {np.mean(v < 0.01):7.1%} {np.mean(v < 0.05):7.1%} "
              f"{np.median(v):7.3f}")
    alarms = np.mean(np.asarray(p["the check (Bonferroni)"]) < ALPHA)
    print(f"healthy false alarms at alpha {ALPHA:g}: {alarms:.1%} (target <= 2 % for the check to decide)")
    if args.loaded:
        loaded = closed_loop("pmsm", (("T0", 0.5),))
        flagged = np.mean([not check(loaded, 2000 + s).passed for s in range(args.loaded)])
        print(f"0.5 N.m load torque the model lacks: flagged in {flagged:.0%} of {args.loaded} motions")


if __name__ == "__main__":
    main()
