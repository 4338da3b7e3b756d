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
from pathlib import Path

from bench_cosim import cosim_run, fmpy_run  # the same baseline as bench_cosim (run from benchmarks/ or the root)

from feeddrive.cosim.scenario import load_scenario

ROOT = Path(__file__).resolve().parents[1]


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
