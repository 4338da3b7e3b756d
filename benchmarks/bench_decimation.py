"""Accuracy and interval coverage of the estimator with and without decimation (issue 26), DC and PMSM.

``EstimationOptions.decimation`` keeps every D-th filtered sample for the regressions (``auto``: the largest D
with 2 pi f_c (2 h D) <= 0.5 rad). This runs the same motions and noise draws through IV at each factor asked
for and prints, per parameter: the mean and standard deviation of the relative error, the mean 95 % half-width
and the fraction of motions whose interval holds the truth; then the noise-free errors (target <= 0.5 %) and the
CPU time per motion.

* DC: the 4 s round trip of benchmarks/bench_estimator.py (0 -> +70 -> 0 -> -70 -> 0 rad/s) at 10 kHz, white
  noise at ``--snr`` dB on u, i, w, filter ``--cutoff`` Hz (the monitor's 100 Hz by default);
* PMSM: the closed-loop motion of tests/estimator/pmsm_data.py at 8 kHz, 100 Hz filter, noise on u_d, u_q, i_d,
  i_q, w (as benchmarks/bench_pmsm_coverage.py).

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_decimation.py [--motions 100] [--snr 30] [--cutoff 100]
        [--decimation 1,auto] [--drive dc,pmsm]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "estimator"))
from bench_estimator import CORNERS, LEVELS  # noqa: E402
from pmsm_data import FILTER, H, add_noise, closed_loop  # noqa: E402

from feeddrive.estimator import EstimationOptions, FilterSpec, MotionData, estimate_motion  # noqa: E402
from feeddrive.estimator.design import simulate_closed_loop  # noqa: E402
from feeddrive.estimator.simulation import MODEL  # noqa: E402
from feeddrive.models.drives import drive_model  # noqa: E402


def dc_case(cutoff: float):
    """(truth, clean signals, noisy MotionData of a seed, options of a factor) of the DC round trip."""
    h = 1e-4
    t = np.arange(int(round(CORNERS[-1] / h))) * h
    sig = simulate_closed_loop(np.interp(t, CORNERS, LEVELS), h)

    def data(snr: float | None, seed: int) -> MotionData:
        rng = np.random.default_rng(seed)
        out = {k: sig[k] + (0.0 if snr is None else rng.standard_normal(sig[k].size) * np.sqrt(np.mean(sig[k] ** 2))
                            / 10 ** (snr / 20)) for k in ("u", "i", "w")}
        return MotionData(h, **out)

    return MODEL.nominal(("physical",)), data, lambda d: EstimationOptions(filter=FilterSpec(cutoff), decimation=d)


def pmsm_case():
    model = drive_model("pmsm")
    nominal = model.nominal()
    truth = nominal | {"K_t": 1.5 * nominal["p"] * nominal["psi_f"], "K_e": nominal["p"] * nominal["psi_f"]}
    clean = closed_loop("pmsm")

    def data(snr: float | None, seed: int) -> MotionData:
        d = clean if snr is None else add_noise(clean, snr, seed)
        return MotionData(H, w=d["w"], signals={k: d[k] for k in ("u_d", "u_q", "i_d", "i_q")})

    return truth, data, lambda d: EstimationOptions(model="pmsm", filter=FILTER, decimation=d)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--motions", type=int, default=100)
    ap.add_argument("--snr", type=float, default=30.0)
    ap.add_argument("--cutoff", type=float, default=100.0, help="the DC case's filter cut-off [Hz]")
    ap.add_argument("--decimation", default="1,auto", help="comma-separated factors: auto or integers >= 1")
    ap.add_argument("--drive", default="dc,pmsm", help="comma-separated: dc, pmsm")
    args = ap.parse_args()
    factors = [d if d == "auto" else int(d) for d in args.decimation.split(",")]
    for drive in args.drive.split(","):
        truth, data, options = dc_case(args.cutoff) if drive == "dc" else pmsm_case()
        for d in factors:
            opts = options(d)
            clean = estimate_motion(data(None, 0), opts)
            err: dict[str, list[float]] = {}
            half: dict[str, list[float]] = {}
            cover: dict[str, list[bool]] = {}
            cpu = time.process_time()
            for seed in range(args.motions):
                est = estimate_motion(data(args.snr, seed), opts)
                for n, p in {**est.parameters, **est.derived}.items():
                    err.setdefault(n, []).append(p.value / truth[n] - 1)
                    half.setdefault(n, []).append((p.ci95[1] - p.ci95[0]) / 2 / truth[n])
                    cover.setdefault(n, []).append(p.ci95[0] <= truth[n] <= p.ci95[1])
            cpu = (time.process_time() - cpu) / max(args.motions, 1)
            print(f"{drive}: decimation {d} (estimated at {est.rate_hz:.0f} Hz of {1 / data(None, 0).h:.0f} Hz), "
                  f"{args.motions} motions, {args.snr:g} dB, IV, filter {opts.filter.cutoff_hz:g} Hz; "
                  f"{1e3 * cpu:.0f} ms CPU per motion")
            print(f"{'':6} {'mean %':>8} {'sd %':>7} {'CI95 +-%':>9} {'coverage':>9} {'noise-free %':>13}")
            exact = {**clean.parameters, **clean.derived}
            for n in err:
                e = 100 * np.asarray(err[n])
                print(f"{n:6} {e.mean():+8.3f} {e.std(ddof=1) if e.size > 1 else 0.0:7.3f} "
                      f"{100 * np.mean(half[n]):9.3f} {np.mean(cover[n]):9.0%} "
                      f"{100 * (exact[n].value / truth[n] - 1):+13.4f}")


if __name__ == "__main__":
    main()
