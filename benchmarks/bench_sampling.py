"""Bias of R and L against the plant's oversampling and the sensors' sampling mode, on a vendor-style drive.

The drive (tests/plants/vendor_drive.py) holds its inputs over each step and has no reference filter:
every step of the NC's speed command jumps its terminal voltage. Noise-free sensors sample every
analogue channel as ``--channels`` says (all of them, or the two voltages alone); the monitor estimates
R and L from the tool change of examples/tool_change.yaml. Prints a Markdown table of the biases [%].

    python benchmarks/bench_sampling.py [--steps 1e-4 1e-3] [--oversample 1 2 4 10]
                                        [--modes instant mean lowpass] [--channels all|voltage]
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import yaml

from feeddrive.cosim.run import run_scenario
from feeddrive.cosim.scenario import scenario_from_dict

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "plants"))
from vendor_drive import ROLE_MAP, TRUTH, build_vendor_drive  # noqa: E402

SILENT = {"noise": 0.0}


def scenario(fmu: Path, step: float, oversample: int, mode: str, channels: str, seed: int = 1,
             noise: bool = False) -> dict:
    """The tool change on the vendor drive; ``mode`` on every analogue channel or on the voltage alone."""
    data = yaml.safe_load((ROOT / "examples" / "tool_change.yaml").read_text())
    data["step"] = step
    data["plant"] = {"fmu": str(fmu), "oversample": oversample, "map": ROLE_MAP}
    chain = {"sampling": mode}
    other = chain if channels == "all" else {"sampling": "instant"}
    quiet = {} if noise else SILENT
    data["sensors"] = {"seed": seed, "current": [other | quiet, other | quiet], "voltage": chain | quiet,
                       "voltage_ref": chain | quiet, "tachometer": other | quiet, "encoder": SILENT}
    data["monitor"] = {"db": ":memory:"}
    return data


def biases(data: dict, out: Path) -> dict[str, float]:
    """Relative error [%] of R and L from the run's one motion."""
    run = run_scenario(scenario_from_dict(data), out, plots=False)
    (motion,) = run.report["motions"]
    p = motion["parameters"]
    return {k: 100 * (p[k]["value"] / TRUTH[k] - 1) for k in ("R", "L")}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=float, nargs="+", default=[1e-4, 1e-3])
    ap.add_argument("--oversample", type=int, nargs="+", default=[1, 2, 4, 10])
    ap.add_argument("--modes", nargs="+", default=["instant", "mean", "lowpass"])
    ap.add_argument("--channels", choices=("all", "voltage"), default="all")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        fmu = build_vendor_drive(Path(tmp) / "VendorHeldDrive.fmu")
        print("| recording | oversample | sampling | R [%] | L [%] |\n| --- | --- | --- | --- | --- |")
        for step in args.steps:
            for m in args.oversample:
                for mode in args.modes:
                    b = biases(scenario(fmu, step, m, mode, args.channels), Path(tmp) / f"{step}-{m}-{mode}")
                    print(f"| {1 / step / 1000:g} kHz | {m} | {mode} | {b['R']:+.2f} | {b['L']:+.2f} |", flush=True)


if __name__ == "__main__":
    main()
