"""Speed of the plant FMU: doStep calls per second and real-time factor (a script, not a test).

Usage::

    python benchmarks/bench_fmu.py [--seconds 10] [--h 1e-4]

Each way of driving the Co-Simulation FMU runs the same closed-loop speed step over the same
simulated time, in this process, so the ratios compare like with like. The baseline is fmpy's
``simulate_fmu`` (what a user gets without the co-simulation master).
"""
from __future__ import annotations

import argparse
import tempfile
import time

import numpy as np
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi2 import FMU2Slave

from feeddrive.fmu_build import DEFAULT_CS_SUBSTEP, builtin_fmu


def _slave(fmu_dir: str) -> tuple[FMU2Slave, dict[str, int]]:
    md = read_model_description(fmu_dir)
    slave = FMU2Slave(guid=md.guid, unzipDirectory=fmu_dir, modelIdentifier=md.coSimulation.modelIdentifier)
    slave.instantiate()
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    return slave, {v.name: v.valueReference for v in md.modelVariables}


def do_step_loop(fmu_dir: str, h: float, n: int, with_io: bool) -> float:
    """Wall time [s] of n doStep calls (optionally with setReal of 3 inputs and getReal of 7 outputs)."""
    slave, vr = _slave(fmu_dir)
    inputs = [vr[k] for k in ("w_ref", "Tl", "u_in")]
    outputs = [vr[k] for k in ("u", "u_ref", "i", "w", "theta", "x", "i_ref")]
    values = [50.0, 0.0, 0.0]
    slave.setReal(inputs[:1], values[:1])
    start = time.perf_counter()
    if with_io:
        for k in range(n):
            slave.setReal(inputs, values)
            slave.doStep(k * h, h)
            slave.getReal(outputs)
    else:
        for k in range(n):
            slave.doStep(k * h, h)
    wall = time.perf_counter() - start
    w = slave.getReal([vr["w"]])[0]
    slave.terminate()
    slave.freeInstance()
    if not abs(w - 50.0) < 1e-6:
        raise RuntimeError(f"benchmark run did not reach the speed reference: w = {w}")
    return wall


def simulate_fmu_time(fmu: str, h: float, seconds: float) -> float:
    start = time.perf_counter()
    res = simulate_fmu(fmu, fmi_type="CoSimulation", stop_time=seconds, output_interval=h,
                       start_values={"w_ref": 50.0}, output=["i", "w", "u"])
    wall = time.perf_counter() - start
    if not np.isclose(res["w"][-1], 50.0, atol=1e-6):
        raise RuntimeError("simulate_fmu run did not reach the speed reference")
    return wall


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="simulated time per run [s]")
    parser.add_argument("--h", type=float, default=1e-4, help="communication step [s]")
    args = parser.parse_args()
    n = round(args.seconds / args.h)
    fmu = builtin_fmu()
    with tempfile.TemporaryDirectory() as fmu_dir:
        extract(str(fmu), fmu_dir)
        runs = {
            "fmpy simulate_fmu (baseline)": simulate_fmu_time(str(fmu), args.h, args.seconds),
            "FMU2Slave.doStep loop": do_step_loop(fmu_dir, args.h, n, with_io=False),
            "setReal(3) + doStep + getReal(7) loop": do_step_loop(fmu_dir, args.h, n, with_io=True),
        }
    base = runs["fmpy simulate_fmu (baseline)"]
    print(f"{fmu}\n{n} communication steps of {args.h:g} s ({args.seconds:g} s simulated), "
          f"substep {DEFAULT_CS_SUBSTEP:g} s\n")
    print(f"{'how the FMU is driven':40} {'wall [s]':>9} {'steps/s':>10} {'us/step':>8} {'RT factor':>10} "
          f"{'speed-up':>9}")
    for name, wall in runs.items():
        print(f"{name:40} {wall:9.3f} {n / wall:10.0f} {wall / n * 1e6:8.2f} {args.seconds / wall:10.1f} "
              f"{base / wall:9.2f}")


if __name__ == "__main__":
    main()
