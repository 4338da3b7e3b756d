"""``cosim export-system SCENARIO.yaml --out DIR [--no-ssp] [--overwrite]``: the scenario as an OSP system.

Writes the plant FMU, the NC, sensors and monitor FMUs, OspSystemStructure.xml (connections, step,
initial values), OspScenario.json (the timed events) and an SSP archive into DIR; see
cosim/export/system.py. Open it with OSP's cosim-cli (``cosim run DIR``, the stop time and OspScenario.json as its ``cosim help
run`` says) or libcosimpy (``CosimExecution.from_osp_config_file(DIR)``, ``load_scenario``).
"""
from __future__ import annotations

import argparse
from pathlib import Path


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scenario", type=Path, help="scenario YAML file")
    parser.add_argument("--out", type=Path, required=True, help="folder of the system (created)")
    parser.add_argument("--no-ssp", action="store_true", help="do not write the SSP archive")
    parser.add_argument("--overwrite", action="store_true", help="replace the files of an earlier export")


def main(args: argparse.Namespace) -> int:
    from feeddrive.cosim.export.system import export_system, stop_time
    from feeddrive.cosim.scenario import load_scenario

    scenario = load_scenario(args.scenario)
    paths = export_system(scenario, args.out, ssp=not args.no_ssp, overwrite=args.overwrite)
    stop = stop_time(scenario)
    print(f"{scenario.name}: {len([k for k in paths if k in ('nc', 'plant', 'sensors', 'monitor')])} FMUs, "
          f"step {scenario.step:g} s, stop {stop:.12g} s, {len(scenario.events)} timed events -> {args.out}")
    for key in ("system", "scenario", "ssp"):
        if key in paths:
            print(f"  {paths[key]}")
    if scenario.plant.input_hold == "foh":
        print("  note: OSP masters set no input derivatives: the plant holds its speed reference over each step "
              "(input_hold zoh; R and L come out ~0.2 % lower than with cosim run's foh)")
    print(f"  open it: libcosimpy CosimExecution.from_osp_config_file({str(Path(args.out))!r}), run to {stop:.12g} s, "
          "or OSP's cosim-cli 'cosim run' on the folder (README)")
    return 0
