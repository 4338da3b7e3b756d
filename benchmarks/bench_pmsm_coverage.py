"""Coverage campaign of the estimator on the PMSM model (issue 25): bias, scatter and 95 % CI coverage.

The closed-loop PMSM motion of tests/estimator/pmsm_data.py (nine speed levels of both signs, field
weakening above 150 rad/s, 8 kHz) with white noise at ``--snr`` dB on u_d, u_q, i_d, i_q and w, one noise
draw per motion, estimated by IV (filter cut-off 100 Hz). Prints, per parameter: the mean and standard
deviation of the relative error, the largest |error|, the mean 95 % half-width and the fraction of motions
whose interval holds the true value; then the same for the derived K_t and K_e.
Targets (issue 25): IV within 2 % on R, L_q, psi_f and Jt; coverage >= 90 % per parameter over >= 100 motions.

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_pmsm_coverage.py [--motions 100] [--snr 30] [--drive pmsm]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "estimator"))
from pmsm_data import FILTER, H, add_noise, closed_loop  # noqa: E402

from feeddrive.estimator import EstimationOptions, MotionData, estimate_motion  # noqa: E402
from feeddrive.models.drives import drive_model  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--motions", type=int, default=100)
    ap.add_argument("--snr", type=float, default=30.0)
    ap.add_argument("--drive", default="pmsm", choices=("pmsm", "pmsm-spm"))
    args = ap.parse_args()
    model = drive_model(args.drive)
    nominal = model.nominal()
    truth = nominal | {"K_t": 1.5 * nominal["p"] * nominal["psi_f"], "K_e": nominal["p"] * nominal["psi_f"]}
    clean = closed_loop(args.drive)
    err: dict[str, list[float]] = {}
    half: dict[str, list[float]] = {}
    cover: dict[str, list[bool]] = {}
    cpu = time.process_time()
    for seed in range(args.motions):
        d = add_noise(clean, args.snr, seed)
        est = estimate_motion(MotionData(H, w=d["w"], signals={k: d[k] for k in ("u_d", "u_q", "i_d", "i_q")}),
                              EstimationOptions(model=args.drive, filter=FILTER))
        for n, p in {**est.parameters, **est.derived}.items():
            err.setdefault(n, []).append(p.value / truth[n] - 1)
            half.setdefault(n, []).append((p.ci95[1] - p.ci95[0]) / 2 / truth[n])
            cover.setdefault(n, []).append(p.ci95[0] <= truth[n] <= p.ci95[1])
    cpu = time.process_time() - cpu
    print(f"{args.drive}: {args.motions} motions of {clean['t'][-1] + H:.2f} s at {1 / H:.0f} Hz, {args.snr:g} dB, "
          f"IV, filter {FILTER.cutoff_hz:g} Hz; {cpu / args.motions:.2f} s CPU per motion")
    print(f"{'':6} {'mean %':>8} {'sd %':>7} {'max|e| %':>9} {'CI95 +-%':>9} {'coverage':>9}")
    for n in err:
        e = 100 * np.asarray(err[n])
        print(f"{n:6} {e.mean():+8.3f} {e.std(ddof=1):7.3f} {np.abs(e).max():9.3f} {100 * np.mean(half[n]):9.3f} "
              f"{np.mean(cover[n]):9.0%}")


if __name__ == "__main__":
    main()
