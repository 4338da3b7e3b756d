"""What the servo sensors' interval means cost: the vendor PMSM FMU at ``--oversample`` (10) with its servo sensors
sampling interval means (stepped at the plant's rate, cosim/sensors_servo.py) against the same run with every
servo channel ``instant`` (stepped at the recording rate), no monitor. Prints the best of ``--repeat`` wall times
of each and their ratio (the machine may be shared: only the ratio of the same run means anything).

    python benchmarks/bench_servo_sampling.py [--oversample 10] [--repeat 3]
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "tests" / "plants"), str(ROOT / "tests" / "cosim")]
from test_monitor_pmsm import vendor_scenario  # noqa: E402
from vendor_pmsm import build_vendor_pmsm  # noqa: E402

from feeddrive.cosim.run import run_scenario  # noqa: E402
from feeddrive.cosim.scenario import scenario_from_dict  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--oversample", type=int, default=10)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        fmu = build_vendor_pmsm(Path(tmp) / "fmu")
        best = {}
        for k in range(args.repeat):
            for mode in ("mean", "instant"):
                data = vendor_scenario(fmu, args.oversample)
                data.pop("monitor")
                if mode == "instant":
                    ch = {"sampling": "instant"}
                    data["components"][0]["config"] |= {"phases": [ch] * 3, "second": ch, "voltage": ch,
                                                        "voltage_ref": ch}
                scenario = scenario_from_dict(data)
                tic = time.perf_counter()
                run_scenario(scenario, Path(tmp) / f"{mode}-{k}", plots=False)
                best[mode] = min(best.get(mode, float("inf")), time.perf_counter() - tic)
    print(f"vendor PMSM, oversample {args.oversample}, best of {args.repeat}: servo sensors mean "
          f"{best['mean']:.2f} s, instant {best['instant']:.2f} s, ratio {best['mean'] / best['instant']:.2f}")


if __name__ == "__main__":
    main()
