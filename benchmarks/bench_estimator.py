"""Time per motion of the estimator, against one ``numpy.linalg.lstsq`` on the same regressor.

A 4 s round trip (0 -> +70 -> 0 -> -70 -> 0 rad/s, 184 rad/s^2 ramps) of the closed-loop model,
with white noise at 30 dB SNR on u, i, w, sampled at 1 kHz and 10 kHz. For each rate it times
(best of ``--repeat``) ``estimate_motion`` with method ``ls`` (filter, derivatives, regressions,
LS with covariance and the excitation check), ``iv`` (LS + iterated split-sample IV) and ``oe``
(LS + IV + output error), and the baseline: one ``numpy.linalg.lstsq`` of the electrical regression
(n x 3) on the same data; and ``ls+val``: the monitor's measurement validation
(``estimator.validation.validate_measurements`` on two current sensors, voltage and reference,
tachometer and encoder) followed by LS. Targets at 10 kHz (issue 26): LS with validation <= 10 ms,
IV <= 30 ms, OE <= 1 s. Times are CPU times (``time.process_time``), each call on signals not filtered
before; the machine's load is printed first.

    python benchmarks/bench_estimator.py [--repeat 5] [--decimation auto|D]

``--decimation``: ``EstimationOptions.decimation`` (default ``auto``; ``1``: every filtered sample, as before
issue 26's decimation).

The estimator's matrix products are (n x 4)^T (n x 4): on a machine whose cores are busy, OpenBLAS
threads only wait for each other (IV measured 5x slower here under a load of 3.5 on 2 cores); run
with ``OPENBLAS_NUM_THREADS=1`` to measure the estimator rather than the thread contention.
"""
from __future__ import annotations

import argparse
import os
import time

import numpy as np

from feeddrive.estimator import EstimationOptions, MotionData, estimate_motion
from feeddrive.estimator.design import simulate_closed_loop
from feeddrive.estimator.estimate import prepare
from feeddrive.estimator.filtering import clear_filter_memo
from feeddrive.estimator.validation import validate_measurements

CORNERS = np.cumsum([0, 0.1, 0.38, 0.9, 0.38, 0.3, 0.38, 0.9, 0.38, 0.28])
LEVELS = [0, 0, 70, 70, 0, 0, -70, -70, 0, 0]
TARGET_MS = {"ls+val": 10.0, "iv": 30.0, "oe": 1000.0}


def best(fn, repeat: int) -> float:
    """Best CPU time of ``repeat`` calls [s], each on signals not filtered before (a new motion)."""
    times = []
    for _ in range(repeat):
        clear_filter_memo()
        t = time.process_time()
        fn()
        times.append(time.process_time() - t)
    return min(times)


def motion(h: float, seed: int = 0) -> tuple[MotionData, dict[str, np.ndarray]]:
    """The noisy motion, and the redundant measurements of it (a second, independently noisy sensor each)."""
    t = np.arange(int(round(CORNERS[-1] / h))) * h
    sig = simulate_closed_loop(np.interp(t, CORNERS, LEVELS), h)
    rng = np.random.default_rng(seed)

    def noisy(k: str) -> np.ndarray:
        return sig[k] + rng.standard_normal(sig[k].size) * np.sqrt(np.mean(sig[k] ** 2)) / 10 ** 1.5

    first = {k: noisy(k) for k in ("u", "i", "w")}
    redundant = {"Im1": first["i"], "Im2": noisy("i"), "u": first["u"], "u_ref": noisy("u"),
                 "w_tach": first["w"], "w_enc": noisy("w")}
    return MotionData(h, **first), redundant


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--decimation", default="auto", help="auto (default) or a factor >= 1 (1: every sample)")
    args = parser.parse_args()
    decimation = args.decimation if args.decimation == "auto" else int(args.decimation)
    print(f"decimation {decimation}")
    print(f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())} on {os.cpu_count()} CPUs, "
          f"OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS', 'unset')}")
    print(f"{'rate':>7} {'method':>6} {'CPU ms':>10} {'x lstsq':>9} {'target ms':>10}")
    for h in (1e-3, 1e-4):
        data, redundant = motion(h)
        reg = prepare(data, EstimationOptions(decimation=1))  # the baseline on every sample
        elec = next(r for r in reg.regressions if r.equation == "electrical")
        y, Phi = elec.evaluate(reg.signals)
        base = best(lambda: np.linalg.lstsq(Phi, y, rcond=None), 5 * args.repeat)
        print(f"{1 / h:7.0f} {'lstsq':>6} {1e3 * base:10.3f} {1.0:9.1f} {'':>10}   (baseline, {len(y)} x 3)")
        runs = {method: (lambda o=EstimationOptions(method=method, decimation=decimation):  # noqa: B008
                         estimate_motion(data, o))
                for method in ("ls", "iv", "oe")}
        spec = EstimationOptions().filter
        runs["ls+val"] = lambda: (validate_measurements(redundant, h, None, spec), runs["ls"]())
        for name in ("ls", "ls+val", "iv", "oe"):
            runs[name]()  # warm the caches (CasADi functions built once per length)
            t = best(runs[name], args.repeat)
            target = f"{TARGET_MS[name]:10.0f}" if h == 1e-4 and name in TARGET_MS else ""
            print(f"{1 / h:7.0f} {name:>6} {1e3 * t:10.3f} {t / base:9.1f} {target:>10}")


if __name__ == "__main__":
    main()
