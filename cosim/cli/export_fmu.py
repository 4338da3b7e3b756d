"""``cosim export-fmu nc|sensors|monitor SCENARIO.yaml --out DIR [--overwrite]``: one component as an FMU.

Builds an FMI 2.0 Co-Simulation FMU (pythonfmu) of the scenario's NC, sensors or monitor, configured
from the scenario's section (stored whole in the FMU's resources/component.json; its scalar keys are
FMU parameters). The target machine needs Python and this package installed.
"""
from __future__ import annotations

import argparse
from pathlib import Path

#: the exportable components (feeddrive.cosim.export.build.KINDS; not imported here, so that the other
#: subcommands do not load pythonfmu)
COMPONENTS = ("nc", "sensors", "monitor")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("component", choices=COMPONENTS, help="the component to export")
    parser.add_argument("scenario", type=Path, help="scenario YAML file whose section configures the FMU")
    parser.add_argument("--out", type=Path, required=True, help="folder for the .fmu (created)")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing FMU of the same name")


def main(args: argparse.Namespace) -> int:
    from feeddrive.cosim.export.build import build_component_fmu
    from feeddrive.cosim.fmu_inspect import model_description
    from feeddrive.cosim.scenario import load_scenario

    scenario = load_scenario(args.scenario)
    path = build_component_fmu(args.component, scenario, args.out, overwrite=args.overwrite)
    md = model_description(path)
    count = {c: sum(v.causality == c for v in md.modelVariables) for c in ("input", "output", "parameter")}
    print(path)
    print(f"{md.modelName}: FMI 2.0 Co-Simulation (pythonfmu), {count['input']} inputs, {count['output']} "
          f"outputs, {count['parameter']} parameters, step_size {scenario.step:g} s; "
          f"needs Python with feeddrive-monitor installed")
    return 0
