"""What stepping the servo sensors in the compiled fine loop saves on a PMSM run (cosim/fastloop/servo.py).

Runs a PMSM scenario (default examples/pmsm_axis.yaml: the built-in PMSM, a tool change, 21 334 samples) with
the servo sensors in the compiled loop, then with them stepped in Python at the end of every block (as before:
``fastloop.servo.candidate`` answering None, so every sample ends a block), and with the Python loop throughout
(``FEEDDRIVE_FASTLOOP=0``). Prints the best of ``--repeat`` wall times of the master's run (no files written)
and the ratios (the machine may be shared: only ratios of the same run mean anything). ``--oversample`` runs
the plant at that many steps per sample (the servo sensors then step every plant step for their interval means).

    python benchmarks/bench_servo_loop.py [--scenario examples/pmsm_axis.yaml] [--oversample 1] [--repeat 3]
"""
from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import yaml

from feeddrive.cosim.fastloop import servo
from feeddrive.cosim.master import Master
from feeddrive.cosim.scenario import scenario_from_dict

ROOT = Path(__file__).resolve().parents[1]


def _run(data: dict) -> tuple[float, str]:
    with Master.from_scenario(scenario_from_dict(data)) as master:
        master.setup()
        tic = time.perf_counter()
        master.run()
        return time.perf_counter() - tic, master.loop


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default=str(ROOT / "examples" / "pmsm_axis.yaml"))
    parser.add_argument("--oversample", type=int, default=1)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    data = yaml.safe_load(Path(args.scenario).read_text())
    data["plant"] = data.get("plant", {}) | {"oversample": args.oversample}
    candidate = servo.candidate
    best: dict[str, float] = {}
    for _ in range(args.repeat):
        for mode in ("compiled", "servo in python", "python loop"):
            servo.candidate = candidate if mode == "compiled" else (lambda *a: None)
            os.environ["FEEDDRIVE_FASTLOOP"] = "0" if mode == "python loop" else "1"
            try:
                dt, loop = _run(data)
            finally:
                servo.candidate = candidate
                os.environ.pop("FEEDDRIVE_FASTLOOP")
            best[mode] = min(best.get(mode, float("inf")), dt)
            print(f"  {mode}: {dt:.2f} s ({loop})")
    c = best["compiled"]
    print(f"{Path(args.scenario).name}, oversample {args.oversample}, best of {args.repeat}: compiled servo sensors "
          f"{c:.2f} s, servo sensors in Python {best['servo in python']:.2f} s (x{best['servo in python'] / c:.1f}), "
          f"Python loop {best['python loop']:.2f} s (x{best['python loop'] / c:.1f})")


if __name__ == "__main__":
    main()
