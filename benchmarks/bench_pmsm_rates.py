"""The PMSM at an NC's sample rate (issue 25): 95 % coverage of the intervals given, and what is refused.

The tool change of tests/estimator/test_pmsm_rates.py (out and back at 188.5 rad/s, simulated every 125 us),
sampled instantaneously every 1, 2 and 4 ms as an NC's trace, noise-free and with white noise at 40 and 30 dB
(``--draws`` noise draws each), estimated by IV with the default cut-off ``min(100 Hz, 0.1 / h)``. Prints per
rate and noise: the intervals given, how many missed the truth (a 95 % interval misses 5 % by design), which,
and how often each parameter was given and refused.

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_pmsm_rates.py [--draws 10]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "estimator"))
from pmsm_data import H, add_noise  # noqa: E402
from test_pmsm_rates import TOL, TRUTH, estimate, simulated  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--draws", type=int, default=10)
    args = ap.parse_args()
    clean = simulated()
    total = missed_all = 0
    for k in (8, 16, 32):
        for snr in (None, 40.0, 30.0):
            missed, n, given, refused = [], 0, {}, {}
            for seed in (range(args.draws) if snr else [0]):
                est = estimate(clean if snr is None else add_noise(clean, snr, seed), k)
                for name, p in est.parameters.items():
                    n += 1
                    given[name] = given.get(name, 0) + 1
                    err = p.value / TRUTH[name] - 1
                    if not p.ci95[0] <= TRUTH[name] <= p.ci95[1] or (snr is None and abs(err) > TOL[name]):
                        missed.append(f"{name} {err:+.2%} (draw {seed})")
                for name in est.refused:
                    refused[name] = refused.get(name, 0) + 1
            total, missed_all = total + n, missed_all + len(missed)
            print(f"{k * H * 1e3:g} ms, {'noise-free' if snr is None else f'{snr:g} dB'}: {n} intervals given, "
                  f"{len(missed)} missed {missed}; given {given}; refused {refused}")
    print(f"all: {missed_all} of {total} intervals given missed the truth ({missed_all / max(total, 1):.1%})")


if __name__ == "__main__":
    main()
