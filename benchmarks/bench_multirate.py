"""Wall time of the multi-rate co-simulation against fmpy running the plant alone at the fine step.

For each oversampling m: the full co-simulation of a scenario (NC -> plant FMU stepped m times per
recording step -> sensors stepped m times, sampling the interval mean -> monitor; ``Master.run`` only)
against ``fmpy.simulate_fmu`` on the same plant FMU alone at the fine step ``step / m``, recording every
fine step, with the NC's speed reference as its input table: the same number of doStep calls. Prints
seconds (best of ``--repeat``) and the ratio cosim / fmpy (target <= 0.3 at m = 10, issue 26), the loop
that stepped the plant and the sensors (the compiled fine loop, cosim/fastloop, where it applies), and
with ``--python`` the same co-simulation in the Python loop (``FEEDDRIVE_FASTLOOP=0``) in the same run.

    python benchmarks/bench_multirate.py [--scenario examples/tool_change.yaml] [--oversample 1 4 10] [--python]
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
    parser.add_argument("--python", action="store_true", help="also time the Python loop (FEEDDRIVE_FASTLOOP=0)")
    args = parser.parse_args(argv)
    base = load_scenario(args.scenario)
    print(f"scenario {base.name}, recording step {base.step:g} s, best of {args.repeat}")
    extra = " Python loop [s] | Python / fmpy |" if args.python else ""
    print(f"| oversample | doStep calls | cosim [s] | fmpy [s] | cosim / fmpy |{extra}\n"
          f"| --- | --- | --- | --- | --- |{' --- | --- |' if args.python else ''}")
    for m in args.oversample:
        scenario = base.model_copy(update={"plant": base.plant.model_copy(update={"oversample": m})})
        best: dict[str, float] = {}
        for _ in range(args.repeat):
            wall, master, signals = cosim_run(scenario)
            runs = {"cosim": wall, "fmpy": fmpy_run(scenario, master.stop_time, signals, m)}
            if args.python:
                runs["python"] = cosim_run(scenario, python_loop=True)[0]
            best = {k: min(v, best.get(k, v)) for k, v in runs.items()}
        more = f" {best['python']:.2f} | {best['python'] / best['fmpy']:.2f} |" if args.python else ""
        print(f"| {m} | {master.n_steps * m} | {best['cosim']:.2f} | {best['fmpy']:.2f} | "
              f"{best['cosim'] / best['fmpy']:.2f} |{more}", flush=True)
    print(f"loop: {master.loop}")


if __name__ == "__main__":
    main()
