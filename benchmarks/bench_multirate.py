"""Wall time of the multi-rate co-simulation against fmpy running the plant alone at the fine step.

For each oversampling m: the full co-simulation of a scenario (NC -> plant FMU stepped m times per
recording step -> sensors stepped m times, sampling the interval mean -> monitor; ``Master.run`` only)
against ``fmpy.simulate_fmu`` on the same plant FMU alone at the fine step ``step / m``, recording every
fine step, with the NC's speed reference as its input table: the same number of doStep calls. Prints
seconds (best of ``--repeat``) and the ratio cosim / fmpy (target <= 1.0 at m = 10).

    python benchmarks/bench_multirate.py [--scenario examples/tool_change.yaml] [--oversample 1 4 10]
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from fmpy import read_model_description, simulate_fmu

from feeddrive.cosim.master import Master
from feeddrive.cosim.scenario import load_scenario

ROOT = Path(__file__).resolve().parents[1]


def cosim_run(scenario) -> tuple[float, Master, dict]:
    master = Master.from_scenario(scenario)
    master.setup()
    t = time.perf_counter()
    rec = master.run()
    wall = time.perf_counter() - t
    master.terminate()
    return wall, master, rec.signals()


def fmpy_run(scenario, stop: float, signals: dict, m: int) -> float:
    """simulate_fmu on the plant alone at step / m, recording every fine step, the NC's reference as input."""
    h = scenario.step
    inputs = [v.name for v in read_model_description(scenario.plant.fmu).modelVariables if v.causality == "input"]
    n = len(signals["nc.speed_ref"])
    table = np.zeros(n, dtype=[("time", float)] + [(name, float) for name in inputs])
    table["time"] = h * np.arange(n)
    for role in ("speed_ref", "load"):
        entry = scenario.plant.map.get(role)
        if entry is not None:  # the plant's input over [t_n, t_n+1] is the NC's output at t_n+1
            table[entry.var] = entry.scale * np.r_[signals[f"nc.{role}"][1:], 0.0] + entry.offset
    t = time.perf_counter()
    simulate_fmu(scenario.plant.fmu, fmi_type="CoSimulation", stop_time=stop, step_size=h / m, output_interval=h / m,
                 input=table, start_values=dict(scenario.plant.parameters))
    return time.perf_counter() - t


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", type=Path, default=ROOT / "examples" / "tool_change.yaml")
    parser.add_argument("--oversample", type=int, nargs="+", default=[1, 4, 10])
    parser.add_argument("--repeat", type=int, default=2)
    args = parser.parse_args(argv)
    base = load_scenario(args.scenario)
    print(f"scenario {base.name}, recording step {base.step:g} s, best of {args.repeat}")
    print("| oversample | doStep calls | cosim [s] | fmpy [s] | cosim / fmpy |\n| --- | --- | --- | --- | --- |")
    for m in args.oversample:
        scenario = base.model_copy(update={"plant": base.plant.model_copy(update={"oversample": m})})
        best: dict[str, float] = {}
        for _ in range(args.repeat):
            wall, master, signals = cosim_run(scenario)
            runs = {"cosim": wall, "fmpy": fmpy_run(scenario, master.stop_time, signals, m)}
            best = {k: min(v, best.get(k, v)) for k, v in runs.items()}
        print(f"| {m} | {master.n_steps * m} | {best['cosim']:.2f} | {best['fmpy']:.2f} | "
              f"{best['cosim'] / best['fmpy']:.2f} |", flush=True)


if __name__ == "__main__":
    main()
